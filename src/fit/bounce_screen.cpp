// Scatter, irregular bounces, drop consistency and drag from the bounces alone
// (bounce_screen.hpp).
#include "bouncecal/fit/bounce_screen.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "bouncecal/core/format.hpp"
#include "bouncecal/core/stats.hpp"
#include "bouncecal/fit/scatter_model.hpp"
#include "bouncecal/physics/flight.hpp"
#include "fit/text.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// A smooth e(u) = sum_j beta_j f_j(u) over a choice of the terms {1, x, u/u_ref, x^2},
// x = ln(u/u_ref): ln u carries the viscoelastic e ~ 1 - c u^(1/5) family, u the
// Hunt-Crossley-like linear fall, x^2 a rise-and-fall; fitted with the scatter model.
struct SmoothCurve {
  std::vector<int> terms;  // indices into {1, x, u/u_ref, x^2}
  double u_ref = 1.0;
  Eigen::VectorXd beta;
  Eigen::MatrixXd beta_cov;
  ScatterFit scatter;
  std::vector<double> residual, z;  // per point: model - measured, and in sigmas

  Eigen::VectorXd Basis(double u) const {
    const double x = std::log(u / u_ref);
    const double all[4] = {1.0, x, u / u_ref, x * x};
    Eigen::VectorXd f(static_cast<Eigen::Index>(terms.size()));
    for (size_t j = 0; j < terms.size(); ++j) f(static_cast<Eigen::Index>(j)) = all[terms[j]];
    return f;
  }
  double Value(double u) const { return Basis(u).dot(beta); }
  double Slope(double u) const {  // de/du
    const double x = std::log(u / u_ref);
    const double all[4] = {0.0, 1.0 / u, 1.0 / u_ref, 2.0 * x / u};
    double d = 0.0;
    for (size_t j = 0; j < terms.size(); ++j)
      d += beta(static_cast<Eigen::Index>(j)) * all[terms[j]];
    return d;
  }
};

// GLS + REML fit of the curve; with fixed_sigma >= 0 the scatter is held at that value.
SmoothCurve FitCurve(const RestitutionData& data, std::vector<int> terms,
                     double fixed_sigma = -1.0) {
  SmoothCurve c;
  const int n = data.size();
  c.terms = std::move(terms);
  const int degree = static_cast<int>(c.terms.size()) - 1;
  double lsum = 0.0;
  for (const auto& p : data.points) lsum += std::log(p.u_m_s);
  c.u_ref = std::exp(lsum / n);
  Eigen::MatrixXd x(n, degree + 1);
  Eigen::VectorXd e(n);
  for (int k = 0; k < n; ++k) {
    x.row(k) = c.Basis(data.points[static_cast<size_t>(k)].u_m_s).transpose();
    e(k) = data.points[static_cast<size_t>(k)].e;
  }
  c.beta = Eigen::VectorXd::Zero(degree + 1);
  std::vector<double> slopes(static_cast<size_t>(n), 0.0);
  Eigen::MatrixXd ct;
  // Two passes: the timing covariance depends on the curve's slope at each point.
  for (int pass = 0; pass < 2; ++pass) {
    ct = data.TimingCovariance(slopes);
    ScatterProblem sp(-e, x, ct);
    if (fixed_sigma >= 0.0) {
      const ScatterProblem::Evaluation ev = sp.At(fixed_sigma);
      c.scatter.ok = ev.ok;
      c.scatter.sigma = fixed_sigma;
      c.scatter.step = ev.step;
      c.scatter.covariance = ev.covariance;
    } else {
      c.scatter = sp.Fit();
    }
    if (!c.scatter.ok) return c;
    c.beta = c.scatter.step;
    c.beta_cov = c.scatter.covariance;
    for (int k = 0; k < n; ++k) {
      slopes[static_cast<size_t>(k)] = c.Slope(data.points[static_cast<size_t>(k)].u_m_s);
    }
  }
  const ScatterProblem last(-e, x, ct);
  const Eigen::MatrixXd cov = last.Covariance(c.scatter.sigma);
  const Eigen::VectorXd fitted_var = last.FittedVariance(c.scatter.sigma);
  if (fitted_var.size() != n) {
    c.scatter.ok = false;
    return c;
  }
  c.residual.resize(static_cast<size_t>(n));
  c.z.resize(static_cast<size_t>(n));
  for (int k = 0; k < n; ++k) {
    const double r = x.row(k).dot(c.beta) - e(k);
    const double var = cov(k, k) - fitted_var(k);  // residual variance (leverage)
    c.residual[static_cast<size_t>(k)] = r;
    c.z[static_cast<size_t>(k)] = var > 0.0 ? r / std::sqrt(var) : kNaN;
  }
  return c;
}

// Terms of the screen's curve by the number of bounces (at least ~5 points per term).
std::vector<int> TermsFor(int n) {
  if (n >= 20) return {0, 1, 2, 3};
  if (n >= 10) return {0, 1, 2};
  if (n >= 5) return {0, 1};
  return {0};
}

// The drop-consistency part of the screen: the first impact against the local trend.
void CheckDropHeight(const Scene& scene, const AnalysisOptions& options, const Analysis& a,
                     const RestitutionData& later, double sigma_s, Analysis* out) {
  const Bounce& b0 = a.bounces[0];
  // Local trend: the first (fastest) up to 8 regular bounces after the first impact.
  std::vector<bool> keep(later.points.size(), false);
  int m = 0;
  for (size_t k = 0; k < later.points.size() && m < 8; ++k) {
    if (a.bounces[static_cast<size_t>(later.points[k].bounce)].irregular) continue;
    keep[k] = true;
    ++m;
  }
  if (m < 3) return;
  // A quadratic trend in ln v when there are enough points, else a linear one.
  const RestitutionData local = later.Subset(keep);
  const SmoothCurve trend =
      FitCurve(local, m >= 6 ? std::vector<int>{0, 1, 3} : std::vector<int>{0, 1}, sigma_s);
  if (!trend.scatter.ok) return;
  // The arrival speed u* the next bounces agree with: v_out,0 / u* = trend(u*) (a fixed point
  // started at the next bounce's speed, so the trend is only evaluated near its data, however
  // wrong the stated drop is).
  const double u0 = b0.v_in_m_s, vout = b0.v_out_m_s;
  double u = local.points.front().u_m_s;
  for (int it = 0; it < 100; ++it) u = vout / std::clamp(trend.Value(u), 0.05, 1.0);
  const Eigen::VectorXd xs = trend.Basis(u);
  // sigma of u*: r(u) = v_out,0 / u - trend(u) has r'(u*) = -v_out,0 / u*^2 - trend'(u*); the
  // trend's own variance, the scatter and the first interval's timing move r by sigma_r.
  RestitutionData first;
  AppendRestitutionPoints(a, 0, true, &first);
  if (first.points.empty() || first.points[0].bounce != 0) return;
  std::vector<bool> only(first.points.size(), false);
  only[0] = true;
  RestitutionData only_first = first.Subset(only);
  only_first.height_sigma_m.assign(only_first.height_sigma_m.size(), 0.0);
  const double var_t = only_first.TimingCovariance({0.0})(0, 0) * std::pow(u0 / u, 2);
  // The trend's form is itself uncertain (it matters when the scatter and the timing noise are
  // tiny): the other plausible form, {1, ln u, u}, predicts at u* too, and the difference of the
  // two enters as a model variance.
  double var_model = 0.0;
  if (m >= 6) {
    const SmoothCurve other = FitCurve(local, {0, 1, 2}, sigma_s);
    if (other.scatter.ok) var_model = std::pow(other.Value(u) - trend.Value(u), 2);
  }
  const double var_r = xs.dot(trend.beta_cov * xs) + sigma_s * sigma_s + var_t + var_model;
  const double dr = -vout / (u * u) - trend.Slope(u);
  const double var_u = var_r / (dr * dr) + std::pow(b0.dv_in_dh * a.height_sigma_m, 2);
  const double z = (u0 - u) / std::sqrt(var_u);
  const double pred = trend.Value(u);
  if (!(std::abs(z) > options.drop_z_max)) return;
  out->drop_consistent = false;
  const double h_fit = HeightForArrivalSpeed(scene, u);
  if (std::isfinite(h_fit)) out->drop_height_fit_m = h_fit;
  std::string stated = scene.drop.height_m ? Printf("height %.4g m", *scene.drop.height_m)
                                           : Printf("impact speed %.4g m/s", u0);
  std::string cause;
  const double q =
      scene.drop.height_m && std::isfinite(h_fit) ? *scene.drop.height_m / h_fit : kNaN;
  if (std::isfinite(q) && q > 50.0 && q < 200.0) {
    cause = "the height looks like centimetres (drop.height_m is in metres)";
  } else if (std::isfinite(q) && q > 500.0 && q < 2000.0) {
    cause = "the height looks like millimetres (drop.height_m is in metres)";
  } else if (z > 0.0) {
    cause =
        "the first e is too low: the recording may start after the drop's first impact (the "
        "first heard impact is then a later bounce), or the stated drop is too high";
  } else {
    cause =
        "the first e is too high: the ball was released higher than stated (the height is "
        "that of the ball's bottom above the plate), or the stated drop is too low";
  }
  out->warnings.push_back(
      {"drop_height_inconsistent",
       "impact 0: e = " + Printf("%.4f", b0.e) + " from the stated " + stated +
           Printf(" (%.3g m/s)", u0) +
           ", but the next bounces' trend (e = " + Printf("%.3f", pred) +
           Printf(") agrees with an arrival at %.3g +- %.2g m/s", u, std::sqrt(var_u)) +
           Printf(" (%.1f sigma)", std::abs(z)) +
           (std::isfinite(h_fit) ? Printf(", a drop of %.3g m", h_fit) : "") + ": " + cause +
           "; the first impact is left out of fits",
       0,
       std::isfinite(h_fit)
           ? Printf("measure the drop height of the ball's bottom again, or try --height %.3g "
                    "with --height-sigma (the [drop] table), or leave the drop out (calibrate "
                    "--ignore-drop)",
                    h_fit)
           : std::string("measure the drop height again, or leave the drop out (calibrate "
                         "--ignore-drop)")});
}

}  // namespace

double HeightForArrivalSpeed(const Scene& scene, double v_m_s) {
  const FlightModel flight = FlightModel::FromScene(scene);
  if (!(v_m_s > 0.0) || !(v_m_s < flight.terminal_speed_m_s())) return kNaN;
  double lo = 0.0, hi = 1.0;
  while (flight.FallArrivalSpeed(hi) < v_m_s && hi < 1e7) hi *= 2.0;
  if (!(flight.FallArrivalSpeed(hi) >= v_m_s)) return kNaN;
  for (int i = 0; i < 200 && hi - lo > 1e-12 * hi; ++i) {
    const double mid = 0.5 * (lo + hi);
    (flight.FallArrivalSpeed(mid) < v_m_s ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

void ScreenBounces(const Scene& scene, const AnalysisOptions& options, Analysis* a) {
  RestitutionData later;  // bounces after the first impact (their speeds come from intervals)
  AppendRestitutionPoints(*a, 0, false, &later);
  const int n = later.size();
  if (n < 3) return;  // too few to tell scatter from a trend
  SmoothCurve curve = FitCurve(later, TermsFor(n));
  if (!curve.scatter.ok) return;
  // Irregular bounces: beyond the Bonferroni quantile; then refit without them.
  const double z_max = NormalQuantileTwoSided(options.irregular_alpha / n);
  std::vector<bool> keep(static_cast<size_t>(n), true);
  int flagged = 0;
  for (int k = 0; k < n; ++k) {
    const double z = curve.z[static_cast<size_t>(k)];
    if (!(std::abs(z) > z_max)) continue;
    keep[static_cast<size_t>(k)] = false;
    ++flagged;
    const RestitutionPoint& p = later.points[static_cast<size_t>(k)];
    Bounce& b = a->bounces[static_cast<size_t>(p.bounce)];
    b.irregular = true;
    a->warnings.push_back(
        {"irregular_bounce",
         "impact " + std::to_string(p.bounce) +
             Printf(": e = %.4f is %.1f sigma ", p.e, std::abs(z)) + (z > 0 ? "below" : "above") +
             Printf(" the smooth e(v) of the other bounces (%.4f, scatter %.2g)",
                    p.e + curve.residual[static_cast<size_t>(k)], curve.scatter.sigma) +
             Printf("; beyond %.1f sigma for %d bounces: a mis-tracked impact or an irregular "
                    "bounce, left out of fits",
                    z_max, n),
         p.bounce,
         "listen to that impact (detect --click-track FILE.wav); nothing to do if the ball hit "
         "an uneven spot"});
  }
  if (flagged > 0 && n - flagged >= 3) {
    const RestitutionData regular = later.Subset(keep);
    SmoothCurve refit = FitCurve(regular, TermsFor(regular.size()));
    if (refit.scatter.ok) curve = refit;
  }
  const double s = curve.scatter.sigma;
  a->scatter_e = s;
  a->scatter_e_sigma = curve.scatter.sigma_sigma;
  for (Bounce& b : a->bounces) {
    if (std::isfinite(b.e_sigma)) {
      b.e_total_sigma = std::hypot(b.e_sigma, s);
      b.eta_sigma = 2.0 * std::abs(b.e) * b.e_total_sigma;
    }
  }
  if (std::isfinite(a->bounces[0].e) && std::isfinite(a->bounces[0].v_in_m_s)) {
    CheckDropHeight(scene, options, *a, later, s, a);
  }
}

void CheckDrag(const Sequence& sequence, const Scene& scene, const AnalysisOptions& options,
               Analysis* a) {
  if (!std::isfinite(scene.ball.Mass())) return;
  Scene with_drag = scene;
  with_drag.effects.drag = DragModel::kQuadratic;
  AnalysisOptions o = options;
  o.screen = false;
  o.check_drag = false;
  const Analysis d = AnalyzeBounces(sequence, with_drag, o);
  // Each bounce's change against its own sigma: a median sigma over the sequence grew with the
  // weak, slow tail (timing sigma 0.1-0.5 ms there), where drag does not act, and hid a change
  // of 20 sigma on the fast first bounces.
  double effect = 0.0, v_max = 0.0, ratio = 0.0;
  int at = -1;
  for (size_t k = 0; k < a->bounces.size() && k < d.bounces.size(); ++k) {
    const Bounce& b = a->bounces[k];
    if (!std::isfinite(b.e) || !std::isfinite(d.bounces[k].e)) continue;
    v_max = std::max(v_max, b.v_in_m_s);
    const double de = std::abs(d.bounces[k].e - b.e);
    effect = std::max(effect, de);
    if (!(b.e_sigma > 0.0)) continue;
    if (de / b.e_sigma > ratio) ratio = de / b.e_sigma, at = static_cast<int>(k);
  }
  if (at < 0) return;
  a->drag_effect_e = effect;
  if (!(ratio > options.drag_effect_sigmas)) return;
  const double vt = FlightModel::FromScene(with_drag).terminal_speed_m_s();
  a->warnings.push_back(
      {"drag_likely_needed",
       Printf("the scene has no air drag, but this ball (%.3g m, %.3g kg) has a terminal speed of "
              "%.3g m/s and arrives at up to %.3g m/s: ",
              scene.ball.diameter_m, scene.ball.Mass(), vt, v_max) +
           Printf("quadratic drag changes e by up to %.2g; at impact %d it moves e from %.4f to "
                  "%.4f, ",
                  effect, a->bounces[static_cast<size_t>(at)].index,
                  a->bounces[static_cast<size_t>(at)].e, d.bounces[static_cast<size_t>(at)].e) +
           Printf("%.0f times that e's sigma; turn it on (effects.drag = \"quadratic\")", ratio),
       -1, "--drag quadratic ([effects] drag = \"quadratic\" in the scene file)"});
}

}  // namespace bouncecal
