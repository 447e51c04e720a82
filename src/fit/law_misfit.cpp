// Calibration stage 5a: is the law's e(v) adequate? (calibrate_stages.hpp; docs/physics.md §9.4)
//
// The law is compared with a more flexible e(v) — the law plus a x + b x^2, x = ln(u / u_mean) —
// fairly: each model with its own per-bounce scatter sigma_s, the flexible one penalised for
// its extra parameters by the likelihood-ratio test (Wilks: 2 (nll_law - nll_flexible) ~
// chi2(extra) when the law is right), the scatter profiled by maximum likelihood under each.
// (The test this replaces compared both at the flexible curve's sigma_s, the scatter left once
// the curve has followed the points: with 10 bounces it made every misfit significant.)
//
// Significance is not enough to reject: what matters downstream is the size of the misfit, the
// rms over the bounces of the two fitted curves' difference. The law is poor_fit only when the
// misfit is significant AND larger than both the e a simulator is required to reproduce
// (CalibrationOptions::misfit_tolerance_e) and the ball's own scatter about the flexible curve
// (a misfit inside the bounce-to-bounce scatter does not change what a DEM run can show).
// Significant and smaller: converged, with the warning law_misfit_small and the numbers.
#include <algorithm>
#include <cmath>

#include "bouncecal/core/format.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "fit/calibrate_stages.hpp"
#include "fit/text.hpp"

namespace bouncecal::calib {
namespace {

// Upper tail of chi2 with 1 or 2 degrees of freedom.
double Chi2Survival(double chi2, int dof) {
  if (dof == 1) return std::erfc(std::sqrt(std::max(chi2, 0.0) / 2.0));
  return std::exp(-std::max(chi2, 0.0) / 2.0);
}

// -ln L (Gaussian, ML form) of a model at its own sigma_s: profiled by maximum likelihood when
// the scatter is estimated, else at sigma_s = 0 (timing noise only).
double ProfileNegLogLikelihood(const Eigen::VectorXd& r, const Eigen::MatrixXd& j,
                               const Eigen::MatrixXd& timing_cov, bool estimate_scatter, bool* ok) {
  ScatterOptions ml;
  ml.reml = false;
  const ScatterProblem sp(r, j, timing_cov, {}, ml);
  if (estimate_scatter) {
    const ScatterFit f = sp.Fit();
    *ok = f.ok;
    return f.neg_log_likelihood;
  }
  const ScatterProblem::Evaluation ev = sp.At(0.0);
  *ok = ev.ok;
  return 0.5 * (static_cast<double>(r.size()) * std::log(2.0 * M_PI) + ev.log_det_c + ev.chi2);
}

}  // namespace

LawMisfit TestLawMisfit(const FitProblem& fp, const Solution& s) {
  LawMisfit m;
  m.tolerance_e = fp.options.misfit_tolerance_e;
  const int n = fp.data.size();
  const int p = static_cast<int>(s.jacobian.cols());
  // Enough points for the extra terms and a scatter estimate: n - p - extra >= 3.
  const int extra = n - p - 2 >= 3 ? 2 : (n - p - 1 >= 3 ? 1 : 0);
  if (extra == 0 || fp.options.strategy == FitStrategy::kTrajectory) return m;
  double mean = 0.0;
  for (const auto& pt : fp.data.points) mean += std::log(pt.u_m_s) / n;
  Eigen::MatrixXd flexible(n, p + extra);
  flexible.leftCols(p) = s.jacobian;
  for (int k = 0; k < n; ++k) {
    const double x = std::log(fp.data.points[static_cast<size_t>(k)].u_m_s) - mean;
    flexible(k, p) = x;
    if (extra == 2) flexible(k, p + 1) = x * x;
  }
  const bool scatter = fp.options.estimate_scatter;
  bool ok_law = false, ok_flexible = false;
  const double nll_law =
      ProfileNegLogLikelihood(s.residuals, s.jacobian, s.timing_cov, scatter, &ok_law);
  const double nll_flexible =
      ProfileNegLogLikelihood(s.residuals, flexible, s.timing_cov, scatter, &ok_flexible);
  // The two curves, each at its own REML sigma_s (the fit's, for the law): their difference at
  // the bounces is the law's systematic misfit; the scatter about the flexible one is the ball's.
  const ScatterProblem sp(s.residuals, flexible, s.timing_cov);
  const ScatterFit f = scatter ? sp.Fit() : ScatterFit{};
  const ScatterProblem::Evaluation ev = sp.At(scatter ? f.sigma : 0.0);
  if (!ok_law || !ok_flexible || !ev.ok) return m;
  m.dof = extra;
  m.chi2 = std::max(2.0 * (nll_law - nll_flexible), 0.0);
  m.p_value = Chi2Survival(m.chi2, extra);
  const Eigen::VectorXd law_step =
      s.scatter.step.size() == p ? s.scatter.step : Eigen::VectorXd(Eigen::VectorXd::Zero(p));
  const Eigen::VectorXd difference = flexible * ev.step - s.jacobian * law_step;
  m.rms_e = std::sqrt(difference.squaredNorm() / n);
  m.scatter_e = scatter ? f.sigma : 0.0;
  m.tolerance_e = std::max(fp.options.misfit_tolerance_e, m.scatter_e);
  m.significant = m.p_value < fp.options.poor_fit_p_value;
  m.matters = m.significant && m.rms_e > m.tolerance_e;
  return m;
}

std::vector<std::string> SpeedDependentLaws(const FitProblem& fp) {
  // A decade of speeds about the measured median: a property of the law, not of how wide the
  // measured range happens to be.
  const double v = fp.v_median > 0.0 ? fp.v_median : 1.0;
  const double lo = v / std::sqrt(10.0), hi = v * std::sqrt(10.0);
  // A change of e larger than this over the decade is the law's own: far above the contact
  // integrator's noise (relative tolerance 1e-9) and far below any e(v) a fit could use.
  constexpr double kMinChange = 1e-6;
  std::vector<std::string> out;
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;
    try {
      Scene scene = fp.scene;
      scene.law = LawSpec{};
      scene.law.name = info.name;
      const LawSetup su = MakeLawSetup(scene, fp.options);
      // Gravity off: the contact alone (g during a contact shifts e by ~1e-5 at low speeds).
      const double e_lo = ModelRestitution(su, su.start, lo, 0.0, fp.sim, nullptr);
      const double e_hi = ModelRestitution(su, su.start, hi, 0.0, fp.sim, nullptr);
      if (std::abs(e_hi - e_lo) > kMinChange) out.push_back(info.name);
    } catch (const std::exception&) {  // a law this scene cannot make is not suggested
    }
  }
  return out;
}

std::string LawShapeHint(const FitProblem& fp, const std::string& law) {
  std::vector<std::string> others;
  for (const std::string& name : SpeedDependentLaws(fp))
    if (name != law) others.push_back(name);
  std::string hint = "fit every law and rank them (--law all)";
  if (!others.empty()) hint += "; a law whose e changes with speed: " + fit_text::Join(others);
  if (!fp.scene.effects.contact_duration)
    hint +=
        "; take the contact time out of the intervals (--contact-duration, [effects] "
        "contact_duration = true)";
  bool exact_drop = false;
  for (const RecordingData& r : fp.recordings)
    exact_drop |= r.drop_used && !(r.analysis.height_sigma_m > 0.0);
  if (exact_drop)
    hint += "; give the drop height's uncertainty (--height-sigma, [drop] height_sigma_m)";
  return hint;
}

std::string MisfitText(const LawMisfit& m) {
  return "the law's e(v) differs from a smoother fit through the bounces by " +
         FormatGeneral(m.rms_e, 2) + " rms (likelihood ratio chi2 = " + FormatGeneral(m.chi2, 3) +
         " for " + std::to_string(m.dof) + " dof, p = " + FormatGeneral(m.p_value, 2) +
         ", each with its own scatter); tolerance " + FormatGeneral(m.tolerance_e, 2) +
         " (the larger of the e a simulator must reproduce and the " +
         "ball's scatter about that fit, " + FormatGeneral(m.scatter_e, 2) + ")";
}

}  // namespace bouncecal::calib
