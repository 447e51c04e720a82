// bench_calibrate — what calibration accuracy costs in time, and the seed paper's numbers.
//
// Prints markdown tables (measured on this machine, one thread; times are thread CPU time):
//  1. strategy (trajectory / restitution) x derivatives (auto / numeric) x simulator tolerance:
//     damping error against the truth (RMS over seeded noisy data sets), mean reported sigma,
//     iterations, simulations and run time per fit;
//  2. end-to-end calibrate (read + detect + fit, as `bouncecal calibrate` does) on a rendered
//     10 s, 48 kHz recording under a nonlinear law, and the `--law all` comparison on it;
//  3. seed 002's numbers: dt0 = 2 sqrt(2h/g) for h = 0.2 m and the damping for its measured
//     mean eta = 0.58 (paper: gamma = 0.5 by a five-value sweep; its simulation gave 0.598);
//  4. the scatter error model (docs/physics.md §6): bounce sequences rendered with per-bounce
//     restitution scatter sigma_s (0.002, 0.004, 0.01) and 5 us timing noise, truth e(v) from
//     the independent Boost.Odeint law oracle (tests/law_oracle.hpp, gravity in the contact) and
//     exact flights: sigma_s recovered, pull RMS of the damping parameter and of the e(v) band
//     (target [0.7, 1.4]), chi2/dof of the full model (~1), per strategy.
//
//  5. whole `bouncecal calibrate` processes on the bundled recording (data/default_steel_copper,
//     read + detect + fit), every law and `--law all`, against the bare start-up and against
//     walton-braun (targets: every law <= 5x walton-braun, --law all <= 6x); with
//     BOUNCECAL_BASELINE=/path/to/an/older/bouncecal also that binary's, in the same rounds.
//
// Usage: bench_calibrate [--quick] [--scatter-only] [--processes]
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "../tests/oracle_truth.hpp"
#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "bouncecal/synth/synth.hpp"
#include "process_time.hpp"

using namespace bouncecal;

namespace {

// Thread CPU time: what one core spends, independent of other processes on a shared machine.
double Now() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

Scene SteelScene(const std::string& law) {
  Scene s;  // seed 002: 1 cm steel ball from 0.2 m
  s.law.name = law;
  return s;
}

// The scene a fit of simulated impacts needs: the simulator puts each contact in the interval.
Scene FitScene(const std::string& law) {
  Scene s = SteelScene(law);
  s.effects.contact_duration = true;
  return s;
}

// The law with its damping set so that e(1 m/s) = e_target (the law's own inverse map).
Scene WithDampingForE(Scene s, double e_target) {
  auto law = CreateLaw(s.law, s);
  auto p = law->DampingForRestitution(law->ParameterValues(), BodyFromScene(s), e_target, 1.0);
  if (!p) throw Error(ErrorCode::kBadParameter, s.law.name + ": no inverse map");
  for (size_t i = 0; i < law->Parameters().size(); ++i) {
    if (law->Parameters()[i].damping) s.law.parameters[law->Parameters()[i].name] = (*p)[i];
  }
  return s;
}

std::string DampingName(const Scene& s) {
  auto law = CreateLaw(s.law, s);
  for (const auto& p : law->Parameters()) {
    if (p.damping) return p.name;
  }
  return "";
}

Sequence Measured(const Simulation& sim, int n, double sigma_s, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  Sequence seq;
  for (int k = 0; k < n && k < static_cast<int>(sim.impacts.size()); ++k) {
    Impact imp;
    imp.time_s = 1.0 + sim.impacts[static_cast<size_t>(k)].time_s + sigma_s * noise(rng);
    imp.sigma_s = sigma_s;
    seq.impacts.push_back(imp);
  }
  return seq;
}

void CostTable(const std::string& law_name, double e_target, int seeds, int impacts,
               double sigma_s) {
  const Scene truth = WithDampingForE(SteelScene(law_name), e_target);
  const std::string dname = DampingName(truth);
  const double want = truth.law.parameters.at(dname);
  auto law = CreateLaw(truth.law, truth);
  Scene s = truth;
  s.limits.max_impacts = impacts;
  SimulatorOptions so;
  so.rel_tolerance = 1e-12;
  const Simulation sim = Simulate(s, *law, law->ParameterValues(), so);
  std::printf(
      "\n### %s: %s = %.6g (e = %.2f at 1 m/s), %d impacts, %.0f us timing noise, "
      "%d seeds\n\n",
      law_name.c_str(), dname.c_str(), want, e_target, impacts, sigma_s * 1e6, seeds);
  std::printf(
      "| strategy | derivatives | rtol | RMS error of %s (rel.) | mean reported sigma "
      "(rel.) | iterations | simulations | time per fit (ms) |\n",
      dname.c_str());
  std::printf("|---|---|---|---|---|---|---|---|\n");
  for (FitStrategy st : {FitStrategy::kTrajectory, FitStrategy::kRestitution}) {
    for (DerivativeMode dm : {DerivativeMode::kAuto, DerivativeMode::kNumeric}) {
      for (double rtol : {1e-6, 1e-8, 1e-10}) {
        double se = 0.0, ssig = 0.0, time = 0.0;
        long sims = 0;
        int iters = 0, ok = 0;
        std::string fail;
        for (int seed = 1; seed <= seeds; ++seed) {
          CalibrationOptions o;
          o.strategy = st;
          o.derivatives = dm;
          o.rel_tolerance = rtol;
          o.loss = RobustLoss::kNone;
          const Sequence seq = Measured(sim, impacts, sigma_s, static_cast<std::uint64_t>(seed));
          try {
            const double t0 = Now();
            const Calibration c = Calibrate({{"bench", seq}}, FitScene(law_name), o);
            time += Now() - t0;
            for (const auto& p : c.parameters) {
              if (p.name != dname) continue;
              se += std::pow((p.value - want) / want, 2);
              ssig += p.sigma / want;
            }
            sims += c.simulations;
            iters += c.iterations;
            ++ok;
          } catch (const Error& e) {
            fail = e.what();
          }
        }
        if (ok == 0) {
          std::printf("| %s | %s | %.0e | failed: %s | | | | |\n", FitStrategyName(st),
                      DerivativeModeName(dm), rtol, fail.c_str());
          continue;
        }
        std::printf("| %s | %s | %.0e | %.2e | %.2e | %.1f | %.0f | %.1f |\n", FitStrategyName(st),
                    DerivativeModeName(dm), rtol, std::sqrt(se / ok), ssig / ok,
                    static_cast<double>(iters) / ok, static_cast<double>(sims) / ok,
                    1e3 * time / ok);
      }
    }
  }
}

void EndToEnd(const std::string& law_name, double e_target, bool run_all) {
  // A 10 s, 48 kHz recording of the steel ball under law_name, rendered with the steel-copper
  // preset's plate, noise and hum, written as 16-bit WAV.
  const Scene truth = WithDampingForE(SteelScene(law_name), e_target);
  auto law = CreateLaw(truth.law, truth);
  Scene s = truth;
  s.drop.first_impact_time_s = 1.0;
  const Simulation sim = Simulate(s, *law, law->ParameterValues());
  std::vector<TruthImpact> impacts;
  for (const auto& i : sim.impacts) {
    if (!impacts.empty() && i.time_s - impacts.back().time_s < 0.01) break;
    impacts.push_back({i.time_s, i.v_in_m_s, i.v_out_m_s, i.contact_s});
  }
  RenderOptions ro = SynthPreset("steel-copper").render;
  ro.latency_s = 0.0;
  ro.duration_s = 10.0;
  const auto rec = RenderRecording(impacts, ro);
  const std::string path =
      (std::filesystem::temp_directory_path() / "bench_calibrate_10s.wav").string();
  WriteAudio(path, rec.channels, rec.sample_rate_hz);
  const std::string dname = DampingName(truth);
  const double want = truth.law.parameters.at(dname);

  std::printf("\n### End to end: %s, %.1f s at %.0f Hz, %zu rendered impacts, %s = %.6g\n\n",
              law_name.c_str(), rec.duration_s(), rec.sample_rate_hz, impacts.size(), dname.c_str(),
              want);
  std::printf(
      "| run | read (ms) | detect (ms) | fit (ms) | total (ms) | impacts used | fitted | "
      "error (rel.) | target |\n|---|---|---|---|---|---|---|---|---|\n");
  double best_total = 1e300;
  for (int rep = 0; rep < 3; ++rep) {
    const double t0 = Now();
    const Audio audio = ReadAudio(path);
    const double t1 = Now();
    const DetectionResult det = DetectImpacts(audio, DetectOptions{});
    const double t2 = Now();
    Sequence seq = det.main();
    Scene start = FitScene(law_name);
    const Calibration c = Calibrate({{path, seq}}, start, {});
    const double t3 = Now();
    double got = 0.0, sigma = 0.0;
    for (const auto& p : c.parameters) {
      if (p.name == dname) got = p.value, sigma = p.sigma;
    }
    best_total = std::min(best_total, t3 - t0);
    std::printf(
        "| calibrate #%d | %.1f | %.1f | %.1f | %.1f | %zu | %s = %.6g ± %.2g | %.2e | "
        "<= 500 ms |\n",
        rep + 1, 1e3 * (t1 - t0), 1e3 * (t2 - t1), 1e3 * (t3 - t2), 1e3 * (t3 - t0),
        seq.impacts.size(), dname.c_str(), got, sigma, (got - want) / want);
  }
  if (run_all) {
    const double t0 = Now();
    const Audio audio = ReadAudio(path);
    const DetectionResult det = DetectImpacts(audio, DetectOptions{});
    const auto rows = CompareLaws({{path, det.main()}}, FitScene(law_name), {});
    const double t1 = Now();
    int failed = 0;
    for (const auto& r : rows) failed += r.fit.outcome == FitOutcome::kFailed ? 1 : 0;
    std::printf(
        "| --law all (%zu laws, %d failed; best: %s) | | | | %.1f | %zu | | | <= 5000 ms "
        "|\n",
        rows.size(), failed, rows.empty() ? "-" : rows.front().fit.law.c_str(), 1e3 * (t1 - t0),
        det.main().impacts.size());
    std::printf("\nLaw comparison on this recording:\n\n%s",
                LawComparisonTable(rows, {0.3, 1.0, 1.9}).c_str());
  }
  std::filesystem::remove(path);
}

void SeedPaper() {
  std::printf("\n### Seed 002 (Zhong et al. 2009) reproduced\n\n");
  std::printf("| quantity | bouncecal | paper | note |\n|---|---|---|---|\n");
  const FlightModel f = FlightModel::Vacuum(9.8);
  const double dt0 = f.FlightTime(f.FallArrivalSpeed(0.2));
  std::printf(
      "| first (silent) interval dt0 = 2 sqrt(2h/g), h = 0.2 m, g = 9.8 | %.5f s | "
      "0.4040 s | exact flight formulas |\n",
      dt0);
  Scene s = SteelScene("walton-braun");
  auto law = CreateLaw(s.law, s);
  const ContactBody body = BodyFromScene(s);
  const double eta = 0.58;
  const double e = std::sqrt(1.0 - eta);
  auto p = law->DampingForRestitution(law->ParameterValues(), body, e, 1.0);
  const int gi = law->ParameterIndex("gamma");
  std::printf(
      "| gamma for the measured mean eta = 0.58 (e = %.4f) | %.4f | 0.5 | inverse map "
      "gamma = eta/(2-eta); the paper swept {0.1,0.3,0.5,0.7,0.9} and took the nearest |\n",
      e, (*p)[static_cast<size_t>(gi)]);
  std::vector<double> q = law->ParameterValues();
  q[static_cast<size_t>(gi)] = 0.5;
  const double e05 = *law->Restitution(q, body, 1.0);
  std::printf(
      "| eta for gamma = 0.5 (closed form) | %.4f | 0.598 (its DEM) | exact 2g/(1+g) = "
      "0.6667; a fixed 10 us step over a ~60 us contact |\n",
      1.0 - e05 * e05);
  SimulatorOptions so;
  const double e05_sim =
      SimulateContact(*law, q, body, std::sqrt(2 * 9.8 * 0.2), 9.8, so).restitution;
  std::printf(
      "| eta for gamma = 0.5 (bouncecal simulator, located contact end) | %.4f | 0.598 "
      "| |\n",
      1.0 - e05_sim * e05_sim);
  q[static_cast<size_t>(gi)] = (*p)[static_cast<size_t>(gi)];
  const double e_fit =
      SimulateContact(*law, q, body, std::sqrt(2 * 9.8 * 0.2), 9.8, so).restitution;
  std::printf(
      "| eta for gamma = %.4f (simulator) | %.4f | 0.58 (measured) | the calibrated "
      "law reproduces the measurement |\n",
      (*p)[static_cast<size_t>(gi)], 1.0 - e_fit * e_fit);
}

// ---- 4. the scatter error model -------------------------------------------------------------

struct ScatterCase {
  Scene scene;  // hertz-viscoelastic, 1 cm steel ball from 0.5 m, A for e(1 m/s) = 0.85
  double a_true = 0.0;
};

ScatterCase MakeScatterCase() {
  ScatterCase c;
  c.scene = WithDampingForE(SteelScene("hertz-viscoelastic"), 0.85);
  c.scene.drop.height_m = 0.5;
  c.a_true = c.scene.law.parameters.at("A");
  return c;
}

// Onsets of one drop with scatter (truth from the oracle) and Gaussian timing noise; the
// trajectory's simulator puts each contact in the interval, so its truth does too.
Sequence ScatterSequence(const ScatterCase& c, double scatter, std::uint64_t seed,
                         double timing_sigma_s, bool contact_in_interval) {
  oracle_truth::Options o;
  o.scatter_e = scatter;
  o.timing_sigma_s = timing_sigma_s;
  o.contact_in_interval = contact_in_interval;
  o.seed = seed;
  return oracle_truth::Make(c.scene, o).sequence;
}

void ScatterTable(int seeds) {
  const ScatterCase c = MakeScatterCase();
  auto law = CreateLaw(c.scene.law, c.scene);
  const ContactBody body = BodyFromScene(c.scene);
  std::printf(
      "\n### Scatter error model: hertz-viscoelastic A = %.4g s (e(1 m/s) = 0.85), 1 cm steel "
      "ball from 0.5 m (exact), 5 us timing noise, %d seeds per row\n\n",
      c.a_true, seeds);
  std::printf(
      "| strategy | sigma_s true | sigma_s fitted (mean) | RMS (fit - true)/sigma | "
      "pull RMS of A (mean) | pull RMS of e(v) band | chi2/dof (mean) | bounces | converged | "
      "time per fit (ms) |\n|---|---|---|---|---|---|---|---|---|---|\n");
  for (FitStrategy st : {FitStrategy::kRestitution, FitStrategy::kTrajectory}) {
    for (double scatter : {0.0, 0.002, 0.004, 0.01}) {
      double s_sum = 0, s_pull = 0, a_pull = 0, a_bias = 0, e_pull = 0, chi = 0, time = 0;
      int n_e = 0, ok = 0, bounces = 0;
      for (int seed = 1; seed <= seeds; ++seed) {
        const bool traj = st == FitStrategy::kTrajectory;
        const Sequence seq =
            ScatterSequence(c, scatter, static_cast<std::uint64_t>(seed), 5e-6, traj);
        Scene start = c.scene;
        start.law.parameters.erase("A");        // start from the law's default, not the truth
        start.effects.contact_duration = traj;  // the kinematics take the contacts out
        CalibrationOptions o;
        o.strategy = st;
        const double t0 = Now();
        const Calibration fit = Calibrate({{"scatter", seq}}, start, o);
        time += Now() - t0;
        if (fit.outcome != FitOutcome::kConverged) continue;
        ++ok;
        bounces += fit.num_residuals;
        s_sum += fit.scatter_e;
        s_pull += std::pow((fit.scatter_e - scatter) / fit.scatter_e_sigma, 2);
        for (const auto& p : fit.parameters) {
          if (p.name == "A") {
            a_pull += std::pow((p.value - c.a_true) / p.sigma, 2);
            a_bias += (p.value - c.a_true) / p.sigma;
          }
        }
        chi += fit.chi2_dof;
        // The e(v) band against the law's own e(v) at the true A (oracle, no gravity: the
        // reported band is the law's e).
        for (const EOfVPoint& pt : fit.e_of_v) {
          const double e_true =
              oracle::Integrate(*law, law->ParameterValues(), body, pt.v_m_s).restitution;
          e_pull += std::pow((pt.e - e_true) / pt.sigma, 2);
          ++n_e;
        }
      }
      if (ok == 0) {
        std::printf("| %s | %.3f | no fit converged | | | | | | 0/%d | |\n", FitStrategyName(st),
                    scatter, seeds);
        continue;
      }
      std::printf("| %s | %.3f | %.4f | %.2f | %.2f (%+.2f) | %.2f | %.2f | %d | %d/%d | %.0f |\n",
                  FitStrategyName(st), scatter, s_sum / ok, std::sqrt(s_pull / ok),
                  std::sqrt(a_pull / ok), a_bias / ok, std::sqrt(e_pull / std::max(n_e, 1)),
                  chi / ok, bounces / ok, ok, seeds, 1e3 * time / seeds);
    }
  }
}

// Whole `bouncecal calibrate` processes on the bundled recording (tools/process_time.hpp): the
// commands (and the baseline's) take turns in each round, so one run's ratios are comparable.
void ProcessTable(int runs) {
  using bench::Command;
  const std::string binary = bench::ProgramNextToThis();
  const std::string data = std::string(BOUNCECAL_SOURCE_DIR) + "/data/default_steel_copper";
  const char* baseline = std::getenv("BOUNCECAL_BASELINE");
  std::printf(
      "\n## Whole processes: `calibrate` on the bundled recording\n\nMedian of %d runs of `%s "
      "calibrate %s.flac --scene %s.toml --quiet --law LAW > /dev/null` (read + detect + fit), "
      "the commands taking turns; CPU = the child's user + system time. Targets: every law <= "
      "5x walton-braun, --law all <= 6x (it runs the laws on the machine's cores: wall).%s\n\n",
      runs, binary.c_str(), data.c_str(), data.c_str(),
      baseline ? " Baseline: the same commands with BOUNCECAL_BASELINE." : "");
  std::printf(
      "| command | wall (ms) | CPU (ms) | CPU / --version | wall / walton-braun | CPU / "
      "walton-braun |%s\n",
      baseline ? " baseline wall (ms) | baseline CPU (ms) | baseline CPU / its --version |" : "");
  std::printf("|---|---|---|---|---|---|%s\n", baseline ? "---|---|---|" : "");
  std::vector<Command> commands = {{binary, "--version"}};
  std::vector<std::string> laws;
  for (const LawInfo& info : RegisteredLaws()) {
    if (!info.needs_expression) laws.push_back(info.name);
  }
  laws.push_back("all");
  for (const std::string& law : laws) {
    commands.push_back(
        {binary, "calibrate", data + ".flac", "--scene", data + ".toml", "--quiet", "--law", law});
  }
  size_t walton_braun = 0;
  for (size_t i = 0; i < commands.size(); ++i) {
    if (commands[i].back() == "walton-braun") walton_braun = i;
  }
  const size_t n = commands.size();
  bench::AddBaselineCopies(&commands, baseline);
  const std::vector<bench::ProcessTime> t = bench::MedianProcesses(commands, runs);
  for (size_t i = 0; i < n; ++i) {
    const std::string line = i == 0 ? "--version" : "calibrate --law " + commands[i].back();
    std::printf("| `%s`%s | %.1f | %.1f | %.1f | %.2f | %.2f |", line.c_str(),
                bench::ExitNote(t[i]).c_str(), 1e3 * t[i].wall_s, 1e3 * t[i].cpu_s,
                t[i].cpu_s / t[0].cpu_s, t[i].wall_s / t[walton_braun].wall_s,
                t[i].cpu_s / t[walton_braun].cpu_s);
    if (baseline) {
      const bench::ProcessTime& b = t[n + i];
      std::printf(" %.1f | %.1f | %.1f |", 1e3 * b.wall_s, 1e3 * b.cpu_s, b.cpu_s / t[n].cpu_s);
    }
    std::printf("\n");
  }
}

}  // namespace

int main(int argc, char** argv) {
  bool quick = false, scatter_only = false, processes_only = false;
  for (int i = 1; i < argc; ++i) {
    quick |= std::string(argv[i]) == "--quick";
    scatter_only |= std::string(argv[i]) == "--scatter-only";
    processes_only |= std::string(argv[i]) == "--processes";
  }
  try {
    std::printf("# bench_calibrate%s\n", quick ? " (--quick)" : "");
    if (scatter_only || processes_only) {
      if (scatter_only) ScatterTable(quick ? 4 : 20);
      if (processes_only) ProcessTable(quick ? 3 : 7);
      return 0;
    }
    SeedPaper();
    const int seeds = quick ? 2 : 5;
    CostTable("walton-braun", 0.8, seeds, 14, 5e-6);
    CostTable("hertz-viscoelastic", 0.9, seeds, 20, 5e-6);
    EndToEnd("hertz-viscoelastic", 0.92, true);
    ScatterTable(quick ? 4 : 20);
    ProcessTable(quick ? 3 : 7);
  } catch (const Error& e) {
    std::fprintf(stderr, "bench_calibrate: %s\n", e.what());
    return e.exit_code();
  }
  return 0;
}
