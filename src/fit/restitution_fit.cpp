// Calibration stage 3 (restitution strategy): per-bounce restitution with scatter
// (calibrate_stages.hpp, scatter_model.hpp).
//
// Model of bounce k: e_meas,k = e(u_k; theta) + g_k + eps_k, where e is the law's restitution at
// the measured arrival speed u_k and g_k the effect of gravity during the contact (the closed
// forms leave it out; the simulator, and a real ball, have it: g_k = e_sim,g(u_k) - e_closed(u_k)
// from one simulated contact, refreshed at each alternation; ~1e-5..1e-4 for a steel ball).
// Residuals r_k = model - measured with covariance C = C_t(theta) + sigma_s^2 I (C_t from the
// onset and height sigmas, with the model slope de/du at each point). theta minimises the
// whitened sum |L^-1 r|^2 (C = L L^T, Ceres) at fixed sigma_s; sigma_s then follows from the
// REML profile (ScatterProblem::Fit); the two alternate until sigma_s settles.
#include <algorithm>
#include <cmath>
#include <tuple>
#include <utility>

#include <ceres/ceres.h>

#include "bouncecal/core/error.hpp"
#include "fit/calibrate_stages.hpp"
#include "fit/solver_options.hpp"

namespace bouncecal::calib {
namespace {

constexpr int kMaxAlternations = 12;

// Free parameters that vary (not held), as indices into setup.free.
std::vector<int> Active(const LawSetup& s, const std::vector<bool>& held) {
  std::vector<int> a;
  for (size_t j = 0; j < s.free.size(); ++j) {
    if (held.empty() || !held[j]) a.push_back(static_cast<int>(j));
  }
  return a;
}

// The law's e at the given speeds and, when asked, de/du_j for the active scaled parameters.
bool EvaluateAt(const FitProblem& fp, const std::vector<double>& p, const std::vector<int>& active,
                const std::vector<double>& speeds, Eigen::VectorXd* e, Eigen::MatrixXd* jac,
                std::atomic<long>* sims) {
  const LawSetup& s = fp.setup;
  const Eigen::Index n = static_cast<Eigen::Index>(speeds.size());
  e->resize(n);
  if (jac) jac->setZero(n, static_cast<Eigen::Index>(active.size()));
  std::string err;
  if (!s.law->IsValid(p, s.body, &err)) return false;
  const bool analytic = fp.options.derivatives == DerivativeMode::kAuto && s.has_gradient;
  std::vector<double> de(p.size(), 0.0);
  try {
    for (Eigen::Index k = 0; analytic && k < n; ++k) {
      double ek = 0.0;
      if (!s.law->RestitutionGradient(p, s.body, speeds[static_cast<size_t>(k)], &ek, de.data()))
        return false;
      (*e)(k) = ek;
      for (size_t j = 0; jac && j < active.size(); ++j) {
        const size_t a = static_cast<size_t>(active[j]);
        (*jac)(k, static_cast<Eigen::Index>(j)) = de[static_cast<size_t>(s.free[a])] * s.scale[a];
      }
    }
    if (!analytic) {
      // Closed forms are noise-free: a small step; simulated contacts: rtol^(1/3).
      const double rel = s.has_closed_e ? 1e-6 : RelativeStep(fp.options.rel_tolerance);
      const int contacts = 1 + (jac ? 2 * static_cast<int>(active.size()) : 0);
      ForEachSpeed(fp, static_cast<std::size_t>(n), contacts, [&](std::size_t kk) {
        const Eigen::Index k = static_cast<Eigen::Index>(kk);
        const double u = speeds[kk];
        (*e)(k) = ModelRestitution(s, p, u, fp.g, fp.sim, sims);
        for (size_t j = 0; jac && j < active.size(); ++j) {
          const size_t a = static_cast<size_t>(active[j]);
          const size_t i = static_cast<size_t>(s.free[a]);
          const ParameterSpec& sp = s.specs()[i];
          const double x = p[i];
          const double h = rel * std::max(std::abs(x), s.typical[i]);
          std::vector<double> q = p;
          const double hi = std::min(x + h, sp.upper), lo = std::max(x - h, sp.lower);
          if (!(hi > lo)) continue;
          q[i] = hi;
          const double eh = ModelRestitution(s, q, u, fp.g, fp.sim, sims);
          q[i] = lo;
          const double el = ModelRestitution(s, q, u, fp.g, fp.sim, sims);
          (*jac)(k, static_cast<Eigen::Index>(j)) = (eh - el) / (hi - lo) * s.scale[a];
        }
      });
    }
  } catch (const Error&) {
    return false;
  }
  if (!e->allFinite()) return false;
  return !jac || jac->allFinite();
}

// Natural cubic spline y(x) through (x_i, y_i) (Press et al., Numerical Recipes, 3rd ed., §3.3).
class Spline {
 public:
  Spline(std::vector<double> x, std::vector<double> y) : x_(std::move(x)), y_(std::move(y)) {
    const size_t n = x_.size();
    m_.assign(n, 0.0);
    std::vector<double> u(n, 0.0);
    for (size_t i = 1; i + 1 < n; ++i) {
      const double sig = (x_[i] - x_[i - 1]) / (x_[i + 1] - x_[i - 1]);
      const double p = sig * m_[i - 1] + 2.0;
      m_[i] = (sig - 1.0) / p;
      u[i] = (y_[i + 1] - y_[i]) / (x_[i + 1] - x_[i]) - (y_[i] - y_[i - 1]) / (x_[i] - x_[i - 1]);
      u[i] = (6.0 * u[i] / (x_[i + 1] - x_[i - 1]) - sig * u[i - 1]) / p;
    }
    m_[n - 1] = 0.0;
    for (size_t k = n - 1; k-- > 0;) m_[k] = m_[k] * m_[k + 1] + u[k];
  }
  double Value(double t, double* slope = nullptr) const {
    size_t i = static_cast<size_t>(std::upper_bound(x_.begin(), x_.end(), t) - x_.begin());
    i = std::clamp<size_t>(i, 1, x_.size() - 1);
    const double h = x_[i] - x_[i - 1], a = (x_[i] - t) / h, b = (t - x_[i - 1]) / h;
    if (slope) {
      *slope = (y_[i] - y_[i - 1]) / h - (3 * a * a - 1) / 6 * h * m_[i - 1] +
               (3 * b * b - 1) / 6 * h * m_[i];
    }
    return a * y_[i - 1] + b * y_[i] +
           ((a * a * a - a) * m_[i - 1] + (b * b * b - b) * m_[i]) * h * h / 6;
  }

 private:
  std::vector<double> x_, y_, m_;
};

// Simulated contacts are costly: with many points the law is simulated on a log-spaced grid of
// speeds over the points' range and interpolated (natural cubic spline in ln u; e(u) is smooth,
// and the interpolation error is far below the timing sigmas, tests/calibrate_stages_test).
constexpr int kGridNodes = 12;

bool UseGrid(const FitProblem& fp) {
  const bool analytic = fp.options.derivatives == DerivativeMode::kAuto && fp.setup.has_gradient;
  return !analytic && !fp.setup.has_closed_e && fp.data.size() > kGridNodes;
}

std::vector<double> GridSpeeds(const FitProblem& fp) {
  double lo = std::numeric_limits<double>::max(), hi = 0.0;
  for (const auto& pt : fp.data.points) lo = std::min(lo, pt.u_m_s), hi = std::max(hi, pt.u_m_s);
  std::vector<double> g;
  for (int i = 0; i < kGridNodes; ++i)
    g.push_back(lo * std::pow(hi / lo, i / double(kGridNodes - 1)));
  return g;
}

std::vector<double> PointSpeeds(const FitProblem& fp) {
  std::vector<double> u;
  for (const auto& pt : fp.data.points) u.push_back(pt.u_m_s);
  return u;
}

// The law's e at every point and, when asked, de/du_j for the active scaled parameters.
bool ModelValues(const FitProblem& fp, const std::vector<double>& p, const std::vector<int>& active,
                 Eigen::VectorXd* e, Eigen::MatrixXd* jac, std::atomic<long>* sims) {
  if (!UseGrid(fp)) return EvaluateAt(fp, p, active, PointSpeeds(fp), e, jac, sims);
  const std::vector<double> nodes = GridSpeeds(fp);
  Eigen::VectorXd eg;
  Eigen::MatrixXd jg;
  if (!EvaluateAt(fp, p, active, nodes, &eg, jac ? &jg : nullptr, sims)) return false;
  std::vector<double> x;
  for (double u : nodes) x.push_back(std::log(u));
  const int n = fp.data.size();
  e->resize(n);
  if (jac) jac->resize(n, jg.cols());
  for (Eigen::Index c = -1; c < (jac ? jg.cols() : 0); ++c) {
    const Eigen::VectorXd col = c < 0 ? eg : Eigen::VectorXd(jg.col(c));
    const Spline sp(x, std::vector<double>(col.data(), col.data() + col.size()));
    for (int k = 0; k < n; ++k) {
      const double v = sp.Value(std::log(fp.data.points[static_cast<size_t>(k)].u_m_s));
      (c < 0 ? (*e)(k) : (*jac)(k, c)) = v;
    }
  }
  return true;
}

// de/du of the model at each point (the measured speed carries timing noise too).
std::vector<double> ModelSlopes(const FitProblem& fp, const std::vector<double>& p,
                                std::atomic<long>* sims) {
  std::vector<double> out(fp.data.points.size(), 0.0);
  if (UseGrid(fp)) {
    const std::vector<double> nodes = GridSpeeds(fp);
    Eigen::VectorXd eg;
    if (!EvaluateAt(fp, p, {}, nodes, &eg, nullptr, sims)) return out;
    std::vector<double> x;
    for (double u : nodes) x.push_back(std::log(u));
    const Spline sp(x, std::vector<double>(eg.data(), eg.data() + eg.size()));
    for (size_t k = 0; k < out.size(); ++k) {
      const double u = fp.data.points[k].u_m_s;
      double d = 0.0;
      sp.Value(std::log(u), &d);
      out[k] = d / u;  // de/du = (de/d ln u) / u
    }
    return out;
  }
  const double rel = fp.setup.has_closed_e ? 1e-5 : RelativeStep(fp.options.rel_tolerance);
  ForEachSpeed(fp, out.size(), 2, [&](std::size_t k) {
    const double u = fp.data.points[k].u_m_s, h = rel * u;
    try {
      out[k] = (ModelRestitution(fp.setup, p, u + h, fp.g, fp.sim, sims) -
                ModelRestitution(fp.setup, p, u - h, fp.g, fp.sim, sims)) /
               (2.0 * h);
    } catch (const Error&) {
      out[k] = 0.0;
    }
    if (!std::isfinite(out[k])) out[k] = 0.0;
  });
  return out;
}

// Gravity during the contact, which the closed forms leave out (file comment).
std::vector<double> GravityOffsets(const FitProblem& fp, const std::vector<double>& p,
                                   std::atomic<long>* sims) {
  std::vector<double> out(fp.data.points.size(), 0.0);
  if (!fp.setup.has_closed_e) return out;  // simulated contacts include gravity already
  for (size_t k = 0; k < out.size(); ++k) {
    const double u = fp.data.points[k].u_m_s;
    try {
      const auto closed = fp.setup.law->Restitution(p, fp.setup.body, u);
      if (!closed) continue;
      if (sims) ++*sims;
      out[k] =
          SimulateContact(*fp.setup.law, p, fp.setup.body, u, fp.g, fp.sim).restitution - *closed;
    } catch (const Error&) {
      out[k] = 0.0;
    }
    if (!std::isfinite(out[k])) out[k] = 0.0;
  }
  return out;
}

// All residuals of the per-bounce model, whitened by the Cholesky factor of C. The data are
// const: fits may run in parallel.
class RestitutionCost final : public ceres::CostFunction {
 public:
  RestitutionCost(const FitProblem& fp, std::vector<double> base, std::vector<int> active,
                  Eigen::VectorXd offsets, Eigen::MatrixXd chol_lower, std::atomic<long>* sims)
      : fp_(fp),
        base_(std::move(base)),
        active_(std::move(active)),
        offsets_(std::move(offsets)),
        l_(std::move(chol_lower)),
        sims_(sims) {
    set_num_residuals(fp.data.size());
    mutable_parameter_block_sizes()->push_back(static_cast<int>(active_.size()));
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    std::vector<double> p = base_;
    const LawSetup& s = fp_.setup;
    for (size_t j = 0; j < active_.size(); ++j) {
      const size_t a = static_cast<size_t>(active_[j]);
      p[static_cast<size_t>(s.free[a])] = s.scale[a] * parameters[0][j];
    }
    const bool want = jacobians && jacobians[0];
    Eigen::VectorXd e;
    Eigen::MatrixXd jac;
    if (const auto last = last_.Find(p, want)) {
      std::tie(e, jac) = *last;
    } else {
      if (!ModelValues(fp_, p, active_, &e, want ? &jac : nullptr, sims_)) return false;
      last_.Store(p, want, {e, jac});
    }
    const int n = fp_.data.size();
    Eigen::VectorXd r(n);
    for (int k = 0; k < n; ++k)
      r(k) = e(k) + offsets_(k) - fp_.data.points[static_cast<size_t>(k)].e;
    const auto tri = l_.triangularView<Eigen::Lower>();
    Eigen::Map<Eigen::VectorXd>(residuals, n) = tri.solve(r);
    if (want) {
      const Eigen::MatrixXd jw = tri.solve(jac);
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[0], n, static_cast<Eigen::Index>(active_.size())) = jw;
    }
    return true;
  }

 private:
  const FitProblem& fp_;
  const std::vector<double> base_;
  const std::vector<int> active_;
  const Eigen::VectorXd offsets_;
  const Eigen::MatrixXd l_;
  std::atomic<long>* sims_;
  LastEvaluation<std::pair<Eigen::VectorXd, Eigen::MatrixXd>> last_;  // e and de/du at p
};

ceres::LossFunction* MakeLoss(const CalibrationOptions& o) {
  switch (o.loss) {
    case RobustLoss::kHuber:
      return new ceres::HuberLoss(o.loss_scale_sigma);
    case RobustLoss::kCauchy:
      return new ceres::CauchyLoss(o.loss_scale_sigma);
    case RobustLoss::kNone:
      return nullptr;
  }
  return nullptr;
}

// One Ceres solve of theta at fixed covariance (Cholesky factor l). Returns false when the
// solver cannot start or fails.
bool SolveTheta(const FitProblem& fp, const std::vector<int>& active, const Eigen::VectorXd& off,
                const Eigen::MatrixXd& l, std::vector<double>* p, Solution* sol,
                std::atomic<long>* sims) {
  const LawSetup& s = fp.setup;
  std::vector<double> u;
  for (int a : active)
    u.push_back((*p)[static_cast<size_t>(s.free[static_cast<size_t>(a)])] /
                s.scale[static_cast<size_t>(a)]);
  ceres::Problem problem;
  problem.AddResidualBlock(new RestitutionCost(fp, *p, active, off, l, sims), MakeLoss(fp.options),
                           u.data());
  SetLawBounds(s, active, u.data(), &problem);
  const ceres::Solver::Options so = SolverOptions(fp.options);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  sol->iterations += static_cast<int>(summary.iterations.size());
  if (!summary.IsSolutionUsable()) {
    sol->failure = "law " + s.law->Name() + ": the solver failed: " + summary.message;
    return false;
  }
  if (summary.termination_type == ceres::NO_CONVERGENCE) {
    sol->iteration_limit = true;
    sol->limit_note =
        "the solver reached max_iterations = " + std::to_string(fp.options.max_iterations) +
        " before converging";
  } else {
    sol->iteration_limit = false;
  }
  for (size_t j = 0; j < active.size(); ++j) {
    const size_t a = static_cast<size_t>(active[j]);
    (*p)[static_cast<size_t>(s.free[a])] = s.scale[a] * u[j];
  }
  sol->cost = summary.final_cost;
  return true;
}

}  // namespace

Solution SolveRestitution(const FitProblem& fp, const std::vector<double>& start,
                          const std::vector<bool>& held, double sigma_start, bool alternate,
                          std::atomic<long>* sims, const std::vector<double>* reference) {
  Solution sol;
  sol.held = held.empty() ? std::vector<bool>(fp.setup.free.size(), false) : held;
  const std::vector<int> active = Active(fp.setup, sol.held);
  const int n = fp.data.size();
  std::vector<double> p = start;
  double sigma = fp.options.estimate_scatter ? sigma_start : 0.0;
  bool settled = !alternate;
  Eigen::VectorXd e, off;
  Eigen::MatrixXd jac, ct;
  for (int outer = 0; outer < (alternate ? kMaxAlternations : 1); ++outer) {
    const std::vector<double>& at = reference ? *reference : p;
    const std::vector<double> g = GravityOffsets(fp, at, sims);
    off = Eigen::Map<const Eigen::VectorXd>(g.data(), n);
    ct = fp.data.TimingCovariance(ModelSlopes(fp, at, sims));
    Eigen::LLT<Eigen::MatrixXd> llt(ct + sigma * sigma * Eigen::MatrixXd::Identity(n, n));
    if (llt.info() != Eigen::Success) {
      sol.failure = "the covariance of the restitution points is not positive definite";
      return sol;
    }
    if (!SolveTheta(fp, active, off, llt.matrixL(), &p, &sol, sims)) return sol;
    if (!alternate) break;
    if (!ModelValues(fp, p, active, &e, &jac, sims)) {
      sol.failure = "law " + fp.setup.law->Name() + ": the model fails at the fitted values";
      return sol;
    }
    if (!fp.options.estimate_scatter) {
      settled = true;
      break;
    }
    Eigen::VectorXd r(n);
    for (int k = 0; k < n; ++k) r(k) = e(k) + off(k) - fp.data.points[static_cast<size_t>(k)].e;
    const ScatterFit f = ScatterProblem(r, jac, ct).Fit();
    if (!f.ok) break;
    const double tol = std::isfinite(f.sigma_sigma) ? 1e-2 * f.sigma_sigma : 1e-4 * f.sigma;
    const bool same = std::abs(f.sigma - sigma) <= tol;
    sigma = f.sigma;
    if (same) {
      settled = true;
      break;
    }
  }
  // The optimum: residuals, Jacobian and the scatter fit there.
  if (!ModelValues(fp, p, active, &e, &jac, sims)) {
    sol.failure = "law " + fp.setup.law->Name() + ": the model fails at the fitted values";
    return sol;
  }
  sol.residuals.resize(n);
  for (int k = 0; k < n; ++k) {
    sol.residuals(k) = e(k) + off(k) - fp.data.points[static_cast<size_t>(k)].e;
  }
  sol.jacobian = jac;
  sol.timing_cov = ct;
  const ScatterProblem sp(sol.residuals, jac, ct);
  if (fp.options.estimate_scatter && alternate) {
    sol.scatter = sp.Fit();
    sol.scatter.sigma = sigma;  // the sigma_s theta was solved at (settled: within 1 % of it)
  }
  const ScatterProblem::Evaluation ev = sp.At(sigma);
  sol.scatter.ok = ev.ok;
  sol.scatter.sigma = sigma;
  sol.scatter.covariance = ev.covariance;
  sol.scatter.chi2 = ev.chi2;
  sol.scatter.criterion = ev.criterion;
  sol.scatter.neg_log_likelihood = 0.5 * (n * std::log(2.0 * M_PI) + ev.log_det_c + ev.chi2);
  if (!ev.ok) {
    sol.failure = "law " + fp.setup.law->Name() + ": the fit's information matrix is singular";
    return sol;
  }
  if (!settled) {
    sol.iteration_limit = true;
    sol.limit_note = "the scatter sigma_s did not settle in " + std::to_string(kMaxAlternations) +
                     " alternations with the law's parameters";
  }
  sol.p = p;
  sol.ok = true;
  return sol;
}

}  // namespace bouncecal::calib
