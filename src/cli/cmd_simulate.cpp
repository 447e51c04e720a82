// `bouncecal simulate`: a ball bouncing under a contact law, impact by impact.
//
//   bouncecal simulate --scene drop.toml
//   bouncecal simulate --law walton-braun --set gamma=0.5 --height 0.2 --json
//   bouncecal simulate --params params.json      # replay a fit: law, parameters, scene, drop
//
// Human table on stdout by default; --json (schema bouncecal.simulation/1, docs/schema.md) /
// --csv (shortest round-trip numbers; e empty when the ball arrived at rest) for scripts;
// messages on stderr only.
#include <charconv>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/param_resolved.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "commands.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {

struct SimulateFlags {
  SceneFlags scene;
  std::string params_file;  // --params: the scene, law and drop of a parameter file
  std::optional<double> rtol;
  std::optional<double> horizon_s;
  std::optional<int> max_impacts;
  bool integrate = false;
  bool json = false;
  bool csv = false;
};

double Restitution(const SimImpact& i) { return i.v_in_m_s > 0.0 ? i.v_out_m_s / i.v_in_m_s : 0.0; }

void PrintCsv(const Simulation& s) {
  std::cout << "index,time_s,v_in_m_s,v_out_m_s,e,contact_s,peak_overlap_m,peak_force_n,steps\n";
  for (size_t k = 0; k < s.impacts.size(); ++k) {
    const SimImpact& i = s.impacts[k];
    std::cout << k << "," << CsvNumber(i.time_s) << "," << CsvNumber(i.v_in_m_s) << ","
              << CsvNumber(i.v_out_m_s) << ","
              << (i.v_in_m_s > 0.0 ? CsvNumber(i.v_out_m_s / i.v_in_m_s) : "") << ","
              << CsvNumber(i.contact_s) << "," << CsvNumber(i.peak_overlap_m) << ","
              << CsvNumber(i.peak_force_n) << "," << i.steps << "\n";
  }
}

template <class Integer>
void AppendInteger(std::string& row, Integer value, int width) {
  char buffer[32];
  const std::to_chars_result r = std::to_chars(buffer, buffer + sizeof buffer, value);
  const size_t n = static_cast<size_t>(r.ptr - buffer), w = static_cast<size_t>(width);
  if (n < w) row.append(w - n, ' ');
  row.append(buffer, n);
  row.push_back(' ');
}

void PrintHuman(const ContactLaw& law, const std::vector<double>& p, const Simulation& s) {
  std::printf("law %s:", law.Name().c_str());
  for (size_t i = 0; i < p.size(); ++i) {
    std::printf(" %s = %g %s", law.Parameters()[i].name.c_str(), p[i],
                law.Parameters()[i].unit.c_str());
  }
  std::printf("\n%5s %14s %11s %11s %9s %11s %12s %11s %6s\n", "k", "time_s", "v_in_m_s",
              "v_out_m_s", "e", "contact_us", "overlap_um", "force_n", "steps");
  // "%5zu %14.9f %11.6f %11.6f %9.6f %11.4f %12.5f %11.4g %6d\n" without printf's format parsing
  // (10 000 rows for the Hunt-Crossley laws).
  std::string row;
  for (size_t k = 0; k < s.impacts.size(); ++k) {
    const SimImpact& i = s.impacts[k];
    row.clear();
    AppendInteger(row, k, 5);
    AppendFixed(&row, i.time_s, 9, 14);
    row.push_back(' ');
    AppendFixed(&row, i.v_in_m_s, 6, 11);
    row.push_back(' ');
    AppendFixed(&row, i.v_out_m_s, 6, 11);
    row.push_back(' ');
    AppendFixed(&row, Restitution(i), 6, 9);
    row.push_back(' ');
    AppendFixed(&row, i.contact_s * 1e6, 4, 11);
    row.push_back(' ');
    AppendFixed(&row, i.peak_overlap_m * 1e6, 5, 12);
    row.push_back(' ');
    AppendGeneral(&row, i.peak_force_n, 4, 11);
    row.push_back(' ');
    AppendInteger(row, i.steps, 6);
    row.back() = '\n';
    std::fwrite(row.data(), 1, row.size(), stdout);
  }
  const EnergyLedger& e = s.energy;
  std::printf(
      "energy (J): initial %.6g, final mechanical %.6g, dissipated in contacts %.6g, by drag "
      "%.6g, internal %.6g, balance error %.3g\n",
      e.initial_j, e.final_mechanical_j, e.dissipated_contact_j, e.dissipated_drag_j, e.internal_j,
      e.balance_error_j);
  if (s.map_panels + s.map_panels_refused > 0) {
    std::printf(
        "contact map: %d contacts interpolated (steps 0) from %d panels, %d panels refused by "
        "their check (integrated); --integrate integrates every contact\n",
        s.mapped_contacts, s.map_panels, s.map_panels_refused);
  }
  std::printf("stop: %s (%s)\n", StopReasonName(s.stop_reason), s.stop_detail.c_str());
}

// The replay scene of a parameter file (param_resolved.hpp). Scene and law flags would make it
// another scene than the fit's, so they are refused with --params.
Scene ParamsScene(const SimulateFlags& f) {
  const SceneFlags& s = f.scene;
  const bool any_scene_flag = !s.scene_file.empty() || s.height_m || s.impact_speed_m_s ||
                              s.diameter_m || s.density_kg_m3 || s.mass_kg || !s.material.empty() ||
                              !s.drag.empty() || s.buoyancy || s.contact_duration || s.g_m_s2 ||
                              !s.law.empty() || !s.law_sets.empty() || !s.expression.empty();
  if (any_scene_flag) {
    throw Error(ErrorCode::kUsage,
                "--params " + f.params_file +
                    ": the file is the whole scene and law; scene and law flags cannot be "
                    "combined with it (use --max-impacts/--horizon to shorten the run)");
  }
  return ReplayFromParamFile(ReadParamFile(f.params_file), f.params_file).scene;
}

// "law NAME (expression '...')" or "law NAME (k = ..., A = ...)": what produced a result.
std::string LawLabel(const Scene& scene, const ContactLaw& law, const std::vector<double>& p) {
  std::string label = "law " + Abbreviate(law.Name());
  if (!scene.law.expression.empty()) return label + " '" + Abbreviate(scene.law.expression) + "'";
  for (size_t i = 0; i < p.size(); ++i) {
    label += (i == 0 ? " (" : ", ") + law.Parameters()[i].name + " = " + FormatGeneral(p[i]);
  }
  return label + (p.empty() ? "" : ")");
}

// A simulation the integrator gave up on, or with a non-finite number anywhere, is not a
// result: exit 9 naming the law and its parameters (docs/cli.md "Exit codes"), never "inf"/"nan" or
// a JSON null where a number is documented.
void CheckUsable(const Scene& scene, const ContactLaw& law, const std::vector<double>& p,
                 const Simulation& sim) {
  if (sim.stop_reason == StopReason::kStepLimit) {
    throw Error(ErrorCode::kBadParameter,
                "simulate: " + LawLabel(scene, law, p) + ": no usable result: " + sim.stop_detail);
  }
  const EnergyLedger& en = sim.energy;
  const std::pair<const char*, double> ledger[] = {
      {"initial", en.initial_j},
      {"final mechanical", en.final_mechanical_j},
      {"dissipated in contacts", en.dissipated_contact_j},
      {"dissipated by drag", en.dissipated_drag_j},
      {"internal", en.internal_j},
      {"balance error", en.balance_error_j}};
  std::string bad;
  for (const auto& [name, value] : ledger) {
    if (!std::isfinite(value) && bad.empty()) bad = std::string("energy ") + name;
  }
  for (size_t k = 0; k < sim.impacts.size() && bad.empty(); ++k) {
    const SimImpact& i = sim.impacts[k];
    for (double v :
         {i.time_s, i.v_in_m_s, i.v_out_m_s, i.contact_s, i.peak_overlap_m, i.peak_force_n}) {
      if (!std::isfinite(v)) bad = "impact " + std::to_string(k);
    }
  }
  if (!bad.empty()) {
    throw Error(ErrorCode::kBadParameter, "simulate: " + LawLabel(scene, law, p) + ": the " + bad +
                                              " is not a finite number (the scene's "
                                              "values or the law's parameters are out of the "
                                              "range the simulation can represent)");
  }
}

void Run(const SimulateFlags& f) {
  if (f.json && f.csv) throw Error(ErrorCode::kUsage, "--json and --csv are exclusive");
  Scene scene = f.params_file.empty() ? ResolveScene(f.scene) : ParamsScene(f);
  if (f.horizon_s) {
    if (!(*f.horizon_s > 0.0) || !std::isfinite(*f.horizon_s)) {
      throw Error(ErrorCode::kUsage, "--horizon: must be a positive number of seconds");
    }
    scene.limits.horizon_s = *f.horizon_s;
  }
  if (f.max_impacts) {
    if (*f.max_impacts < 1 || *f.max_impacts > kMaxImpactsLimit) {
      // Checked before the work: 10^8 impacts would have run for an hour and written ~30 GB.
      throw Error(ErrorCode::kUsage, "--max-impacts " + std::to_string(*f.max_impacts) +
                                         ": must be in [1, " + std::to_string(kMaxImpactsLimit) +
                                         "] (about 300 bytes of JSON per impact)");
    }
    scene.limits.max_impacts = *f.max_impacts;
  }
  SimulatorOptions options;
  if (f.rtol) options.rel_tolerance = *f.rtol;
  options.use_closed_form = !f.integrate;
  options.contact_map = !f.integrate;
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kUsage, "--rtol: " + why);
  const std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);
  const std::vector<double> p = law->ParameterValues();
  const Simulation sim = Simulate(scene, *law, p, options);
  CheckUsable(scene, *law, p, sim);
  if (f.json) {
    std::cout << DumpJson(SimulationJson(scene, *law, p, sim), 2) << "\n";
  } else if (f.csv) {
    PrintCsv(sim);
  } else {
    PrintHuman(*law, p, sim);
  }
}

}  // namespace

void RegisterSimulate(CLI::App& app) {
  auto flags = std::make_shared<SimulateFlags>();
  CLI::App* sub = app.add_subcommand(
      "simulate", "simulate a bouncing ball under a contact law (impacts, energy ledger)");
  AddSceneFlags(sub, &flags->scene, true);
  sub->add_option("--params", flags->params_file,
                  "replay a parameter file (calibrate -o): its law, parameters, scene and the "
                  "fitted first impact speed");
  sub->add_option("--rtol", flags->rtol,
                  "relative tolerance of the contact integrator (default 1e-9)");
  sub->add_option("--horizon", flags->horizon_s, "stop after this time, s (scene limits)");
  sub->add_option("--max-impacts", flags->max_impacts, "stop after this many impacts");
  sub->add_flag("--integrate", flags->integrate,
                "integrate every contact even where the law has a closed form or the contact map "
                "would serve it");
  sub->add_flag("--json", flags->json, "JSON on stdout");
  sub->add_flag("--csv", flags->csv, "CSV of the impacts on stdout");
  sub->callback([flags]() { Run(*flags); });
}

}  // namespace bouncecal::cli
