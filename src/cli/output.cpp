#include "output.hpp"

#include <cmath>
#include <cstdio>

#include "bouncecal/core/error.hpp"

namespace bouncecal::cli {

nlohmann::json JsonNumber(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

nlohmann::json JsonNumber(const std::optional<double>& v) {
  return v ? JsonNumber(*v) : nlohmann::json();
}

nlohmann::json WarningsJson(const std::vector<Warning>& warnings) {
  nlohmann::json out = nlohmann::json::array();
  for (const Warning& w : warnings) {
    out.push_back({{"code", w.code},
                   {"message", w.message},
                   {"impact", w.impact >= 0 ? nlohmann::json(w.impact) : nlohmann::json()}});
  }
  return out;
}

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
    std::fprintf(stderr, "bouncecal: warning [%s]: %s\n", w.code.c_str(), w.message.c_str());
}

}  // namespace bouncecal::cli
