// Calibration stages 1-2: problem set-up and start values (calibrate_stages.hpp).
#include <algorithm>
#include <cmath>
#include <functional>
#include <iomanip>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/parallel.hpp"
#include "bouncecal/core/stats.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "fit/calibrate_stages.hpp"

namespace bouncecal::calib {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string Join(const std::vector<std::string>& v) {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) out += (i ? ", " : "") + v[i];
  return out;
}

void ClampIntoBounds(const LawSetup& s, std::vector<double>* p) {
  const auto& specs = s.specs();
  for (size_t i = 0; i < p->size(); ++i)
    (*p)[i] = std::clamp((*p)[i], specs[i].lower, specs[i].upper);
}

std::vector<int> FreeDamping(const LawSetup& s) {
  std::vector<int> out;
  for (int i : s.free) {
    if (s.specs()[static_cast<size_t>(i)].damping) out.push_back(i);
  }
  return out;
}

// The law's inverse map e -> damping at (e, v): every free damping parameter set.
std::optional<std::vector<double>> InverseMapStart(const LawSetup& s, double e, double v) {
  auto p = s.law->DampingForRestitution(s.start, s.body, e, v);
  if (!p) return std::nullopt;
  std::vector<double> q = s.start;
  for (int i : FreeDamping(s)) q[static_cast<size_t>(i)] = (*p)[static_cast<size_t>(i)];
  ClampIntoBounds(s, &q);
  std::string err;
  if (!s.law->IsValid(q, s.body, &err)) return std::nullopt;
  return q;
}

// A log-spaced scan of a single free damping parameter for e(v) = e (every registered law's e
// falls as its damping grows, so the closest point brackets the answer).
std::optional<std::vector<double>> ScanStart(const LawSetup& s, double e_target, double v, double g,
                                             const SimulatorOptions& sim,
                                             std::atomic<long>* simulations) {
  const std::vector<int> damp = FreeDamping(s);
  if (damp.size() != 1) return std::nullopt;
  const size_t i = static_cast<size_t>(damp[0]);
  const ParameterSpec& sp = s.specs()[i];
  const double x0 = s.typical[i];
  const double lo = std::max(sp.lower, x0 * 1e-4), hi = std::min(sp.upper, x0 * 1e4);
  if (!(lo > 0.0) || !(hi > lo)) return std::nullopt;
  std::vector<double> q = s.start, best;
  double best_err = std::numeric_limits<double>::max();
  const int n = 17;
  for (int j = 0; j < n; ++j) {
    q[i] = lo * std::pow(hi / lo, j / double(n - 1));
    std::string err;
    if (!s.law->IsValid(q, s.body, &err)) continue;
    double e = kNaN;
    try {
      e = ModelRestitution(s, q, v, g, sim, simulations);
    } catch (const Error&) {
      continue;
    }
    if (std::isfinite(e) && std::abs(e - e_target) < best_err)
      best_err = std::abs(e - e_target), best = q;
  }
  if (best.empty()) return std::nullopt;
  return best;
}

// Checks the data are enough for the free parameters (and sigma_s); fills not_determinable.
void CountData(FitProblem* fp, const std::vector<CalibrationInput>& recordings) {
  const int nfree = static_cast<int>(fp->setup.free.size());
  const bool traj = fp->options.strategy == FitStrategy::kTrajectory;
  const int scatter = fp->options.estimate_scatter ? 1 : 0;
  const int points = fp->data.size();
  if (points < nfree + scatter + 1) {
    std::ostringstream os;
    os << "the data cannot determine the parameters: " << points
       << " bounce(s) with a measured restitution for " << nfree << " free law parameter(s)"
       << (scatter ? " and the scatter" : "") << "; need at least " << nfree + scatter + 1
       << " (a bounce needs three impacts, or two and a stated drop height)";
    fp->not_determinable = os.str();
    return;
  }
  if (traj) {
    int impacts = 0;
    for (const auto& r : recordings) impacts += static_cast<int>(r.sequence.impacts.size());
    const int need = nfree + 2 * static_cast<int>(recordings.size()) + 1;
    if (impacts < need) {
      fp->not_determinable =
          "the data cannot determine the parameters: " + std::to_string(impacts) +
          " impact times for " + std::to_string(need - 1) +
          " free parameters (the law's, and the first impact speed and time "
          "origin of each recording)";
    }
  }
}

}  // namespace

std::vector<double> LawSetup::Full(const double* u) const {
  std::vector<double> p = start;
  for (size_t j = 0; j < free.size(); ++j) p[static_cast<size_t>(free[j])] = scale[j] * u[j];
  return p;
}

std::vector<double> LawSetup::Scaled(const std::vector<double>& p) const {
  std::vector<double> u(free.size());
  for (size_t j = 0; j < free.size(); ++j) u[j] = p[static_cast<size_t>(free[j])] / scale[j];
  return u;
}

double RelativeStep(double rtol) { return std::clamp(std::cbrt(rtol), 1e-6, 1e-2); }

LawSetup MakeLawSetup(const Scene& scene, const CalibrationOptions& options) {
  LawSetup s;
  s.law = CreateLaw(scene.law, scene);
  s.body = BodyFromScene(scene);
  s.start = s.law->ParameterValues();
  const auto& specs = s.law->Parameters();
  auto check_name = [&](const std::string& n, const char* what) {
    if (s.law->ParameterIndex(n) < 0) {
      std::vector<std::string> names;
      for (const auto& sp : specs) names.push_back(sp.name);
      throw Error(ErrorCode::kBadParameter, std::string(what) + " '" + n + "': law " +
                                                s.law->Name() + " has no such parameter (" +
                                                Join(names) + ")");
    }
  };
  for (const auto& n : options.free_parameters) check_name(n, "free_parameters");
  for (const auto& n : options.fixed_parameters) check_name(n, "fixed_parameters");
  auto listed = [](const std::vector<std::string>& v, const std::string& n) {
    return std::find(v.begin(), v.end(), n) != v.end();
  };
  for (size_t i = 0; i < specs.size(); ++i) {
    const auto& sp = specs[i];
    const bool freed = listed(options.free_parameters, sp.name);
    const bool held = listed(options.fixed_parameters, sp.name);
    if ((sp.damping || freed) && !held && sp.upper > sp.lower)
      s.free.push_back(static_cast<int>(i));
    double typ = std::max(std::abs(s.start[i]), std::abs(sp.default_value));
    // Both zero (a damping coefficient defaulting to 0): one unit, or half the upper bound
    // when that is below one. The seeded start refines it.
    if (!(typ > 0.0)) typ = std::isfinite(sp.upper) && sp.upper < 1.0 ? 0.5 * sp.upper : 1.0;
    s.typical.push_back(typ);
  }
  if (s.free.empty()) {
    throw Error(ErrorCode::kUsage,
                "law " + s.law->Name() + ": no free parameter to fit (every parameter is held)");
  }
  std::vector<double> de(s.start.size(), 0.0);
  double e = 0.0;
  const double v_probe = 1.0;
  s.has_closed_e = s.law->Restitution(s.start, s.body, v_probe).has_value();
  s.has_gradient = s.law->RestitutionGradient(s.start, s.body, v_probe, &e, de.data());
  const LawInfo* info = FindLaw(s.law->Name());
  s.concurrent = info != nullptr && !info->needs_expression;
  for (int i : s.free) s.scale.push_back(s.typical[static_cast<size_t>(i)]);
  return s;
}

// Integrator steps an evaluation must hold to be spread over threads: starting one costs
// ~50 us, a DOP853 step 0.25-0.5 us. Measured on the bundled recording (2 cores, 11 alternating
// runs): jiang-liu's contacts (~134 steps each at its fitted damping; 12 speeds x 3 contacts per
// evaluation with the Jacobian) 286 -> 182 ms wall; the Hunt-Crossley family's (24 steps: 864
// per evaluation, below the bound) gained nothing when spread and cost 5 ms more CPU.
constexpr double kSpreadSteps = 1200.0;

// Runs task(k) for k in [0, n), each the `contacts` simulated contacts at one speed: on
// CalibrationOptions::threads threads when the law allows it and the evaluation is worth it
// (each k's result is computed as on one thread, so the values do not depend on the count).
void ForEachSpeed(const FitProblem& fp, std::size_t n, int contacts,
                  const std::function<void(std::size_t)>& task) {
  const LawSetup& s = fp.setup;
  const double steps = static_cast<double>(n) * contacts * s.contact_steps;
  const bool spread = !s.has_closed_e && s.concurrent && steps >= kSpreadSteps;
  ParallelFor(spread ? fp.options.threads : 1, n, task);
}

double ModelRestitution(const LawSetup& s, const std::vector<double>& p, double v_m_s, double g,
                        const SimulatorOptions& sim, std::atomic<long>* simulations) {
  if (s.has_closed_e) {
    if (auto e = s.law->Restitution(p, s.body, v_m_s)) return *e;
  }
  if (simulations) ++*simulations;
  return SimulateContact(*s.law, p, s.body, v_m_s, g, sim).restitution;
}

void AnalyzeRecordings(FitProblem* problem, const std::vector<CalibrationInput>& recordings,
                       const std::vector<double>* law_contact) {
  FitProblem& fp = *problem;
  const CalibrationOptions& options = fp.options;
  const Scene& scene = fp.scene;
  const bool several = recordings.size() > 1;
  fp.recordings.clear();
  fp.warnings.clear();
  fp.data = {};
  std::vector<double> scatters;
  AnalysisOptions ao = options.analysis;
  ao.use_drop = options.use_drop;
  if (law_contact && scene.effects.contact_duration) {
    // The contact durations of the law itself (at these parameters) instead of the Hertz
    // estimate: the intervals of a ball under this law contain exactly these contacts.
    const LawSetup& su = fp.setup;
    const std::vector<double> p = *law_contact;
    if (su.law->ContactTime(p, su.body, 1.0)) {
      ao.contact_time_of_speed = [&su, p, scene](double v) {
        const auto t = su.law->ContactTime(p, su.body, v);
        return t ? *t : HertzContactTime(scene, v);
      };
    }
  }
  for (size_t r = 0; r < recordings.size(); ++r) {
    RecordingData rd;
    rd.name = recordings[r].name;
    rd.sequence = recordings[r].sequence;
    try {
      rd.analysis = AnalyzeBounces(rd.sequence, scene, ao);
    } catch (const Error& e) {
      if (e.code() != ErrorCode::kNoBounces) throw;
      fp.not_determinable = rd.name + ": " + e.what() + " (a bounce needs at least 3 impacts)";
    }
    for (Warning w : rd.analysis.warnings) {
      if (several) w.message = rd.name + ": " + w.message;
      fp.warnings.push_back(w);
    }
    const bool drop_given = scene.drop.height_m || scene.drop.impact_speed_m_s;
    rd.drop_used = options.use_drop && drop_given && rd.analysis.drop_consistent &&
                   !rd.analysis.bounces.empty() && std::isfinite(rd.analysis.bounces[0].e);
    RestitutionData one;
    AppendRestitutionPoints(rd.analysis, 0, rd.drop_used, &one);
    // Points of this recording, renumbered into the joint data; irregular bounces left out.
    const int offset = static_cast<int>(fp.data.onset_sigma_s.size());
    for (RestitutionPoint p : one.points) {
      if (rd.analysis.bounces[static_cast<size_t>(p.bounce)].irregular) continue;
      p.recording = static_cast<int>(r);
      for (int& o : p.onset) o = o >= 0 ? o + offset : -1;
      fp.data.points.push_back(p);
    }
    fp.data.onset_sigma_s.insert(fp.data.onset_sigma_s.end(), one.onset_sigma_s.begin(),
                                 one.onset_sigma_s.end());
    fp.data.height_sigma_m.push_back(rd.drop_used ? rd.analysis.height_sigma_m : 0.0);
    if (rd.analysis.scatter_e) scatters.push_back(*rd.analysis.scatter_e);
    fp.recordings.push_back(std::move(rd));
  }
  std::vector<double> es, vs;
  for (const auto& p : fp.data.points) es.push_back(p.e), vs.push_back(p.u_m_s);
  fp.e_median = Median(es);
  fp.v_median = Median(vs);
  fp.scatter_start = options.estimate_scatter && !scatters.empty() ? Median(scatters) : 0.0;
}

FitProblem SetUpProblem(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                        const CalibrationOptions& options) {
  std::string err;
  if (!options.IsValid(&err)) throw Error(ErrorCode::kUsage, err);
  if (!scene.IsValid(&err)) throw Error(ErrorCode::kBadScene, err);
  if (recordings.empty()) throw Error(ErrorCode::kUsage, "calibrate: no recordings");
  FitProblem fp;
  fp.options = options;
  fp.scene = scene;
  fp.setup = MakeLawSetup(scene, options);
  fp.g = scene.EffectiveGravity();
  fp.sim.rel_tolerance = options.rel_tolerance;
  fp.sim.abs_tolerance = std::min(1e-12, options.rel_tolerance * 1e-3);
  AnalyzeRecordings(&fp, recordings, nullptr);
  if (fp.not_determinable.empty()) CountData(&fp, recordings);
  return fp;
}

void ProbeContactCost(FitProblem* fp, const std::vector<double>& p) {
  LawSetup& s = fp->setup;
  s.contact_steps = 0;
  if (s.has_closed_e || !s.concurrent || fp->options.threads < 2) return;
  // Not counted as a fit simulation: it decides only how the work is scheduled.
  try {
    const double v = fp->v_median > 0.0 ? fp->v_median : 1.0;
    SimulateContact(*s.law, p, s.body, v, fp->g, fp->sim, &s.contact_steps);
  } catch (const Error&) {
    s.contact_steps = 0;  // the fit reports the failure where it meets it
  }
}

std::vector<std::vector<double>> MakeStarts(FitProblem* fp, std::atomic<long>* simulations) {
  LawSetup& s = fp->setup;
  std::vector<std::vector<double>> starts;
  fp->seed_note = "start from the scene's values";
  const bool have_e = fp->e_median > 0.0 && fp->e_median < 1.0 && fp->v_median > 0.0;
  if (fp->options.seed_from_inverse_map && have_e) {
    if (auto q = InverseMapStart(s, fp->e_median, fp->v_median)) {
      starts.push_back(*q);
      fp->seed_note =
          "start from the inverse map e -> damping at e = " + FormatGeneral(fp->e_median, 4) +
          ", v = " + FormatGeneral(fp->v_median, 4) + " m/s";
    }
    if (auto q = ScanStart(s, fp->e_median, fp->v_median, fp->g, fp->sim, simulations)) {
      if (starts.empty()) {
        fp->seed_note = "start from a scan of the damping at e = " + FormatGeneral(fp->e_median, 4);
      }
      starts.push_back(*q);
    }
  }
  starts.push_back(s.start);  // the scene's values (or the law's defaults)
  // Damping a decade either side of the first start: a second basin shows up as disagreeing
  // starts instead of going unnoticed.
  for (double f : {0.1, 10.0}) {
    std::vector<double> q = starts.front();
    for (int i : FreeDamping(s)) q[static_cast<size_t>(i)] *= f;
    ClampIntoBounds(s, &q);
    std::string err;
    if (s.law->IsValid(q, s.body, &err)) starts.push_back(q);
  }
  // Distinct starts only, at most max_starts.
  std::vector<std::vector<double>> out;
  for (const auto& q : starts) {
    bool dup = false;
    for (const auto& o : out) {
      bool same = true;
      for (size_t i = 0; i < q.size(); ++i) {
        same &= std::abs(q[i] - o[i]) <= 1e-6 * std::max(std::abs(o[i]), s.typical[i]);
      }
      dup |= same;
    }
    if (!dup) out.push_back(q);
    if (static_cast<int>(out.size()) >= fp->options.max_starts) break;
  }
  // The first start fixes the scaling: its values are the best magnitude estimates.
  s.start = out.front();
  for (size_t j = 0; j < s.free.size(); ++j) {
    const double v = std::abs(s.start[static_cast<size_t>(s.free[j])]);
    if (v > 0.0 && std::isfinite(v)) {
      s.typical[static_cast<size_t>(s.free[j])] = v;
      s.scale[j] = v;
    }
  }
  return out;
}

}  // namespace bouncecal::calib
