// bouncecal/fit/scatter_model.hpp — the per-bounce scatter error model (docs/physics.md §6).
//
// Real balls do not bounce identically: bounce k's restitution is e_k = e(u_k; theta) + eps_k with
// eps_k ~ N(0, sigma_s^2) independent (a random effect), on top of the timing noise of the
// onsets. For n measured points with residuals r = model - measured, Jacobian J = dr/dtheta and
// timing covariance C_t (banded: neighbouring restitutions share onsets), the residuals have
//   C(sigma_s) = C_t + sigma_s^2 G G^T
// with G the map from the per-bounce scatter eps to the measured quantity (the identity for
// per-bounce restitution; dt/deps for impact times). theta and sigma_s are estimated by
// restricted maximum likelihood (REML, Patterson & Thompson, Biometrika 58 (1971) 545):
//   minimise  1/2 [ log det C + log det(J^T C^-1 J) + r~^T C^-1 r~ ]
// over sigma_s >= 0, where r~ are the residuals after the generalized-least-squares step of
// theta at that sigma_s (linearised: r~ = r + J dtheta). The log det J^T C^-1 J term is what
// keeps sigma_s from being biased low with ~10-30 bounces (plain ML divides by n instead of
// n - p). Parameter covariance: (J^T C^-1 J)^-1 at the optimum; chi2 = r~^T C^-1 r~ ~ n - p.
//
// Numerics: the normal matrix J^T C^-1 J is never formed (its condition is the square of J's:
// a trend in ln v, v and (ln v)^2 over a narrow speed range reaches 1e15 and put the rank
// decision at the rounding level). Each evaluation whitens J and r by a factor W with
// W^T W = C^-1 and solves the least-squares problem by an SVD of the whitened Jacobian with its
// columns scaled to unit norm (so the result does not depend on the parameters' units);
// directions with singular values below kRankCut of the largest are the null space, left out
// of the step, the log-determinant and the covariance (a pseudo-inverse).
//
//   ScatterProblem sp(r, J, C_t, {});           // G = identity
//   ScatterFit f = sp.Fit();                    // f.sigma, f.sigma_sigma, f.step, f.covariance
//
// RestitutionData is the measured side of the per-bounce model: each point's measured arrival
// speed u and restitution e with their derivatives with respect to the onsets (and the drop
// height), from which TimingCovariance builds C_t for a given model slope de/du at each point
// (the model is evaluated at the measured speed, which carries timing noise too).
#pragma once

#include <array>
#include <limits>
#include <vector>

#include <Eigen/Dense>

#include "bouncecal/fit/kinematics.hpp"

namespace bouncecal {

// One measured restitution point: bounce `bounce` of recording `recording`.
struct RestitutionPoint {
  int recording = 0;
  int bounce = 0;        // Bounce::index
  double u_m_s = 0.0;    // measured arrival speed
  double e = 0.0;        // measured restitution
  double e_sigma = 0.0;  // timing (and height) sigma of e alone
  // Global onset indices of t_{k-1}, t_k, t_{k+1} (-1: none) and the derivatives of e and u.
  std::array<int, 3> onset{-1, -1, -1};
  std::array<double, 3> de_dt{0.0, 0.0, 0.0};
  std::array<double, 3> du_dt{0.0, 0.0, 0.0};
  // First impact with the speed from a stated drop height: derivatives with respect to it.
  bool from_drop = false;
  double de_dh = 0.0, du_dh = 0.0;
};

struct RestitutionData {
  std::vector<RestitutionPoint> points;
  std::vector<double> onset_sigma_s;   // per global onset
  std::vector<double> height_sigma_m;  // per recording (0: exact or no drop)

  int size() const { return static_cast<int>(points.size()); }
  // Covariance of the residuals r_k = e_model(u_k) - e_k from the timing (and height) noise,
  // for model slopes de/du at each point (first order; Eq. in the file comment of scatter_model).
  Eigen::MatrixXd TimingCovariance(const std::vector<double>& model_slopes) const;
  // The points for which keep[k] is true (same onsets and heights).
  RestitutionData Subset(const std::vector<bool>& keep) const;
};

// The points of one analysed recording with a finite e and arrival speed, appended to `data`
// as recording `recording` (onsets numbered after those already in data). include_first: keep
// bounce 0 when its arrival speed comes from the drop. Points flagged irregular are kept (the
// caller decides).
void AppendRestitutionPoints(const Analysis& analysis, int recording, bool include_first,
                             RestitutionData* data);

struct ScatterOptions {
  bool reml = true;      // REML (unbiased sigma_s for small n); false: plain maximum likelihood
  int grid_points = 48;  // log-spaced search grid before the golden-section refinement
  bool IsValid(std::string* error) const;
};

struct ScatterFit {
  bool ok = false;
  double sigma = 0.0;  // sigma_s
  // 1-sigma of sigma_s from the curvature of the criterion; when sigma_s is 0 (the timing noise
  // explains the scatter) the one-sided 68 % upper limit instead (sigma_at_zero = true).
  double sigma_sigma = std::numeric_limits<double>::quiet_NaN();
  bool sigma_at_zero = false;
  Eigen::VectorXd step;             // linearised GLS update of the parameters at sigma_s
  Eigen::MatrixXd covariance;       // (J^T C^-1 J)^-1 at sigma_s
  double chi2 = 0.0;                // r~^T C^-1 r~ after the step
  double criterion = 0.0;           // the minimised REML (or ML) criterion
  double neg_log_likelihood = 0.0;  // Gaussian -log L (ML form, with n/2 log 2 pi), for AIC
};

class ScatterProblem {
 public:
  // r: residuals (model - measured, n), J: n x p, timing_cov: n x n, design G: n x m (empty:
  // the identity, m = n).
  ScatterProblem(Eigen::VectorXd r, Eigen::MatrixXd J, Eigen::MatrixXd timing_cov,
                 Eigen::MatrixXd design = {}, ScatterOptions options = {});

  struct Evaluation {
    bool ok = false;
    double criterion = 0.0, chi2 = 0.0, log_det_c = 0.0, log_det_info = 0.0;
    Eigen::VectorXd step;
    Eigen::MatrixXd covariance;
  };
  Evaluation At(double sigma) const;  // criterion and GLS step at one sigma_s (Cholesky of C)
  ScatterFit Fit() const;             // sigma_s minimising the criterion (and its sigma)
  Eigen::MatrixXd Covariance(double sigma) const;  // C(sigma)
  // diag(J Cov J^T) at sigma_s, the variance of the fitted model at each point (a GLS
  // residual's is C_kk minus it): |(L U)_k|^2 with C = L L^T and U the whitened Jacobian's left
  // singular vectors, which does not cancel as x_k^T Cov x_k does when J is ill-conditioned.
  // Empty when C(sigma) is not positive definite.
  Eigen::VectorXd FittedVariance(double sigma) const;

  // Singular values of the column-scaled whitened Jacobian at or below this fraction of the
  // largest span the null space. With unit columns the ratio measures how nearly a column lies
  // in the span of the others; an exact degeneracy leaves ~1e-15 after rounding, the narrow
  // speed-range trend of the bounce screen 3e-8 (scatter_model_test). Parameters whose relative
  // sigma is large or that load on directions below 1e-8 are reported by the uncertainty stage.
  static constexpr double kRankCut = 1e-10;

 private:
  friend class ScatterProfile;
  // The GLS step, chi2, covariance and log det(J^T C^-1 J) of the whitened problem
  // min |rw + jw d|^2 (rw = W r, jw = W J), by the SVD of jw with columns scaled to unit norm.
  // basis (optional): the kept left singular vectors (n x rank).
  void SolveWhitened(const Eigen::MatrixXd& jw, const Eigen::VectorXd& rw, Evaluation* ev,
                     Eigen::MatrixXd* basis = nullptr) const;

  Eigen::VectorXd r_;
  Eigen::MatrixXd j_, ct_, ggt_;
  bool identity_design_ = true;  // G = I (ggt_ is the identity)
  ScatterOptions options_;
  double scale_ = 1.0;           // typical sigma_s scale: sqrt(median C_t / median (G G^T))
  Eigen::VectorXd column_norm_;  // |J_j| (0: the parameter does not move the model)
};

// The criterion of a ScatterProblem at many sigma_s for the cost of one reduction (what Fit
// evaluates ~100 times). With A = C_t and B = G G^T, C(sigma) = A + sigma^2 B is brought once to
//   C(sigma) = F (P + sigma^2 R) F^T,   P + sigma^2 R tridiagonal,
// by Householder tridiagonalisation (Golub & Van Loan, Matrix Computations, 4th ed., §8.3.1):
// for G = I, A = Q T Q^T, F = Q, P = T, R = I; otherwise A = L L^T (Cholesky),
// L^-1 B L^-T = Q T Q^T, F = L Q, P = I, R = T. Each sigma_s is then an O(n) LDL^T of the
// tridiagonal (§4.3.6), log det C = log det(F F^T) + sum log d_i, and the whitened J and r are
// (D^-1/2 L^-1) F^-1 J, F^-1 r from the precomputed F^-1 J, F^-1 r: O(n p^2) per sigma_s with the
// SVD instead of the O(n^3) Cholesky. Equal to ScatterProblem::At within rounding (tested to
// 1e-10); a sigma_s where the tridiagonal is not positive definite falls back to At.
class ScatterProfile {
 public:
  explicit ScatterProfile(const ScatterProblem& problem);
  ScatterProblem::Evaluation At(double sigma) const;

 private:
  const ScatterProblem& problem_;
  bool ok_ = false;  // the reduction succeeded (else every At is the problem's own)
  Eigen::VectorXd p_diag_, p_off_, r_diag_, r_off_;
  double log_det_f_ = 0.0;  // log det(F F^T)
  Eigen::MatrixXd jf_;      // F^-1 J
  Eigen::VectorXd rf_;      // F^-1 r
};

}  // namespace bouncecal
