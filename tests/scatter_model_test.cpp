// The scatter error model (scatter_model.hpp) against independent computations: a linear model
// with known timing covariance and known scatter, many seeds (REML sigma_s unbiased, its sigma
// and the parameter sigmas covering the truth), the GLS step against the normal equations
// solved directly, the timing covariance against a Monte Carlo of the onsets, and the normal
// quantile against tabulated values.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "bouncecal/fit/scatter_model.hpp"

namespace bouncecal {
namespace {

// y = X beta + eps_t + eps_s with a banded timing covariance (neighbours correlated, as
// restitutions sharing onsets are) and independent scatter of sigma_s.
struct LinearCase {
  Eigen::MatrixXd x, ct;
  Eigen::VectorXd beta;
};

LinearCase MakeCase(int n) {
  LinearCase c;
  c.x.resize(n, 2);
  c.ct = Eigen::MatrixXd::Zero(n, n);
  for (int k = 0; k < n; ++k) {
    const double t = std::log(0.1 + 3.0 * k / n);
    c.x(k, 0) = 1.0;
    c.x(k, 1) = t;
    c.ct(k, k) = std::pow(1e-3 * (1.0 + k / 10.0), 2);
    if (k > 0) c.ct(k, k - 1) = c.ct(k - 1, k) = -0.4 * std::sqrt(c.ct(k, k) * c.ct(k - 1, k - 1));
  }
  c.beta = Eigen::Vector2d(0.9, -0.02);
  return c;
}

Eigen::VectorXd Draw(const LinearCase& c, double sigma_s, std::mt19937_64* rng) {
  const int n = static_cast<int>(c.x.rows());
  Eigen::LLT<Eigen::MatrixXd> llt(c.ct);
  std::normal_distribution<double> z(0.0, 1.0);
  Eigen::VectorXd w(n), s(n);
  for (int k = 0; k < n; ++k) w(k) = z(*rng), s(k) = z(*rng);
  return c.x * c.beta + Eigen::MatrixXd(llt.matrixL()) * w + sigma_s * s;
}

TEST(ScatterModel, RemlRecoversSigmaAndItsSigmaCoversTheTruth) {
  const LinearCase c = MakeCase(25);
  std::mt19937_64 rng(11);
  for (double sigma_s : {0.002, 0.004, 0.01}) {
    double mean = 0.0, pull2 = 0.0, beta_pull2 = 0.0, sig_sig = 0.0;
    const int seeds = 400;
    for (int s = 0; s < seeds; ++s) {
      const Eigen::VectorXd y = Draw(c, sigma_s, &rng);
      // Residuals model - measured at beta = 0: r = -y, J = X; the GLS step is beta.
      const ScatterFit f = ScatterProblem(-y, c.x, c.ct).Fit();
      ASSERT_TRUE(f.ok);
      mean += f.sigma / seeds;
      if (!f.sigma_at_zero) pull2 += std::pow((f.sigma - sigma_s) / f.sigma_sigma, 2);
      sig_sig += f.sigma_sigma / seeds;
      beta_pull2 += std::pow((f.step(1) - c.beta(1)) / std::sqrt(f.covariance(1, 1)), 2);
    }
    // REML: unbiased to a few percent with 25 points (ML would be ~4 % low from n/(n-p) alone).
    // Measured (400 seeds): mean/true 0.976, 0.991, 0.993 for 0.002, 0.004, 0.01; sigma_s pull
    // RMS 0.99-1.09; slope pull RMS 1.22, 1.11, 0.99 (sigma_s near the timing noise is itself
    // uncertain, which the slope's sigma does not carry); bound 4 % and [0.7, 1.4].
    EXPECT_NEAR(mean / sigma_s, 1.0, 0.04) << sigma_s;
    EXPECT_GT(std::sqrt(pull2 / seeds), 0.7) << sigma_s;
    EXPECT_LT(std::sqrt(pull2 / seeds), 1.4) << sigma_s;
    EXPECT_GT(std::sqrt(beta_pull2 / seeds), 0.7) << sigma_s;
    EXPECT_LT(std::sqrt(beta_pull2 / seeds), 1.4) << sigma_s;
    // sigma(sigma_s) from the Fisher information of sigma_s^2, I = 1/2 sum 1/(sigma_s^2 +
    // tau_k^2)^2 (timing correlations left out), times n/(n - p) for the fitted parameters:
    // -> sigma_s / sqrt(2 (n - p)) when the scatter dominates the timing. Measured ratio of the
    // mean reported sigma to it: 0.993-0.997.
    double info = 0.0;
    for (int k = 0; k < 25; ++k) info += 0.5 / std::pow(sigma_s * sigma_s + c.ct(k, k), 2);
    const double expect = std::sqrt(25.0 / 23.0 / info) / (2.0 * sigma_s);
    EXPECT_NEAR(sig_sig / expect, 1.0, 0.1) << sigma_s;
  }
}

TEST(ScatterModel, ZeroScatterGivesTheTimingOnlyGlsStep) {
  const LinearCase c = MakeCase(20);
  std::mt19937_64 rng(3);
  const Eigen::VectorXd y = Draw(c, 0.0, &rng);
  const ScatterProblem sp(-y, c.x, c.ct);
  const ScatterProblem::Evaluation ev = sp.At(0.0);
  ASSERT_TRUE(ev.ok);
  // Normal equations solved directly: beta = (X^T C^-1 X)^-1 X^T C^-1 y.
  const Eigen::MatrixXd ci = c.ct.inverse();
  const Eigen::VectorXd beta = (c.x.transpose() * ci * c.x).ldlt().solve(c.x.transpose() * ci * y);
  EXPECT_NEAR(ev.step(0), beta(0), 1e-12);
  EXPECT_NEAR(ev.step(1), beta(1), 1e-12);
  const Eigen::VectorXd r = y - c.x * beta;
  EXPECT_NEAR(ev.chi2, r.dot(ci * r), 1e-9);
  const Eigen::MatrixXd cov = (c.x.transpose() * ci * c.x).inverse();
  EXPECT_NEAR(ev.covariance(1, 1), cov(1, 1), 1e-12 * cov(1, 1) + 1e-18);
  // Timing noise alone: the scatter estimate is 0 or far below the timing sigma (1e-3).
  const ScatterFit f = sp.Fit();
  ASSERT_TRUE(f.ok);
  EXPECT_LT(f.sigma, 1e-3);
  EXPECT_TRUE(std::isfinite(f.sigma_sigma));
}

TEST(ScatterModel, CriterionIsTheRestrictedLikelihood) {
  // 1/2 [log det C + log det(X^T C^-1 X) + r~^T C^-1 r~] computed directly.
  const LinearCase c = MakeCase(12);
  std::mt19937_64 rng(5);
  const Eigen::VectorXd y = Draw(c, 0.004, &rng);
  const double s = 0.003;
  const Eigen::MatrixXd cm = c.ct + s * s * Eigen::MatrixXd::Identity(12, 12);
  const Eigen::MatrixXd ci = cm.inverse();
  const Eigen::MatrixXd info = c.x.transpose() * ci * c.x;
  const Eigen::VectorXd beta = info.ldlt().solve(c.x.transpose() * ci * y);
  const Eigen::VectorXd r = y - c.x * beta;
  const double want =
      0.5 * (std::log(cm.determinant()) + std::log(info.determinant()) + r.dot(ci * r));
  EXPECT_NEAR(ScatterProblem(-y, c.x, c.ct).At(s).criterion, want, 1e-8);
  ScatterOptions ml;
  ml.reml = false;
  EXPECT_NEAR(ScatterProblem(-y, c.x, c.ct, {}, ml).At(s).criterion,
              want - 0.5 * std::log(info.determinant()), 1e-8);
}

// The bounce screen's trend {1, ln(u/u_ref), u/u_ref, ln^2} over a narrow speed range (a steel
// ball bouncing with e ~ 1: ten bounces at 1.005, then 0.998, like the calibrate test
// FitAtBoundWhenTheDataPushPastTheLawsRange): the columns are nearly dependent (u/u_ref = 1 + x +
// x^2/2 + x^3/6 + ..., |x| < 0.03); the whitened Jacobian's condition number is 3.4e7 (the
// screen's in that test: ~4e7) and that of its normal matrix 1.1e15.
struct NarrowTrendCase {
  Eigen::MatrixXd j, ct;
  Eigen::VectorXd r;
};

NarrowTrendCase MakeNarrowTrend() {
  const int n = 29;
  std::vector<double> u(static_cast<size_t>(n)), e(static_cast<size_t>(n));
  double v = 3.13, lsum = 0.0;
  for (int k = 0; k < n; ++k) {
    e[static_cast<size_t>(k)] = k < 10 ? 1.005 : 0.998;
    u[static_cast<size_t>(k)] = v;
    lsum += std::log(v);
    v *= e[static_cast<size_t>(k)];
  }
  const double u_ref = std::exp(lsum / n);
  NarrowTrendCase c;
  c.j.resize(n, 4);
  c.r.resize(n);
  c.ct = Eigen::MatrixXd::Zero(n, n);
  std::mt19937_64 rng(17);
  std::normal_distribution<double> z(0.0, 1.0);
  for (int k = 0; k < n; ++k) {
    const double x = std::log(u[static_cast<size_t>(k)] / u_ref);
    c.j.row(k) << 1.0, x, u[static_cast<size_t>(k)] / u_ref, x * x;
    // 5 us onsets on ~0.64 s flights: sigma_e ~ 1e-5, neighbours sharing an onset.
    c.ct(k, k) = 1e-10;
    if (k > 0) c.ct(k, k - 1) = c.ct(k - 1, k) = -0.5e-10;
    c.r(k) = -e[static_cast<size_t>(k)] + 1e-5 * z(rng);
  }
  return c;
}

// chi2 of the whitened least-squares problem by Householder QR in long double (64-bit mantissa:
// ~1e-19 relative, times the condition number 1e7), independent of the code under test.
long double ReferenceChi2(const NarrowTrendCase& c, double sigma) {
  using MatrixL = Eigen::Matrix<long double, Eigen::Dynamic, Eigen::Dynamic>;
  using VectorL = Eigen::Matrix<long double, Eigen::Dynamic, 1>;
  const Eigen::Index n = c.r.size();
  MatrixL cm = c.ct.cast<long double>();
  cm.diagonal().array() += static_cast<long double>(sigma) * sigma;
  const Eigen::LLT<MatrixL> llt(cm);
  const MatrixL jw = llt.matrixL().solve(MatrixL(c.j.cast<long double>()));
  const VectorL rw = llt.matrixL().solve(VectorL(c.r.cast<long double>()));
  const Eigen::HouseholderQR<MatrixL> qr(jw);
  const VectorL qtr = qr.householderQ().adjoint() * rw;
  return qtr.tail(n - jw.cols()).squaredNorm();
}

TEST(ScatterModel, IllConditionedTrendIsTheSameFitRescaledAndPermuted) {
  const NarrowTrendCase c = MakeNarrowTrend();
  const Eigen::Index n = c.r.size();
  {
    // The case is as ill-conditioned as the screen's: the normal matrix's eigenvalue ratio is
    // below 1e-14 (measured 8.8e-16, at the old 1e-16 cut-off).
    const Eigen::LLT<Eigen::MatrixXd> llt(c.ct);
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(llt.matrixL().solve(c.j));
    const Eigen::VectorXd sv = svd.singularValues();
    ASSERT_LT(std::pow(sv(sv.size() - 1) / sv(0), 2), 1e-14);
  }
  // Permuted rows (reversed, then every third moved to the end), and C_t the same way.
  std::vector<int> order;
  for (int k = static_cast<int>(n) - 1; k >= 0; --k) {
    if (k % 3 != 0) order.push_back(k);
  }
  for (int k = static_cast<int>(n) - 1; k >= 0; --k) {
    if (k % 3 == 0) order.push_back(k);
  }
  NarrowTrendCase perm = c;
  for (Eigen::Index a = 0; a < n; ++a) {
    perm.r(a) = c.r(order[static_cast<size_t>(a)]);
    perm.j.row(a) = c.j.row(order[static_cast<size_t>(a)]);
    for (Eigen::Index b = 0; b < n; ++b) {
      perm.ct(a, b) = c.ct(order[static_cast<size_t>(a)], order[static_cast<size_t>(b)]);
    }
  }
  // Parameters in other units (columns scaled by 1e3 .. 1e-4) and the data in other units (r, J
  // times 1e2, C_t times 1e4, sigma_s times 1e2).
  const Eigen::Vector4d units(1e3, 1e-2, 7.0, 1e-4);
  NarrowTrendCase scaled = c;
  scaled.j = c.j * units.asDiagonal();
  const double a = 1e2;
  NarrowTrendCase data_units = c;
  data_units.r *= a;
  data_units.j *= a;
  data_units.ct *= a * a;
  const ScatterProblem base(c.r, c.j, c.ct), p_perm(perm.r, perm.j, perm.ct),
      p_scaled(scaled.r, scaled.j, scaled.ct), p_data(data_units.r, data_units.j, data_units.ct);
  for (double sigma : {0.0, 3e-6, 1e-4}) {
    const ScatterProblem::Evaluation ev = base.At(sigma);
    ASSERT_TRUE(ev.ok);
    // The answer itself: chi2 against the long-double QR within 1e-9 relative (measured 4e-11;
    // the normal equations with the 1e-16 eigenvalue cut gave 2.4e8 for 5.1e7 at sigma_s = 0,
    // and 1.0e8 with the columns in the units below). Other units and orders: measured 7e-11.
    const double want = static_cast<double>(ReferenceChi2(c, sigma));
    EXPECT_NEAR(ev.chi2, want, 1e-9 * want) << sigma;
    for (const ScatterProblem::Evaluation& other :
         {p_perm.At(sigma), p_scaled.At(sigma), p_data.At(a * sigma)}) {
      ASSERT_TRUE(other.ok);
      EXPECT_NEAR(other.chi2, ev.chi2, 1e-9 * ev.chi2) << sigma;
    }
    // The fitted trend (J step) is the same in every parametrisation.
    const Eigen::VectorXd fit = c.j * ev.step, fit_scaled = scaled.j * p_scaled.At(sigma).step;
    EXPECT_LT((fit - fit_scaled).norm(), 1e-9 * fit.norm()) << sigma;
  }
  // sigma_s fitted the same (the golden-section search stops at 1e-6 in ln sigma_s).
  const ScatterFit f = base.Fit();
  ASSERT_TRUE(f.ok);
  for (const ScatterFit& other : {p_perm.Fit(), p_scaled.Fit()}) {
    EXPECT_NEAR(other.sigma, f.sigma, 1e-5 * f.sigma);
  }
  EXPECT_NEAR(p_data.Fit().sigma, a * f.sigma, 1e-5 * a * f.sigma);
}

TEST(ScatterModel, NonFiniteJacobianIsAFailedEvaluationNotANullColumn) {
  // A NaN column (a failed simulation) must fail the fit, not be dropped as undetermined.
  const LinearCase c = MakeCase(12);
  std::mt19937_64 rng(29);
  const Eigen::VectorXd y = Draw(c, 0.004, &rng);
  Eigen::MatrixXd j = c.x;
  j(3, 1) = std::numeric_limits<double>::quiet_NaN();
  const ScatterProblem sp(-y, j, c.ct);
  EXPECT_FALSE(sp.At(0.003).ok);
  EXPECT_FALSE(ScatterProfile(sp).At(0.003).ok);
  EXPECT_FALSE(sp.Fit().ok);
}

// C(sigma) = C_t + sigma^2 G G^T for a design G that is not the identity (impact times: the
// scatter of bounce k moves every later impact).
Eigen::MatrixXd LaterImpactsDesign(int n) {
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(n, n);
  for (int k = 0; k < n; ++k) {
    for (int i = 0; i < k; ++i) g(k, i) = 0.1 * (k - i);
  }
  return g;
}

TEST(ScatterModel, ProfileEqualsTheDirectCholesky) {
  const LinearCase c = MakeCase(25);
  std::mt19937_64 rng(23);
  const Eigen::VectorXd y = Draw(c, 0.004, &rng);
  const ScatterProblem identity(-y, c.x, c.ct);
  const ScatterProblem design(-y, c.x, c.ct, LaterImpactsDesign(25));
  for (const ScatterProblem* sp : {&identity, &design}) {
    const ScatterProfile profile(*sp);
    for (double sigma = 1e-6; sigma < 1.0; sigma *= 1.7) {
      for (double s : {0.0, sigma}) {
        const ScatterProblem::Evaluation want = sp->At(s), got = profile.At(s);
        ASSERT_TRUE(want.ok && got.ok) << s;
        // Measured: relative differences below 6e-12 (chi2 with the design G), 1e-15 (G = I).
        EXPECT_NEAR(got.criterion, want.criterion, 1e-10 * std::abs(want.criterion)) << s;
        EXPECT_NEAR(got.chi2, want.chi2, 1e-10 * want.chi2) << s;
        EXPECT_NEAR(got.log_det_c, want.log_det_c, 1e-10 * std::abs(want.log_det_c)) << s;
        EXPECT_LT((got.step - want.step).norm(), 1e-10 * want.step.norm()) << s;
        EXPECT_LT((got.covariance - want.covariance).norm(), 1e-10 * want.covariance.norm()) << s;
      }
    }
    // The fitted sigma_s is a minimum of the direct criterion.
    const ScatterFit f = sp->Fit();
    ASSERT_TRUE(f.ok);
    ASSERT_GT(f.sigma, 0.0);
    const double at = sp->At(f.sigma).criterion;
    EXPECT_GE(sp->At(1.01 * f.sigma).criterion, at - 1e-9);
    EXPECT_GE(sp->At(0.99 * f.sigma).criterion, at - 1e-9);
  }
}

TEST(ScatterModel, TimingCovarianceMatchesMonteCarloOfTheOnsets) {
  // Two points sharing onsets: r_k = slope_k * u_k - e_k with u, e linear in the onsets.
  RestitutionData d;
  d.onset_sigma_s = {2e-5, 1e-5, 3e-5, 1.5e-5};
  d.height_sigma_m = {0.01};
  RestitutionPoint p0;
  p0.onset = {0, 1, 2};
  p0.de_dt = {3.0, -7.0, 4.0};
  p0.du_dt = {-20.0, 20.0, 0.0};
  RestitutionPoint p1 = p0;
  p1.onset = {1, 2, 3};
  p1.de_dt = {2.5, -6.0, 3.5};
  p1.du_dt = {-15.0, 15.0, 0.0};
  RestitutionPoint p2;  // the first impact, from the drop height
  p2.onset = {-1, 0, 1};
  p2.de_dt = {0.0, -5.0, 5.0};
  p2.from_drop = true;
  p2.de_dh = -0.4;
  p2.du_dh = 2.2;
  d.points = {p2, p0, p1};
  const std::vector<double> slopes = {-0.01, -0.02, -0.03};
  const Eigen::MatrixXd c = d.TimingCovariance(slopes);
  std::mt19937_64 rng(9);
  std::normal_distribution<double> z(0.0, 1.0);
  const int draws = 200000;
  Eigen::MatrixXd mc = Eigen::MatrixXd::Zero(3, 3);
  for (int i = 0; i < draws; ++i) {
    double dt[4];
    for (int j = 0; j < 4; ++j) dt[j] = d.onset_sigma_s[static_cast<size_t>(j)] * z(rng);
    const double dh = 0.01 * z(rng);
    Eigen::Vector3d r;
    for (int k = 0; k < 3; ++k) {
      const RestitutionPoint& p = d.points[static_cast<size_t>(k)];
      double de = p.from_drop ? p.de_dh * dh : 0.0, du = p.from_drop ? p.du_dh * dh : 0.0;
      for (int j = 0; j < 3; ++j) {
        if (p.onset[static_cast<size_t>(j)] < 0) continue;
        de += p.de_dt[static_cast<size_t>(j)] * dt[p.onset[static_cast<size_t>(j)]];
        du += p.du_dt[static_cast<size_t>(j)] * dt[p.onset[static_cast<size_t>(j)]];
      }
      r(k) = slopes[static_cast<size_t>(k)] * du - de;
    }
    mc += r * r.transpose() / draws;
  }
  for (int a = 0; a < 3; ++a) {
    for (int b = 0; b < 3; ++b) {
      // Monte Carlo relative sigma ~ sqrt(2 / 2e5) = 0.3 %; bound 2 % of the diagonal scale.
      EXPECT_NEAR(c(a, b), mc(a, b), 0.02 * std::sqrt(c(a, a) * c(b, b))) << a << "," << b;
    }
  }
}

}  // namespace
}  // namespace bouncecal
