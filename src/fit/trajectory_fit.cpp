// Calibration stage 3 (trajectory strategy): simulated impact times with the per-bounce scatter
// propagated along the trajectory (calibrate_stages.hpp).
//
// Residuals per recording: r_j = t0 + s_j(theta, v0) - t_j (model - measured, s), covariance
//   C = diag(sigma_t^2) + sigma_s^2 G G^T,   G_jk = d s_j / d eps_k
// where eps_k perturbs bounce k's restitution: v_out,k = (e(u_k) + eps_k) u_k, and the change
// runs through every later flight (docs/physics.md §2 flight formulas, the law's e'(u) at each
// later impact). sigma_s comes from the restitution fit. G is computed at the start and again at
// the optimum (one refit). A stated drop with sigma ties v0 through a prior residual (v0 - v_drop)
// / sigma_v; an exact one holds v0.
#include <algorithm>
#include <cmath>
#include <limits>
#include <set>

#include <ceres/ceres.h>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/flight.hpp"
#include "fit/calibrate_stages.hpp"
#include "fit/solver_options.hpp"

namespace bouncecal::calib {
namespace {

constexpr double kMinTimeSigmaS = 1e-7;  // a zero sigma would give an infinite weight

struct SimPoint {
  std::vector<double> times_s;    // n_sim entries (missing impacts at the last simulated one)
  std::vector<double> v_in_m_s;   // simulated arrival speeds
  std::vector<double> v_out_m_s;  // simulated rebound speeds
  int simulated = 0;
  StopReason stop = StopReason::kAtRest;
  bool has_jacobian = false;
  // ds_k / d(active law param j, scaled) at [k * (na + 1) + j]; column na is d/dv0.
  std::vector<double> jac;
};

}  // namespace

std::vector<int> MissedCounts(const Sequence& sequence) {
  const std::vector<Impact>& q = sequence.impacts;
  std::vector<int> count(q.size(), 0);
  const std::set<int> flagged(sequence.missed_after.begin(), sequence.missed_after.end());
  // The last regular intervals (not spanning a gap), newest last, and the interval the sequence
  // has reached (measured, or predicted across earlier gaps).
  std::vector<double> regular;
  double current = 0.0;
  for (size_t k = 0; k + 1 < q.size(); ++k) {
    const double dt = q[k + 1].time_s - q[k].time_s;
    if (!flagged.count(static_cast<int>(k))) {
      regular.push_back(dt);
      current = dt;
      continue;
    }
    std::vector<double> ratios;
    for (size_t i = regular.size() >= 4 ? regular.size() - 3 : 1; i < regular.size(); ++i)
      if (regular[i - 1] > 0.0) ratios.push_back(regular[i] / regular[i - 1]);
    double r = 1.0;
    if (!ratios.empty()) {
      std::sort(ratios.begin(), ratios.end());
      r = ratios[ratios.size() / 2];
    }
    if (!(current > 0.0) || !(r > 0.0) || !(r < 1.0)) {
      count[k] = 1;  // nothing to extrapolate from: the flag's own "at least one"
      continue;
    }
    int best = 1;
    double best_miss = std::numeric_limits<double>::infinity(), sum = 0.0, d = current;
    for (int n = 1; n <= 50; ++n) {
      if (n == 1)
        sum = d * r + d * r * r;
      else
        sum += d * std::pow(r, n + 1);
      const double miss = std::fabs(sum - dt);
      if (miss < best_miss) best_miss = miss, best = n;
    }
    count[k] = best;
    current = d * std::pow(r, best + 1);
  }
  return count;
}

namespace {

// One recording's simulated impact times. Const after construction: evaluations do not share
// state, so fits may run in parallel.
class TrajectoryModel {
 public:
  TrajectoryModel(const FitProblem& fp, const RecordingData& rec, std::vector<int> active)
      : fp_(fp),
        scene_(fp.scene),
        flight_(FlightModel::FromScene(fp.scene)),
        active_(std::move(active)),
        analytic_(fp.options.derivatives == DerivativeMode::kAuto && fp.setup.has_gradient &&
                  !fp.scene.effects.contact_duration && !fp.scene.effects.surface_compliance),
        rel_step_(RelativeStep(fp.options.rel_tolerance)) {
    const std::vector<int> missed = MissedCounts(rec.sequence);
    int before = 0;
    for (size_t k = 0; k < rec.sequence.impacts.size(); ++k) {
      const Impact& i = rec.sequence.impacts[k];
      times_s_.push_back(i.time_s);
      sigmas_s_.push_back(std::max(i.sigma_s, kMinTimeSigmaS));
      // Impacts the detector flagged as missed (between measured k and k+1) still happen in
      // the simulation: measured impact k is simulated impact k + (misses before it).
      sim_index_.push_back(static_cast<int>(k) + before);
      before += missed[k];
    }
    n_sim_ = static_cast<size_t>(sim_index_.back()) + 1;
    sim_.rel_tolerance = fp.options.rel_tolerance;
    sim_.abs_tolerance = std::min(1e-12, fp.options.rel_tolerance * 1e-3);
    // Simulate exactly as many impacts as were measured; let the ball bounce down to tiny
    // speeds so a missing impact means the law really stopped the ball.
    scene_.limits.max_impacts = static_cast<int>(n_sim_);
    scene_.limits.rest_speed_m_s = std::min(scene_.limits.rest_speed_m_s, 1e-6);
    scene_.limits.horizon_s = 3.0 * (times_s_.back() - times_s_.front()) + 2.0;
    scene_.drop.first_impact_time_s = 0.0;
  }

  bool analytic() const { return analytic_; }
  int size() const { return static_cast<int>(times_s_.size()); }
  size_t sim_index(int k) const { return static_cast<size_t>(sim_index_[static_cast<size_t>(k)]); }
  double time(int k) const { return times_s_[static_cast<size_t>(k)]; }
  double sigma(int k) const { return sigmas_s_[static_cast<size_t>(k)]; }
  const std::vector<int>& active() const { return active_; }

  std::optional<SimPoint> Times(const std::vector<double>& p, double v0, bool jacobian,
                                std::atomic<long>* sims) const {
    auto s = SimulateTimes(p, v0, sims);
    if (!s || !jacobian) return s;
    if (!ComputeJacobian(p, v0, &*s, sims)) return std::nullopt;
    return s;
  }

  // G: d s_j / d eps_k (measured j, simulated bounce k), see the file comment.
  Eigen::MatrixXd ScatterDesign(const SimPoint& s, const std::vector<double>& p,
                                std::atomic<long>* sims) const {
    const int n = size();
    const int nb = std::max(s.simulated - 1, 0);
    Eigen::MatrixXd ds = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(n_sim_), nb);
    std::vector<double> slope(static_cast<size_t>(s.simulated), 0.0), e(slope);
    for (int k = 0; k < s.simulated; ++k) {
      const double u = s.v_in_m_s[static_cast<size_t>(k)], h = 1e-5 * u;
      e[static_cast<size_t>(k)] = s.v_out_m_s[static_cast<size_t>(k)] / u;
      try {
        slope[static_cast<size_t>(k)] =
            (ModelRestitution(fp_.setup, p, u + h, fp_.g, fp_.sim, sims) -
             ModelRestitution(fp_.setup, p, u - h, fp_.g, fp_.sim, sims)) /
            (2.0 * h);
      } catch (const Error&) {
      }
    }
    for (int k = 0; k < nb; ++k) {
      double du = 0.0, dt = 0.0;
      for (int m = k; m + 1 < s.simulated; ++m) {
        const double u = s.v_in_m_s[static_cast<size_t>(m)];
        const double w = s.v_out_m_s[static_cast<size_t>(m)];
        const double dw = (e[static_cast<size_t>(m)] + u * slope[static_cast<size_t>(m)]) * du +
                          (m == k ? u : 0.0);
        dt += flight_.FlightTimeDerivative(w) * dw;
        du = flight_.ArrivalSpeedDerivative(w) * dw;
        ds(m + 1, k) = dt;
      }
      for (size_t j = static_cast<size_t>(s.simulated); j < n_sim_; ++j) {
        ds(static_cast<Eigen::Index>(j), k) = ds(s.simulated - 1, k);
      }
    }
    Eigen::MatrixXd g(n, nb);
    for (int j = 0; j < n; ++j) g.row(j) = ds.row(static_cast<Eigen::Index>(sim_index(j)));
    return g;
  }

 private:
  std::optional<SimPoint> SimulateTimes(const std::vector<double>& p, double v0,
                                        std::atomic<long>* sims) const {
    if (!(v0 > 0.0) || !std::isfinite(v0)) return std::nullopt;
    std::string err;
    if (!fp_.setup.law->IsValid(p, fp_.setup.body, &err)) return std::nullopt;
    Scene s = scene_;
    s.drop.height_m.reset();
    s.drop.height_sigma_m.reset();
    s.drop.impact_speed_m_s = v0;
    Simulation sim;
    try {
      if (sims) ++*sims;
      sim = Simulate(s, *fp_.setup.law, p, sim_);
    } catch (const Error&) {
      return std::nullopt;
    }
    if (sim.impacts.empty()) return std::nullopt;
    SimPoint out;
    out.simulated = static_cast<int>(std::min(sim.impacts.size(), n_sim_));
    out.stop = sim.stop_reason;
    const double t_first = sim.impacts.front().time_s;
    for (size_t k = 0; k < n_sim_; ++k) {
      // Missing impacts (the ball came to rest or stuck) sit at the last simulated one: as an
      // impact fades out its flight shrinks to zero, so this keeps the residual continuous.
      const size_t j = std::min(k, static_cast<size_t>(out.simulated - 1));
      out.times_s.push_back(sim.impacts[j].time_s - t_first);
      if (!std::isfinite(out.times_s.back())) return std::nullopt;
    }
    for (int k = 0; k < out.simulated; ++k) {
      out.v_in_m_s.push_back(sim.impacts[static_cast<size_t>(k)].v_in_m_s);
      out.v_out_m_s.push_back(sim.impacts[static_cast<size_t>(k)].v_out_m_s);
    }
    return out;
  }

  bool ComputeJacobian(const std::vector<double>& p, double v0, SimPoint* pt,
                       std::atomic<long>* sims) const {
    const LawSetup& su = fp_.setup;
    const size_t na = active_.size(), n = n_sim_;
    pt->jac.assign(n * (na + 1), 0.0);
    // Analytic columns for the damping parameters and v0; stiffness-like parameters change
    // impact times mostly through contact durations and gravity during slow contacts, which
    // the closed-form chain does not see: those columns are differenced on the simulator.
    const bool analytic = analytic_ && AnalyticJacobian(p, pt);
    if (!analytic) pt->jac.assign(n * (na + 1), 0.0);
    auto column = [&](size_t col, const std::vector<double>& ph, double v0h,
                      const std::vector<double>& pl, double v0l, double dx) {
      auto hi = SimulateTimes(ph, v0h, sims);
      auto lo = SimulateTimes(pl, v0l, sims);
      if (!hi || !lo) return false;
      for (size_t k = 0; k < n; ++k)
        pt->jac[k * (na + 1) + col] = (hi->times_s[k] - lo->times_s[k]) / dx;
      return true;
    };
    for (size_t j = 0; j < na; ++j) {
      const size_t a = static_cast<size_t>(active_[j]);
      const size_t i = static_cast<size_t>(su.free[a]);
      const ParameterSpec& spec = su.specs()[i];
      if (analytic && spec.damping) continue;
      const double x = p[i];
      const double h = rel_step_ * std::max(std::abs(x), su.typical[i]);
      const double hi = std::min(x + h, spec.upper), lo = std::max(x - h, spec.lower);
      std::vector<double> ph = p, pl = p;
      ph[i] = hi;
      pl[i] = lo;
      // d/du = d/dx * scale
      if (hi > lo && !column(j, ph, v0, pl, v0, (hi - lo) / su.scale[a])) return false;
    }
    const double h = rel_step_ * v0;
    if (!analytic && !column(na, p, v0 + h, p, v0 - h, 2 * h)) return false;
    pt->has_jacobian = true;
    return true;
  }

  // d s_k / d(theta, v0) by the chain rule through the law's closed-form e(v) and the exact
  // flight formulas (docs/physics.md §2): v_out,k = e(v_in,k) v_in,k, s_{k+1} = s_k + T(v_out,k) +
  // t_c(v_in,k), v_in,k+1 = A(v_out,k). Exact for closed-form contacts; for integrated laws it
  // neglects gravity during the contact (a small Jacobian error only: residuals always come
  // from the simulator, so the optimum is unaffected to first order).
  bool AnalyticJacobian(const std::vector<double>& p, SimPoint* pt) const {
    const LawSetup& su = fp_.setup;
    const size_t na = active_.size(), nall = p.size(), n = n_sim_;
    std::vector<double> du(na + 1, 0.0), ds(na + 1, 0.0), dw(na + 1, 0.0), de_dp(nall, 0.0);
    du[na] = 1.0;  // d v_in,0 / d v0
    for (size_t k = 0; k < n; ++k) {
      for (size_t j = 0; j <= na; ++j) pt->jac[k * (na + 1) + j] = ds[j];
      if (k + 1 >= n || static_cast<int>(k) + 1 >= pt->simulated) continue;
      const double u = pt->v_in_m_s[k];
      double e = 0.0;
      if (!su.law->RestitutionGradient(p, su.body, u, &e, de_dp.data())) return false;
      const double hu = 1e-6 * u;
      auto el = su.law->Restitution(p, su.body, u - hu);
      auto eh = su.law->Restitution(p, su.body, u + hu);
      if (!el || !eh) return false;
      const double de_du = (*eh - *el) / (2 * hu);
      for (size_t j = 0; j <= na; ++j) {
        const double dp =
            j < na ? u * de_dp[static_cast<size_t>(su.free[static_cast<size_t>(active_[j])])] *
                         su.scale[static_cast<size_t>(active_[j])]
                   : 0.0;
        dw[j] = (e + u * de_du) * du[j] + dp;
      }
      const double dT = flight_.FlightTimeDerivative(e * u);
      const double dA = flight_.ArrivalSpeedDerivative(e * u);
      // The simulator's intervals include the contact duration t_c(p, v_in) (closed form
      // where the law has one; differenced, as closed forms are noise-free).
      std::vector<double> dtc(na + 1, 0.0);
      if (auto tc = su.law->ContactTime(p, su.body, u)) {
        auto th = su.law->ContactTime(p, su.body, u + hu);
        auto tl = su.law->ContactTime(p, su.body, u - hu);
        const double dtc_du = th && tl ? (*th - *tl) / (2 * hu) : 0.0;
        for (size_t j = 0; j <= na; ++j) {
          dtc[j] = dtc_du * du[j];
          if (j == na) continue;
          const size_t a = static_cast<size_t>(active_[j]);
          const size_t i = static_cast<size_t>(su.free[a]);
          const double x = p[i], hx = 1e-6 * std::max(std::abs(x), su.typical[i]);
          std::vector<double> q = p;
          q[i] = std::min(x + hx, su.specs()[i].upper);
          const double th2 = su.law->ContactTime(q, su.body, u).value_or(*tc);
          const double xh = q[i];
          q[i] = std::max(x - hx, su.specs()[i].lower);
          const double tl2 = su.law->ContactTime(q, su.body, u).value_or(*tc);
          if (xh > q[i]) dtc[j] += (th2 - tl2) / (xh - q[i]) * su.scale[a];
        }
      }
      for (size_t j = 0; j <= na; ++j) {
        ds[j] += dT * dw[j] + dtc[j];
        du[j] = dA * dw[j];
      }
      if (!std::isfinite(dT) || !std::isfinite(dA)) return false;
    }
    return true;
  }

  const FitProblem& fp_;
  Scene scene_;
  FlightModel flight_;
  std::vector<int> active_;
  bool analytic_;
  double rel_step_;
  SimulatorOptions sim_;
  std::vector<double> times_s_, sigmas_s_;
  std::vector<int> sim_index_;
  size_t n_sim_ = 0;
};

// All impacts of one recording, whitened by the Cholesky factor of C.
// Blocks: the active law parameters (scaled), then v0 (when free), then t0.
class TrajectoryCost final : public ceres::CostFunction {
 public:
  TrajectoryCost(const FitProblem& fp, const TrajectoryModel& model, std::vector<double> base,
                 std::optional<double> fixed_v0, Eigen::MatrixXd chol_lower,
                 std::atomic<long>* sims)
      : fp_(fp),
        model_(model),
        base_(std::move(base)),
        fixed_v0_(fixed_v0),
        l_(std::move(chol_lower)),
        sims_(sims) {
    set_num_residuals(model.size());
    mutable_parameter_block_sizes()->push_back(static_cast<int>(model.active().size()));
    if (!fixed_v0) mutable_parameter_block_sizes()->push_back(1);
    mutable_parameter_block_sizes()->push_back(1);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const LawSetup& su = fp_.setup;
    const std::vector<int>& active = model_.active();
    const size_t na = active.size();
    std::vector<double> p = base_;
    for (size_t j = 0; j < na; ++j) {
      const size_t a = static_cast<size_t>(active[j]);
      p[static_cast<size_t>(su.free[a])] = su.scale[a] * parameters[0][j];
    }
    const double v0 = fixed_v0_ ? *fixed_v0_ : parameters[1][0];
    const double t0 = parameters[fixed_v0_ ? 1 : 2][0];
    const bool want = jacobians != nullptr;
    std::vector<double> key = p;
    key.push_back(v0);
    auto s = last_.Find(key, want);
    if (!s) {
      s = model_.Times(p, v0, want, sims_);
      if (!s) return false;
      last_.Store(std::move(key), want, *s);
    }
    const int n = model_.size();
    Eigen::VectorXd r(n);
    for (int k = 0; k < n; ++k) r(k) = t0 + s->times_s[model_.sim_index(k)] - model_.time(k);
    const auto tri = l_.triangularView<Eigen::Lower>();
    Eigen::Map<Eigen::VectorXd>(residuals, n) = tri.solve(r);
    if (!want) return true;
    Eigen::MatrixXd j(n, static_cast<Eigen::Index>(na + 2));
    for (int k = 0; k < n; ++k) {
      const size_t row = model_.sim_index(k) * (na + 1);
      for (size_t c = 0; c <= na; ++c) j(k, static_cast<Eigen::Index>(c)) = s->jac[row + c];
      j(k, static_cast<Eigen::Index>(na + 1)) = 1.0;
    }
    const Eigen::MatrixXd jw = tri.solve(j);
    using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
    if (jacobians[0])
      Eigen::Map<RowMajor>(jacobians[0], n, static_cast<Eigen::Index>(na)) =
          jw.leftCols(static_cast<Eigen::Index>(na));
    int b = 1;
    if (!fixed_v0_) {
      if (jacobians[b])
        Eigen::Map<Eigen::VectorXd>(jacobians[b], n) = jw.col(static_cast<Eigen::Index>(na));
      ++b;
    }
    if (jacobians[b])
      Eigen::Map<Eigen::VectorXd>(jacobians[b], n) = jw.col(static_cast<Eigen::Index>(na + 1));
    return true;
  }

 private:
  const FitProblem& fp_;
  const TrajectoryModel& model_;
  const std::vector<double> base_;
  const std::optional<double> fixed_v0_;
  const Eigen::MatrixXd l_;
  std::atomic<long>* sims_;
  LastEvaluation<SimPoint> last_;  // the simulated times (and Jacobian) at p, v0
};

// The drop's first impact speed as a measurement of v0: (v0 - v_drop) / sigma_v.
class DropPriorCost final : public ceres::SizedCostFunction<1, 1> {
 public:
  DropPriorCost(double v_drop, double sigma) : v_(v_drop), sigma_(sigma) {}
  bool Evaluate(double const* const* x, double* r, double** j) const override {
    r[0] = (x[0][0] - v_) / sigma_;
    if (j && j[0]) j[0][0] = 1.0 / sigma_;
    return true;
  }

 private:
  const double v_, sigma_;
};

struct RecordingSetup {
  std::unique_ptr<TrajectoryModel> model;
  double v0 = 0.0, t0 = 0.0;
  double v0_lower = 1e-6, t0_lower = 0.0, t0_upper = 0.0;
  std::optional<double> fixed_v0;
  double v_drop = 0.0, v_drop_sigma = 0.0;  // prior (sigma > 0)
};

RecordingSetup SetUpRecording(const FitProblem& fp, size_t r, const std::vector<double>& p,
                              const std::vector<int>& active, std::atomic<long>* sims) {
  const RecordingData& rec = fp.recordings[r];
  RecordingSetup rs;
  rs.model = std::make_unique<TrajectoryModel>(fp, rec, active);
  const auto& imp = rec.sequence.impacts;
  const FlightModel flight = FlightModel::FromScene(fp.scene);
  const double interval = imp[1].time_s - imp[0].time_s;
  const double vout = flight.LaunchSpeedForFlightTime(interval);
  // Physical constraints: e0 <= 1 (v0 at least the first rebound speed), and the simulated
  // first impact is the first detected one (t0 within half the first interval of it).
  rs.v0_lower = std::isfinite(vout) && vout > 0.0 ? vout : 1e-6;
  rs.t0 = imp.front().time_s;
  rs.t0_lower = rs.t0 - 0.5 * interval;
  rs.t0_upper = rs.t0 + 0.5 * interval;
  const Bounce& b0 = rec.analysis.bounces.front();
  if (rec.drop_used) {
    rs.v_drop = b0.v_in_m_s;
    rs.v_drop_sigma = b0.v_in_sigma_m_s;
    if (!(rs.v_drop_sigma > 0.0)) rs.fixed_v0 = rs.v_drop;
  }
  if (rs.fixed_v0) {
    rs.v0 = *rs.fixed_v0;
  } else if (rec.drop_used) {
    rs.v0 = std::max(rs.v_drop, rs.v0_lower);
  } else {
    // v_out,0 from the first interval, divided by the law's own e at that speed.
    double e0 = fp.e_median > 0.05 && fp.e_median < 1.0 ? fp.e_median : 0.8;
    try {
      const double e_law = ModelRestitution(fp.setup, p, vout / e0, fp.g, fp.sim, sims);
      if (e_law > 0.05 && e_law < 1.0) e0 = e_law;
    } catch (const Error&) {
    }
    rs.v0 = vout / e0;
  }
  const auto& o = fp.options;
  if (!rs.fixed_v0 && o.start_impact_speeds_m_s.size() == fp.recordings.size() &&
      o.start_impact_speeds_m_s[r] > 0.0) {
    rs.v0 = o.start_impact_speeds_m_s[r];
  }
  if (o.start_time_origins_s.size() == fp.recordings.size() &&
      std::isfinite(o.start_time_origins_s[r])) {
    rs.t0 = std::clamp(o.start_time_origins_s[r], rs.t0_lower, rs.t0_upper);
  }
  if (!rs.fixed_v0) rs.v0 = std::max(rs.v0, rs.v0_lower);
  return rs;
}

// Whitening factor of one recording: C = diag(sigma_t^2) + sigma_s^2 G G^T.
Eigen::MatrixXd Whitening(const TrajectoryModel& m, const Eigen::MatrixXd& g, double sigma_s) {
  const int n = m.size();
  Eigen::MatrixXd c = sigma_s * sigma_s * g * g.transpose();
  for (int k = 0; k < n; ++k) c(k, k) += m.sigma(k) * m.sigma(k);
  Eigen::LLT<Eigen::MatrixXd> llt(c);
  return llt.matrixL();
}

// The solution in raw form (model - measured, s) for the uncertainty stage and the scatter
// estimate: rows of every recording's impacts, then the drop priors; columns u (active), then
// per recording v0 (when free) and t0.
bool AssembleRaw(const FitProblem& fp, const std::vector<RecordingSetup>& recs,
                 const std::vector<Eigen::MatrixXd>& g, const std::vector<double>& p,
                 const std::vector<int>& active, Solution* out, std::atomic<long>* sims) {
  Solution& sol = *out;
  const LawSetup& su = fp.setup;
  const size_t nr = recs.size();
  sol.v0.clear(), sol.t0.clear(), sol.v0_free.clear(), sol.simulated_impacts.clear();
  sol.v_in.clear();
  const size_t na = active.size();
  int rows = 0, cols = static_cast<int>(na), gcols = 0;
  for (size_t r = 0; r < nr; ++r) {
    rows += recs[r].model->size() + (recs[r].v_drop_sigma > 0.0 && !recs[r].fixed_v0 ? 1 : 0);
    cols += (recs[r].fixed_v0 ? 0 : 1) + 1;
    gcols += static_cast<int>(g[r].cols());
  }
  sol.residuals = Eigen::VectorXd::Zero(rows);
  sol.jacobian = Eigen::MatrixXd::Zero(rows, cols);
  sol.timing_cov = Eigen::MatrixXd::Zero(rows, rows);
  sol.design = Eigen::MatrixXd::Zero(rows, std::max(gcols, 1));
  int row = 0, col = static_cast<int>(na), gc = 0;
  for (size_t r = 0; r < nr; ++r) {
    const RecordingSetup& rs = recs[r];
    const TrajectoryModel& m = *rs.model;
    const auto s = m.Times(p, rs.v0, true, sims);
    if (!s) {
      sol.failure = "law " + su.law->Name() + ": the simulator fails at the fitted values";
      return false;
    }
    if (s->simulated < static_cast<int>(m.sim_index(m.size() - 1)) + 1 &&
        s->stop == StopReason::kStuck) {
      sol.failure = "law " + su.law->Name() + " sticks at the best fit for " +
                    fp.recordings[r].name + " (no rebound after simulated impact " +
                    std::to_string(s->simulated) + "): it cannot describe this recording";
      return false;
    }
    const int v0_col = rs.fixed_v0 ? -1 : col++;
    const int t0_col = col++;
    for (int k = 0; k < m.size(); ++k, ++row) {
      sol.residuals(row) = rs.t0 + s->times_s[m.sim_index(k)] - m.time(k);
      const size_t jr = m.sim_index(k) * (na + 1);
      for (size_t c = 0; c < na; ++c)
        sol.jacobian(row, static_cast<Eigen::Index>(c)) = s->jac[jr + c];
      if (v0_col >= 0) sol.jacobian(row, v0_col) = s->jac[jr + na];
      sol.jacobian(row, t0_col) = 1.0;
      sol.timing_cov(row, row) = m.sigma(k) * m.sigma(k);
      sol.design.block(row, gc, 1, g[r].cols()) = g[r].row(k);
    }
    if (rs.v_drop_sigma > 0.0 && !rs.fixed_v0) {
      sol.residuals(row) = rs.v0 - rs.v_drop;
      sol.jacobian(row, v0_col) = 1.0;
      sol.timing_cov(row, row) = rs.v_drop_sigma * rs.v_drop_sigma;
      ++row;
    }
    gc += static_cast<int>(g[r].cols());
    sol.v0.push_back(rs.v0);
    sol.t0.push_back(rs.t0);
    sol.v0_free.push_back(!rs.fixed_v0);
    sol.simulated_impacts.push_back(s->simulated);
    sol.v_in.push_back(s->v_in_m_s);
  }
  return true;
}

// One Ceres solve of the trajectory at fixed covariance (scatter design g, sigma_s): the law's
// active parameters (scaled, u), and per recording v0 (when free, with the drop's prior) and t0
// within their physical bounds. Updates u, p and the nuisances; false when the solver fails.
bool SolvePass(const FitProblem& fp, const std::vector<Eigen::MatrixXd>& g, double sigma_s,
               const std::vector<int>& active, std::vector<RecordingSetup>* recordings,
               std::vector<double>* u_ptr, std::vector<double>* p_ptr, Solution* sol_ptr,
               std::atomic<long>* sims) {
  std::vector<RecordingSetup>& recs = *recordings;
  std::vector<double>& u = *u_ptr;
  std::vector<double>& p = *p_ptr;
  Solution& sol = *sol_ptr;
  const LawSetup& su = fp.setup;
  const size_t nr = recs.size();
  ceres::Problem problem;
  for (size_t r = 0; r < nr; ++r) {
    RecordingSetup& rs = recs[r];
    std::vector<double*> blocks = {u.data()};
    if (!rs.fixed_v0) blocks.push_back(&rs.v0);
    blocks.push_back(&rs.t0);
    problem.AddResidualBlock(new TrajectoryCost(fp, *rs.model, p, rs.fixed_v0,
                                                Whitening(*rs.model, g[r], sigma_s), sims),
                             nullptr, blocks);
    if (!rs.fixed_v0) {
      if (rs.v_drop_sigma > 0.0) {
        problem.AddResidualBlock(new DropPriorCost(rs.v_drop, rs.v_drop_sigma), nullptr, &rs.v0);
      }
      problem.SetParameterLowerBound(&rs.v0, 0, rs.v0_lower);
      problem.SetParameterUpperBound(&rs.v0, 0, 1e3);
    }
    problem.SetParameterLowerBound(&rs.t0, 0, rs.t0_lower);
    problem.SetParameterUpperBound(&rs.t0, 0, rs.t0_upper);
  }
  if (!u.empty()) SetLawBounds(su, active, u.data(), &problem);
  const ceres::Solver::Options so = SolverOptions(fp.options);
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  sol.iterations += static_cast<int>(summary.iterations.size());
  if (!summary.IsSolutionUsable()) {
    sol.failure = "law " + su.law->Name() + ": the solver failed: " + summary.message;
    return false;
  }
  sol.iteration_limit = summary.termination_type == ceres::NO_CONVERGENCE;
  if (sol.iteration_limit) {
    sol.limit_note =
        "the solver reached max_iterations = " + std::to_string(fp.options.max_iterations) +
        " before converging";
  }
  for (size_t j = 0; j < active.size(); ++j) {
    const size_t a = static_cast<size_t>(active[j]);
    p[static_cast<size_t>(su.free[a])] = su.scale[a] * u[j];
  }
  sol.cost = summary.final_cost;
  return true;
}

}  // namespace

Solution SolveTrajectory(const FitProblem& fp, const std::vector<double>& start,
                         const std::vector<bool>& held, double sigma_start,
                         std::atomic<long>* sims) {
  double sigma_s = sigma_start;
  Solution sol;
  const LawSetup& su = fp.setup;
  sol.held = held.empty() ? std::vector<bool>(su.free.size(), false) : held;
  std::vector<int> active;
  for (size_t j = 0; j < su.free.size(); ++j) {
    if (!sol.held[j]) active.push_back(static_cast<int>(j));
  }
  const size_t nr = fp.recordings.size();
  std::vector<RecordingSetup> recs;
  for (size_t r = 0; r < nr; ++r) recs.push_back(SetUpRecording(fp, r, start, active, sims));
  std::vector<double> u;
  for (int a : active)
    u.push_back(start[static_cast<size_t>(su.free[static_cast<size_t>(a)])] /
                su.scale[static_cast<size_t>(a)]);
  std::vector<double> p = start;
  std::vector<Eigen::MatrixXd> g(nr);
  for (int pass = 0; pass < 2; ++pass) {
    // The scatter design at the current point (start, then the first optimum).
    for (size_t r = 0; r < nr; ++r) {
      const auto s = recs[r].model->Times(p, recs[r].v0, false, sims);
      if (!s) {
        sol.failure = "law " + su.law->Name() + ": the simulator fails at the " +
                      (pass == 0 ? "start" : "fitted") + " values for " + fp.recordings[r].name;
        return sol;
      }
      if (s->simulated < 2 && s->stop == StopReason::kStuck) {
        sol.failure = "law " + su.law->Name() + " sticks at the " +
                      (pass == 0 ? "start" : "fitted") +
                      " values (no rebound at the first impact) for " + fp.recordings[r].name;
        return sol;
      }
      g[r] = recs[r].model->ScatterDesign(*s, p, sims);
    }
    if (pass == 1 && fp.options.estimate_scatter) {
      // sigma_s from the impact times themselves (the same REML criterion, G propagating it),
      // starting from the restitution fit's value.
      Solution raw;
      if (AssembleRaw(fp, recs, g, p, active, &raw, sims)) {
        const ScatterFit f =
            ScatterProblem(raw.residuals, raw.jacobian, raw.timing_cov, raw.design).Fit();
        if (f.ok) {
          sigma_s = f.sigma;
          sol.scatter.sigma_sigma = f.sigma_sigma;
          sol.scatter.sigma_at_zero = f.sigma_at_zero;
        }
      }
    }
    const double cost = sol.cost;
    if (!SolvePass(fp, g, sigma_s, active, &recs, &u, &p, &sol, sims)) return sol;
    if (pass == 1) sol.cost = cost;  // the first pass's, at the given sigma_s: compares starts
  }
  for (size_t r = 0; r < nr; ++r) {
    const auto pt = recs[r].model->Times(p, recs[r].v0, false, sims);
    if (pt) g[r] = recs[r].model->ScatterDesign(*pt, p, sims);
  }
  if (!AssembleRaw(fp, recs, g, p, active, &sol, sims)) return sol;
  const ScatterProblem::Evaluation ev =
      ScatterProblem(sol.residuals, sol.jacobian, sol.timing_cov, sol.design).At(sigma_s);
  if (!ev.ok) {
    sol.failure = "law " + su.law->Name() + ": the fit's information matrix is singular";
    return sol;
  }
  sol.scatter.ok = true;
  sol.scatter.sigma = sigma_s;
  sol.scatter.covariance = ev.covariance;
  sol.scatter.chi2 = ev.chi2;
  sol.scatter.criterion = ev.criterion;
  const double rows = static_cast<double>(sol.residuals.size());
  sol.scatter.neg_log_likelihood = 0.5 * (rows * std::log(2.0 * M_PI) + ev.log_det_c + ev.chi2);
  int col = static_cast<int>(active.size());
  sol.v0_sigma.clear();
  sol.t0_sigma.clear();
  for (size_t r = 0; r < nr; ++r) {
    const double nan = std::numeric_limits<double>::quiet_NaN();
    sol.v0_sigma.push_back(recs[r].fixed_v0 ? nan
                                            : std::sqrt(std::max(ev.covariance(col, col), 0.0)));
    if (!recs[r].fixed_v0) ++col;
    sol.t0_sigma.push_back(std::sqrt(std::max(ev.covariance(col, col), 0.0)));
    ++col;
  }
  sol.p = p;
  sol.ok = true;
  return sol;
}

}  // namespace bouncecal::calib
