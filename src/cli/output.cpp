#include "output.hpp"

#include <algorithm>
#include <cstdio>
#include <thread>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"

namespace bouncecal::cli {

CLI::Option* AddOutputOption(CLI::App* sub, const std::string& names, std::string* path,
                             const std::string& help) {
  const std::string shown = names.substr(names.rfind(',') + 1);  // "--output" of "-o,--output"
  return sub->add_option(names, *path, help)->each([shown](const std::string& value) {
    if (value.empty()) {
      throw Error(ErrorCode::kOutput, shown + ": the output path is empty (give a file name)");
    }
  });
}

void PrintWarnings(const std::vector<Warning>& warnings) {
  for (const Warning& w : warnings)
    std::fprintf(stderr, "bouncecal: warning [%s]: %s%s\n", w.code.c_str(),
                 FlagText(w.message).c_str(),
                 w.hint.empty() ? "" : ("; next: " + FlagText(w.hint)).c_str());
}

int DefaultJobs() {
  const unsigned n = std::thread::hardware_concurrency();
  return static_cast<int>(std::clamp(n == 0 ? 1u : n, 1u, 8u));
}

namespace {

// Library text -> command-line text. Phrases first (whole wordings the flag changes), then
// field names, each replaced only as a whole name (SceneOverrides::law is not
// SceneOverrides::law_sets).
constexpr NameInFrontEnd kPhrases[] = {
    {"exists and WriteOptions::force is false (set it to replace the file)",
     "exists; use --force to replace it"},
    {"scene from overrides: ", "scene from flags: "},
    {" (after the overrides)", " (after command-line overrides)"},
};
constexpr NameInFrontEnd kFields[] = {
    {"SceneOverrides::height_m", "--height"},
    {"SceneOverrides::height_sigma_m", "--height-sigma"},
    {"SceneOverrides::impact_speed_m_s", "--impact-speed"},
    {"SceneOverrides::diameter_m", "--diameter"},
    {"SceneOverrides::density_kg_m3", "--density"},
    {"SceneOverrides::mass_kg", "--mass"},
    {"SceneOverrides::material", "--material"},
    {"SceneOverrides::drag", "--drag"},
    {"SceneOverrides::g_m_s2", "--g"},
    {"SceneOverrides::law", "--law"},
    {"SceneOverrides::law_sets", "--set"},
    {"SceneOverrides::expression", "--expression"},
    {"DropInputOptions::impacts_files", "--impacts"},
    {"DetectOptions::start_s/end_s", "--start/--end"},
    {"DetectOptions::start_s", "--start"},
    {"DetectOptions::end_s", "--end"},
    {"DetectOptions::min_snr_db", "--min-snr-db"},
    {"DetectOptions::channel", "--channel"},
    {"ExportOptions::force", "--force"},
    {"ExportOptions::allow_approximation", "--allow-approximation"},
    {"WriteOptions::force", "--force"},
};

}  // namespace

std::string FlagText(const std::string& message) {
  std::string m = message;
  for (const NameInFrontEnd& p : kPhrases) {
    const std::string from = p.library, to = p.front_end;
    for (std::size_t at = m.find(from); at != std::string::npos; at = m.find(from, at + to.size()))
      m.replace(at, from.size(), to);
  }
  return RenameFields(m, kFields);
}

}  // namespace bouncecal::cli
