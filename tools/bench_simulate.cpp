// bench_simulate — what accuracy costs in time, what each effect costs, the speed targets, and
// what a user waits for (whole processes).
//
//   build/bench_simulate              (prints markdown tables on stdout; ~2 minutes)
//   BOUNCECAL_BASELINE=/path/to/an/older/bouncecal build/bench_simulate
//                                     (adds that binary's whole-process times, for before/after)
//   build/bench_simulate --processes  (section 5 alone)
//   build/bench_simulate --target     (section 4 alone)
//   build/bench_simulate --law NAME   (section 1 for one law alone)
//   build/bench_simulate --contact-map (section 6 alone)
//
// 1. Per registered law, a 30-impact sequence of the seed's 1 cm steel ball dropped from 0.2 m
//    (contacts integrated, gravity in the contact) across rtol 1e-3 .. 1e-12: max error in e
//    and in impact times against the tightest setting, integrator steps per contact (and the
//    share rejected), and the run time per simulation (thread CPU time, min over repetitions).
//    Then every law's time per contact at the same accuracy (interpolated on those tables), as a
//    ratio to hertz-tsuji's, and the cost of forward sensitivities.
// 2. A fixed-step DEM integrator (symplectic Euler and velocity Verlet) at the seed's
//    dt = 10 us and at 1 us, contact start/end taken at the first step that crossed, as DEM
//    codes do, for the seed's Walton-Braun law (k = 1e7 N/m, gamma = 0.5): its eta error.
// 3. The cost of each effect switched on alone against all off (all off timed twice: the
//    noise floor).
// 4. The speed target: 30 bounces of a 1 cm steel ball under Hertz-Tsuji in <= 0.5 ms at the
//    default accuracy (and the default tolerance with dopri5 forced, for comparison).
// 5. Whole processes: `bouncecal --version` and `laws` (the bare start-up) against `simulate` of
//    every law (median wall and CPU time of the child over repeated runs).
// 6. The contact map (SimulatorOptions::contact_map, what `simulate` uses): the default scene
//    until rest (or 10 000 impacts) for every law, every contact integrated against the map,
//    both at the default rtol 1e-9, each against every contact integrated at rtol 1e-12: the
//    largest errors in impact speed, impact time and e, the steps and the run time.
#include <time.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <string>
#include <vector>

#include <map>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "process_time.hpp"

using namespace bouncecal;

namespace {

using Clock = std::chrono::steady_clock;

// CPU time of this thread (s): what one core spends, unaffected by other processes sharing
// the machine (wall-clock minima are not reliable on a loaded 2-core box).
double ThreadSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// Run time of one call of fn (s, thread CPU time): min over `batches` of the mean over a batch
// sized to take about `batch_s`.
template <class Fn>
double TimePerCall(const Fn& fn, int batches = 5, double batch_s = 0.02) {
  fn();  // warm up (one-time tables of the laws, caches)
  int n = 1;
  for (;;) {  // size the batch
    const double t0 = ThreadSeconds();
    for (int i = 0; i < n; ++i) fn();
    const double dt = ThreadSeconds() - t0;
    if (dt > batch_s || n >= (1 << 20)) break;
    n *= 2;
  }
  double best = 1e300;
  for (int b = 0; b < batches; ++b) {
    const double t0 = ThreadSeconds();
    for (int i = 0; i < n; ++i) fn();
    best = std::min(best, (ThreadSeconds() - t0) / n);
  }
  return best;
}

Scene SeedScene(const std::string& law) {
  Scene s;  // seed 002: 1 cm steel ball (7800 kg/m^3) from 0.2 m, g = 9.8
  s.law.name = law;
  s.limits.max_impacts = 30;
  return s;
}

double E(const SimImpact& i) { return i.v_out_m_s / i.v_in_m_s; }

// One row of an accuracy table, kept for the same-accuracy comparison.
struct AccuracyRow {
  double rtol, err_e, err_t, us_per_simulation, steps_per_contact;
  size_t impacts;
};
std::map<std::string, std::vector<AccuracyRow>>& Rows() {
  static std::map<std::string, std::vector<AccuracyRow>> rows;
  return rows;
}

void AccuracyTable(const std::string& name) {
  Scene s = SeedScene(name);
  std::unique_ptr<ContactLaw> law;
  try {
    law = CreateLaw(s.law, s);
  } catch (const Error& e) {
    std::printf("\n### %s\n\nskipped: %s\n", name.c_str(), e.what());
    return;
  }
  const std::vector<double> p = law->ParameterValues();
  std::printf("\n### %s (", name.c_str());
  for (size_t i = 0; i < p.size(); ++i) {
    std::printf("%s%s = %g %s", i ? ", " : "", law->Parameters()[i].name.c_str(), p[i],
                law->Parameters()[i].unit.c_str());
  }
  std::printf(")\n\n");
  std::printf(
      "| rtol | max abs error in e | max abs error in impact times (s) | steps/contact |"
      " rejected | impacts | time per simulation (us) |\n|---|---|---|---|---|---|---|\n");
  SimulatorOptions ref_o;
  ref_o.use_closed_form = false;
  ref_o.rel_tolerance = 1e-12;
  ref_o.abs_tolerance = 1e-14;
  const Simulation ref = Simulate(s, *law, p, ref_o);
  for (int ex = 3; ex <= 12; ++ex) {
    SimulatorOptions o = ref_o;
    o.rel_tolerance = std::pow(10.0, -ex);
    o.abs_tolerance = std::min(1e-3 * o.rel_tolerance, 1e-6);
    if (ex == 12) o.abs_tolerance = ref_o.abs_tolerance;
    const Simulation sim = Simulate(s, *law, p, o);
    double err_e = 0.0, err_t = 0.0;
    const size_t n = std::min(sim.impacts.size(), ref.impacts.size());
    long rejected = 0;
    for (size_t k = 0; k < n; ++k) {
      if (ref.impacts[k].v_out_m_s > 0.0) {
        err_e = std::max(err_e, std::abs(E(sim.impacts[k]) - E(ref.impacts[k])));
      }
      err_t = std::max(err_t, std::abs(sim.impacts[k].time_s - ref.impacts[k].time_s));
    }
    for (const SimImpact& i : sim.impacts) rejected += i.rejected_steps;
    const double us = 1e6 * TimePerCall([&] { (void)Simulate(s, *law, p, o); }, 3, 0.01);
    const double steps = static_cast<double>(sim.total_steps) /
                         static_cast<double>(std::max<size_t>(1, sim.impacts.size()));
    std::printf(
        "| 1e-%d | %.2e | %.2e | %.1f | %.0f %% | %zu%s | %.1f |\n", ex, err_e, err_t, steps,
        100.0 * static_cast<double>(rejected) / static_cast<double>(std::max(1L, sim.total_steps)),
        sim.impacts.size(), sim.impacts.size() != ref.impacts.size() ? " (ref differs)" : "", us);
    if (ex < 12) Rows()[name].push_back({o.rel_tolerance, err_e, err_t, us, steps, n});
  }
  SimulatorOptions cf;
  if (auto out = law->SolveContact(p, BodyFromScene(s), 1.0)) {
    cf.gravity_in_contact = false;  // the closed form neglects gravity in the contact
    const Simulation sim = Simulate(s, *law, p, cf);
    double err_e = 0.0;
    for (size_t k = 0; k < std::min(sim.impacts.size(), ref.impacts.size()); ++k) {
      err_e = std::max(err_e, std::abs(E(sim.impacts[k]) - E(ref.impacts[k])));
    }
    const double us = 1e6 * TimePerCall([&] { (void)Simulate(s, *law, p, cf); }, 3, 0.01);
    std::printf(
        "| closed form (no gravity in contact) | %.2e (gravity's effect) | - | 0 | - | %zu |"
        " %.1f |\n",
        err_e, sim.impacts.size(), us);
  }
}

// Time per contact (us) at which `law` reaches an error in e of `target`: log-log interpolation
// between the two rows that bracket it (NaN when no row is that accurate).
double TimeAtAccuracy(const std::string& law, double target) {
  const std::vector<AccuracyRow>& rows = Rows()[law];
  for (size_t i = 0; i < rows.size(); ++i) {
    if (rows[i].err_e > target) continue;
    const double t1 = rows[i].us_per_simulation / static_cast<double>(rows[i].impacts);
    if (i == 0 || rows[i - 1].err_e <= rows[i].err_e) return t1;
    const double t0 = rows[i - 1].us_per_simulation / static_cast<double>(rows[i - 1].impacts);
    const double f =
        std::log(target / rows[i - 1].err_e) / std::log(rows[i].err_e / rows[i - 1].err_e);
    return std::exp(std::log(t0) + f * (std::log(t1) - std::log(t0)));
  }
  return std::nan("");
}

void SameAccuracyTable() {
  std::printf(
      "\n## Every law at the same accuracy\n\nTime per contact (us) for a maximum error in e "
      "over the 30-impact sequence (log-log interpolation between the rows above), and its "
      "ratio to hertz-tsuji at the same error.\n\n| law | e error 1e-6 | 1e-8 | 1e-10 |"
      "\n|---|---|---|---|\n");
  for (const auto& [law, rows] : Rows()) {
    std::printf("| %s |", law.c_str());
    for (double target : {1e-6, 1e-8, 1e-10}) {
      const double t = TimeAtAccuracy(law, target), ref = TimeAtAccuracy("hertz-tsuji", target);
      std::printf(" %.1f (%.2fx) |", t, t / ref);
    }
    std::printf("\n");
  }
}

// Forward sensitivities against what they replace (central differences: 2 simulations per
// parameter and one pair for the first impact speed).
void SensitivityTable() {
  std::printf(
      "\n## Forward sensitivities (30 impacts, rtol 1e-9; every parameter and the first impact "
      "speed)\n\n| law | Simulate (us) | SimulateWithSensitivities (us) | ratio | central "
      "differences, 2 (P + 1) simulations (us) |\n|---|---|---|---|---|\n");
  for (const char* name : {"hertz-tsuji", "hertz-viscoelastic", "walton-braun", "jiang-liu"}) {
    Scene s = SeedScene(name);
    const auto law = CreateLaw(s.law, s);
    const std::vector<double> p = law->ParameterValues();
    const double plain = TimePerCall([&] { (void)Simulate(s, *law, p, {}); }, 3, 0.02);
    SimulationSensitivities sens;
    const double with =
        TimePerCall([&] { (void)SimulateWithSensitivities(s, *law, p, {}, &sens); }, 3, 0.02);
    std::printf("| %s | %.0f | %.0f | %.1f | %.0f |\n", name, 1e6 * plain, 1e6 * with, with / plain,
                1e6 * plain * 2.0 * static_cast<double>(p.size() + 1));
  }
}

// ---------------------------------------------------------------------------------------
// A fixed-step DEM of the same drop, as seed 002 ran it: the overlap is checked at each step;
// the contact starts at the first step with delta > 0 and ends at the first with delta <= 0.
struct DemImpact {
  double start_s, end_s, v_in, v_out;
};

std::vector<DemImpact> RunDem(bool verlet, double dt, double k, double gamma, double m, double g,
                              double h, int impacts) {
  // Height z of the ball's bottom above the plate; overlap delta = -z.
  double z = h, v = 0.0, t = 0.0;
  auto accel = [&](double zz, double vv) {
    const double d = -zz;
    if (d <= 0.0) return -g;
    const double dd = -vv;                                            // overlap rate
    const double f = (dd > 0.0 ? 1.0 + gamma : 1.0 - gamma) * k * d;  // seed 002 eqs. 3-4
    return -g + f / m;
  };
  std::vector<DemImpact> out;
  bool in_contact = false;
  double v_prev = 0.0;
  DemImpact cur{};
  double a = accel(z, v);
  while (static_cast<int>(out.size()) < impacts && t < 5.0) {
    v_prev = v;
    if (verlet) {
      z += v * dt + 0.5 * a * dt * dt;
      const double a_new = accel(z, v + a * dt);  // predicted velocity picks the branch
      v += 0.5 * (a + a_new) * dt;
      a = a_new;
    } else {
      v += accel(z, v) * dt;  // symplectic Euler (leapfrog)
      z += v * dt;
    }
    t += dt;
    if (!in_contact && z < 0.0) {
      in_contact = true;
      cur.start_s = t;
      cur.v_in = -v_prev;
    } else if (in_contact && z >= 0.0) {
      in_contact = false;
      cur.end_s = t;
      cur.v_out = v;
      out.push_back(cur);
    }
  }
  return out;
}

void DemTable() {
  const double k = 1e7, gamma = 0.5, g = 9.8, h = 0.2;
  Scene s = SeedScene("walton-braun");
  const double m = s.ball.Mass();
  const double eta_exact = 2.0 * gamma / (1.0 + gamma);  // seed 002 eq. 23
  std::printf(
      "\n## Fixed-step DEM vs located contacts: seed 002's Walton-Braun, k = 1e7 N/m, "
      "gamma = 0.5, 1 cm steel ball (m = %.4g kg) from 0.2 m\n\n",
      m);
  std::printf(
      "exact eta = 2 gamma/(1 + gamma) = %.4f; contact time %.1f us.\n\n", eta_exact,
      1e6 * 0.5 * M_PI * (std::sqrt(m / ((1 + gamma) * k)) + std::sqrt(m / ((1 - gamma) * k))));
  std::printf(
      "| integrator | dt | eta-bar (impacts 1-3, intervals, seed eq. 10), h = 0.2 m | same, "
      "mean over 20 grid phases | min .. max over phases | eta error (phase mean) | steps per "
      "contact | time per 30 impacts (us) |\n|---|---|---|---|---|---|---|---|\n");
  auto eta_bar = [](const std::vector<DemImpact>& imp) {
    double eta = 0.0;
    for (int i = 1; i <= 3; ++i) {
      const double t0 = imp[i].start_s - imp[i - 1].start_s;
      const double t1 = imp[i + 1].start_s - imp[i].start_s;
      eta += (t0 * t0 - t1 * t1) / (t0 * t0) / 3.0;
    }
    return eta;
  };
  const double v0 = std::sqrt(2.0 * g * h);
  for (bool verlet : {false, true}) {
    for (double dt : {1e-5, 1e-6}) {
      const auto imp = RunDem(verlet, dt, k, gamma, m, g, h, 30);
      // The grid phase relative to first touch is arbitrary: shift the drop height by
      // fractions of one step of travel (v0 dt) and look at the spread.
      double mean = 0.0, lo = 1e9, hi = -1e9;
      constexpr int kPhases = 20;
      for (int j = 0; j < kPhases; ++j) {
        const double hj = h + v0 * dt * j / kPhases;
        const double eta = eta_bar(RunDem(verlet, dt, k, gamma, m, g, hj, 6));
        mean += eta / kPhases;
        lo = std::min(lo, eta);
        hi = std::max(hi, eta);
      }
      double steps = 0.0;
      for (const auto& d : imp) steps += (d.end_s - d.start_s) / dt;
      const double us =
          1e6 * TimePerCall([&] { (void)RunDem(verlet, dt, k, gamma, m, g, h, 30); }, 3, 0.05);
      std::printf("| %s | %g us | %.4f | %.4f | %.4f .. %.4f | %+.4f | %.1f | %.0f |\n",
                  verlet ? "velocity Verlet" : "symplectic Euler", dt * 1e6, eta_bar(imp), mean, lo,
                  hi, mean - eta_exact, steps / static_cast<double>(imp.size()), us);
    }
  }
  // The same with bouncecal: integrated with located switch/end, and in closed form.
  s.law.parameters = {{"k", k}, {"gamma", gamma}};
  const std::unique_ptr<ContactLaw> law = CreateLaw(s.law, s);
  const auto p = law->ParameterValues();
  for (bool closed : {false, true}) {
    SimulatorOptions o;
    o.use_closed_form = closed;
    o.gravity_in_contact = !closed;
    const Simulation sim = Simulate(s, *law, p, o);
    double eta_t = 0.0;
    for (int i = 1; i <= 3; ++i) {
      const double t0 = sim.impacts[i].time_s - sim.impacts[i - 1].time_s;
      const double t1 = sim.impacts[i + 1].time_s - sim.impacts[i].time_s;
      eta_t += (t0 * t0 - t1 * t1) / (t0 * t0) / 3.0;
    }
    const double us = 1e6 * TimePerCall([&] { (void)Simulate(s, *law, p, o); }, 3, 0.02);
    std::printf(
        "| bouncecal %s | adaptive, rtol 1e-9 | %.4f | (no grid) | - | %+.4f | %.1f | %.0f |\n",
        closed ? "closed form" : "DOP853 + located events", eta_t, eta_t - eta_exact,
        static_cast<double>(sim.total_steps) / static_cast<double>(sim.impacts.size()), us);
  }
  std::printf(
      "\nWhy the DEM is off: at 2 m/s the ball moves 20 um per 10 us step while the whole "
      "overlap is only ~33 um and the contact lasts ~7 steps. The contact starts at the first "
      "step found inside the plate (the ball is already up to 20 um deep when the force first "
      "acts), the loading branch (1 + gamma) k is kept until the first step whose velocity has "
      "turned, and the end is the first step back outside: each is an O(dt) error that depends "
      "on where the time grid happens to fall relative to first touch. The energy loss per "
      "impact therefore scatters with the grid phase (the min .. max column) and eta-bar of "
      "three impacts scatters by several percent. It is also biased: symplectic Euler "
      "(leapfrog, the usual DEM scheme) picks the branch from the half-step velocity, so the "
      "stiff loading branch is kept on average half a step past the turning point and gives "
      "back energy it should not; averaged over grid phases eta-bar comes out near 0.59, where "
      "seed 002 reported 0.598 for gamma = 0.5 (exact 0.667). Velocity Verlet's predicted "
      "velocity switches earlier and partly cancels the bias. dt = 1 us shrinks both tenfold "
      "at ten times the cost; locating the events removes them. Intervals (eq. 10) also include "
      "the "
      "contact duration, which eq. 10 ignores (the -0.0003 of the closed-form row).\n");
}

// ---------------------------------------------------------------------------------------
void EffectsTable(const std::string& law_name) {
  std::printf("\n## Only the effects a scene calls for (%s, 30 impacts, rtol 1e-9)\n\n",
              law_name.c_str());
  std::printf(
      "| effects on | time per simulation (us) | vs all off | impacts | integrator steps "
      "|\n|---|---|---|---|---|\n");
  struct Config {
    const char* name;
    void (*apply)(Scene*);
  };
  const Config configs[] = {
      {"none (all off)", [](Scene*) {}},
      {"none (all off, timed again: noise floor)", [](Scene*) {}},
      {"drag quadratic", [](Scene* s) { s->effects.drag = DragModel::kQuadratic; }},
      {"drag linear", [](Scene* s) { s->effects.drag = DragModel::kLinear; }},
      {"buoyancy", [](Scene* s) { s->effects.buoyancy = true; }},
      {"surface compliance (plate 0.5 kg on 1e7 N/m, 20 N s/m)",
       [](Scene* s) {
         s->effects.surface_compliance = true;
         s->surface.kind = Surface::Kind::kSpringMass;
         s->surface.mass_kg = 0.5;
         s->surface.stiffness_n_m = 1e7;
         s->surface.damping_n_s_m = 20.0;
       }},
  };
  // Round-robin: every round times one batch of each configuration, so drifts of the shared
  // machine hit all alike; each configuration keeps its fastest batch.
  struct Prepared {
    Scene scene;
    std::unique_ptr<ContactLaw> law;
    std::vector<double> p;
    Simulation sim;
    double best_s = 1e300;
  };
  std::vector<Prepared> runs;
  for (const Config& c : configs) {
    Prepared r;
    r.scene = SeedScene(law_name);
    c.apply(&r.scene);
    r.law = CreateLaw(r.scene.law, r.scene);
    r.p = r.law->ParameterValues();
    r.sim = Simulate(r.scene, *r.law, r.p, {});
    runs.push_back(std::move(r));
  }
  constexpr int kRounds = 15, kPerBatch = 8;
  for (int round = 0; round < kRounds; ++round) {
    for (Prepared& r : runs) {
      const double t0 = ThreadSeconds();
      for (int i = 0; i < kPerBatch; ++i) (void)Simulate(r.scene, *r.law, r.p, {});
      r.best_s = std::min(r.best_s, (ThreadSeconds() - t0) / kPerBatch);
    }
  }
  for (size_t i = 0; i < runs.size(); ++i) {
    const double us = 1e6 * runs[i].best_s;
    std::printf("| %s | %.1f | %+.1f%% | %zu | %ld |\n", configs[i].name, us,
                100.0 * (runs[i].best_s / runs[0].best_s - 1.0), runs[i].sim.impacts.size(),
                runs[i].sim.total_steps);
  }
}

void SpeedTarget() {
  const std::string name = "hertz-tsuji";
  Scene s = SeedScene(name);
  std::printf("\n## Speed target: 30 bounces, 1 cm steel ball, %s, one core\n\n", name.c_str());
  std::unique_ptr<ContactLaw> law;
  try {
    law = CreateLaw(s.law, s);
  } catch (const Error& e) {
    std::printf("not measured: %s\n", e.what());
    return;
  }
  const auto p = law->ParameterValues();
  SimulatorOptions ref_o;
  ref_o.rel_tolerance = 1e-12;
  ref_o.abs_tolerance = 1e-14;
  const Simulation ref = Simulate(s, *law, p, ref_o);
  // The accuracy the default (rtol 1e-9) gave before this integrator (bench_simulate at commit
  // 46f675b): e 5.85e-9, impact times 9.42e-9 s.
  constexpr double kOldDefaultErrE = 5.85e-9, kOldDefaultErrT = 9.42e-9;
  std::printf(
      "| rtol | error in e | error in impact times (s) | time per 30-bounce simulation (us) | "
      "simulations per second | target (<= 500 us) | steps/contact |\n|---|---|---|---|---|---|"
      "---|\n");
  // The last row: the default tolerance with the order-5 method the integrator used there
  // before DOP853 (ContactMethod::kDopri5), timed in the same run.
  struct Row {
    double rtol;
    ContactMethod method;
  };
  for (const Row& row : {Row{1e-6, ContactMethod::kAuto}, Row{1e-7, ContactMethod::kAuto},
                         Row{1e-8, ContactMethod::kAuto}, Row{3e-9, ContactMethod::kAuto},
                         Row{1e-9, ContactMethod::kAuto}, Row{1e-9, ContactMethod::kDopri5}}) {
    const double rtol = row.rtol;
    SimulatorOptions o;
    o.rel_tolerance = rtol;
    o.contact_method = row.method;
    const Simulation sim = Simulate(s, *law, p, o);
    double err_e = 0.0, err_t = 0.0;
    for (size_t k = 0; k < std::min(sim.impacts.size(), ref.impacts.size()); ++k) {
      err_e = std::max(err_e, std::abs(E(sim.impacts[k]) - E(ref.impacts[k])));
      err_t = std::max(err_t, std::abs(sim.impacts[k].time_s - ref.impacts[k].time_s));
    }
    const double sec = TimePerCall([&] { (void)Simulate(s, *law, p, o); }, 7, 0.05);
    const bool old_accuracy = err_e <= kOldDefaultErrE && err_t <= kOldDefaultErrT;
    const char* note = row.method == ContactMethod::kDopri5 ? " (dopri5)"
                       : rtol == 1e-9                       ? " (default)"
                                                            : "";
    std::printf("| %g%s | %.2e | %.2e | %.1f | %.0f | %s | %.1f |\n", rtol, note, err_e, err_t,
                1e6 * sec, 1.0 / sec, sec <= 5e-4 ? "met" : "NOT met",
                static_cast<double>(sim.total_steps) / static_cast<double>(sim.impacts.size()));
    if (old_accuracy && rtol > 1e-9) {
      std::printf("|   (errors within the previous default's %.2e / %.2e s) | | | | | | |\n",
                  kOldDefaultErrE, kOldDefaultErrT);
    }
  }
}

// ---------------------------------------------------------------------------------------
// Whole processes: what a user waits for, start-up included (tools/process_time.hpp). The
// commands (and the baseline's) take turns in each round, so one run's ratios are comparable.
void ProcessTable() {
  using bench::Command;
  const std::string binary = bench::ProgramNextToThis();
  const char* baseline = std::getenv("BOUNCECAL_BASELINE");
  constexpr int kRuns = 11;
  std::printf(
      "\n## Whole processes: bare start-up against `simulate` (default scene: 1 cm steel ball "
      "from 0.2 m, until rest)\n\nMedian of %d runs of `%s ARGS > /dev/null`, the commands "
      "taking turns; CPU = the child's user + system time. Target: `simulate` of any law <= 5x "
      "the bare start-up.%s\n\n",
      kRuns, binary.c_str(),
      baseline ? " Baseline: the same commands with BOUNCECAL_BASELINE." : "");
  std::printf(
      "| command | wall (ms) | CPU (ms) | wall / --version | CPU / --version |%s\n",
      baseline ? " baseline wall (ms) | baseline CPU (ms) | baseline CPU / its --version |" : "");
  std::printf("|---|---|---|---|---|%s\n", baseline ? "---|---|---|" : "");
  std::vector<Command> commands = {{binary, "--version"}, {binary, "laws"}};
  for (const LawInfo& info : RegisteredLaws()) {
    if (!info.needs_expression) commands.push_back({binary, "simulate", "--law", info.name});
  }
  const size_t n = commands.size();
  bench::AddBaselineCopies(&commands, baseline);
  const std::vector<bench::ProcessTime> t = bench::MedianProcesses(commands, kRuns);
  for (size_t i = 0; i < n; ++i) {
    std::printf("| `%s`%s | %.1f | %.1f | %.1f | %.1f |", bench::ArgumentLine(commands[i]).c_str(),
                bench::ExitNote(t[i]).c_str(), 1e3 * t[i].wall_s, 1e3 * t[i].cpu_s,
                t[i].wall_s / t[0].wall_s, t[i].cpu_s / t[0].cpu_s);
    if (baseline) {
      const bench::ProcessTime& b = t[n + i];
      std::printf(" %.1f | %.1f | %.1f |", 1e3 * b.wall_s, 1e3 * b.cpu_s, b.cpu_s / t[n].cpu_s);
    }
    std::printf("\n");
  }
}

// ---------------------------------------------------------------------------------------
// The contact map against integrating every contact (section 6).
struct SequenceErrors {
  double v_in = 0.0, time_s = 0.0, e = 0.0;
};

// Impact by impact against the reference (the last impact left out: its contact may end stuck,
// where the reported duration depends on the stuck test).
SequenceErrors ErrorsAgainst(const Simulation& a, const Simulation& ref) {
  SequenceErrors out;
  const size_t n = std::min(a.impacts.size(), ref.impacts.size());
  for (size_t i = 0; i + 1 < n; ++i) {
    const SimImpact& x = a.impacts[i];
    const SimImpact& y = ref.impacts[i];
    out.v_in = std::max(out.v_in, std::abs(x.v_in_m_s - y.v_in_m_s) / y.v_in_m_s);
    out.time_s = std::max(out.time_s, std::abs(x.time_s - y.time_s));
    out.e = std::max(out.e, std::abs(E(x) - E(y)));
  }
  return out;
}

void ContactMapTable() {
  std::printf(
      "\n## The contact map (`simulate`'s default) against integrating every contact "
      "(`--integrate`)\n\nDefault scene (1 cm steel ball from 0.2 m) until rest or 10 000 "
      "impacts, both at rtol 1e-9; errors against every contact integrated at rtol 1e-12 (the "
      "last impact left out); steps: all integrator steps of the run, the map's included; time: "
      "thread CPU time per simulation, min of 3.\n\n");
  std::printf(
      "| law | impacts | mapped | panels (refused) | steps integrated | steps mapped | ms "
      "integrated | ms mapped | max rel err v_in integrated | mapped | max err t (s) "
      "integrated | mapped | max err e integrated | mapped |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;
    Scene s;
    s.law.name = info.name;
    const auto law = CreateLaw(s.law, s);
    const std::vector<double> p = law->ParameterValues();
    auto run = [&](bool map, double rtol) {
      SimulatorOptions o;
      o.contact_map = map;
      o.rel_tolerance = rtol;
      return Simulate(s, *law, p, o);
    };
    auto seconds = [&](bool map) {
      double best = 1e300;
      for (int r = 0; r < 3; ++r) {
        const double t0 = ThreadSeconds();
        run(map, 1e-9);
        best = std::min(best, ThreadSeconds() - t0);
      }
      return best;
    };
    const Simulation ref = run(false, 1e-12), a = run(false, 1e-9), b = run(true, 1e-9);
    const SequenceErrors ea = ErrorsAgainst(a, ref), eb = ErrorsAgainst(b, ref);
    std::printf(
        "| %s | %zu | %d | %d (%d) | %ld | %ld | %.2f | %.2f | %.1e | %.1e | %.1e | %.1e | %.1e "
        "| %.1e |\n",
        info.name.c_str(), b.impacts.size(), b.mapped_contacts, b.map_panels, b.map_panels_refused,
        a.total_steps, b.total_steps, 1e3 * seconds(false), 1e3 * seconds(true), ea.v_in, eb.v_in,
        ea.time_s, eb.time_s, ea.e, eb.e);
    std::fflush(stdout);
  }
}

bool Registered(const std::string& name) {
  for (const LawInfo& i : RegisteredLaws()) {
    if (i.name == name) return true;
  }
  return false;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc > 1 && std::string(argv[1]) == "--processes") {
    ProcessTable();  // section 5 alone
    return 0;
  }
  if (argc > 1 && std::string(argv[1]) == "--target") {
    SpeedTarget();  // section 4 alone
    return 0;
  }
  if (argc > 1 && std::string(argv[1]) == "--contact-map") {
    ContactMapTable();  // section 6 alone
    return 0;
  }
  if (argc > 2 && std::string(argv[1]) == "--law") {
    AccuracyTable(argv[2]);  // section 1 for one law alone
    return 0;
  }
  const auto t0 = Clock::now();
  std::printf("# bench_simulate\n\n## What accuracy costs in time\n\n");
  std::printf(
      "30-impact sequence (or until rest), seed 002 scene, contacts integrated with "
      "gravity; errors against rtol 1e-12; time = thread CPU time per simulation, min over "
      "repetitions.\n");
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;  // needs a user expression
    AccuracyTable(info.name);
  }
  SameAccuracyTable();
  SensitivityTable();
  DemTable();
  EffectsTable(Registered("hertz-tsuji") ? "hertz-tsuji" : "walton-braun");
  SpeedTarget();
  ProcessTable();
  ContactMapTable();
  std::printf("\n(bench ran %.1f s)\n", std::chrono::duration<double>(Clock::now() - t0).count());
  return 0;
}
