// `bouncecal laws [--json|--csv] [--scene FILE] [NAME]`: every registered contact law with its
// formula, source, end rule, parameters (unit, bounds, default, damping flag) and the closed
// forms it provides. Defaults that depend on the scene (Hertz stiffness from the materials) are
// shown for the given scene, or for the default scene (seed 002: 1 cm steel ball on copper).
// --json: schema bouncecal.laws/1 (docs/schema.md); --csv: law,parameter,unit,default,lower,
// upper,damping,description (one row per parameter; shortest round-trip numbers).
#include <cmath>
#include <iomanip>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "commands.hpp"

namespace bouncecal::cli {
namespace {

struct LawsFlags {
  bool json = false;
  bool csv = false;
  std::string scene_file;
  std::string name;
};

// A default or a bound; the registry writes an unbounded side as +-1e300.
std::string BoundText(double v) {
  if (v <= -1e300) return "-inf";
  if (v >= 1e300) return "inf";
  return FormatGeneral(v);
}

void Run(const LawsFlags& f) {
  const Scene scene = f.scene_file.empty() ? Scene{} : LoadSceneFile(f.scene_file);
  std::vector<LawInfo> infos = RegisteredLaws();
  if (!f.name.empty()) {
    std::vector<LawInfo> one;
    for (const LawInfo& i : infos) {
      if (i.name == f.name) one.push_back(i);
    }
    if (one.empty()) CreateLaw(ExampleLawSpec(f.name), scene);  // throws the "unknown law" error
    infos = one;
  }
  std::vector<nlohmann::json> laws;
  std::ostringstream text;
  std::ostringstream csv;
  csv << "law,parameter,unit,default,lower,upper,damping,description\n";
  for (const LawInfo& info : infos) {
    const std::unique_ptr<ContactLaw> law = CreateLaw(ExampleLawSpec(info.name), scene);
    const std::string expression = ExampleLawSpec(info.name).expression;
    laws.push_back(LawListingJson(*law, info.summary, expression));
    for (const ParameterSpec& s : law->Parameters()) {
      csv << CsvField(info.name) << "," << CsvField(s.name) << "," << CsvField(s.unit) << ","
          << CsvNumber(s.default_value) << "," << CsvNumber(s.lower) << "," << CsvNumber(s.upper)
          << "," << (s.damping ? 1 : 0) << "," << CsvField(s.description) << "\n";
    }

    text << info.name << " — " << info.summary << "\n";
    text << "  " << law->Formula() << "\n";
    text << "  source: " << law->Source() << "\n";
    text << "  contact ends at: "
         << (law->EndRule() == ContactEnd::kForceZero ? "force = 0" : "overlap = 0")
         << (law->StateSize() > 0 ? "; internal state: " + std::to_string(law->StateSize()) : "")
         << "\n";
    if (info.needs_expression) {
      text << "  parameters: any names you give (example below); d = overlap (m), v = rate (m/s)\n";
    }
    text << "  " << std::left << std::setw(8) << "param" << std::setw(10) << "unit" << std::setw(12)
         << "default" << std::setw(24) << "bounds"
         << "role\n";
    for (const ParameterSpec& s : law->Parameters()) {
      text << "  " << std::setw(8) << s.name << std::setw(10) << s.unit << std::setw(12)
           << BoundText(s.default_value) << std::setw(24)
           << ("[" + BoundText(s.lower) + ", " + BoundText(s.upper) + "]")
           << (s.damping ? "damping (fitted)" : "held") << "\n";
    }
    std::string forms;
    for (const std::string& c : law->ClosedForms()) forms += (forms.empty() ? "" : ", ") + c;
    text << "  closed forms: " << (forms.empty() ? "none (integrated)" : forms) << "\n\n";
  }
  if (f.json) {
    std::cout << DumpJson(LawsJson(laws), 2) << "\n";
  } else if (f.csv) {
    std::cout << csv.str();
  } else {
    std::cout << text.str();
  }
}

}  // namespace

void RegisterLaws(CLI::App& app) {
  auto flags = std::make_shared<LawsFlags>();
  CLI::App* sub = app.add_subcommand(
      "laws", "list the contact laws: parameters, units, bounds, defaults, closed forms");
  sub->add_option("name", flags->name, "show only this law");
  sub->add_option("--scene", flags->scene_file,
                  "scene whose materials set the defaults (default: 1 cm steel ball on copper)");
  auto* json = sub->add_flag("--json", flags->json, "JSON on stdout");
  auto* csv = sub->add_flag("--csv", flags->csv, "CSV on stdout: one row per law parameter");
  json->excludes(csv);
  sub->callback([flags]() { Run(*flags); });
}

}  // namespace bouncecal::cli
