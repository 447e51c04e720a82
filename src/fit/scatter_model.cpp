// The per-bounce scatter error model (scatter_model.hpp; docs/physics.md §6).
//
// Covariance of the per-bounce residuals r_k = e(u_k; theta) - e_k, first order in the onset
// times t_j and the drop height h:
//   dr_k/dt_j = e'(u_k) du_k/dt_j - de_k/dt_j,   dr_k/dh = e'(u_k) du_k/dh - de_k/dh
//   C_t = D diag(sigma_t^2) D^T + sum over recordings sigma_h^2 h h^T
// D has three entries per row (t_{k-1}, t_k, t_{k+1}), so C_t is banded (neighbouring points
// share two onsets).
#include "bouncecal/fit/scatter_model.hpp"
#include "bouncecal/core/stats.hpp"

#include <algorithm>
#include <cmath>
#include <string>

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

Eigen::MatrixXd RestitutionData::TimingCovariance(const std::vector<double>& model_slopes) const {
  const Eigen::Index n = size();
  const Eigen::Index m = static_cast<Eigen::Index>(onset_sigma_s.size());
  Eigen::MatrixXd d = Eigen::MatrixXd::Zero(n, m);
  Eigen::MatrixXd c = Eigen::MatrixXd::Zero(n, n);
  std::vector<Eigen::VectorXd> height(height_sigma_m.size(), Eigen::VectorXd::Zero(n));
  for (Eigen::Index k = 0; k < n; ++k) {
    const RestitutionPoint& p = points[static_cast<size_t>(k)];
    const double slope = model_slopes[static_cast<size_t>(k)];
    for (int j = 0; j < 3; ++j) {
      if (p.onset[static_cast<size_t>(j)] < 0) continue;
      d(k, p.onset[static_cast<size_t>(j)]) +=
          (slope * p.du_dt[static_cast<size_t>(j)] - p.de_dt[static_cast<size_t>(j)]) *
          onset_sigma_s[static_cast<size_t>(p.onset[static_cast<size_t>(j)])];
    }
    if (p.from_drop) height[static_cast<size_t>(p.recording)](k) = slope * p.du_dh - p.de_dh;
  }
  c = d * d.transpose();
  for (size_t r = 0; r < height.size(); ++r) {
    const double s = height_sigma_m[r];
    if (s > 0.0) c += s * s * height[r] * height[r].transpose();
  }
  return c;
}

RestitutionData RestitutionData::Subset(const std::vector<bool>& keep) const {
  RestitutionData out;
  out.onset_sigma_s = onset_sigma_s;
  out.height_sigma_m = height_sigma_m;
  for (size_t k = 0; k < points.size(); ++k) {
    if (keep[k]) out.points.push_back(points[k]);
  }
  return out;
}

void AppendRestitutionPoints(const Analysis& analysis, int recording, bool include_first,
                             RestitutionData* data) {
  const int offset = static_cast<int>(data->onset_sigma_s.size());
  const std::vector<Bounce>& b = analysis.bounces;
  for (const Bounce& bo : b) data->onset_sigma_s.push_back(bo.time_sigma_s);
  if (data->height_sigma_m.size() <= static_cast<size_t>(recording)) {
    data->height_sigma_m.resize(static_cast<size_t>(recording) + 1, 0.0);
  }
  data->height_sigma_m[static_cast<size_t>(recording)] = analysis.height_sigma_m;
  for (const Bounce& bo : b) {
    if (!std::isfinite(bo.e) || !std::isfinite(bo.v_in_m_s) || !(bo.v_in_m_s > 0.0)) continue;
    if (bo.index == 0 && !include_first) continue;
    RestitutionPoint p;
    p.recording = recording;
    p.bounce = bo.index;
    p.u_m_s = bo.v_in_m_s;
    p.e = bo.e;
    p.e_sigma = bo.e_sigma;
    const int k = offset + bo.index;
    p.onset = {bo.index > 0 ? k - 1 : -1, k, k + 1};
    p.de_dt = {bo.de_dt_prev, bo.de_dt_this, bo.de_dt_next};
    p.du_dt = {bo.dv_in_dt_prev, bo.dv_in_dt_this, 0.0};
    p.from_drop = bo.index == 0;
    p.de_dh = bo.de_dh;
    p.du_dh = bo.dv_in_dh;
    data->points.push_back(p);
  }
}

bool ScatterOptions::IsValid(std::string* error) const {
  if (grid_points < 4 || grid_points > 10000) {
    if (error) *error = "grid_points = " + std::to_string(grid_points) + " must be in [4, 10000]";
    return false;
  }
  return true;
}

ScatterProblem::ScatterProblem(Eigen::VectorXd r, Eigen::MatrixXd J, Eigen::MatrixXd timing_cov,
                               Eigen::MatrixXd design, ScatterOptions options)
    : r_(std::move(r)), j_(std::move(J)), ct_(std::move(timing_cov)), options_(options) {
  const Eigen::Index n = r_.size();
  identity_design_ = design.size() == 0;
  ggt_ = identity_design_ ? Eigen::MatrixXd(Eigen::MatrixXd::Identity(n, n))
                          : Eigen::MatrixXd(design * design.transpose());
  std::vector<double> dt, dg;
  for (Eigen::Index k = 0; k < n; ++k) {
    if (ct_(k, k) > 0.0) dt.push_back(ct_(k, k));
    if (ggt_(k, k) > 0.0) dg.push_back(ggt_(k, k));
  }
  const double mt = UpperMedian(dt), mg = UpperMedian(dg);
  scale_ = std::isfinite(mt) && std::isfinite(mg) && mg > 0.0 ? std::sqrt(mt / mg) : 1e-6;
  if (!(scale_ > 0.0)) scale_ = 1e-6;
  column_norm_ = j_.colwise().norm().transpose();
}

Eigen::MatrixXd ScatterProblem::Covariance(double sigma) const {
  return ct_ + sigma * sigma * ggt_;
}

void ScatterProblem::SolveWhitened(const Eigen::MatrixXd& jw, const Eigen::VectorXd& rw,
                                   Evaluation* ev, Eigen::MatrixXd* basis) const {
  const Eigen::Index p = jw.cols();
  ev->step = Eigen::VectorXd::Zero(p);
  ev->covariance = Eigen::MatrixXd::Zero(p, p);
  ev->log_det_info = 0.0;
  ev->ok = false;
  if (!jw.allFinite() || !rw.allFinite())
    return;  // a NaN is a failed evaluation, not a null column
  // Columns that move the model, scaled to unit norm by the unwhitened |J_j| (the same scale at
  // every sigma_s, so the REML term's constant does not depend on sigma_s).
  std::vector<Eigen::Index> cols;
  for (Eigen::Index j = 0; j < p; ++j) {
    if (column_norm_(j) > 0.0 && std::isfinite(column_norm_(j))) cols.push_back(j);
  }
  Eigen::VectorXd rt = rw;
  if (basis) basis->resize(rw.size(), 0);
  if (!cols.empty()) {
    const Eigen::Index q = static_cast<Eigen::Index>(cols.size());
    Eigen::MatrixXd js(jw.rows(), q);
    for (Eigen::Index i = 0; i < q; ++i) {
      js.col(i) = jw.col(cols[static_cast<size_t>(i)]) / column_norm_(cols[static_cast<size_t>(i)]);
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(js, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::VectorXd& sv = svd.singularValues();
    const double smax = sv.size() > 0 ? sv(0) : 0.0;
    Eigen::VectorXd ds = Eigen::VectorXd::Zero(q);
    Eigen::MatrixXd covs = Eigen::MatrixXd::Zero(q, q);
    Eigen::Index rank = 0;
    for (Eigen::Index i = 0; i < sv.size(); ++i) {
      if (!(sv(i) > kRankCut * smax)) break;  // sorted: the rest is the null space
      ++rank;
      const Eigen::VectorXd u = svd.matrixU().col(i), v = svd.matrixV().col(i);
      const double a = u.dot(rw);
      rt -= a * u;  // the residual's component in the column space, removed
      ds -= v * (a / sv(i));
      covs += v * v.transpose() / (sv(i) * sv(i));
      ev->log_det_info += 2.0 * std::log(sv(i));
    }
    if (basis) *basis = svd.matrixU().leftCols(rank);
    // Back to the parameters' units: d = S^-1 ds, cov = S^-1 covs S^-1, det picks up |J_j|^2.
    for (Eigen::Index a = 0; a < q; ++a) {
      const Eigen::Index ja = cols[static_cast<size_t>(a)];
      ev->log_det_info += 2.0 * std::log(column_norm_(ja));
      ev->step(ja) = ds(a) / column_norm_(ja);
      for (Eigen::Index b = 0; b < q; ++b) {
        const Eigen::Index jb = cols[static_cast<size_t>(b)];
        ev->covariance(ja, jb) = covs(a, b) / (column_norm_(ja) * column_norm_(jb));
      }
    }
  }
  ev->chi2 = rt.squaredNorm();
  ev->criterion = 0.5 * (ev->log_det_c + ev->chi2 + (options_.reml ? ev->log_det_info : 0.0));
  ev->ok = std::isfinite(ev->criterion);
}

ScatterProblem::Evaluation ScatterProblem::At(double sigma) const {
  Evaluation ev;
  const Eigen::Index n = r_.size();
  Eigen::LLT<Eigen::MatrixXd> llt(Covariance(sigma));
  if (llt.info() != Eigen::Success) return ev;
  const Eigen::MatrixXd& l = llt.matrixLLT();
  for (Eigen::Index k = 0; k < n; ++k) {
    if (!(l(k, k) > 0.0)) return ev;
    ev.log_det_c += 2.0 * std::log(l(k, k));
  }
  // Parameters the data cannot tell apart (a null direction) are left out of the step, the
  // log-determinant and the covariance (a pseudo-inverse), so an undetermined parameter does not
  // break the fit of the others; the caller reports it as undetermined.
  SolveWhitened(llt.matrixL().solve(j_), llt.matrixL().solve(r_), &ev);
  return ev;
}

Eigen::VectorXd ScatterProblem::FittedVariance(double sigma) const {
  Eigen::LLT<Eigen::MatrixXd> llt(Covariance(sigma));
  if (llt.info() != Eigen::Success) return {};
  Evaluation ev;
  Eigen::MatrixXd u;
  SolveWhitened(llt.matrixL().solve(j_), llt.matrixL().solve(r_), &ev, &u);
  return (llt.matrixL() * u).rowwise().squaredNorm();
}

ScatterProfile::ScatterProfile(const ScatterProblem& problem) : problem_(problem) {
  const Eigen::Index n = problem.r_.size();
  if (n == 0) return;
  Eigen::MatrixXd m;  // the matrix to tridiagonalise: A (G = I) or L^-1 B L^-T
  Eigen::MatrixXd jf = problem.j_;
  Eigen::VectorXd rf = problem.r_;
  if (problem.identity_design_) {
    m = problem.ct_;
  } else {
    const Eigen::LLT<Eigen::MatrixXd> llt(problem.ct_);
    if (llt.info() != Eigen::Success) return;
    const Eigen::MatrixXd& l = llt.matrixLLT();
    for (Eigen::Index k = 0; k < n; ++k) {
      if (!(l(k, k) > 0.0)) return;
      log_det_f_ += 2.0 * std::log(l(k, k));
    }
    const Eigen::MatrixXd li_b = llt.matrixL().solve(problem.ggt_);
    m = llt.matrixL().solve(li_b.transpose());
    jf = llt.matrixL().solve(jf);
    rf = llt.matrixL().solve(rf);
  }
  const Eigen::Tridiagonalization<Eigen::MatrixXd> tri(m);
  jf_ = tri.matrixQ().transpose() * jf;
  rf_ = tri.matrixQ().transpose() * rf;
  const Eigen::VectorXd diag = tri.diagonal();
  Eigen::VectorXd off = Eigen::VectorXd::Zero(n);  // off(k): element (k, k - 1)
  if (n > 1) off.tail(n - 1) = tri.subDiagonal();
  const Eigen::VectorXd ones = Eigen::VectorXd::Ones(n), zeros = Eigen::VectorXd::Zero(n);
  p_diag_ = problem.identity_design_ ? diag : ones;
  p_off_ = problem.identity_design_ ? off : zeros;
  r_diag_ = problem.identity_design_ ? ones : diag;
  r_off_ = problem.identity_design_ ? zeros : off;
  ok_ = jf_.allFinite() && rf_.allFinite();
}

ScatterProblem::Evaluation ScatterProfile::At(double sigma) const {
  if (!ok_) return problem_.At(sigma);
  ScatterProblem::Evaluation ev;
  const Eigen::Index n = rf_.size();
  const double s2 = sigma * sigma;
  // LDL^T of K = P + sigma^2 R (tridiagonal): l_k = K_k,k-1 / d_k-1, d_k = K_kk - l_k K_k,k-1.
  Eigen::VectorXd d(n), l = Eigen::VectorXd::Zero(n);
  ev.log_det_c = log_det_f_;
  for (Eigen::Index k = 0; k < n; ++k) {
    const double off = p_off_(k) + s2 * r_off_(k);
    if (k > 0) l(k) = off / d(k - 1);
    d(k) = p_diag_(k) + s2 * r_diag_(k) - l(k) * off;
    if (!(d(k) > 0.0) || !std::isfinite(d(k))) return problem_.At(sigma);
    ev.log_det_c += std::log(d(k));
  }
  // Whitened rows: D^-1/2 L^-1 (F^-1 J), D^-1/2 L^-1 (F^-1 r) (forward substitution, then scale).
  Eigen::MatrixXd jw = jf_;
  Eigen::VectorXd rw = rf_;
  for (Eigen::Index k = 1; k < n; ++k) {
    jw.row(k) -= l(k) * jw.row(k - 1);
    rw(k) -= l(k) * rw(k - 1);
  }
  const Eigen::VectorXd w = d.cwiseSqrt().cwiseInverse();
  jw = w.asDiagonal() * jw;
  rw = rw.cwiseProduct(w);
  problem_.SolveWhitened(jw, rw, &ev);
  return ev;
}

ScatterFit ScatterProblem::Fit() const {
  ScatterFit fit;
  const Eigen::Index n = r_.size();
  if (n == 0) return fit;
  const ScatterProfile profile(*this);  // ~100 evaluations for the cost of one reduction
  // Grid in log sigma from 1e-3 to 1e3 of the timing scale (and past the residual rms), then
  // golden-section refinement between the best grid point's neighbours.
  const double rms = std::sqrt(r_.squaredNorm() / static_cast<double>(n));
  const double gscale = std::sqrt(ggt_.diagonal().mean());
  const double lo = 1e-3 * scale_;
  const double hi = std::max(1e3 * scale_, 10.0 * rms / std::max(gscale, 1e-300));
  const int m = options_.grid_points;
  std::vector<double> grid(static_cast<size_t>(m)), value(static_cast<size_t>(m));
  int best = -1;
  for (int i = 0; i < m; ++i) {
    grid[static_cast<size_t>(i)] = lo * std::pow(hi / lo, i / double(m - 1));
    const Evaluation ev = profile.At(grid[static_cast<size_t>(i)]);
    value[static_cast<size_t>(i)] = ev.ok ? ev.criterion : std::numeric_limits<double>::infinity();
    if (ev.ok && (best < 0 || ev.criterion < value[static_cast<size_t>(best)])) best = i;
  }
  const Evaluation at0 = profile.At(0.0);
  if (best < 0 && !at0.ok) return fit;
  double sigma = 0.0;
  if (best >= 0) {
    double a = std::log(grid[static_cast<size_t>(std::max(best - 1, 0))]);
    double b = std::log(grid[static_cast<size_t>(std::min(best + 1, m - 1))]);
    const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
    auto f = [&](double x) {
      const Evaluation ev = profile.At(std::exp(x));
      return ev.ok ? ev.criterion : std::numeric_limits<double>::infinity();
    };
    double x1 = b - phi * (b - a), x2 = a + phi * (b - a);
    double f1 = f(x1), f2 = f(x2);
    while (b - a > 1e-6) {
      if (f1 <= f2) {
        b = x2, x2 = x1, f2 = f1, x1 = b - phi * (b - a), f1 = f(x1);
      } else {
        a = x1, x1 = x2, f1 = f2, x2 = a + phi * (b - a), f2 = f(x2);
      }
    }
    sigma = std::exp(0.5 * (a + b));
  }
  Evaluation ev = best >= 0 ? profile.At(sigma) : at0;
  // sigma_s = 0 (the timing noise alone explains the scatter) is a candidate of its own: the
  // criterion tends to a finite limit there, which the log grid only approaches.
  if (at0.ok && (!ev.ok || at0.criterion <= ev.criterion)) {
    sigma = 0.0;
    ev = at0;
  }
  fit.ok = ev.ok;
  fit.sigma = sigma;
  fit.step = ev.step;
  fit.covariance = ev.covariance;
  fit.chi2 = ev.chi2;
  fit.criterion = ev.criterion;
  fit.neg_log_likelihood =
      0.5 * (static_cast<double>(n) * std::log(2.0 * M_PI) + ev.log_det_c + ev.chi2);
  auto crit = [&](double s) {
    const Evaluation e = profile.At(s);
    return e.ok ? e.criterion : kNaN;
  };
  if (sigma > 0.0) {
    // Curvature of the criterion in sigma_s: var(sigma_s) = 1 / f''.
    const double h = 0.02 * sigma;
    const double f2 = (crit(sigma + h) - 2.0 * ev.criterion + crit(sigma - h)) / (h * h);
    fit.sigma_sigma = f2 > 0.0 ? 1.0 / std::sqrt(f2) : kNaN;
  } else {
    // One-sided: the sigma_s where the criterion has risen by 1/2 (68 % upper limit).
    fit.sigma_at_zero = true;
    double a = 0.0, b = lo;
    while (b < hi && !(crit(b) - ev.criterion > 0.5)) a = b, b *= 2.0;
    for (int it = 0; it < 60 && b < hi; ++it) {
      const double c = 0.5 * (a + b);
      (crit(c) - ev.criterion > 0.5 ? b : a) = c;
    }
    fit.sigma_sigma = b < hi ? 0.5 * (a + b) : kNaN;
  }
  return fit;
}

}  // namespace bouncecal
