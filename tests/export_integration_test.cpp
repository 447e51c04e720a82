// Integration suite (ctest label "integration"): fits of four laws exported to LAMMPS, LIGGGHTS
// and Yade, run by the real simulators, and compared with `bouncecal simulate --params`.
//
// Each case: render a recording with the law (synth, 5 cm drop so the runs stay short), fit it
// (calibrate; outcome must be "converged"), export it (--impacts 3), run the directory's run.sh,
// read trace.csv, locate the impacts from it with this file's own extractor (independent of
// the exported impacts.awk, which must agree to 1e-9), and compare impact by impact with the
// replay of the same parameter file:
//   - e per impact within 0.002, or within the stated mapping error plus the stated time-step
//     error when the mapping is an approximation (the mapping error must then be <= 0.01);
//   - intervals between impacts within 0.1 %.
// A simulator missing from PATH FAILS the case with the install command; nothing is skipped.
// Every case writes one Markdown row to build/integration/LAW_TARGET.md; the docs/export.md law x
// simulator table is `tools/integration_table.sh` over those rows.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "test_util.hpp"

namespace {

using bouncecal::testing_util::CommandResult;
using bouncecal::testing_util::RunCommand;
using bouncecal::testing_util::ScratchDir;
using bouncecal::testing_util::Slurp;
using nlohmann::json;

const std::string kBin = BOUNCECAL_BINARY;

struct Case {
  std::string law;
  std::string set;  // synth's law parameter
  std::string target;
};

void PrintTo(const Case& c, std::ostream* os) { *os << c.law << " -> " << c.target; }

struct Impact {
  double time_s, v_in_m_s, v_out_m_s;
};

// Impacts from a trace (t_s,z_m,vz_m_s): a bounce is a rise of vz; arrival from the last
// flight sample before it, rebound from the first after it, on the exact gravity parabola.
std::vector<Impact> ImpactsFromTrace(const std::string& path, double radius_m, double g) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);  // header
  std::vector<Impact> out;
  bool have = false, pending = false;
  double prev_v = 0.0, last_t = 0.0, last_z = -1.0, last_v = 0.0;
  Impact cur{};
  while (std::getline(in, line)) {
    double t, z, v;
    char c1, c2;
    std::istringstream ss(line);
    if (!(ss >> t >> c1 >> z >> c2 >> v)) break;
    if (have && !pending && v > prev_v + 1e-12 + 1e-9 * std::abs(prev_v)) {
      if (last_z < radius_m) break;
      const double w = std::sqrt(last_v * last_v + 2.0 * g * (last_z - radius_m));
      cur = {last_t + (last_v + w) / g, w, 0.0};
      pending = true;
    }
    have = true;
    prev_v = v;
    if (z >= radius_m) {
      if (pending) {
        cur.v_out_m_s = std::sqrt(v * v + 2.0 * g * (z - radius_m));
        out.push_back(cur);
        pending = false;
      }
      last_t = t;
      last_z = z;
      last_v = v;
    }
  }
  return out;
}

std::vector<Impact> ReadImpactsCsv(const std::string& path) {
  std::ifstream in(path);
  std::string line;
  std::getline(in, line);
  std::vector<Impact> out;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string f[4];
    for (auto& s : f) std::getline(ss, s, ',');
    out.push_back({std::stod(f[1]), std::stod(f[2]), std::stod(f[3])});
  }
  return out;
}

const char* Package(const std::string& target) {
  return target == "lammps" ? "lammps" : target == "liggghts" ? "liggghts" : "yade";
}
const char* Program(const std::string& target) {
  return target == "lammps" ? "lmp" : target == "liggghts" ? "liggghts" : "yade";
}

// The simulator must be there: a missing one fails with the install command.
void RequireSimulator(const std::string& target) {
  const CommandResult which =
      RunCommand("sh", std::string("-c 'command -v ") + Program(target) + "'");
  ASSERT_EQ(which.exit_code, 0) << Program(target)
                                << " is not on PATH: the integration suite needs the real "
                                   "simulators; install them with tools/install-integration-"
                                   "deps.sh (apt-get install -y "
                                << Package(target) << " openmpi-bin)";
}

// Exports `params` (a converged fit of `law`) to `target` in dir/deck, runs it, and compares the
// simulator's first three impacts with `bouncecal simulate --params` of the same file; writes
// the docs/export.md table's row, `label` in its first column, as build/integration/ROW.md. Returns
// the mapping (export --json).
json ExportRunAndCompare(const ScratchDir& dir, const std::string& params, const std::string& law,
                         const std::string& target, const std::string& row_name,
                         const std::string& label, std::chrono::steady_clock::time_point start) {
  const std::string out = dir / "deck";
  const json fit = json::parse(Slurp(params));
  // Export (from the scratch directory, which must then hold the deck and nothing new: the
  // simulator's version query once left LIGGGHTS's log.liggghts in the working directory) and
  // run.
  auto entries = [&dir] {
    std::set<std::string> names;
    for (const auto& entry : std::filesystem::directory_iterator(dir.path()))
      names.insert(entry.path().filename().string());
    return names;
  };
  std::set<std::string> expected = entries();
  expected.insert("deck");
  CommandResult r = RunCommand("sh", "-c 'cd " + dir.path().string() + " && " + kBin + " export " +
                                         params + " --to " + target + " -o " + out +
                                         " --impacts 3 --allow-approximation --json'");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  if (r.exit_code != 0) return json();
  EXPECT_EQ(entries(), expected);
  const json mapping = json::parse(r.out);
  EXPECT_EQ(mapping["target"], target);
  EXPECT_EQ(mapping["law"]["name"], law);
  const double mapping_error = mapping["max_e_error"].get<double>();
  const double step_error = mapping["time_step_e_error"].get<double>();
  EXPECT_LE(mapping_error, 0.01) << "the mapping must carry the fit within 0.01";
  r = RunCommand(out + "/run.sh", "");
  EXPECT_EQ(r.exit_code, 0) << r.out << r.err;
  if (r.exit_code != 0) return mapping;

  // Impacts: this file's extractor on trace.csv, and run.sh's impacts.csv, agree.
  const double radius = fit["resolved"]["ball"]["radius_m"].get<double>();
  const double g = fit["resolved"]["environment"]["effective_g_m_s2"].get<double>();
  const std::vector<Impact> sim = ImpactsFromTrace(out + "/trace.csv", radius, g);
  const std::vector<Impact> csv = ReadImpactsCsv(out + "/impacts.csv");
  EXPECT_GE(sim.size(), 3u);
  EXPECT_EQ(csv.size(), sim.size());
  if (sim.size() < 3 || csv.size() != sim.size()) return mapping;
  for (size_t k = 0; k < sim.size(); ++k) {
    EXPECT_NEAR(csv[k].time_s, sim[k].time_s, 1e-9);
    EXPECT_NEAR(csv[k].v_out_m_s / csv[k].v_in_m_s, sim[k].v_out_m_s / sim[k].v_in_m_s, 1e-9);
  }

  // The replay of the same file.
  r = RunCommand(kBin, "simulate --params " + params + " --max-impacts 3 --json");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  const json ref = json::parse(r.out)["impacts"];
  EXPECT_EQ(ref.size(), 3u);
  if (ref.size() != 3u) return mapping;
  // 0.002 for exact and matched mappings (their error is 0 to 1e-8); an approximation may be
  // off by its stated error plus the time step's. An approximation's e error carries into the
  // next flight, so its intervals are compared for the rebound speed the simulator produced
  // (interval x v_out,sim / v_out,ref): the flight and contact timing, not the e error again.
  const bool approximated = mapping["mapping"] == "approximated";
  const double e_tol = std::max(0.002, mapping_error + step_error);
  // A fit with air drag is exported without it (the deck's note says so): the simulator's
  // flights are vacuum flights, so only e per impact (the contact law's) is compared.
  bool vacuum = false;
  for (const auto& n : mapping["notes"])
    vacuum |= n.get<std::string>().find("air drag") != std::string::npos;
  double worst_e = 0.0, worst_interval = 0.0;
  for (size_t k = 0; k < 3; ++k) {
    const double e_ref = ref[k]["e"].get<double>();
    const double e_sim = sim[k].v_out_m_s / sim[k].v_in_m_s;
    EXPECT_NEAR(e_sim, e_ref, e_tol) << "impact " << k;
    worst_e = std::max(worst_e, std::abs(e_sim - e_ref));
    if (vacuum) continue;
    const double v_ref = ref[k]["v_in_m_s"].get<double>();
    EXPECT_NEAR(sim[k].v_in_m_s / v_ref, 1.0,
                approximated ? static_cast<double>(k + 1) * e_tol / e_ref : 2e-3)
        << "impact " << k;
    if (k > 0) {
      double dt_ref = ref[k]["time_s"].get<double>() - ref[k - 1]["time_s"].get<double>();
      if (approximated) {
        dt_ref *= sim[k - 1].v_out_m_s / ref[k - 1]["v_out_m_s"].get<double>();
      }
      const double dt_sim = sim[k].time_s - sim[k - 1].time_s;
      EXPECT_NEAR(dt_sim / dt_ref, 1.0, 1e-3) << "interval " << k - 1;
      worst_interval = std::max(worst_interval, std::abs(dt_sim / dt_ref - 1.0));
    }
  }

  // One row of the law x simulator table of docs/export.md.
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::filesystem::create_directories(std::string(BOUNCECAL_BUILD_DIR) + "/integration");
  std::ofstream row(std::string(BOUNCECAL_BUILD_DIR) + "/integration/" + row_name + ".md");
  char interval[32] = "– (vacuum)";  // flights without the fit's drag are not compared
  if (!vacuum) std::snprintf(interval, sizeof interval, "%.1e", worst_interval);
  char buf[1024];
  std::snprintf(
      buf, sizeof buf, "| %s | %s | `%s` | %s | %.2g | %.5f | %.5f | %.1e | %.1e | %s | %.0f |\n",
      label.c_str(), mapping["simulator_version"].get<std::string>().c_str(),
      mapping["native_law"].get<std::string>().c_str(),
      mapping["mapping"].get<std::string>().c_str(), mapping_error, ref[0]["e"].get<double>(),
      sim[0].v_out_m_s / sim[0].v_in_m_s, worst_e, step_error, interval, seconds);
  row << buf;
  return mapping;
}

class ExportRun : public ::testing::TestWithParam<Case> {};

TEST_P(ExportRun, SimulatorBouncesLikeTheFit) {
  const Case& c = GetParam();
  const auto start = std::chrono::steady_clock::now();
  RequireSimulator(c.target);
  if (::testing::Test::HasFatalFailure()) return;
  ScratchDir dir("bc_integ");
  const std::string wav = dir / "rec.wav", params = dir / "params.json";
  // Fit: a 5 cm drop rendered with the law, fitted with the same law.
  CommandResult r = RunCommand(
      kBin, "synth --law " + c.law + " --set " + c.set + " --height 0.05 --seed 7 -o " + wav);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // The ball, drop and contacts the synth preset used (calibrate needs the ball; the law's
  // contacts are in the intervals).
  r = RunCommand(kBin, "calibrate " + wav + " --law " + c.law +
                           " --diameter 0.01 --material steel --height 0.05 --contact-duration "
                           "--strategy trajectory -o " +
                           params);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const json fit = json::parse(Slurp(params));
  ASSERT_EQ(fit["fit"]["outcome"], "converged") << fit["fit"]["message"];
  ExportRunAndCompare(dir, params, c.law, c.target, c.law + "_" + c.target, c.law, start);
}

// Constant-e balls fitted as a user first would (default restitution strategy, the contact
// duration not taken out of the intervals): the law's small misfit (law_misfit_small, below
// the 0.002 the simulators are held to) no longer blocks the export, and the simulators
// reproduce the fit. A 1 cm steel ball with air drag and the seed law's finite contacts
// (calibrate_verdict_test.cpp: the same recordings, their verdicts), and a glass marble.
struct ConstantECase {
  std::string name;    // row name
  std::string label;   // the docs/export.md table's first column
  std::string preset;  // synth preset (render settings)
  std::string scene;   // scene file text: ball, surface, drop, effects, law
  std::string law;
  std::string target;
};
void PrintTo(const ConstantECase& c, std::ostream* os) { *os << c.name << " -> " << c.target; }

class ConstantEExportRun : public ::testing::TestWithParam<ConstantECase> {};

TEST_P(ConstantEExportRun, ConvergedWithASmallMisfitExportsAndRuns) {
  const ConstantECase& c = GetParam();
  const auto start = std::chrono::steady_clock::now();
  RequireSimulator(c.target);
  if (::testing::Test::HasFatalFailure()) return;
  ScratchDir dir("bc_integ_e");
  const std::string scene = dir / "scene.toml", wav = dir / "rec.flac",
                    params = dir / "params.json";
  std::ofstream(scene) << c.scene;
  CommandResult r = RunCommand(kBin, "synth --preset " + c.preset + " --scene " + scene +
                                         " --truth-from law --seed 11 -o " + wav);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCommand(kBin, "calibrate " + wav + " --scene " + scene + " --quiet -o " + params);
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  const json fit = json::parse(Slurp(params));
  ASSERT_EQ(fit["fit"]["outcome"], "converged") << fit["fit"]["reason"];
  const json mapping =
      ExportRunAndCompare(dir, params, c.law, c.target, c.name + "_" + c.target, c.label, start);
  // The deck's JSON states the fit's misfit beside the mapping error.
  ASSERT_TRUE(mapping.is_object());
  EXPECT_EQ(mapping["law_misfit_e"], fit["fit"]["misfit_e"]);
}

std::vector<ConstantECase> ConstantECases() {
  const std::string steel =
      "[ball]\ndiameter_m = 0.01\nmaterial = \"steel\"\n[surface]\nmaterial = \"copper\"\n"
      "[drop]\nheight_m = 0.2\n[effects]\ndrag = \"quadratic\"\n"
      "[law]\nname = \"walton-braun\"\n[law.parameters]\ngamma = 0.406\n";
  const std::string marble =
      "[ball]\ndiameter_m = 0.016\nmaterial = \"glass\"\n[surface]\nmaterial = \"glass\"\n"
      "[drop]\nheight_m = 0.15\n[effects]\ndrag = \"quadratic\"\n"
      "[law]\nname = \"hertz-tsuji\"\n[law.parameters]\ne = 0.93\n";
  std::vector<ConstantECase> out;
  for (const char* target : {"lammps", "liggghts", "yade"}) {
    out.push_back({"steel_drag_walton_braun",
                   "walton-braun: 1 cm steel, drag, contacts in the intervals (law_misfit_small)",
                   "steel-copper", steel, "walton-braun", target});
    out.push_back({"glass_marble_hertz_tsuji",
                   "hertz-tsuji: glass marble, drag, contacts in the intervals (law_misfit_small)",
                   "glass-glass", marble, "hertz-tsuji", target});
  }
  return out;
}

INSTANTIATE_TEST_SUITE_P(Integration, ConstantEExportRun, ::testing::ValuesIn(ConstantECases()),
                         [](const ::testing::TestParamInfo<ConstantECase>& param_info) {
                           return param_info.param.name + "_" + param_info.param.target;
                         });

std::vector<Case> Cases() {
  const std::vector<std::pair<std::string, std::string>> laws = {
      {"walton-braun", "gamma=0.07"},
      {"hertz-tsuji", "e=0.9"},
      {"hertz-viscoelastic", "A=2e-7"},
      {"linear-dashpot", "c=10"},
  };
  std::vector<Case> out;
  for (const auto& [law, set] : laws) {
    for (const char* target : {"lammps", "liggghts", "yade"}) out.push_back({law, set, target});
  }
  return out;
}

INSTANTIATE_TEST_SUITE_P(Integration, ExportRun, ::testing::ValuesIn(Cases()),
                         [](const ::testing::TestParamInfo<Case>& param_info) {
                           std::string name = param_info.param.law + "_" + param_info.param.target;
                           for (char& ch : name) {
                             if (ch == '-') ch = '_';
                           }
                           return name;
                         });

// The packing deck (seed paper's validation scene) runs under MPI with 2 ranks; 2000 steps only
// (the full run is tools/packing.sh): every sphere is created and the density line is printed.
class PackingRun : public ::testing::TestWithParam<std::string> {};

TEST_P(PackingRun, DeckRunsUnderTwoMpiRanks) {
  const std::string target = GetParam();
  const CommandResult which =
      RunCommand("sh", std::string("-c 'command -v ") + Program(target) + " && command -v mpirun'");
  ASSERT_EQ(which.exit_code, 0) << Program(target) << " or mpirun is not on PATH: install them "
                                << "with tools/install-integration-deps.sh (apt-get install -y "
                                << Package(target) << " openmpi-bin)";
  ScratchDir dir("bc_pack");
  const std::string wav = dir / "rec.wav", params = dir / "params.json", out = dir / "deck";
  CommandResult r = RunCommand(kBin, "synth --law walton-braun --set gamma=0.2 --seed 3 -o " + wav);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCommand(kBin, "calibrate " + wav +
                           " --law walton-braun --diameter 0.01 --material steel "
                           "--contact-duration --strategy trajectory -o " +
                           params);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCommand(kBin, "export " + params + " --to " + target + " --scene packing -o " + out);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = RunCommand("env", "NP=2 " + out + "/run.sh -var steps 2000");
  ASSERT_EQ(r.exit_code, 0) << r.out << r.err;
  // density,spheres_in_slab,spheres,wall_time_s,ranks
  const std::string last = r.out.substr(r.out.rfind('\n', r.out.size() - 2) + 1);
  double density = -1.0;
  int in_slab = -1, spheres = -1, ranks = -1;
  double wall = -1.0;
  ASSERT_EQ(
      std::sscanf(last.c_str(), "%lf,%d,%d,%lf,%d", &density, &in_slab, &spheres, &wall, &ranks), 5)
      << r.out;
  EXPECT_EQ(spheres, 2000);
  EXPECT_EQ(ranks, 2);
  EXPECT_GE(density, 0.0);  // still falling after 2000 steps: the slab may be empty
  EXPECT_LT(density, 0.75);
}

INSTANTIATE_TEST_SUITE_P(Integration, PackingRun, ::testing::Values("lammps", "liggghts"));

}  // namespace
