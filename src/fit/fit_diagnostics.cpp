// Calibration stage 5: the outcome, its reason, its hint (the next step), the goodness of fit and
// the coded warnings (calibrate_stages.hpp).
//
// Goodness of fit (poor_fit). With sigma_s estimated, chi2/dof of the full model is ~1 by
// construction, so the law is tested in ways sigma_s cannot absorb:
//  - restitution: the law's e(v) against a more flexible e(v), each with its own scatter, and
//    the misfit's size against what matters downstream (law_misfit.cpp): poor_fit when the
//    misfit is significant and larger than the tolerance; significant and smaller:
//    law_misfit_small.
//  - the scatter itself: sigma_s more than two of its sigmas above plausible_scatter_e.
//  - trajectory: chi2 of the impact times with the restitution fit's sigma_s, against its
//    chi2(dof) distribution (normal approximation), p < poor_fit_p_value.
// Outcome precedence: failed > not_determinable > iteration_limit > poor_fit > converged (a
// fit stopped early has no goodness to test). Every outcome but converged names what to try.
#include <algorithm>
#include <cmath>
#include <functional>

#include "fit/calibrate_stages.hpp"
#include "fit/text.hpp"

namespace bouncecal::calib {
namespace {}  // namespace

namespace {

// Stage 5's goodness-of-fit part: poor_fit (with its hint) or law_misfit_small.
void JudgeGoodness(
    const FitProblem& fp, const Solution& s, Diagnosis* d,
    const std::function<void(FitOutcome, const std::string&, const std::string&)>& set) {
  const CalibrationOptions& o = fp.options;
  const std::string law = fp.setup.law->Name();
  if (o.strategy == FitStrategy::kRestitution) {
    const LawMisfit m = TestLawMisfit(fp, s);
    d->trend_chi2 = m.chi2;
    d->trend_dof = m.dof;
    if (m.dof > 0) {
      d->misfit_p_value = m.p_value;
      d->misfit_e = m.rms_e;
      d->misfit_tolerance_e = m.tolerance_e;
      d->misfit_scatter_e = m.scatter_e;
    }
    if (m.matters) {
      set(FitOutcome::kPoorFit, MisfitText(m) + ": the law's e(v) has the wrong shape",
          LawShapeHint(fp, law));
    } else if (m.significant) {
      d->warnings.push_back(
          {"law_misfit_small",
           MisfitText(m) + ": significant, but below the tolerance, so the fit is usable", -1,
           "for a closer e(v): " + LawShapeHint(fp, law)});
    }
  } else {
    const int dof = static_cast<int>(s.residuals.size() - s.jacobian.cols());
    if (dof > 0) {
      const double z = (s.scatter.chi2 - dof) / std::sqrt(2.0 * dof);
      const double pv = 0.5 * std::erfc(z / std::sqrt(2.0));
      if (pv < o.poor_fit_p_value) {
        set(FitOutcome::kPoorFit,
            "chi2/dof = " + FormatGeneral(s.scatter.chi2 / dof, 3) +
                " of the impact times with the scatter sigma_s = " +
                FormatGeneral(s.scatter.sigma, 2) + " of the restitution fit (p = " +
                FormatGeneral(pv, 2) + "): the simulated trajectory does not follow the recording",
            "fit each bounce's e with its scatter instead (--strategy restitution); or fit every "
            "law and rank them (--law all)");
      }
    }
  }
  const double ss = s.scatter.sigma, ss_sigma = s.scatter.sigma_sigma;
  if (ss - 2.0 * (std::isfinite(ss_sigma) ? ss_sigma : 0.0) > o.plausible_scatter_e) {
    set(FitOutcome::kPoorFit,
        "the scatter of e about the law, " + FormatGeneral(ss, 2) + " +- " +
            FormatGeneral(ss_sigma, 2) + ", exceeds what real balls show (" +
            FormatGeneral(o.plausible_scatter_e, 2) + "): the law does not describe these bounces",
        "listen to the impacts used (detect --click-track FILE.wav): they may not all be this "
        "ball's bounces; then fit every law and rank them (--law all)");
  }
}

}  // namespace

Diagnosis Diagnose(const FitProblem& fp, const Solution& s, const Uncertainty& u,
                   const StartsReport& starts) {
  Diagnosis d;
  const CalibrationOptions& o = fp.options;
  const LawSetup& su = fp.setup;
  auto set = [&](FitOutcome out, const std::string& reason, const std::string& hint) {
    if (static_cast<int>(out) > static_cast<int>(d.outcome)) {
      d.outcome = out;
      d.reason = reason;
      d.hint = hint;
    }
  };
  if (!s.ok) {
    d.outcome = FitOutcome::kFailed;
    d.reason = s.failure;
    d.hint =
        "check the impacts (detect --click-track FILE.wav) and the scene (the ball, --height); "
        "fit every law and rank them (--law all)";
    return d;
  }
  // Undetermined damping parameters (a freed stiffness that stays undetermined is a note).
  std::vector<std::string> why, names;
  const bool none_determined =
      std::find(u.undetermined.begin(), u.undetermined.end(), false) == u.undetermined.end();
  for (size_t j = 0; j < su.free.size(); ++j) {
    const ParameterSpec& spec = su.specs()[static_cast<size_t>(su.free[j])];
    if (u.undetermined[j] && (none_determined || spec.damping)) {
      why.push_back(u.undetermined_why[j]);
      names.push_back(spec.name);
    }
  }
  if (!why.empty()) {
    std::string r = "the data cannot determine ";
    for (size_t i = 0; i < why.size(); ++i) r += (i ? "; " : "") + why[i];
    set(FitOutcome::kNotDeterminable, r,
        "hold " + fit_text::Join(names) + " at a value you know (--fix " + names.front() +
            " --set " + names.front() +
            "=VALUE), free fewer parameters, or record bounces over a wider range of speeds");
  }
  if (s.iteration_limit) {
    const std::string more = "raise --max-iterations (now " + std::to_string(o.max_iterations) +
                             ") or give start values (--set NAME=VALUE)";
    set(FitOutcome::kIterationLimit, s.limit_note, more);
    d.warnings.push_back({"iteration_limit",
                          s.limit_note + ": the parameters are not at an optimum; "
                                         "raise max_iterations or check the start values",
                          -1, more});
  }
  JudgeGoodness(fp, s, &d, set);
  // Parameters stopped at a bound.
  for (size_t j = 0; j < su.free.size(); ++j) {
    if (u.undetermined[j]) continue;
    const size_t i = static_cast<size_t>(su.free[j]);
    const ParameterSpec& sp = su.specs()[i];
    const double tol = 1e-8 * std::max(std::abs(s.p[i]), su.typical[i]);
    if (s.p[i] <= sp.lower + tol || s.p[i] >= sp.upper - tol) {
      d.warnings.push_back({"fit_at_bound",
                            sp.name + " = " + FormatGeneral(s.p[i], 4) + " " + sp.unit +
                                " stopped at its bound [" + FormatGeneral(sp.lower, 3) + ", " +
                                FormatGeneral(sp.upper, 3) +
                                "]: the data push it outside the law's physical "
                                "range; its sigma is one-sided at best",
                            -1,
                            "fit every law and rank them (--law all), and check the scene (the "
                            "ball, --drag, --height)"});
    }
  }
  if (starts.disagree) {
    d.warnings.push_back({"starts_disagree",
                          "of " + std::to_string(starts.tried) + " start points, " + starts.note +
                              ": the data allow more than one answer",
                          -1,
                          "record more bounces over a wider range of speeds, or hold a parameter "
                          "at a value you know (--fix NAME --set NAME=VALUE)"});
  }
  if (d.reason.empty()) d.reason = "converged";
  if (d.outcome == FitOutcome::kConverged)
    d.hint =
        "write the parameter file (-o PARAMS.json) and export it to a simulator (bouncecal "
        "export PARAMS.json --to lammps|liggghts|yade)";
  return d;
}

}  // namespace bouncecal::calib
