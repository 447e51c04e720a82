// Calibration: Calibrate as a list of named stages (calibrate_stages.hpp), the law comparison,
// and the names and options of calibrate.hpp. The reports are in fit_report.cpp.
#include "bouncecal/fit/calibrate.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/parallel.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "fit/calibrate_stages.hpp"
#include "fit/text.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

using fit_text::Join;

// The result skeleton: law identity, every parameter at the given values, no sigmas.
Calibration Skeleton(const calib::FitProblem& fp, const std::vector<double>& p) {
  Calibration c;
  const calib::LawSetup& su = fp.setup;
  c.law = su.law->Name();
  c.formula = su.law->Formula();
  c.source = su.law->Source();
  c.strategy = fp.options.strategy;
  c.derivatives = fp.options.derivatives;
  c.residual_unit = fp.options.strategy == FitStrategy::kTrajectory ? "s" : "1";
  const auto& specs = su.specs();
  for (size_t i = 0; i < specs.size(); ++i) {
    FittedParameter f;
    f.name = specs[i].name;
    f.unit = specs[i].unit;
    f.value = p[i];
    f.sigma = kNaN;
    f.lower = specs[i].lower;
    f.upper = specs[i].upper;
    f.damping = specs[i].damping;
    f.fixed = std::find(su.free.begin(), su.free.end(), static_cast<int>(i)) == su.free.end();
    c.parameters.push_back(f);
  }
  c.warnings = fp.warnings;
  c.scene = fp.scene;
  for (const auto& f : c.parameters) c.scene.law.parameters[f.name] = f.value;
  if (!fp.options.use_drop) {
    // The drop was not given: the result must not claim one.
    c.scene.drop.height_m.reset();
    c.scene.drop.height_sigma_m.reset();
    c.scene.drop.impact_speed_m_s.reset();
  }
  return c;
}

// Stage 6: the result from the solution, its uncertainty and its diagnosis.
void Assemble(const calib::FitProblem& fp, const calib::Solution& s, const calib::Uncertainty& u,
              const calib::Diagnosis& d, const calib::StartsReport& starts, Calibration* c) {
  const calib::LawSetup& su = fp.setup;
  const bool traj = fp.options.strategy == FitStrategy::kTrajectory;
  for (size_t i = 0; i < c->parameters.size(); ++i) {
    FittedParameter& f = c->parameters[i];
    const auto it = std::find(su.free.begin(), su.free.end(), static_cast<int>(i));
    if (it == su.free.end()) {
      f.determined = u.held_determinable[i];
      continue;
    }
    const size_t j = static_cast<size_t>(it - su.free.begin());
    f.determined = !u.undetermined[j];
    f.sigma = f.determined ? u.sigma[i] : kNaN;
    const double tol = 1e-8 * std::max(std::abs(f.value), su.typical[i]);
    f.at_bound = f.value <= f.lower + tol || f.value >= f.upper - tol;
  }
  c->analytic_jacobian =
      fp.options.derivatives == DerivativeMode::kAuto && su.has_gradient &&
      (!traj || (!fp.scene.effects.contact_duration && !fp.scene.effects.surface_compliance));
  c->e_of_v = u.e_of_v;
  c->v_min_m_s = u.v_min_m_s;
  c->v_max_m_s = u.v_max_m_s;
  c->scatter_e = s.scatter.sigma;
  c->scatter_e_sigma = s.scatter.sigma_sigma;
  c->scatter_at_zero = s.scatter.sigma_at_zero || !(s.scatter.sigma > 0.0);
  const int n = static_cast<int>(s.residuals.size());
  const int p = static_cast<int>(s.jacobian.cols());
  c->num_residuals = n;
  c->num_free = p;
  c->dof = n - p;
  c->chi2 = s.scatter.chi2;
  c->chi2_dof = c->dof > 0 ? c->chi2 / c->dof : kNaN;
  c->trend_chi2 = d.trend_chi2;
  c->trend_dof = d.trend_dof;
  c->misfit_p_value = d.misfit_p_value;
  c->misfit_e = d.misfit_e;
  c->misfit_tolerance_e = d.misfit_tolerance_e;
  c->misfit_scatter_e = d.misfit_scatter_e;
  c->neg_log_likelihood = s.scatter.neg_log_likelihood;
  const int k = p + (fp.options.estimate_scatter ? 1 : 0);
  c->aic = 2.0 * c->neg_log_likelihood + 2.0 * k;
  c->bic = 2.0 * c->neg_log_likelihood + k * std::log(static_cast<double>(std::max(n, 1)));
  c->starts = starts.tried;
  c->starts_reached_best = starts.reached_best;
  // Per recording: residuals (and the trajectory's nuisances).
  size_t row = 0;
  double ss = 0.0;
  int nres = 0;
  for (size_t r = 0; r < fp.recordings.size(); ++r) {
    RecordingFit rf;
    rf.name = fp.recordings[r].name;
    rf.impact_speed_m_s = rf.impact_speed_sigma_m_s = rf.time_origin_s = rf.time_origin_sigma_s =
        kNaN;
    if (traj) {
      rf.impacts = static_cast<int>(fp.recordings[r].sequence.impacts.size());
      rf.simulated_impacts = s.simulated_impacts[r];
      rf.impact_speed_m_s = s.v0[r];
      rf.impact_speed_sigma_m_s = s.v0_sigma[r];
      rf.impact_speed_fixed = !s.v0_free[r];
      rf.time_origin_s = s.t0[r];
      rf.time_origin_sigma_s = s.t0_sigma[r];
      for (int q = 0; q < rf.impacts; ++q)
        rf.residuals.push_back(s.residuals(static_cast<Eigen::Index>(row++)));
      if (fp.recordings[r].drop_used && s.v0_free[r] &&
          fp.recordings[r].analysis.height_sigma_m > 0.0)
        ++row;
    } else {
      for (int q = 0; q < fp.data.size(); ++q) {
        if (fp.data.points[static_cast<size_t>(q)].recording != static_cast<int>(r)) continue;
        rf.residuals.push_back(s.residuals(q));
        ++rf.impacts;
      }
    }
    double s2 = 0.0;
    for (double x : rf.residuals) s2 += x * x;
    ss += s2;
    nres += static_cast<int>(rf.residuals.size());
    rf.rms_residual =
        rf.residuals.empty() ? 0.0 : std::sqrt(s2 / static_cast<double>(rf.residuals.size()));
    c->recordings.push_back(rf);
  }
  c->rms_residual = nres ? std::sqrt(ss / nres) : 0.0;
  c->outcome = d.outcome;
  c->reason = d.reason;
  c->hint = d.hint;
  for (const Warning& w : d.warnings) c->warnings.push_back(w);
  std::vector<std::string> notes = {fp.seed_note};
  if (starts.tried > 1) {
    notes.push_back(std::to_string(starts.reached_best) + " of " + std::to_string(starts.tried) +
                    " start points reached the best fit");
  }
  for (size_t j = 0; j < su.free.size(); ++j) {
    if (!u.undetermined_why[j].empty() && !su.specs()[static_cast<size_t>(su.free[j])].damping) {
      notes.push_back("not determined: " + u.undetermined_why[j] + " (held at its start value)");
    }
  }
  c->message = Join(notes, "; ");
}

// A result without a fit (the data cannot give one): parameters at their start values.
Calibration Unfitted(const calib::FitProblem& fp, FitOutcome outcome, const std::string& reason,
                     const std::string& hint) {
  Calibration c = Skeleton(fp, fp.setup.start);
  c.outcome = outcome;
  c.reason = reason;
  c.hint = hint;
  c.message = reason;
  c.chi2 = c.chi2_dof = c.aic = c.bic = kNaN;
  c.scatter_e = c.scatter_e_sigma = kNaN;
  return c;
}

}  // namespace

// =============================================================================================
Calibration Calibrate(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                      const CalibrationOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  std::atomic<long> simulations{0};
  calib::FitProblem fp = calib::SetUpProblem(recordings, scene, options);  // stage 1
  if (!fp.not_determinable.empty()) {
    return Unfitted(fp, FitOutcome::kNotDeterminable, fp.not_determinable,
                    "record more bounces (a higher drop, a quieter room, the microphone near the "
                    "impact point), or give the drop height (--height) so that the first impact "
                    "counts");
  }
  if (fp.e_median >= 1.0) {
    return Unfitted(fp, FitOutcome::kFailed,
                    "the measured median restitution " + FormatGeneral(fp.e_median, 4) +
                        " is >= 1: these impacts do not form a damped bounce sequence",
                    "listen to the impacts used (detect --click-track FILE.wav) and check the "
                    "scene (--drag, --contact-duration)");
  }
  const std::vector<std::vector<double>> starts = calib::MakeStarts(&fp, &simulations);  // 2
  calib::ProbeContactCost(&fp, starts.front());
  if (scene.effects.contact_duration) {
    // The law's own contact durations at its best start (they change with the damping only
    // at the percent level of a few-percent change of the damping).
    calib::AnalyzeRecordings(&fp, recordings, &starts.front());
  }
  calib::StartsReport report;
  std::vector<bool> held(fp.setup.free.size(), false);
  calib::Solution s = calib::SolveFromStarts(fp, starts, held, &report, &simulations);  // 3
  std::vector<std::string> why;
  std::vector<bool> undetermined = calib::FindUndetermined(s, fp, &why);
  if (std::find(undetermined.begin(), undetermined.end(), true) != undetermined.end() &&
      std::find(undetermined.begin(), undetermined.end(), false) != undetermined.end()) {
    // Hold the undetermined ones at their start values and refit the rest from the optimum.
    std::vector<double> restart = s.p;
    for (size_t j = 0; j < undetermined.size(); ++j) {
      const size_t i = static_cast<size_t>(fp.setup.free[j]);
      if (undetermined[j]) restart[i] = fp.setup.start[i];
    }
    calib::StartsReport again;
    s = calib::SolveFromStarts(fp, {restart}, undetermined, &again, &simulations);
  } else if (s.ok &&
             std::find(undetermined.begin(), undetermined.end(), false) == undetermined.end()) {
    s.held = undetermined;  // nothing determined: report every free parameter as such
  }
  calib::Uncertainty u = calib::EstimateUncertainty(fp, s, &simulations);  // stage 4
  u.undetermined = undetermined;
  u.undetermined_why = why;
  if (s.ok) {
    for (size_t j = 0; j < undetermined.size(); ++j) {
      if (undetermined[j]) u.sigma[static_cast<size_t>(fp.setup.free[j])] = kNaN;
    }
  }
  const calib::Diagnosis d = calib::Diagnose(fp, s, u, report);  // stage 5
  Calibration c = Skeleton(fp, s.ok ? s.p : fp.setup.start);
  if (s.ok) {
    Assemble(fp, s, u, d, report, &c);
  } else {
    c = Unfitted(fp, FitOutcome::kFailed, d.reason, d.hint);
  }
  c.iterations = s.iterations;
  c.simulations = simulations.load();
  c.solve_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return c;
}

// =============================================================================================
std::vector<LawComparisonRow> CompareLaws(const std::vector<CalibrationInput>& recordings,
                                          const Scene& scene, const CalibrationOptions& options,
                                          int jobs) {
  struct Job {
    Scene scene;
    CalibrationOptions options;
    LawComparisonRow row;
  };
  std::vector<Job> todo;
  for (const LawInfo& info : RegisteredLaws()) {
    Job job{scene, options, {}};
    if (info.name == scene.law.name) {
      job.scene.law = scene.law;
    } else {
      if (info.needs_expression) continue;  // needs the user's expression
      job.scene.law = LawSpec{};
      job.scene.law.name = info.name;
    }
    job.row.fit.law = info.name;
    job.row.fit.strategy = options.strategy;
    job.row.fit.derivatives = options.derivatives;
    todo.push_back(std::move(job));
  }
  auto run = [&](Job& job) {
    try {
      // Keep only the free/fixed names this law has.
      auto law = CreateLaw(job.scene.law, job.scene);
      auto keep = [&](std::vector<std::string>& v) {
        v.erase(std::remove_if(v.begin(), v.end(),
                               [&](const std::string& n) { return law->ParameterIndex(n) < 0; }),
                v.end());
      };
      keep(job.options.free_parameters);
      keep(job.options.fixed_parameters);
      job.row.fit = Calibrate(recordings, job.scene, job.options);
    } catch (const std::exception& e) {
      // Any exception (not only Error) fails this law's row: none may escape a worker thread.
      job.row.fit.outcome = FitOutcome::kFailed;
      job.row.fit.reason = e.what();
      job.row.fit.message = e.what();
    } catch (...) {
      job.row.fit.outcome = FitOutcome::kFailed;
      job.row.fit.reason = job.row.fit.message = "internal error: unknown exception";
    }
    job.row.adequate = job.row.fit.outcome == FitOutcome::kConverged;
  };
  // The slowest fits start first, so that with several threads the comparison ends with short
  // fits rather than waiting on a long one started last: laws with internal state (their
  // contacts are integrated with a stiff relaxation), then laws without a closed-form e(v)
  // (every contact simulated), then the rest. Results stay in registry order.
  auto cost_rank = [&](const Job& job) {
    try {
      const auto law = CreateLaw(job.scene.law, job.scene);
      const LawInfo* info = FindLaw(job.scene.law.name);
      if (law->StateSize() > 0) return 2;
      return info != nullptr && info->HasClosedForm("restitution") ? 0 : 1;
    } catch (const std::exception&) {
      return 0;  // fails fast in run()
    }
  };
  std::vector<size_t> order(todo.size());
  std::vector<int> rank(todo.size());
  for (size_t i = 0; i < todo.size(); ++i) order[i] = i, rank[i] = cost_rank(todo[i]);
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return rank[a] > rank[b]; });
  // A law's fit spreads its simulated contacts over the same threads (ForEachSpeed): those
  // that have no law left to fit take them, so the slow fits started first end sooner.
  ParallelFor(jobs, todo.size(), [&](size_t i) { run(todo[order[i]]); });

  std::vector<LawComparisonRow> rows;
  for (auto& j : todo) rows.push_back(std::move(j.row));
  // Adequate fits first, by AIC; then the others in registry order.
  std::stable_sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) {
    if (a.adequate != b.adequate) return a.adequate;
    return a.adequate && a.fit.aic < b.fit.aic;
  });
  const double best = !rows.empty() && rows.front().adequate ? rows.front().fit.aic : kNaN;
  for (auto& r : rows) r.delta_aic = r.adequate ? r.fit.aic - best : kNaN;
  return rows;
}

// =============================================================================================
const char* FitStrategyName(FitStrategy s) {
  return s == FitStrategy::kTrajectory ? "trajectory" : "restitution";
}
const char* DerivativeModeName(DerivativeMode d) {
  return d == DerivativeMode::kAuto ? "auto" : "numeric";
}
const char* RobustLossName(RobustLoss l) {
  switch (l) {
    case RobustLoss::kNone:
      return "none";
    case RobustLoss::kHuber:
      return "huber";
    case RobustLoss::kCauchy:
      return "cauchy";
  }
  return "none";
}
const char* FitOutcomeName(FitOutcome o) {
  switch (o) {
    case FitOutcome::kConverged:
      return "converged";
    case FitOutcome::kIterationLimit:
      return "iteration_limit";
    case FitOutcome::kPoorFit:
      return "poor_fit";
    case FitOutcome::kNotDeterminable:
      return "not_determinable";
    case FitOutcome::kFailed:
      return "failed";
  }
  return "failed";
}
ErrorCode FitOutcomeExitCode(FitOutcome o) {
  switch (o) {
    case FitOutcome::kConverged:
      return ErrorCode::kOk;
    case FitOutcome::kIterationLimit:
      return ErrorCode::kFitIterationLimit;
    case FitOutcome::kPoorFit:
      return ErrorCode::kFitPoorFit;
    case FitOutcome::kNotDeterminable:
      return ErrorCode::kFitNotDeterminable;
    case FitOutcome::kFailed:
      return ErrorCode::kFitFailed;
  }
  return ErrorCode::kFitFailed;
}

FitStrategy ParseFitStrategy(const std::string& s) {
  if (s == "trajectory") return FitStrategy::kTrajectory;
  if (s == "restitution") return FitStrategy::kRestitution;
  throw Error(ErrorCode::kUsage, "strategy '" + s + "': expected trajectory or restitution");
}
DerivativeMode ParseDerivativeMode(const std::string& s) {
  if (s == "auto") return DerivativeMode::kAuto;
  if (s == "numeric") return DerivativeMode::kNumeric;
  throw Error(ErrorCode::kUsage, "derivatives '" + s + "': expected auto or numeric");
}
RobustLoss ParseRobustLoss(const std::string& s) {
  if (s == "none") return RobustLoss::kNone;
  if (s == "huber") return RobustLoss::kHuber;
  if (s == "cauchy") return RobustLoss::kCauchy;
  throw Error(ErrorCode::kUsage, "loss '" + s + "': expected none, huber or cauchy");
}

bool CalibrationOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "calibration options: " + m;
    return false;
  };
  if (!(rel_tolerance >= 1e-14 && rel_tolerance <= 1e-2)) {
    return fail("rel_tolerance = " + FormatGeneral(rel_tolerance) + " must be in [1e-14, 1e-2]");
  }
  if (!(loss_scale_sigma > 0.0) || !std::isfinite(loss_scale_sigma)) {
    return fail("loss_scale_sigma = " + FormatGeneral(loss_scale_sigma) + " must be positive");
  }
  if (max_iterations < 1 || max_iterations > 10000) {
    return fail("max_iterations = " + std::to_string(max_iterations) + " must be in [1, 10000]");
  }
  if (threads < 1 || threads > 256) {
    return fail("threads = " + std::to_string(threads) + " must be in [1, 256]");
  }
  if (max_starts < 1 || max_starts > 100) {
    return fail("max_starts = " + std::to_string(max_starts) + " must be in [1, 100]");
  }
  if (e_of_v_points < 2 || e_of_v_points > 1000) {
    return fail("e_of_v_points = " + std::to_string(e_of_v_points) + " must be in [2, 1000]");
  }
  if (!(undetermined_relative_sigma > 0.0)) {
    return fail("undetermined_relative_sigma = " + FormatGeneral(undetermined_relative_sigma) +
                " must be positive");
  }
  if (!(poor_fit_p_value > 0.0 && poor_fit_p_value < 1.0)) {
    return fail("poor_fit_p_value = " + FormatGeneral(poor_fit_p_value) + " must be in (0, 1)");
  }
  if (!(misfit_tolerance_e >= 0.0) || !std::isfinite(misfit_tolerance_e)) {
    return fail("misfit_tolerance_e = " + FormatGeneral(misfit_tolerance_e) + " must be >= 0");
  }
  if (!(plausible_scatter_e > 0.0) || !std::isfinite(plausible_scatter_e)) {
    return fail("plausible_scatter_e = " + FormatGeneral(plausible_scatter_e) +
                " must be positive");
  }
  std::string why;
  if (!analysis.IsValid(&why)) return fail("analysis." + why);
  for (const auto& f : free_parameters) {
    if (std::find(fixed_parameters.begin(), fixed_parameters.end(), f) != fixed_parameters.end()) {
      return fail("parameter '" + f + "' is both freed and held");
    }
  }
  return true;
}

std::vector<std::string> Calibration::Determined() const {
  std::vector<std::string> out;
  for (const auto& p : parameters) {
    if (!p.fixed && p.determined) out.push_back(p.name);
  }
  return out;
}

std::vector<std::string> Calibration::Undetermined() const {
  std::vector<std::string> out;
  for (const auto& p : parameters) {
    if (!p.determined) out.push_back(p.name);
  }
  return out;
}

}  // namespace bouncecal
