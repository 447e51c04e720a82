// The scatter error model (scatter_model.hpp) against independent computations: a linear model
// with known timing covariance and known scatter, many seeds (REML sigma_s unbiased, its sigma
// and the parameter sigmas covering the truth), the GLS step against the normal equations
// solved directly, the timing covariance against a Monte Carlo of the onsets, and the normal
// quantile against tabulated values.
#include <gtest/gtest.h>

#include <cmath>
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

TEST(ScatterModel, NormalQuantileMatchesTables) {
  EXPECT_NEAR(NormalQuantileTwoSided(0.05), 1.959964, 1e-6);
  EXPECT_NEAR(NormalQuantileTwoSided(0.01), 2.575829, 1e-6);
  EXPECT_NEAR(NormalQuantileTwoSided(1e-4), 3.890592, 1e-6);
}

}  // namespace
}  // namespace bouncecal
