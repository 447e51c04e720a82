// Calibration: Ceres fits of a contact law to measured impact times or restitution points.
// See include/bouncecal/fit/calibrate.hpp for the model; the layout of this file follows it:
// options -> shared model pieces (law, parameter layout, seeding) -> trajectory model ->
// restitution model -> solve + identifiability + covariance -> reports -> law comparison.
#include "bouncecal/fit/calibrate.hpp"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <sstream>
#include <thread>

#include <ceres/ceres.h>
#include <Eigen/Dense>

#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
// Floors on measurement sigmas: a zero sigma would give an infinite weight.
constexpr double kMinTimeSigmaS = 1e-7;
constexpr double kMinESigma = 1e-6;
// Singular values below this fraction of the largest span the numerical null space
// (sqrt of double precision's ~1e-16 relative noise in J^T J).
constexpr double kNullSpaceRatio = 1e-8;

std::string Fmt(double v, int prec = 6) {
  std::ostringstream os;
  os << std::setprecision(prec) << v;
  return os.str();
}

std::string Join(const std::vector<std::string>& v, const char* sep = ", ") {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) out += (i ? sep : "") + v[i];
  return out;
}

double Median(std::vector<double> v) {
  if (v.empty()) return kNaN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Relative central-difference step for a function whose own noise is ~rtol: the truncation
// error h^2 and the noise error rtol/h balance at h = rtol^(1/3).
double RelativeStep(double rtol) { return std::clamp(std::cbrt(rtol), 1e-6, 1e-2); }

// ---------------------------------------------------------------------------------------------
// The law with its parameter layout: which entries of the full vector are free.
struct LawSetup {
  std::unique_ptr<ContactLaw> law;
  ContactBody body;
  std::vector<double> start;    // full parameter vector (start and held values)
  std::vector<int> free;        // indices into start of the free parameters
  std::vector<double> typical;  // magnitude per full index, for steps and scaling
  // Ceres sees each free law parameter scaled by its typical magnitude (x = scale * u), so
  // stiffnesses of 1e7 and dimensionless dampings of 0.4 give a well-conditioned J^T J (and a
  // covariance Ceres can compute).
  std::vector<double> scale;
  bool has_gradient = false;  // RestitutionGradient works
  bool has_closed_e = false;  // Restitution works

  std::vector<double> Full(const double* const* free_values) const {
    std::vector<double> p = start;
    for (size_t i = 0; i < free.size(); ++i) p[free[i]] = scale[i] * *free_values[i];
    return p;
  }
};

// Restitution at one speed: closed form when the law has it, one simulated contact otherwise.
double ModelRestitution(const LawSetup& s, std::span<const double> p, double v_m_s, double g,
                        const SimulatorOptions& sim, long* simulations) {
  if (s.has_closed_e) {
    if (auto e = s.law->Restitution(p, s.body, v_m_s)) return *e;
  }
  if (simulations) ++*simulations;
  return SimulateContact(*s.law, p, s.body, v_m_s, g, sim).restitution;
}

// Central (one-sided at a bound) difference of f with respect to full parameter index i.
template <typename F>
double ParamDerivative(const LawSetup& s, std::vector<double> p, int i, double rel_step, F&& f) {
  const ParameterSpec& spec = s.law->Parameters()[static_cast<size_t>(i)];
  const double x = p[static_cast<size_t>(i)];
  const double h = rel_step * std::max(std::abs(x), s.typical[static_cast<size_t>(i)]);
  double lo = x - h, hi = x + h;
  if (hi > spec.upper) hi = x;
  if (lo < spec.lower) lo = x;
  if (hi <= lo) return 0.0;
  p[static_cast<size_t>(i)] = hi;
  const double fh = f(p);
  p[static_cast<size_t>(i)] = lo;
  const double fl = f(p);
  return (fh - fl) / (hi - lo);
}

// ---------------------------------------------------------------------------------------------
// Trajectory model of one recording: simulated impact times s_k(theta, v0), cached.
struct SimPoint {
  std::vector<double> times_s;   // N entries (missing impacts at the last one)
  std::vector<double> v_in_m_s;  // simulated arrival speeds (M entries)
  int simulated = 0;             // M
  StopReason stop = StopReason::kAtRest;
  bool has_jacobian = false;
  // ds_k/d(free law param j) at [k * (nfree + 1) + j]; column nfree is d/dv0.
  std::vector<double> jac;
};

class RecordingModel {
 public:
  RecordingModel(const LawSetup& setup, const Scene& scene, const CalibrationInput& rec,
                 const CalibrationOptions& options, bool analytic)
      : setup_(setup),
        scene_(scene),
        flight_(FlightModel::FromScene(scene)),
        analytic_(analytic),
        rel_step_(RelativeStep(options.rel_tolerance)) {
    for (const Impact& i : rec.sequence.impacts) {
      times_s_.push_back(i.time_s);
      sigmas_s_.push_back(std::max(i.sigma_s, kMinTimeSigmaS));
    }
    // Impacts the detector flagged as missed (between measured k and k+1) still happen in
    // the simulation: measured impact k is simulated impact k + (misses before it).
    for (size_t k = 0; k < times_s_.size(); ++k) {
      int before = 0;
      for (int m : rec.sequence.missed_after) before += m >= 0 && static_cast<size_t>(m) < k;
      sim_index_.push_back(static_cast<int>(k) + before);
    }
    n_sim_ = static_cast<size_t>(sim_index_.back()) + 1;
    sim_.rel_tolerance = options.rel_tolerance;
    sim_.abs_tolerance = std::min(1e-12, options.rel_tolerance * 1e-3);
    // Simulate exactly as many impacts as were measured; let the ball bounce down to tiny
    // speeds so a missing impact means the law really stopped the ball.
    scene_.limits.max_impacts = static_cast<int>(n_sim_);
    scene_.limits.rest_speed_m_s = std::min(scene_.limits.rest_speed_m_s, 1e-6);
    scene_.limits.horizon_s = 3.0 * (times_s_.back() - times_s_.front()) + 2.0;
    scene_.drop.first_impact_time_s = 0.0;
  }

  const LawSetup& setup() const { return setup_; }
  int size() const { return static_cast<int>(times_s_.size()); }
  // Simulated impacts needed, and the simulated index of measured impact k.
  int sim_size() const { return static_cast<int>(n_sim_); }
  size_t sim_index(int k) const { return static_cast<size_t>(sim_index_[static_cast<size_t>(k)]); }
  double time(int k) const { return times_s_[static_cast<size_t>(k)]; }
  double sigma(int k) const { return sigmas_s_[static_cast<size_t>(k)]; }
  long simulations() const { return simulations_; }

  // Simulated times at (p, v0); with the Jacobian when asked. nullptr if the simulator fails.
  const SimPoint* Get(const std::vector<double>& p, double v0, bool jacobian) {
    if (!(have_ && p == key_p_ && v0 == key_v0_)) {
      auto s = SimulateTimes(p, v0);
      if (!s) return nullptr;
      point_ = std::move(*s);
      key_p_ = p;
      key_v0_ = v0;
      have_ = true;
    }
    if (jacobian && !point_.has_jacobian) {
      if (!ComputeJacobian(p, v0)) return nullptr;
    }
    return &point_;
  }

 private:
  std::optional<SimPoint> SimulateTimes(const std::vector<double>& p, double v0) {
    if (!(v0 > 0.0) || !std::isfinite(v0)) return std::nullopt;
    std::string err;
    if (!setup_.law->IsValid(p, setup_.body, &err)) return std::nullopt;
    Scene s = scene_;
    s.drop.height_m.reset();
    s.drop.impact_speed_m_s = v0;
    Simulation sim;
    try {
      ++simulations_;
      sim = Simulate(s, *setup_.law, p, sim_);
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
    }
    for (int k = 0; k < out.simulated; ++k) out.v_in_m_s.push_back(sim.impacts[k].v_in_m_s);
    for (double t : out.times_s) {
      if (!std::isfinite(t)) return std::nullopt;
    }
    return out;
  }

  bool ComputeJacobian(const std::vector<double>& p, double v0) {
    const size_t nf = setup_.free.size();
    const size_t n = n_sim_;
    point_.jac.assign(n * (nf + 1), 0.0);
    // Analytic columns for the damping parameters and v0; stiffness-like parameters change
    // impact times mostly through contact durations and gravity during slow contacts, which
    // the closed-form chain does not see: those columns are differenced on the simulator.
    const bool analytic = analytic_ && AnalyticJacobian(p);
    if (!analytic) point_.jac.assign(n * (nf + 1), 0.0);
    // Central differences on whole simulated sequences.
    auto column = [&](size_t col, const std::vector<double>& ph, double v0h,
                      const std::vector<double>& pl, double v0l, double dx) {
      auto hi = SimulateTimes(ph, v0h);
      auto lo = SimulateTimes(pl, v0l);
      if (!hi || !lo) return false;
      for (size_t k = 0; k < n; ++k) {
        point_.jac[k * (nf + 1) + col] = (hi->times_s[k] - lo->times_s[k]) / dx;
      }
      return true;
    };
    for (size_t j = 0; j < nf; ++j) {
      const int i = setup_.free[j];
      const ParameterSpec& spec = setup_.law->Parameters()[static_cast<size_t>(i)];
      if (analytic && spec.damping) continue;
      const double x = p[static_cast<size_t>(i)];
      const double h = rel_step_ * std::max(std::abs(x), setup_.typical[static_cast<size_t>(i)]);
      double lo = x - h, hi = x + h;
      if (hi > spec.upper) hi = x;
      if (lo < spec.lower) lo = x;
      std::vector<double> ph = p, pl = p;
      ph[static_cast<size_t>(i)] = hi;
      pl[static_cast<size_t>(i)] = lo;
      if (hi > lo && !column(j, ph, v0, pl, v0, hi - lo)) return false;
    }
    const double h = rel_step_ * v0;
    if (!analytic && !column(nf, p, v0 + h, p, v0 - h, 2 * h)) return false;
    point_.has_jacobian = true;
    return true;
  }

  // d s_k / d(theta, v0) by the chain rule through the law's closed-form e(v) and the exact
  // flight formulas (PHYSICS.md §2): v_out,k = e(v_in,k) v_in,k, s_{k+1} = s_k + T(v_out,k),
  // v_in,k+1 = A(v_out,k). Exact for laws whose contacts the simulator solves in closed form;
  // for integrated laws it neglects gravity during the ~us contact (a small Jacobian error
  // only: residuals always come from the simulator, so the optimum is unaffected to first order).
  bool AnalyticJacobian(const std::vector<double>& p) {
    const size_t nf = setup_.free.size();
    const size_t nall = p.size();
    const size_t n = n_sim_;
    std::vector<double> du(nf + 1, 0.0), ds(nf + 1, 0.0), dw(nf + 1, 0.0);
    std::vector<double> de_dp(nall, 0.0);
    du[nf] = 1.0;  // d v_in,0 / d v0
    for (size_t k = 0; k < n; ++k) {
      for (size_t j = 0; j <= nf; ++j) point_.jac[k * (nf + 1) + j] = ds[j];
      if (k + 1 >= n) break;
      if (static_cast<int>(k) + 1 >= point_.simulated) {
        // Missing impacts repeat the last simulated time, and so its derivative.
        continue;
      }
      const double u = point_.v_in_m_s[k];
      double e = 0.0;
      if (!setup_.law->RestitutionGradient(p, setup_.body, u, &e, de_dp.data())) return false;
      const double hu = 1e-6 * u;
      auto el = setup_.law->Restitution(p, setup_.body, u - hu);
      auto eh = setup_.law->Restitution(p, setup_.body, u + hu);
      if (!el || !eh) return false;
      const double de_du = (*eh - *el) / (2 * hu);
      const double w = e * u;
      for (size_t j = 0; j <= nf; ++j) {
        dw[j] = (e + u * de_du) * du[j] + (j < nf ? u * de_dp[setup_.free[j]] : 0.0);
      }
      const double dT = flight_.FlightTimeDerivative(w);
      const double dA = flight_.ArrivalSpeedDerivative(w);
      // The simulator's intervals include the contact duration t_c(p, v_in) (closed form
      // where the law has one; differenced, as closed forms are noise-free).
      std::vector<double> dtc(nf + 1, 0.0);
      if (auto tc = setup_.law->ContactTime(p, setup_.body, u)) {
        auto th = setup_.law->ContactTime(p, setup_.body, u + hu);
        auto tl = setup_.law->ContactTime(p, setup_.body, u - hu);
        const double dtc_du = th && tl ? (*th - *tl) / (2 * hu) : 0.0;
        for (size_t j = 0; j <= nf; ++j) {
          dtc[j] = dtc_du * du[j];
          if (j < nf) {
            auto f = [&](const std::vector<double>& q) {
              return setup_.law->ContactTime(q, setup_.body, u).value_or(*tc);
            };
            dtc[j] += ParamDerivative(setup_, p, setup_.free[j], 1e-6, f);
          }
        }
      }
      for (size_t j = 0; j <= nf; ++j) {
        ds[j] += dT * dw[j] + dtc[j];
        du[j] = dA * dw[j];
      }
      if (!std::isfinite(dT) || !std::isfinite(dA)) return false;
    }
    return true;
  }

  const LawSetup& setup_;
  Scene scene_;
  FlightModel flight_;
  bool analytic_;
  double rel_step_;
  SimulatorOptions sim_;
  std::vector<double> times_s_, sigmas_s_;
  std::vector<int> sim_index_;
  size_t n_sim_ = 0;
  long simulations_ = 0;
  bool have_ = false;
  std::vector<double> key_p_;
  double key_v0_ = 0.0;
  SimPoint point_;
};

// One measured impact: r = (t0 + s_k(theta, v0) - t_k) / sigma_k.
// Blocks: the free law parameters (size 1 each), then v0 (when free), then t0.
class ImpactTimeCost : public ceres::CostFunction {
 public:
  ImpactTimeCost(RecordingModel* model, int k, size_t nfree, std::optional<double> fixed_v0)
      : model_(model), k_(k), nfree_(nfree), fixed_v0_(fixed_v0) {
    set_num_residuals(1);
    const size_t blocks = nfree + (fixed_v0 ? 0 : 1) + 1;
    for (size_t i = 0; i < blocks; ++i) mutable_parameter_block_sizes()->push_back(1);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    std::vector<double> p = model_->setup().start;
    const LawSetup& su = model_->setup();
    for (size_t j = 0; j < nfree_; ++j) p[su.free[j]] = su.scale[j] * parameters[j][0];
    const double v0 = fixed_v0_ ? *fixed_v0_ : parameters[nfree_][0];
    const double t0 = parameters[nfree_ + (fixed_v0_ ? 0 : 1)][0];
    bool want_law_jac = false;
    if (jacobians) {
      for (size_t j = 0; j < nfree_ + (fixed_v0_ ? 0 : 1); ++j) {
        if (jacobians[j]) want_law_jac = true;
      }
    }
    const SimPoint* s = model_->Get(p, v0, want_law_jac);
    if (!s) return false;
    const double sigma = model_->sigma(k_);
    residuals[0] = (t0 + s->times_s[model_->sim_index(k_)] - model_->time(k_)) / sigma;
    if (jacobians) {
      const size_t row = model_->sim_index(k_) * (nfree_ + 1);
      for (size_t j = 0; j < nfree_; ++j) {
        if (jacobians[j]) jacobians[j][0] = s->jac[row + j] / sigma * su.scale[j];
      }
      size_t b = nfree_;
      if (!fixed_v0_) {
        if (jacobians[b]) jacobians[b][0] = s->jac[row + nfree_] / sigma;
        ++b;
      }
      if (jacobians[b]) jacobians[b][0] = 1.0 / sigma;
    }
    return std::isfinite(residuals[0]);
  }

 private:
  RecordingModel* model_;
  int k_;
  size_t nfree_;
  std::optional<double> fixed_v0_;
};

// ---------------------------------------------------------------------------------------------
// Restitution model: r = (e_model(v_in) - e) / e_sigma per measured bounce.
struct EPoint {
  double v_m_s, e, sigma;
  std::string recording;
  int index;
};

class RestitutionCost : public ceres::CostFunction {
 public:
  RestitutionCost(const LawSetup& setup, EPoint pt, double g, const SimulatorOptions& sim,
                  bool analytic, double rel_step, long* simulations)
      : setup_(setup),
        pt_(std::move(pt)),
        g_(g),
        sim_(sim),
        analytic_(analytic),
        rel_step_(rel_step),
        simulations_(simulations) {
    set_num_residuals(1);
    for (size_t i = 0; i < setup.free.size(); ++i) mutable_parameter_block_sizes()->push_back(1);
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const std::vector<double> p = setup_.Full(parameters);
    std::string err;
    if (!setup_.law->IsValid(p, setup_.body, &err)) return false;
    try {
      if (analytic_) {
        std::vector<double> de(p.size(), 0.0);
        double e = 0.0;
        if (!setup_.law->RestitutionGradient(p, setup_.body, pt_.v_m_s, &e, de.data())) {
          return false;
        }
        residuals[0] = (e - pt_.e) / pt_.sigma;
        if (jacobians) {
          for (size_t j = 0; j < setup_.free.size(); ++j) {
            if (jacobians[j]) jacobians[j][0] = de[setup_.free[j]] / pt_.sigma * setup_.scale[j];
          }
        }
        return std::isfinite(residuals[0]);
      }
      auto f = [&](const std::vector<double>& q) {
        return ModelRestitution(setup_, q, pt_.v_m_s, g_, sim_, simulations_);
      };
      residuals[0] = (f(p) - pt_.e) / pt_.sigma;
      if (jacobians) {
        // Closed forms are noise-free: a small step; simulated contacts: rtol^(1/3).
        const double step = setup_.has_closed_e ? 1e-6 : rel_step_;
        for (size_t j = 0; j < setup_.free.size(); ++j) {
          if (!jacobians[j]) continue;
          jacobians[j][0] =
              ParamDerivative(setup_, p, setup_.free[j], step, f) / pt_.sigma * setup_.scale[j];
          if (!std::isfinite(jacobians[j][0])) return false;
        }
      }
    } catch (const Error&) {
      return false;
    }
    return std::isfinite(residuals[0]);
  }

 private:
  const LawSetup& setup_;
  EPoint pt_;
  double g_;
  SimulatorOptions sim_;
  bool analytic_;
  double rel_step_;
  long* simulations_;
};

// ---------------------------------------------------------------------------------------------
LawSetup MakeLawSetup(const Scene& scene, const CalibrationOptions& options) {
  LawSetup s;
  s.law = CreateLaw(scene.law, scene);
  s.body = BodyFromScene(scene);
  s.start = s.law->ParameterValues();
  const auto& specs = s.law->Parameters();
  auto check_name = [&](const std::string& n, const char* what) {
    if (s.law->ParameterIndex(n) < 0) {
      std::vector<std::string> names;
      for (const auto& sp : specs) names.push_back(sp.name);
      throw Error(ErrorCode::kBadParameter, std::string(what) + " '" + n + "': law " +
                                                s.law->Name() + " has no such parameter (" +
                                                Join(names) + ")");
    }
  };
  for (const auto& n : options.free_parameters) check_name(n, "--free");
  for (const auto& n : options.fixed_parameters) check_name(n, "--fix");
  for (size_t i = 0; i < specs.size(); ++i) {
    const auto& sp = specs[i];
    const bool freed = std::find(options.free_parameters.begin(), options.free_parameters.end(),
                                 sp.name) != options.free_parameters.end();
    const bool held = std::find(options.fixed_parameters.begin(), options.fixed_parameters.end(),
                                sp.name) != options.fixed_parameters.end();
    if ((sp.damping || freed) && !held && sp.upper > sp.lower) {
      s.free.push_back(static_cast<int>(i));
    }
    double typ = std::max(std::abs(s.start[i]), std::abs(sp.default_value));
    // Both zero (a damping coefficient defaulting to 0): one unit, or half the upper bound
    // when that is below one. SeedDamping refines it from the seeded value.
    if (!(typ > 0.0)) typ = std::isfinite(sp.upper) && sp.upper < 1.0 ? 0.5 * sp.upper : 1.0;
    s.typical.push_back(typ);
  }
  if (s.free.empty()) {
    throw Error(ErrorCode::kFitFailed,
                "law " + s.law->Name() + ": no free parameter to fit (every parameter is held)");
  }
  std::vector<double> de(s.start.size(), 0.0);
  double e = 0.0;
  const double v_probe = 1.0;
  s.has_closed_e = s.law->Restitution(s.start, s.body, v_probe).has_value();
  s.has_gradient = s.law->RestitutionGradient(s.start, s.body, v_probe, &e, de.data());
  return s;
}

// Seeds the free damping parameter(s) so that e(v_med) = e_med: the law's inverse map, or a
// bracketed search on a single free damping parameter when the law has none.
std::string SeedDamping(LawSetup& s, double e_med, double v_med, double g,
                        const SimulatorOptions& sim, long* simulations) {
  if (!(e_med > 0.0 && e_med < 1.0) || !(v_med > 0.0)) return "no measured e to seed from";
  auto clamp_into_bounds = [&](std::vector<double>& p) {
    const auto& specs = s.law->Parameters();
    for (size_t i = 0; i < p.size(); ++i) {
      p[i] = std::clamp(p[i], specs[i].lower, specs[i].upper);
    }
  };
  if (auto p = s.law->DampingForRestitution(s.start, s.body, e_med, v_med)) {
    std::vector<double> q = s.start;
    for (int i : s.free) {
      if (s.law->Parameters()[static_cast<size_t>(i)].damping) q[i] = (*p)[i];
    }
    clamp_into_bounds(q);
    std::string err;
    if (s.law->IsValid(q, s.body, &err)) {
      s.start = q;
      return "start from the inverse map e -> damping at e = " + Fmt(e_med, 4) +
             ", v = " + Fmt(v_med, 4) + " m/s";
    }
  }
  std::vector<int> damp;
  for (int i : s.free) {
    if (s.law->Parameters()[static_cast<size_t>(i)].damping) damp.push_back(i);
  }
  if (damp.size() != 1) return "start from the scene's values";
  const int i = damp[0];
  const auto& sp = s.law->Parameters()[static_cast<size_t>(i)];
  const double x0 = s.typical[static_cast<size_t>(i)];
  double lo = std::max(sp.lower, x0 * 1e-4), hi = std::min(sp.upper, x0 * 1e4);
  if (!(lo > 0.0) || !(hi > lo)) return "start from the scene's values";
  // Log-spaced scan, then keep the best; e falls as damping grows for every registered law.
  double best = s.start[static_cast<size_t>(i)], best_err = std::numeric_limits<double>::max();
  std::vector<double> q = s.start;
  const int n = 17;
  for (int j = 0; j < n; ++j) {
    q[static_cast<size_t>(i)] = lo * std::pow(hi / lo, j / double(n - 1));
    std::string err;
    if (!s.law->IsValid(q, s.body, &err)) continue;
    double e = kNaN;
    try {
      e = ModelRestitution(s, q, v_med, g, sim, simulations);
    } catch (const Error&) {
      continue;
    }
    if (std::isfinite(e) && std::abs(e - e_med) < best_err) {
      best_err = std::abs(e - e_med);
      best = q[static_cast<size_t>(i)];
    }
  }
  s.start[static_cast<size_t>(i)] = best;
  return "start from a scan of " + sp.name + " at e = " + Fmt(e_med, 4);
}

// Undetermined columns of a weighted Jacobian whose columns are scaled to relative changes:
// those loading on the numerical null space, or whose relative sigma exceeds the threshold.
std::vector<bool> Undetermined(const Eigen::MatrixXd& js, double rel_sigma_max,
                               std::vector<double>* rel_sigma) {
  const Eigen::Index n = js.cols();
  std::vector<bool> bad(static_cast<size_t>(n), false);
  rel_sigma->assign(static_cast<size_t>(n), std::numeric_limits<double>::infinity());
  if (n == 0) return bad;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(js, Eigen::ComputeFullV);
  const Eigen::VectorXd sv = svd.singularValues();
  const double smax = sv.size() ? sv(0) : 0.0;
  Eigen::MatrixXd cov = Eigen::MatrixXd::Zero(n, n);
  for (Eigen::Index i = 0; i < sv.size(); ++i) {
    const Eigen::VectorXd v = svd.matrixV().col(i);
    if (!(smax > 0.0) || sv(i) <= kNullSpaceRatio * smax) {
      for (Eigen::Index j = 0; j < n; ++j) {
        if (std::abs(v(j)) > 0.1) bad[static_cast<size_t>(j)] = true;
      }
    } else {
      cov += v * v.transpose() / (sv(i) * sv(i));
    }
  }
  for (Eigen::Index j = 0; j < n; ++j) {
    if (!bad[static_cast<size_t>(j)]) {
      (*rel_sigma)[static_cast<size_t>(j)] = std::sqrt(std::max(cov(j, j), 0.0));
      if ((*rel_sigma)[static_cast<size_t>(j)] > rel_sigma_max) bad[static_cast<size_t>(j)] = true;
    }
  }
  for (Eigen::Index i = sv.size(); i < n; ++i) {  // more columns than rows
    const Eigen::VectorXd v = svd.matrixV().col(i);
    for (Eigen::Index j = 0; j < n; ++j) {
      if (std::abs(v(j)) > 0.1) bad[static_cast<size_t>(j)] = true;
    }
  }
  return bad;
}

// The data of one calibration, with all its Ceres pieces.
struct FitProblem {
  const CalibrationOptions& options;
  const Scene& scene;
  LawSetup setup;
  bool analytic = false;
  SimulatorOptions sim;
  double g = 9.8;
  std::vector<double> law_values;  // one Ceres block per free law parameter
  // Trajectory
  std::vector<std::unique_ptr<RecordingModel>> models;
  std::vector<double> v0, t0;  // per recording
  std::vector<bool> v0_free;
  // Restitution
  std::vector<EPoint> points;
  long restitution_simulations = 0;

  FitProblem(const CalibrationOptions& o, const Scene& s) : options(o), scene(s) {}

  long Simulations() const {
    long n = restitution_simulations;
    for (const auto& m : models) n += m->simulations();
    return n;
  }
};

// Weighted residuals (model - measured)/sigma and the unweighted ones at the current values.
void Residuals(FitProblem& fp, const std::vector<double>& p, std::vector<double>* weighted,
               std::vector<std::vector<double>>* raw, std::vector<const SimPoint*>* points) {
  weighted->clear();
  raw->clear();
  if (fp.options.strategy == FitStrategy::kTrajectory) {
    for (size_t r = 0; r < fp.models.size(); ++r) {
      RecordingModel& m = *fp.models[r];
      const SimPoint* s = m.Get(p, fp.v0[r], false);
      if (!s) throw Error(ErrorCode::kFitFailed, "the simulator failed at the fitted values");
      if (points) points->push_back(s);
      raw->emplace_back();
      for (int k = 0; k < m.size(); ++k) {
        const double d = fp.t0[r] + s->times_s[m.sim_index(k)] - m.time(k);
        raw->back().push_back(d);
        weighted->push_back(d / m.sigma(k));
      }
    }
  } else {
    std::map<std::string, size_t> index;
    for (const auto& pt : fp.points) {
      const double e =
          ModelRestitution(fp.setup, p, pt.v_m_s, fp.g, fp.sim, &fp.restitution_simulations);
      if (!index.count(pt.recording)) {
        index[pt.recording] = raw->size();
        raw->emplace_back();
      }
      (*raw)[index[pt.recording]].push_back(e - pt.e);
      weighted->push_back((e - pt.e) / pt.sigma);
    }
  }
}

std::vector<double> MeasuredSpeedRange(FitProblem& fp, const std::vector<const SimPoint*>& pts) {
  double lo = std::numeric_limits<double>::max(), hi = 0.0;
  if (fp.options.strategy == FitStrategy::kTrajectory) {
    for (const SimPoint* s : pts) {
      for (double v : s->v_in_m_s) {
        if (v > 0 && std::isfinite(v)) lo = std::min(lo, v), hi = std::max(hi, v);
      }
    }
  } else {
    for (const auto& pt : fp.points) lo = std::min(lo, pt.v_m_s), hi = std::max(hi, pt.v_m_s);
  }
  if (!(hi > 0.0)) return {};
  return {lo, hi};
}

}  // namespace

// =============================================================================================
const char* FitStrategyName(FitStrategy s) {
  return s == FitStrategy::kTrajectory ? "trajectory" : "restitution";
}
const char* DerivativeModeName(DerivativeMode d) {
  return d == DerivativeMode::kAuto ? "auto" : "numeric";
}
const char* RobustLossName(RobustLoss l) {
  switch (l) {
    case RobustLoss::kNone:
      return "none";
    case RobustLoss::kHuber:
      return "huber";
    case RobustLoss::kCauchy:
      return "cauchy";
  }
  return "none";
}
const char* FitOutcomeName(FitOutcome o) {
  switch (o) {
    case FitOutcome::kConverged:
      return "converged";
    case FitOutcome::kNotDeterminable:
      return "not_determinable";
    case FitOutcome::kFailed:
      return "failed";
  }
  return "failed";
}

FitStrategy ParseFitStrategy(const std::string& s) {
  if (s == "trajectory") return FitStrategy::kTrajectory;
  if (s == "restitution") return FitStrategy::kRestitution;
  throw Error(ErrorCode::kUsage, "--strategy '" + s + "': expected trajectory or restitution");
}
DerivativeMode ParseDerivativeMode(const std::string& s) {
  if (s == "auto") return DerivativeMode::kAuto;
  if (s == "numeric") return DerivativeMode::kNumeric;
  throw Error(ErrorCode::kUsage, "--derivatives '" + s + "': expected auto or numeric");
}
RobustLoss ParseRobustLoss(const std::string& s) {
  if (s == "none") return RobustLoss::kNone;
  if (s == "huber") return RobustLoss::kHuber;
  if (s == "cauchy") return RobustLoss::kCauchy;
  throw Error(ErrorCode::kUsage, "--loss '" + s + "': expected none, huber or cauchy");
}

bool CalibrationOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "calibration options: " + m;
    return false;
  };
  if (!(rel_tolerance >= 1e-14 && rel_tolerance <= 1e-2)) {
    return fail("rel_tolerance = " + Fmt(rel_tolerance) + " must be in [1e-14, 1e-2]");
  }
  if (!(loss_scale_sigma > 0.0) || !std::isfinite(loss_scale_sigma)) {
    return fail("loss_scale_sigma = " + Fmt(loss_scale_sigma) + " must be positive");
  }
  if (max_iterations < 1 || max_iterations > 10000) {
    return fail("max_iterations = " + std::to_string(max_iterations) + " must be in [1, 10000]");
  }
  if (e_of_v_points < 2 || e_of_v_points > 1000) {
    return fail("e_of_v_points = " + std::to_string(e_of_v_points) + " must be in [2, 1000]");
  }
  if (!(undetermined_relative_sigma > 0.0)) {
    return fail("undetermined_relative_sigma = " + Fmt(undetermined_relative_sigma) +
                " must be positive");
  }
  if (!(comparison_rel_tolerance >= 1e-14 && comparison_rel_tolerance <= 1e-2)) {
    return fail("comparison_rel_tolerance = " + Fmt(comparison_rel_tolerance) +
                " must be in [1e-14, 1e-2]");
  }
  if (comparison_max_iterations < 1 || comparison_max_iterations > 10000) {
    return fail("comparison_max_iterations = " + std::to_string(comparison_max_iterations) +
                " must be in [1, 10000]");
  }
  for (const auto& f : free_parameters) {
    if (std::find(fixed_parameters.begin(), fixed_parameters.end(), f) != fixed_parameters.end()) {
      return fail("parameter '" + f + "' is both freed and held");
    }
  }
  return true;
}

std::vector<std::string> Calibration::Determined() const {
  std::vector<std::string> out;
  for (const auto& p : parameters) {
    if (!p.fixed && p.determined) out.push_back(p.name);
  }
  return out;
}

std::vector<std::string> Calibration::Undetermined() const {
  std::vector<std::string> out;
  for (const auto& p : parameters) {
    if (!p.determined) out.push_back(p.name);
  }
  return out;
}

namespace {

std::string FormatResidual(double v, const std::string& unit) {
  if (unit == "s") return Fmt(v * 1e6, 4) + " us";
  return Fmt(v, 4);
}

}  // namespace

std::string Calibration::BriefReport() const {
  std::ostringstream os;
  os << law << ":";
  bool first = true;
  for (const auto& p : parameters) {
    if (p.fixed) continue;
    os << (first ? " " : ", ") << p.name << " = " << Fmt(p.value, 6);
    if (std::isfinite(p.sigma)) os << " ± " << Fmt(p.sigma, 2);
    if (!p.determined) os << " (undetermined)";
    first = false;
  }
  os << ", rms " << FormatResidual(rms_residual, residual_unit) << ", chi2/dof " << Fmt(chi2_dof, 3)
     << " (" << FitOutcomeName(outcome) << ")";
  return os.str();
}

std::string Calibration::FullReport() const {
  std::ostringstream os;
  os << "law " << law << ", " << FitStrategyName(strategy) << " fit, "
     << DerivativeModeName(derivatives) << " derivatives ("
     << (analytic_jacobian ? "analytic Jacobian from the closed-form e(v)" : "central differences")
     << ")\n";
  os << "outcome: " << FitOutcomeName(outcome);
  if (!message.empty()) os << " — " << message;
  os << "\nparameters:\n";
  size_t w = 4;
  for (const auto& p : parameters) w = std::max(w, p.name.size());
  for (const auto& p : parameters) {
    os << "  " << std::left << std::setw(static_cast<int>(w)) << p.name << " = " << std::setw(12)
       << Fmt(p.value, 7);
    if (!p.fixed && std::isfinite(p.sigma)) {
      os << " ± " << std::setw(10) << Fmt(p.sigma, 3);
    } else {
      os << "   " << std::setw(10) << "";
    }
    os << " " << std::setw(8) << p.unit << std::right;
    if (p.fixed) {
      os << "  held at the scene value"
         << (p.determined ? " (the data could fit it: free it with --free " + p.name + ")"
                          : " (the data cannot determine it)");
    } else if (p.determined) {
      os << "  fitted" << (p.at_bound ? ", at its bound" : "");
    } else {
      os << "  NOT determined by the data (held at its start value)";
    }
    os << "\n";
  }
  if (!recordings.empty()) os << "recordings:\n";
  for (const auto& r : recordings) {
    os << "  " << r.name << ": " << r.impacts
       << (strategy == FitStrategy::kTrajectory ? " impacts" : " bounces");
    if (strategy == FitStrategy::kTrajectory) {
      os << " (" << r.simulated_impacts << " simulated), v0 = " << Fmt(r.impact_speed_m_s, 6);
      if (r.impact_speed_fixed) {
        os << " m/s (from the scene's drop)";
      } else {
        os << " ± " << Fmt(r.impact_speed_sigma_m_s, 2) << " m/s";
      }
      os << ", t0 = " << std::fixed << std::setprecision(7) << r.time_origin_s << std::defaultfloat
         << " ± " << Fmt(r.time_origin_sigma_s * 1e6, 2) << " us";
    }
    os << ", rms " << FormatResidual(r.rms_residual, residual_unit) << "\n";
  }
  os << "fit: " << num_residuals << " residuals, " << num_free << " free parameters, dof " << dof
     << ", chi2/dof " << Fmt(chi2_dof, 4) << ", rms residual "
     << FormatResidual(rms_residual, residual_unit) << "\n";
  os << "     AIC " << Fmt(aic, 6) << ", BIC " << Fmt(bic, 6) << ", " << iterations
     << " iterations, " << simulations << " simulations, " << Fmt(solve_time_s, 3) << " s\n";
  const auto det = Determined();
  const auto und = Undetermined();
  os << "determined by the sound: " << (det.empty() ? "(none)" : Join(det)) << "\n";
  os << "not determined by the sound: " << (und.empty() ? "(none)" : Join(und)) << "\n";
  if (!e_of_v.empty()) {
    os << "e(v) over the measured speeds " << Fmt(v_min_m_s, 4) << " .. " << Fmt(v_max_m_s, 4)
       << " m/s:\n    v (m/s)        e      sigma\n";
    for (const auto& pt : e_of_v) {
      os << "  " << std::setw(9) << Fmt(pt.v_m_s, 4) << "  " << std::setw(9) << Fmt(pt.e, 6) << "  "
         << std::setw(9) << Fmt(pt.sigma, 2) << "\n";
    }
  }
  return os.str();
}

// =============================================================================================
Calibration Calibrate(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                      const CalibrationOptions& options) {
  const auto t_start = std::chrono::steady_clock::now();
  std::string err;
  if (!options.IsValid(&err)) throw Error(ErrorCode::kUsage, err);
  if (!scene.IsValid(&err)) throw Error(ErrorCode::kBadScene, err);
  if (recordings.empty()) throw Error(ErrorCode::kUsage, "calibrate: no recordings");

  FitProblem fp(options, scene);
  fp.setup = MakeLawSetup(scene, options);
  LawSetup& setup = fp.setup;
  const auto& specs = setup.law->Parameters();
  fp.g = scene.EffectiveGravity();
  fp.sim.rel_tolerance = options.rel_tolerance;
  fp.sim.abs_tolerance = std::min(1e-12, options.rel_tolerance * 1e-3);
  const bool trajectory = options.strategy == FitStrategy::kTrajectory;
  const bool effects_closed_form =
      !scene.effects.contact_duration && !scene.effects.surface_compliance;
  fp.analytic = options.derivatives == DerivativeMode::kAuto && setup.has_gradient &&
                (!trajectory || effects_closed_form);

  // Measured restitution per bounce: seeds the damping and is the restitution strategy's data.
  std::vector<double> es, vs;
  for (const auto& rec : recordings) {
    const int n = static_cast<int>(rec.sequence.impacts.size());
    if (n < 2) {
      throw Error(ErrorCode::kFitFailed,
                  rec.name + ": " + std::to_string(n) + (n == 1 ? " impact" : " impacts") +
                      " cannot determine the damping (a bounce needs at least 3 impacts)");
    }
    Analysis a = AnalyzeBounces(rec.sequence, scene);
    for (const Bounce& b : a.bounces) {
      if (b.index == 0 && !options.use_drop) continue;
      if (!std::isfinite(b.e) || !std::isfinite(b.v_in_m_s) || !(b.v_in_m_s > 0.0)) continue;
      es.push_back(b.e);
      vs.push_back(b.v_in_m_s);
      if (std::isfinite(b.e_sigma) && b.e_sigma > 0.0) {
        fp.points.push_back({b.v_in_m_s, b.e, std::max(b.e_sigma, kMinESigma), rec.name, b.index});
      }
    }
  }
  const double e_med = Median(es), v_med = Median(vs);
  if (std::isfinite(e_med) && e_med >= 1.0) {
    throw Error(ErrorCode::kFitFailed,
                "the measured median restitution " + Fmt(e_med, 4) +
                    " is >= 1: these impacts do not form a damped bounce sequence");
  }
  std::string seed_note = "start from the scene's values";
  if (options.seed_from_inverse_map) {
    seed_note = SeedDamping(setup, e_med, v_med, fp.g, fp.sim, &fp.restitution_simulations);
  }

  // A seeded value is the best magnitude estimate of a parameter (steps, scaling).
  for (int i : setup.free) {
    const double v = std::abs(setup.start[static_cast<size_t>(i)]);
    if (v > 0.0 && std::isfinite(v)) setup.typical[static_cast<size_t>(i)] = v;
  }

  // Parameter blocks and counting.
  const size_t nfree = setup.free.size();
  for (int i : setup.free) {
    setup.scale.push_back(setup.typical[static_cast<size_t>(i)]);
    fp.law_values.push_back(setup.start[static_cast<size_t>(i)] / setup.scale.back());
  }
  ceres::Problem::Options popt;
  ceres::Problem problem(popt);
  auto make_loss = [&]() -> ceres::LossFunction* {
    switch (options.loss) {
      case RobustLoss::kHuber:
        return new ceres::HuberLoss(options.loss_scale_sigma);
      case RobustLoss::kCauchy:
        return new ceres::CauchyLoss(options.loss_scale_sigma);
      case RobustLoss::kNone:
        return nullptr;
    }
    return nullptr;
  };
  int num_residuals = 0;
  int num_nuisance = 0;
  if (trajectory) {
    fp.v0.resize(recordings.size());
    fp.t0.resize(recordings.size());
    fp.v0_free.resize(recordings.size());
    const FlightModel flight = FlightModel::FromScene(scene);
    for (size_t r = 0; r < recordings.size(); ++r) {
      const auto& imp = recordings[r].sequence.impacts;
      fp.models.push_back(
          std::make_unique<RecordingModel>(setup, scene, recordings[r], options, fp.analytic));
      fp.t0[r] = imp.front().time_s;
      std::optional<double> fixed_v0;
      if (options.use_drop) {
        if (scene.drop.impact_speed_m_s) {
          fixed_v0 = *scene.drop.impact_speed_m_s;
        } else if (scene.drop.height_m) {
          fixed_v0 = flight.FallArrivalSpeed(*scene.drop.height_m);
        } else {
          throw Error(ErrorCode::kBadScene,
                      "--use-drop: the scene gives neither a drop height nor an impact speed");
        }
        fp.v0[r] = *fixed_v0;
      } else {
        // v_out,0 from the first interval, divided by the median e.
        const double vout = flight.LaunchSpeedForFlightTime(imp[1].time_s - imp[0].time_s);
        const double e0 = std::isfinite(e_med) && e_med > 0.05 ? e_med : 0.8;
        fp.v0[r] = vout / e0;
        // Start v0 from the law's own e at that speed when it can tell.
        try {
          const double e_law = ModelRestitution(setup, setup.start, fp.v0[r], fp.g, fp.sim,
                                                &fp.restitution_simulations);
          if (e_law > 0.05 && e_law < 1.0) fp.v0[r] = vout / e_law;
        } catch (const Error&) {
        }
      }
      if (!fixed_v0 && options.start_impact_speeds_m_s.size() == recordings.size() &&
          options.start_impact_speeds_m_s[r] > 0.0) {
        fp.v0[r] = options.start_impact_speeds_m_s[r];
      }
      if (options.start_time_origins_s.size() == recordings.size() &&
          std::isfinite(options.start_time_origins_s[r])) {
        fp.t0[r] = options.start_time_origins_s[r];
      }
      fp.v0_free[r] = !fixed_v0.has_value();
      for (int k = 0; k < static_cast<int>(imp.size()); ++k) {
        auto* cost = new ImpactTimeCost(fp.models[r].get(), k, nfree, fixed_v0);
        std::vector<double*> blocks;
        for (size_t j = 0; j < nfree; ++j) blocks.push_back(&fp.law_values[j]);
        if (!fixed_v0) blocks.push_back(&fp.v0[r]);
        blocks.push_back(&fp.t0[r]);
        problem.AddResidualBlock(cost, make_loss(), blocks);
        ++num_residuals;
      }
      if (!fixed_v0) {
        problem.SetParameterLowerBound(&fp.v0[r], 0, 1e-6);
        problem.SetParameterUpperBound(&fp.v0[r], 0, 1e3);
        ++num_nuisance;
      }
      ++num_nuisance;
    }
  } else {
    if (fp.points.empty()) {
      throw Error(ErrorCode::kFitFailed,
                  "no bounce with a measured restitution: the recordings cannot determine the "
                  "damping");
    }
    const double rel_step = RelativeStep(options.rel_tolerance);
    for (const auto& pt : fp.points) {
      auto* cost = new RestitutionCost(setup, pt, fp.g, fp.sim, fp.analytic, rel_step,
                                       &fp.restitution_simulations);
      std::vector<double*> blocks;
      for (size_t j = 0; j < nfree; ++j) blocks.push_back(&fp.law_values[j]);
      problem.AddResidualBlock(cost, make_loss(), blocks);
      ++num_residuals;
    }
  }
  for (size_t j = 0; j < nfree; ++j) {
    const auto& sp = specs[static_cast<size_t>(setup.free[j])];
    const double sc = setup.scale[j];
    if (std::isfinite(sp.lower))
      problem.SetParameterLowerBound(&fp.law_values[j], 0, sp.lower / sc);
    if (std::isfinite(sp.upper))
      problem.SetParameterUpperBound(&fp.law_values[j], 0, sp.upper / sc);
  }
  const int num_free = static_cast<int>(nfree) + num_nuisance;
  if (num_residuals <= num_free) {
    std::ostringstream os;
    os << "the data cannot determine the parameters: " << num_residuals
       << (trajectory ? " impact times" : " restitution points") << " for " << num_free
       << " free parameters (" << nfree << " of the law"
       << (trajectory ? " + first impact speed and time origin per recording" : "")
       << "); need at least " << num_free + 1;
    throw Error(ErrorCode::kFitFailed, os.str());
  }

  // The law must rebound at the start values.
  std::vector<double> pw, cur = setup.start;
  std::vector<std::vector<double>> raw;
  std::vector<const SimPoint*> sims;
  if (trajectory) {
    for (size_t r = 0; r < fp.models.size(); ++r) {
      const SimPoint* s = fp.models[r]->Get(cur, fp.v0[r], false);
      if (!s) {
        throw Error(ErrorCode::kFitFailed,
                    "law " + setup.law->Name() + ": the simulator fails at the start values");
      }
      if (s->simulated < 2 && s->stop == StopReason::kStuck) {
        throw Error(ErrorCode::kFitFailed,
                    "law " + setup.law->Name() +
                        " sticks at the start values (no rebound at the first impact): "
                        "choose start values that rebound");
      }
    }
  }

  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = options.max_iterations;
  // Relative cost change 1e-10 and step 1e-10: far below any reported sigma, and above the
  // noise of numerically differenced simulations (which otherwise keep LM crawling).
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-10;
  so.gradient_tolerance = 1e-12;
  so.max_solver_time_in_seconds = 120.0;  // never hang: bounded in time as well as iterations
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  so.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(so, &problem, &summary);
  int iterations = static_cast<int>(summary.iterations.size());

  Calibration c;
  c.law = setup.law->Name();
  c.formula = setup.law->Formula();
  c.source = setup.law->Source();
  c.strategy = options.strategy;
  c.derivatives = options.derivatives;
  c.analytic_jacobian = fp.analytic;
  c.residual_unit = trajectory ? "s" : "1";
  auto current_params = [&]() {
    std::vector<double> p = setup.start;
    for (size_t j = 0; j < nfree; ++j) {
      p[static_cast<size_t>(setup.free[j])] = setup.scale[j] * fp.law_values[j];
    }
    return p;
  };
  if (!summary.IsSolutionUsable()) {
    throw Error(ErrorCode::kFitFailed,
                "law " + setup.law->Name() + ": the solver failed: " + summary.message);
  }

  // Identifiability: weighted Jacobian at the optimum, columns scaled to relative changes;
  // held law parameters get a column too (would freeing them help?).
  auto jacobian_columns = [&](const std::vector<double>& p, const std::vector<int>& law_idx,
                              bool nuisances) {
    std::vector<Eigen::VectorXd> cols;
    std::vector<double> w0;
    std::vector<std::vector<double>> raw0;
    Residuals(fp, p, &w0, &raw0, nullptr);
    const double step = RelativeStep(options.rel_tolerance);
    for (int i : law_idx) {
      auto f = [&](const std::vector<double>& q) {
        std::vector<double> w;
        std::vector<std::vector<double>> rr;
        Residuals(fp, q, &w, &rr, nullptr);
        return w;
      };
      const ParameterSpec& sp = specs[static_cast<size_t>(i)];
      const double x = p[static_cast<size_t>(i)];
      const double h = step * std::max(std::abs(x), setup.typical[static_cast<size_t>(i)]);
      double lo = x - h, hi = x + h;
      if (hi > sp.upper) hi = x;
      if (lo < sp.lower) lo = x;
      Eigen::VectorXd col = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(w0.size()));
      if (hi > lo) {
        std::vector<double> q = p;
        q[static_cast<size_t>(i)] = hi;
        const auto wh = f(q);
        q[static_cast<size_t>(i)] = lo;
        const auto wl = f(q);
        if (wh.size() == w0.size() && wl.size() == w0.size()) {
          const double scale = std::max(std::abs(x), setup.typical[static_cast<size_t>(i)]);
          for (size_t k = 0; k < w0.size(); ++k) {
            col(static_cast<Eigen::Index>(k)) = (wh[k] - wl[k]) / (hi - lo) * scale;
          }
        }
      }
      cols.push_back(col);
    }
    if (nuisances && trajectory) {
      size_t row = 0;
      for (size_t r = 0; r < fp.models.size(); ++r) {
        RecordingModel& m = *fp.models[r];
        const SimPoint* s = m.Get(p, fp.v0[r], true);
        if (!s) throw Error(ErrorCode::kFitFailed, "the simulator failed at the fitted values");
        Eigen::VectorXd cv = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(w0.size()));
        Eigen::VectorXd ct = cv;
        const double span = std::max(m.time(m.size() - 1) - m.time(0), 1e-3);
        for (int k = 0; k < m.size(); ++k, ++row) {
          cv(static_cast<Eigen::Index>(row)) =
              s->jac[m.sim_index(k) * (nfree + 1) + nfree] / m.sigma(k) * fp.v0[r];
          ct(static_cast<Eigen::Index>(row)) = span / m.sigma(k);
        }
        if (fp.v0_free[r]) cols.push_back(cv);
        cols.push_back(ct);
      }
    }
    Eigen::MatrixXd js(static_cast<Eigen::Index>(w0.size()),
                       static_cast<Eigen::Index>(cols.size()));
    for (size_t j = 0; j < cols.size(); ++j) js.col(static_cast<Eigen::Index>(j)) = cols[j];
    return js;
  };

  std::vector<bool> undetermined(specs.size(), false);
  std::vector<bool> held_determinable(specs.size(), false);
  {
    std::vector<double> p = current_params();
    Eigen::MatrixXd js = jacobian_columns(p, setup.free, true);
    std::vector<double> rel;
    const auto bad = Undetermined(js, options.undetermined_relative_sigma, &rel);
    bool any = false;
    for (size_t j = 0; j < nfree; ++j) {
      if (bad[j]) {
        undetermined[static_cast<size_t>(setup.free[j])] = true;
        any = true;
      }
    }
    if (any) {
      // Hold the undetermined ones at their start values and refit the rest.
      bool remaining = false;
      for (size_t j = 0; j < nfree; ++j) {
        if (undetermined[static_cast<size_t>(setup.free[j])]) {
          fp.law_values[j] = setup.start[static_cast<size_t>(setup.free[j])] / setup.scale[j];
          problem.SetParameterBlockConstant(&fp.law_values[j]);
        } else {
          remaining = true;
        }
      }
      if (remaining) {
        ceres::Solver::Summary s2;
        ceres::Solve(so, &problem, &s2);
        iterations += static_cast<int>(s2.iterations.size());
        if (!s2.IsSolutionUsable()) {
          throw Error(ErrorCode::kFitFailed,
                      "law " + setup.law->Name() + ": the solver failed: " + s2.message);
        }
      }
    }
    // Held law parameters: would the data determine each one if it alone were freed?
    p = current_params();
    for (size_t i = 0; i < specs.size(); ++i) {
      if (std::find(setup.free.begin(), setup.free.end(), static_cast<int>(i)) !=
          setup.free.end()) {
        continue;
      }
      std::vector<int> cols;
      for (size_t j = 0; j < nfree; ++j) {
        if (!undetermined[static_cast<size_t>(setup.free[j])]) cols.push_back(setup.free[j]);
      }
      cols.push_back(static_cast<int>(i));
      Eigen::MatrixXd jh = jacobian_columns(p, cols, true);
      const auto badh = Undetermined(jh, options.undetermined_relative_sigma, &rel);
      held_determinable[i] = !badh[cols.size() - 1];
    }
  }

  // Statistics at the optimum (no robust loss in chi2).
  cur = current_params();
  Residuals(fp, cur, &pw, &raw, &sims);
  double chi2 = 0.0;
  for (double r : pw) chi2 += r * r;
  int free_count = num_nuisance;
  for (size_t j = 0; j < nfree; ++j) {
    if (!undetermined[static_cast<size_t>(setup.free[j])]) ++free_count;
  }
  c.num_residuals = num_residuals;
  c.num_free = free_count;
  c.dof = num_residuals - free_count;
  c.chi2 = chi2;
  c.chi2_dof = c.dof > 0 ? chi2 / c.dof : 0.0;
  c.aic = chi2 + 2.0 * free_count;
  c.bic = chi2 + free_count * std::log(static_cast<double>(num_residuals));
  double ss = 0.0;
  size_t nraw = 0;
  for (const auto& v : raw) {
    for (double d : v) ss += d * d, ++nraw;
  }
  c.rms_residual = nraw ? std::sqrt(ss / static_cast<double>(nraw)) : 0.0;
  if (!std::isfinite(chi2) || !std::isfinite(c.rms_residual)) {
    throw Error(ErrorCode::kFitFailed,
                "law " + setup.law->Name() + ": non-finite residuals at the optimum");
  }
  if (trajectory) {
    for (size_t r = 0; r < sims.size(); ++r) {
      if (sims[r]->simulated < fp.models[r]->sim_size() && sims[r]->stop == StopReason::kStuck) {
        throw Error(ErrorCode::kFitFailed, "law " + setup.law->Name() +
                                               " sticks at the best fit for " + recordings[r].name +
                                               " (no rebound after simulated impact " +
                                               std::to_string(sims[r]->simulated) + " of " +
                                               std::to_string(fp.models[r]->sim_size()) +
                                               " measured): it cannot describe this recording");
      }
    }
  }

  // Covariance of the determined free parameters (Ceres, dense SVD), scaled by
  // sqrt(chi2/dof) when that exceeds 1 (the timing sigmas were too optimistic).
  const double scale = std::sqrt(std::max(1.0, c.chi2_dof));
  std::vector<const double*> cov_blocks;
  for (size_t j = 0; j < nfree; ++j) {
    if (!undetermined[static_cast<size_t>(setup.free[j])]) cov_blocks.push_back(&fp.law_values[j]);
  }
  std::vector<double> v0_sigma(fp.v0.size(), kNaN), t0_sigma(fp.t0.size(), kNaN);
  for (size_t r = 0; r < fp.v0.size(); ++r) {
    if (fp.v0_free[r]) cov_blocks.push_back(&fp.v0[r]);
    cov_blocks.push_back(&fp.t0[r]);
  }
  Eigen::MatrixXd law_cov = Eigen::MatrixXd::Constant(static_cast<Eigen::Index>(nfree),
                                                      static_cast<Eigen::Index>(nfree), 0.0);
  bool cov_ok = false;
  {
    ceres::Covariance::Options co;
    co.algorithm_type = ceres::DENSE_SVD;
    co.null_space_rank = -1;
    co.num_threads = 1;
    ceres::Covariance cov(co);
    std::vector<std::pair<const double*, const double*>> pairs;
    for (size_t a = 0; a < cov_blocks.size(); ++a) {
      for (size_t b = a; b < cov_blocks.size(); ++b)
        pairs.emplace_back(cov_blocks[a], cov_blocks[b]);
    }
    if (!cov_blocks.empty() && cov.Compute(pairs, &problem)) {
      cov_ok = true;
      for (size_t a = 0; a < nfree; ++a) {
        for (size_t b = 0; b < nfree; ++b) {
          if (undetermined[static_cast<size_t>(setup.free[a])] ||
              undetermined[static_cast<size_t>(setup.free[b])]) {
            continue;
          }
          double v = 0.0;
          cov.GetCovarianceBlock(&fp.law_values[a], &fp.law_values[b], &v);
          law_cov(static_cast<Eigen::Index>(a), static_cast<Eigen::Index>(b)) =
              v * scale * scale * setup.scale[a] * setup.scale[b];
        }
      }
      for (size_t r = 0; r < fp.v0.size(); ++r) {
        double v = 0.0;
        if (fp.v0_free[r] && cov.GetCovarianceBlock(&fp.v0[r], &fp.v0[r], &v)) {
          v0_sigma[r] = std::sqrt(std::max(v, 0.0)) * scale;
        }
        if (cov.GetCovarianceBlock(&fp.t0[r], &fp.t0[r], &v)) {
          t0_sigma[r] = std::sqrt(std::max(v, 0.0)) * scale;
        }
      }
    }
  }

  // Parameters.
  bool damping_undetermined = false;
  std::vector<std::string> notes;
  for (size_t i = 0; i < specs.size(); ++i) {
    FittedParameter fpar;
    fpar.name = specs[i].name;
    fpar.unit = specs[i].unit;
    fpar.value = cur[i];
    fpar.lower = specs[i].lower;
    fpar.upper = specs[i].upper;
    fpar.damping = specs[i].damping;
    fpar.sigma = kNaN;
    const auto it = std::find(setup.free.begin(), setup.free.end(), static_cast<int>(i));
    if (it == setup.free.end()) {
      fpar.fixed = true;
      fpar.determined = held_determinable[i];
    } else {
      const size_t j = static_cast<size_t>(it - setup.free.begin());
      fpar.determined = !undetermined[i];
      if (fpar.determined && cov_ok) {
        fpar.sigma = std::sqrt(
            std::max(law_cov(static_cast<Eigen::Index>(j), static_cast<Eigen::Index>(j)), 0.0));
      }
      if (!fpar.determined && specs[i].damping) damping_undetermined = true;
      const double tol = 1e-8 * setup.typical[i];
      fpar.at_bound = fpar.value <= specs[i].lower + tol || fpar.value >= specs[i].upper - tol;
    }
    c.parameters.push_back(fpar);
  }
  if (!cov_ok) notes.push_back("the covariance could not be computed (rank-deficient Jacobian)");
  notes.push_back(seed_note);
  if (c.chi2_dof > 10.0) {
    notes.push_back("chi2/dof = " + Fmt(c.chi2_dof, 3) +
                    ": the law does not describe these data within their sigmas "
                    "(sigmas scaled by sqrt(chi2/dof); compare laws with --law all)");
  }
  if (summary.termination_type == ceres::NO_CONVERGENCE) {
    notes.push_back("iteration limit reached");
  }

  // Per recording.
  for (size_t r = 0; r < recordings.size(); ++r) {
    RecordingFit rf;
    rf.name = recordings[r].name;
    if (trajectory) {
      rf.impacts = fp.models[r]->size();
      rf.simulated_impacts = sims[r]->simulated;
      rf.impact_speed_m_s = fp.v0[r];
      rf.impact_speed_sigma_m_s = v0_sigma[r];
      rf.impact_speed_fixed = !fp.v0_free[r];
      rf.time_origin_s = fp.t0[r];
      rf.time_origin_sigma_s = t0_sigma[r];
      rf.residuals = raw[r];
    } else {
      for (size_t q = 0, k = 0; q < fp.points.size(); ++q) {
        if (fp.points[q].recording != rf.name) continue;
        ++rf.impacts;
        (void)k;
      }
      // raw is grouped by recording in order of first appearance.
      size_t g = 0;
      std::vector<std::string> order;
      for (const auto& pt : fp.points) {
        if (std::find(order.begin(), order.end(), pt.recording) == order.end()) {
          order.push_back(pt.recording);
        }
      }
      const auto pos = std::find(order.begin(), order.end(), rf.name);
      g = static_cast<size_t>(pos - order.begin());
      if (pos != order.end()) rf.residuals = raw[g];
      rf.impact_speed_m_s = kNaN;
      rf.impact_speed_sigma_m_s = kNaN;
      rf.time_origin_s = kNaN;
      rf.time_origin_sigma_s = kNaN;
    }
    double s2 = 0.0;
    for (double d : rf.residuals) s2 += d * d;
    rf.rms_residual =
        rf.residuals.empty() ? 0.0 : std::sqrt(s2 / static_cast<double>(rf.residuals.size()));
    c.recordings.push_back(rf);
  }

  // e(v) over the measured speed range, sigma from the law covariance.
  const auto range = MeasuredSpeedRange(fp, sims);
  if (range.size() == 2) {
    c.v_min_m_s = range[0];
    c.v_max_m_s = range[1];
    const int n = options.e_of_v_points;
    const double step = setup.has_closed_e ? 1e-6 : RelativeStep(options.rel_tolerance);
    for (int q = 0; q < n; ++q) {
      const double v = range[0] * std::pow(range[1] / range[0], q / double(n - 1));
      EOfVPoint pt;
      pt.v_m_s = v;
      auto f = [&](const std::vector<double>& p) {
        return ModelRestitution(setup, p, v, fp.g, fp.sim, &fp.restitution_simulations);
      };
      try {
        pt.e = f(cur);
        Eigen::VectorXd grad = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(nfree));
        for (size_t j = 0; j < nfree; ++j) {
          if (!undetermined[static_cast<size_t>(setup.free[j])]) {
            grad(static_cast<Eigen::Index>(j)) =
                ParamDerivative(setup, cur, setup.free[j], step, f);
          }
        }
        pt.sigma = cov_ok ? std::sqrt(std::max(grad.dot(law_cov * grad), 0.0)) : kNaN;
      } catch (const Error&) {
        continue;
      }
      if (std::isfinite(pt.e)) c.e_of_v.push_back(pt);
    }
  }

  bool any_determined = false;
  for (const auto& p : c.parameters) any_determined |= !p.fixed && p.determined;
  const bool not_determinable = damping_undetermined || !any_determined;
  c.outcome = not_determinable ? FitOutcome::kNotDeterminable : FitOutcome::kConverged;
  if (not_determinable) {
    std::vector<std::string> names;
    for (const auto& p : c.parameters) {
      if (!p.fixed && !p.determined && (p.damping || !any_determined)) names.push_back(p.name);
    }
    notes.insert(notes.begin(), "the data cannot determine " + Join(names));
  }
  c.message = Join(notes, "; ");
  c.iterations = iterations;
  c.simulations = fp.Simulations();
  c.solver_report = summary.BriefReport();
  c.scene = scene;
  for (const auto& p : c.parameters) c.scene.law.parameters[p.name] = p.value;
  c.solve_time_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t_start).count();
  return c;
}

// =============================================================================================
std::vector<LawComparisonRow> CompareLaws(const std::vector<CalibrationInput>& recordings,
                                          const Scene& scene, const CalibrationOptions& options,
                                          int jobs) {
  struct Job {
    Scene scene;
    CalibrationOptions options;
    LawComparisonRow row;
  };
  std::vector<Job> todo;
  for (const LawInfo& info : RegisteredLaws()) {
    Job job{scene, options, {}};
    if (info.name == scene.law.name) {
      job.scene.law = scene.law;
    } else {
      if (info.needs_expression) continue;  // needs the user's expression
      job.scene.law = LawSpec{};
      job.scene.law.name = info.name;
    }
    job.options.rel_tolerance = std::max(options.rel_tolerance, options.comparison_rel_tolerance);
    job.options.max_iterations =
        std::min(options.max_iterations, options.comparison_max_iterations);
    job.row.fit.law = info.name;
    job.row.fit.strategy = options.strategy;
    job.row.fit.derivatives = options.derivatives;
    todo.push_back(std::move(job));
  }
  auto run = [&](Job& job) {
    try {
      // Keep only the --free/--fix names this law has.
      auto law = CreateLaw(job.scene.law, job.scene);
      auto keep = [&](std::vector<std::string>& v) {
        v.erase(std::remove_if(v.begin(), v.end(),
                               [&](const std::string& n) { return law->ParameterIndex(n) < 0; }),
                v.end());
      };
      keep(job.options.free_parameters);
      keep(job.options.fixed_parameters);
      job.row.fit = Calibrate(recordings, job.scene, job.options);
    } catch (const Error& e) {
      job.row.fit.outcome = FitOutcome::kFailed;
      job.row.fit.message = e.what();
      job.row.fit.aic = job.row.fit.bic = std::numeric_limits<double>::infinity();
    }
  };
  std::atomic<size_t> next{0};
  auto worker = [&]() {
    for (size_t i = next++; i < todo.size(); i = next++) run(todo[i]);
  };
  const int n = std::max(1, std::min<int>(jobs, static_cast<int>(todo.size())));
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();

  std::vector<LawComparisonRow> rows;
  for (auto& j : todo) rows.push_back(std::move(j.row));
  std::stable_sort(rows.begin(), rows.end(), [](const auto& a, const auto& b) {
    const bool fa = a.fit.outcome == FitOutcome::kFailed;
    const bool fb = b.fit.outcome == FitOutcome::kFailed;
    if (fa != fb) return fb;
    return a.fit.aic < b.fit.aic;
  });
  const double best = rows.empty() ? 0.0 : rows.front().fit.aic;
  for (auto& r : rows) r.delta_aic = r.fit.aic - best;
  // The best law at full precision, from its ranking optimum.
  if (!rows.empty() && rows.front().fit.outcome != FitOutcome::kFailed) {
    const bool already = options.rel_tolerance >= options.comparison_rel_tolerance &&
                         options.max_iterations <= options.comparison_max_iterations;
    if (!already) {
      Scene s = rows.front().fit.scene;
      CalibrationOptions o = options;
      auto law = CreateLaw(s.law, s);
      auto keep = [&](std::vector<std::string>& v) {
        v.erase(std::remove_if(v.begin(), v.end(),
                               [&](const std::string& nm) { return law->ParameterIndex(nm) < 0; }),
                v.end());
      };
      keep(o.free_parameters);
      keep(o.fixed_parameters);
      o.seed_from_inverse_map = false;  // start from the ranking optimum
      for (const auto& rf : rows.front().fit.recordings) {
        o.start_impact_speeds_m_s.push_back(rf.impact_speed_m_s);
        o.start_time_origins_s.push_back(rf.time_origin_s);
      }
      try {
        const double t_rank = rows.front().fit.solve_time_s;
        Calibration refit = Calibrate(recordings, s, o);
        refit.solve_time_s += t_rank;
        // Keep the ranking fit if the refit did not improve on it (it is a valid, less
        // precise result; the tolerances differ, so allow for their noise).
        if (refit.chi2 <= rows.front().fit.chi2 * (1.0 + 1e-3) + 1e-6) {
          const double shift = refit.aic - rows.front().fit.aic;
          rows.front().fit = std::move(refit);
          for (size_t i = 1; i < rows.size(); ++i) rows[i].delta_aic -= shift;
        }
      } catch (const Error&) {
      }
    }
  }
  return rows;
}

std::string LawComparisonTable(const std::vector<LawComparisonRow>& rows,
                               const std::vector<double>& speeds_m_s) {
  std::ostringstream os;
  os << "| rank | law | outcome | fitted | rms | chi2/dof | AIC | dAIC | BIC | time (s) |";
  for (double v : speeds_m_s) os << " e(" << Fmt(v, 3) << " m/s) |";
  os << "\n|---|---|---|---|---|---|---|---|---|---|";
  for (size_t i = 0; i < speeds_m_s.size(); ++i) os << "---|";
  os << "\n";
  int rank = 0;
  for (const auto& r : rows) {
    const Calibration& c = r.fit;
    os << "| " << ++rank << " | " << c.law << " | " << FitOutcomeName(c.outcome) << " | ";
    if (c.outcome == FitOutcome::kFailed) {
      os << c.message << " | | | | | | |";
      for (size_t i = 0; i < speeds_m_s.size(); ++i) os << " |";
      os << "\n";
      continue;
    }
    std::vector<std::string> fitted;
    for (const auto& p : c.parameters) {
      if (!p.fixed) fitted.push_back(p.name + "=" + Fmt(p.value, 4));
    }
    os << Join(fitted, " ") << " | " << FormatResidual(c.rms_residual, c.residual_unit) << " | "
       << Fmt(c.chi2_dof, 3) << " | " << Fmt(c.aic, 6) << " | " << Fmt(r.delta_aic, 4) << " | "
       << Fmt(c.bic, 6) << " | " << Fmt(c.solve_time_s, 3) << " |";
    // e(v) by interpolating the fitted table (log-linear in v), clamped to its range.
    for (double v : speeds_m_s) {
      double e = kNaN;
      const auto& t = c.e_of_v;
      if (!t.empty()) {
        if (v <= t.front().v_m_s) {
          e = t.front().e;
        } else if (v >= t.back().v_m_s) {
          e = t.back().e;
        } else {
          for (size_t i = 1; i < t.size(); ++i) {
            if (v <= t[i].v_m_s) {
              const double a = std::log(v / t[i - 1].v_m_s) / std::log(t[i].v_m_s / t[i - 1].v_m_s);
              e = t[i - 1].e + a * (t[i].e - t[i - 1].e);
              break;
            }
          }
        }
      }
      os << " " << (std::isfinite(e) ? Fmt(e, 5) : std::string("-")) << " |";
    }
    os << "\n";
  }
  return os.str();
}

}  // namespace bouncecal
