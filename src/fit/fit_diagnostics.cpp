// Calibration stage 5: the outcome, its reason, the goodness of fit and the coded warnings
// (calibrate_stages.hpp).
//
// Goodness of fit (poor_fit). With sigma_s estimated, chi2/dof of the full model is ~1 by
// construction, so the law is tested in ways sigma_s cannot absorb:
//  - restitution: a residual trend with speed. The residuals are regressed (GLS, sigma_s
//    re-estimated by REML under this alternative) on x = ln(u / u_mean) and x^2 beside the law's
//    own Jacobian; the Wald statistic of the two coefficients is chi2 with 2 dof (1 when the data
//    are few). The law's e(v) shape is rejected when the trend is significant (p <
//    poor_fit_p_value) AND large: its rms over the bounces exceeds the scatter about law-plus-
//    trend (with the median timing sigma of e) — i.e. most of the apparent scatter sigma_s is
//    the law's misfit, not the ball's. (Significance alone rejects every law on 50 real bounces
//    for percent-level systematics far below the scatter.)
//  - the scatter itself: sigma_s more than two of its sigmas above plausible_scatter_e.
//  - trajectory: chi2 of the impact times with the restitution fit's sigma_s, against its
//    chi2(dof) distribution (normal approximation), p < poor_fit_p_value.
// Outcome precedence: failed > not_determinable > iteration_limit > poor_fit > converged (a
// fit stopped early has no goodness to test).
#include <algorithm>
#include <cmath>
#include <iomanip>
#include <sstream>

#include "bouncecal/core/format.hpp"
#include "bouncecal/core/stats.hpp"
#include "fit/calibrate_stages.hpp"

namespace bouncecal::calib {
namespace {

// Upper tail of chi2 with 1 or 2 degrees of freedom.
double Chi2Survival(double chi2, int dof) {
  if (dof == 1) return std::erfc(std::sqrt(std::max(chi2, 0.0) / 2.0));
  return std::exp(-std::max(chi2, 0.0) / 2.0);
}

}  // namespace

double TrendChi2(const FitProblem& fp, const Solution& s, int* dof, double* trend_rms,
                 double* scale) {
  *dof = 0;
  *trend_rms = *scale = 0.0;
  const int n = fp.data.size();
  const int p = static_cast<int>(s.jacobian.cols());
  // Enough points for the two extra terms and a scatter estimate: n - p - 2 >= 3.
  const int extra = n - p - 2 >= 3 ? 2 : (n - p - 1 >= 3 ? 1 : 0);
  if (extra == 0 || fp.options.strategy == FitStrategy::kTrajectory) return 0.0;
  double mean = 0.0;
  for (const auto& pt : fp.data.points) mean += std::log(pt.u_m_s) / n;
  Eigen::MatrixXd j(n, p + extra);
  j.leftCols(p) = s.jacobian;
  for (int k = 0; k < n; ++k) {
    const double x = std::log(fp.data.points[static_cast<size_t>(k)].u_m_s) - mean;
    j(k, p) = x;
    if (extra == 2) j(k, p + 1) = x * x;
  }
  ScatterOptions so;
  const ScatterProblem sp(s.residuals, j, s.timing_cov, {}, so);
  const ScatterFit f = fp.options.estimate_scatter ? sp.Fit() : ScatterFit{};
  const double sigma_s = fp.options.estimate_scatter ? f.sigma : 0.0;
  const ScatterProblem::Evaluation ev = sp.At(sigma_s);
  // The law alone at the same C: the trend's Wald statistic beta^T Cov_beta^-1 beta is the drop
  // in chi2 the trend gives (the extra-sum-of-squares identity of the general linear hypothesis,
  // Seber & Lee, Linear Regression Analysis, 2nd ed., ch. 4), computed without inverting a block
  // of the covariance (which cancels when the trend is nearly collinear with the law's columns).
  const ScatterProblem::Evaluation ev0 =
      ScatterProblem(s.residuals, s.jacobian, s.timing_cov, {}, so).At(sigma_s);
  if (!ev.ok || !ev0.ok) return 0.0;
  *dof = extra;
  // Size of the misfit: how much the predictions move when the trend is allowed, against the
  // scatter about the law-plus-trend and the typical timing sigma of e.
  const Eigen::VectorXd moved = j * ev.step;
  *trend_rms = std::sqrt(moved.squaredNorm() / n);
  std::vector<double> es;
  for (const auto& pt : fp.data.points) es.push_back(pt.e_sigma);
  *scale = std::hypot(sigma_s, UpperMedian(es));
  return std::max(ev0.chi2 - ev.chi2, 0.0);
}

Diagnosis Diagnose(const FitProblem& fp, const Solution& s, const Uncertainty& u,
                   const StartsReport& starts) {
  Diagnosis d;
  const CalibrationOptions& o = fp.options;
  const LawSetup& su = fp.setup;
  auto set = [&](FitOutcome out, const std::string& reason) {
    if (static_cast<int>(out) > static_cast<int>(d.outcome)) {
      d.outcome = out;
      d.reason = reason;
    }
  };
  if (!s.ok) {
    d.outcome = FitOutcome::kFailed;
    d.reason = s.failure;
    return d;
  }
  // Undetermined damping parameters (a freed stiffness that stays undetermined is a note).
  std::vector<std::string> why;
  const bool none_determined =
      std::find(u.undetermined.begin(), u.undetermined.end(), false) == u.undetermined.end();
  for (size_t j = 0; j < su.free.size(); ++j) {
    if (u.undetermined[j] &&
        (none_determined || su.specs()[static_cast<size_t>(su.free[j])].damping)) {
      why.push_back(u.undetermined_why[j]);
    }
  }
  if (!why.empty()) {
    std::string r = "the data cannot determine ";
    for (size_t i = 0; i < why.size(); ++i) r += (i ? "; " : "") + why[i];
    set(FitOutcome::kNotDeterminable, r);
  }
  if (s.iteration_limit) {
    set(FitOutcome::kIterationLimit, s.limit_note);
    d.warnings.push_back({"iteration_limit",
                          s.limit_note + ": the parameters are not at an optimum; "
                                         "raise max_iterations or check the start values",
                          -1});
  }
  // Goodness of fit.
  if (o.strategy == FitStrategy::kRestitution) {
    double size = 0.0, scale = 0.0;
    d.trend_chi2 = TrendChi2(fp, s, &d.trend_dof, &size, &scale);
    if (d.trend_dof > 0) {
      const double pv = Chi2Survival(d.trend_chi2, d.trend_dof);
      if (pv < o.poor_fit_p_value && size > scale) {
        set(FitOutcome::kPoorFit,
            "the law's e(v) misses the measured trend with speed by " + FormatGeneral(size, 2) +
                " rms, more than the bounces scatter about that trend (" + FormatGeneral(scale, 2) +
                "; trend chi2 = " + FormatGeneral(d.trend_chi2, 3) + " for " +
                std::to_string(d.trend_dof) + " dof, p = " + FormatGeneral(pv, 2) + ")");
      }
    }
  } else {
    const int dof = static_cast<int>(s.residuals.size() - s.jacobian.cols());
    if (dof > 0) {
      const double z = (s.scatter.chi2 - dof) / std::sqrt(2.0 * dof);
      const double pv = 0.5 * std::erfc(z / std::sqrt(2.0));
      if (pv < o.poor_fit_p_value) {
        set(FitOutcome::kPoorFit, "chi2/dof = " + FormatGeneral(s.scatter.chi2 / dof, 3) +
                                      " of the impact times with the scatter "
                                      "sigma_s = " +
                                      FormatGeneral(s.scatter.sigma, 2) +
                                      " of the restitution fit (p = " + FormatGeneral(pv, 2) +
                                      "): the simulated trajectory does not follow the recording");
      }
    }
  }
  const double ss = s.scatter.sigma, ss_sigma = s.scatter.sigma_sigma;
  if (ss - 2.0 * (std::isfinite(ss_sigma) ? ss_sigma : 0.0) > o.plausible_scatter_e) {
    set(FitOutcome::kPoorFit, "the scatter of e about the law, " + FormatGeneral(ss, 2) + " +- " +
                                  FormatGeneral(ss_sigma, 2) + ", exceeds what real balls show (" +
                                  FormatGeneral(o.plausible_scatter_e, 2) +
                                  "): the law does not describe these bounces");
  }
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
                            -1});
    }
  }
  if (starts.disagree) {
    d.warnings.push_back({"starts_disagree",
                          "of " + std::to_string(starts.tried) + " start points, " + starts.note +
                              ": the data allow more than one answer",
                          -1});
  }
  if (d.reason.empty()) d.reason = "converged";
  return d;
}

}  // namespace bouncecal::calib
