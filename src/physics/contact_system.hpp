// The scaled ODE system of one contact (internal to the library, src/): the variables, their
// scales, the three phases' layouts and the right-hand side (System), and the integrator's
// tuning per method. The integration and its events are contact_integrator.cpp's.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "bouncecal/physics/contact_integrator.hpp"
#include "physics/dop853.hpp"
#include "physics/dopri5.hpp"
#include "physics/scalar.hpp"

namespace bouncecal::contact_system {

using dopri5::ValueOf;
using scalar::Quotient;

constexpr int kMaxLawState = 7;
// Event times are located to this relative precision (in units of the contact time).
constexpr double kEventTolerance = 1e-14;
// Maxima (of the overlap, of the force) are located to this fraction of their step: the value
// there is quadratic in the time error.
constexpr double kPeakTolerance = 1e-8;
// Phase changes (contact_integrator.hpp). The approach phase ends once delta' < a fraction of
// v_in (kTuning below); the exit phase starts once delta' < 0 and delta < 0.7 of its peak
// (kTuning's exit_overlap_q2 for laws smooth in delta^(1/2)), and is abandoned if |delta'|
// falls below half its value at entry. Measured on the Hertz laws (bench_simulate): 0.5..0.8
// give the same step counts within 5 %.
constexpr double kExitOverlapFraction = 0.7;
constexpr double kExitSpeedFloor = 0.5;

// The peak overlap in units of v_in t_c (Hertz: delta_max = v t_c / 2.94).
constexpr double kPeakOverlapEstimate = 0.34;

// ContactMethod::kAuto: DOP853 (order 8) at and below this rel_tolerance, dopri5 (order 5)
// above it (bench_simulate: DOP853 takes fewer steps and less time from 1e-7 down).
constexpr double kHighOrderTolerance = 1e-7;

// What differs between the two methods (measured over every law at impact speeds 2 m/s ..
// 0.3 mm/s with gravity, against tests/law_oracle.hpp and with bench_simulate; the dopri5
// values are the ones this integrator was tuned with before DOP853 was added):
//   tolerance_scale: the local error is held at this fraction of rel_tolerance. dopri5: 1/4
//     keeps every law's errors at or below those of the integrator before it (odeint's
//     controlled dopri5), so the option keeps its meaning. DOP853: 0.15 keeps every law's
//     30-bounce errors (bench_simulate) within the documented bounds (e <= 3.7 rtol, impact
//     times <= 40 s rtol) and falling with rtol from 1e-6 down, and its errors per contact at
//     or below dopri5's from 1e-7 to 1e-10. At 1/4 jiang-liu's impact times at 1e-10 broke the
//     bound (4.8e-9 s: its nearly elastic bounces add up one-signed velocity errors); at 1 the
//     Hunt-Crossley first-integral test did (n = 1.2: 1.4e-9 at 1e-9).
//   first_step: the first step, as a fraction of the contact (or of the approach phase's range
//     of u) at rel_tolerance 1: first_step (tolerance_scale rtol)^(1/order). DOP853's first
//     step at 0.5 had errors ~1e-6 of the tolerance.
//   approach_end_speed, approach_end_overlap(_q6): the approach phase (u) ends once delta' < this
//     fraction of v_in, or delta beyond this fraction of the estimated peak overlap (a ball that
//     gravity keeps accelerating). 0.5..0.8 gave dopri5 the same step counts within 5 %;
//     DOP853's longer steps find the u phase's singular end (delta' -> 0) harder: 0.95 and 0.25
//     saved a fifth of its steps and half its rejected ones. With DOP853 the overlap bound is
//     the one that ends the approach (delta' = 0.95 v_in only at ~0.4 of the peak overlap), and
//     its last u step was rejected in every Hunt-Crossley contact above ~1 mm/s. At 0.15
//     (approach_end_overlap, roots q = 2 and 4), bench_simulate --law at rtol 1e-9 (30
//     contacts; steps per contact, rejected share and errors against 0.25): hunt-crossley (-hc,
//     -ln, -flores) 25.0 -> 24.0 (24.1), 5 -> 1 % rejected, errors in e x0.93-0.95;
//     hertz-viscoelastic 26 -> 25, 8 -> 4 %, x0.83; hertz-tsuji 38.5 -> 36.4, 7 -> 3 %, x0.16;
//     from rtol 1e-7 to 1e-11 no error above 1.3x its value at 0.25. simulate --law
//     hunt-crossley-ln: 283 272 -> 278 077 steps. Jiang-liu (q = 6) gained nothing (57.7 -> 58.0
//     steps, impact-time error x3 at 1e-9): approach_end_overlap_q6 = 0.25.
//   exit_first_step: the exit phase's first step against the last time step mapped to u
//     (DOP853's was rejected at full length for the Hertz laws).
//   exit_overlap_q2: for laws smooth in delta^(1/2) (OverlapRoot q = 2), the exit phase (u)
//     starts once the overlap falls below this fraction of its peak (other roots: 0.7). DOP853
//     keeps its time steps longer into the unloading than its u steps just after the switch
//     (the exit's u steps start at ~0.6 of the time steps and grow): 0.5 takes 5 % fewer steps
//     than 0.7 for simulate --law hunt-crossley. 0.3 took 9 % fewer, but one contact's e then
//     stopped converging at ~1e-12 (hunt-crossley-ln at 1.5 m/s: 7.8e-13 at rtol 1e-11 against
//     6.4e-13 at 1e-10; 0.5 falls to 1e-13 like 0.7). Not for q = 4 and 6: hertz-tsuji's
//     impact-time error then rose from rtol 1e-8 to 1e-9 (bench_simulate: 5.1e-10 -> 6.4e-10 s
//     at 0.3, 0.4 and 0.5), jiang-liu gained 3 %.
struct Tuning {
  double tolerance_scale, first_step, approach_end_speed, approach_end_overlap,
      approach_end_overlap_q6, exit_first_step, exit_overlap_q2;
};
template <class M>
inline constexpr Tuning kTuning{0.25,
                                0.5,
                                0.7,
                                std::numeric_limits<double>::infinity(),
                                std::numeric_limits<double>::infinity(),
                                1.0,
                                0.7};
template <>
inline constexpr Tuning kTuning<dop853::Method>{0.15, 2.0, 0.95, 0.15, 0.25, 0.7, 0.5};

enum class Phase { kApproach, kMiddle, kExit };

// Scale factors from physical to integrated (dimensionless) variables.
struct Scales {
  double time_s = 1.0;
  double speed_m_s = 1.0;
  double length_m = 1.0;
  double energy_j = 1.0;
  std::array<double, kMaxLawState> state{};
};

// Physical view of one scaled state vector (room for the law's state: one variable in the
// small layout, kMaxLawState in the big one).
template <class S, size_t K = kMaxLawState>
struct Phys {
  S y{}, yd{}, z{}, zd{}, work{};
  S delta{}, delta_dot{};
  S tau{};  // scaled time (contact-time units)
  std::array<S, K> state{};
};
template <class S, size_t N>
using PhysN = Phys<S, (N > 4 ? kMaxLawState : 1)>;

// The overlap the law sees: >= 0 (past delta = 0 the force is continued by F(0, delta')). In
// sensitivity arithmetic the derivative parts are kept: at the end of a contact (delta ~ 0, on
// either side by rounding) the force's derivative is its one-sided derivative from delta > 0,
// not 0 (dropping it would make the last step's sensitivities wrong by O(h)).
inline double Clamp0(double x) { return x > 0.0 ? x : 0.0; }
inline SensitivityJet Clamp0(const SensitivityJet& x) {
  if (x.a > 0.0) return x;
  SensitivityJet c = x;
  c.a = 0.0;
  return c;
}

// The scaled ODE system. Layout: [y (middle) or tau (approach/exit), y', work, (z, z' if the
// layout is big), law state...]. In the u phases delta = L u^q is given by the independent
// variable u and y = z + delta.
template <size_t N>
class System {
 public:
  static constexpr bool kBig = N > 4;

  System(const ContactDynamics& dyn, const ContactBody& body, double g_m_s2,
         const PlateModel* plate, const Scales& scales)
      : dyn_(dyn),
        body_(body),
        g_(g_m_s2),
        plate_(plate),
        sc_(scales),
        n_state_(dyn.StateSize()),
        inline_force_(dyn.InlineHertzDamper(&hertz_damper_)),
        continues_(dyn.ContinuesBelowZero()),
        s0_(kBig ? 5 : 3),
        inv_mass_(1.0 / body.mass_kg),
        accel_scale_(scales.time_s / scales.speed_m_s),
        power_scale_(scales.time_s / scales.energy_j) {}

  size_t StateOffset() const { return s0_; }
  size_t Active() const { return s0_ + static_cast<size_t>(n_state_); }
  int StateCount() const { return n_state_; }
  const Scales& scales() const { return sc_; }
  const ContactDynamics& dynamics() const { return dyn_; }
  Phase phase() const { return phase_; }
  int root() const { return q_; }
  void SetPhase(Phase p, int q) {
    phase_ = p;
    q_ = q;
  }
  void SetBranch(bool positive) { positive_branch_ = positive; }
  bool positive_branch() const { return positive_branch_; }

  // The components the right-hand side reads (bit i: component i): not the work (slot 2, a
  // quadrature), nor tau (slot 0) in the u phases. The stepper may skip the others in its stage
  // inputs.
  unsigned StageInputs() const {
    const unsigned all_but_work = ~(1u << 2);
    return phase_ == Phase::kMiddle ? all_but_work : all_but_work & ~1u;
  }

  // u^q and q u^(q-1) for the u phases.
  double UPower(double u) const { return IntPow(u, q_); }
  double UPowerSlope(double u) const { return q_ * IntPow(u, q_ - 1); }

  template <class S>
  PhysN<S, N> Unscale(const std::array<S, N>& x, double indep) const {
    PhysN<S, N> ph;
    S z_s(0.0), zd_s(0.0);
    if constexpr (kBig) {
      if (plate_) {
        z_s = x[3];
        zd_s = x[4];
      }
    }
    ph.z = z_s * sc_.length_m;
    if (phase_ == Phase::kMiddle) {
      ph.y = x[0] * sc_.length_m;
      ph.tau = S(indep);
      ph.delta = ph.y - ph.z;
    } else {
      const double up = UPower(indep);  // delta / L
      ph.y = (z_s + up) * sc_.length_m;
      ph.tau = x[0];
      ph.delta = S(up * sc_.length_m);
    }
    ph.yd = x[1] * sc_.speed_m_s;
    ph.work = x[2] * sc_.energy_j;
    ph.zd = zd_s * sc_.speed_m_s;
    ph.delta_dot = ph.yd - ph.zd;
    for (int i = 0; i < n_state_; ++i) ph.state[i] = x[s0_ + i] * sc_.state[i];
    return ph;
  }

  // The overlap the law is asked at: past delta = 0 the law's own continuation if it has one,
  // else 0 (the force is then extended by F(0, delta')), so that the dense output around an
  // end event stays continuous.
  template <class S>
  S Overlap(const S& delta) const {
    return continues_ ? delta : Clamp0(delta);
  }
  // The law's force on the current branch.
  template <class S>
  S Force(const PhysN<S, N>& ph) const {
    return dyn_.ForceOnBranch(Overlap(ph.delta), ph.delta_dot, ph.state.data(), positive_branch_);
  }
  template <class S>
  S Switch(const PhysN<S, N>& ph) const {
    return dyn_.Switch(Overlap(ph.delta), ph.delta_dot, ph.state.data());
  }
  double PlateEnergy(const PhysN<double, N>& ph) const {
    if (!plate_) return 0.0;
    return 0.5 * plate_->mass_kg * ph.zd * ph.zd + 0.5 * plate_->stiffness_n_m * ph.z * ph.z;
  }
  double BallEnergy(const PhysN<double, N>& ph) const {
    const double m = body_.mass_kg;
    return 0.5 * m * ph.yd * ph.yd - m * g_ * ph.y;
  }
  double Elastic(const PhysN<double, N>& ph) const {
    return dyn_.ElasticEnergy(std::max(ph.delta, 0.0), ph.state.data());
  }
  double Internal(const PhysN<double, N>& ph) const { return dyn_.InternalEnergy(ph.state.data()); }

  // d x / d tau (scaled time derivatives) at a physical view; slot 0 is y'.
  template <class S>
  void TimeRates(const std::array<S, N>& x, const PhysN<S, N>& ph, std::array<S, N>& dt) const {
    const S f = Force(ph);
    dt = std::array<S, N>{};
    dt[0] = x[1];                                 // L = V T
    dt[1] = accel_scale_ * (g_ - f * inv_mass_);  // m y'' = m g - F
    dt[2] = power_scale_ * f * ph.yd;             // d(work)/dt = F y'
    if constexpr (kBig) {
      if (plate_) {
        dt[3] = x[4];
        dt[4] = Quotient(sc_.time_s / sc_.speed_m_s *
                             (f - plate_->stiffness_n_m * ph.z - plate_->damping_n_s_m * ph.zd),
                         plate_->mass_kg);  // M z'' = F - K z - C z'
      }
    }
    if (n_state_ > 0) {
      std::array<S, (N > 4 ? kMaxLawState : 1)> rate{};
      dyn_.StateRate(Overlap(ph.delta), ph.delta_dot, ph.state.data(), rate.data());
      for (int i = 0; i < n_state_; ++i) dt[s0_ + i] = Quotient(sc_.time_s * rate[i], sc_.state[i]);
    }
  }

  // dtau/du in the u phases: q u^(q-1) / delta'_scaled.
  template <class S>
  S Rho(const std::array<S, N>& x, double u) const {
    S zd_s(0.0);
    if constexpr (kBig) {
      if (plate_) zd_s = x[4];
    }
    return UPowerSlope(u) / (x[1] - zd_s);
  }

  template <class S>
  void operator()(const std::array<S, N>& x, std::array<S, N>& dx, double indep) const {
    if constexpr (!kBig) {
      if (n_state_ == 0) return BallOnly(x, dx, indep);
    }
    const PhysN<S, N> ph = Unscale(x, indep);
    TimeRates(x, ph, dx);
    if (phase_ != Phase::kMiddle) {
      const S rho = Rho(x, indep);
      for (size_t i = 1; i < N; ++i) dx[i] *= rho;
      dx[0] = rho;
    }
  }

  // The common case written out (rigid surface, no law state): what operator() computes,
  // without the general bookkeeping (the contact's hot loop; the same operations in the same
  // order, so the same values).
  template <class S>
  void BallOnly(const std::array<S, N>& x, std::array<S, N>& dx, double indep) const {
    if (phase_ == Phase::kMiddle) return BallOnlyPhase<true, 0, false>(x, dx, indep);
    return BallOnlyPhase<false, 0, false>(x, dx, indep);
  }

  // The law's force on the current branch in the ball-only layout (no state). kInline: the law's
  // force is HertzDamper's, inlined here in double (the law computes it with the same function:
  // the same values, and the same as the sensitivity run's). A step is a chain of dependent
  // stages and its time is that chain more than its instructions: simulate --law hunt-crossley
  // took 11 % fewer instructions and 4 % less time than with the virtual call.
  template <bool kInline, class S>
  [[gnu::always_inline]] inline S BallForce(const S& delta, const S& yd) const {
    if constexpr (kInline && std::is_same_v<S, double>) {
      return hertz_damper_(Overlap(delta), yd);
    } else {
      return dyn_.ForceOnBranch(Overlap(delta), yd, nullptr, positive_branch_);
    }
  }

  // BallOnly in one phase, its branches resolved at compile time (kTime: the middle phase;
  // kRoot: the root q of the u phases, 0 for any; kInline: BallForce's). The stepper calls it
  // through BallRhs for the ball-only layout: no test of the layout, the phase or q per call,
  // the same values.
  template <bool kTime, int kRoot, bool kInline, class S>
  [[gnu::always_inline]] inline void BallOnlyPhase(const std::array<S, N>& x, std::array<S, N>& dx,
                                                   double indep) const {
    if constexpr (N > 3) {
      for (size_t i = 3; i < N; ++i) dx[i] = S(0.0);
    }
    const S yd = x[1] * sc_.speed_m_s;
    if constexpr (kTime) {
      const S f = BallForce<kInline>(S(x[0] * sc_.length_m), yd);
      dx[0] = x[1];
      dx[1] = accel_scale_ * (g_ - f * inv_mass_);
      dx[2] = power_scale_ * f * yd;
    } else {
      const int q = kRoot > 0 ? kRoot : q_;
      double up = 1.0;  // u^(q-1)
      for (int i = 1; i < q; ++i) up *= indep;
      const S delta = S(up * indep * sc_.length_m);
      const S rho = (q * up) / x[1];
      const S f = BallForce<kInline>(delta, yd);
      dx[0] = rho;
      dx[1] = accel_scale_ * (g_ - f * inv_mass_) * rho;
      dx[2] = power_scale_ * f * yd * rho;
    }
  }

  // The right-hand side as the stepper sees it, for one phase of the ball-only layout.
  template <bool kTime, int kRoot, bool kInline>
  struct BallRhs {
    const System& sys;
    template <class S>
    [[gnu::always_inline]] inline void operator()(const std::array<S, N>& x, std::array<S, N>& dx,
                                                  double indep) const {
      sys.template BallOnlyPhase<kTime, kRoot, kInline>(x, dx, indep);
    }
  };

  // Calls run(rhs) with the cheapest right-hand side equal to operator() in the current phase.
  template <class Run>
  void WithRhs(const Run& run) const {
    if constexpr (!kBig) {
      if (n_state_ == 0) {
        if (inline_force_) return WithBallRhs<true>(run);
        return WithBallRhs<false>(run);
      }
    }
    run(*this);
  }
  template <bool kInline, class Run>
  void WithBallRhs(const Run& run) const {
    if (phase_ == Phase::kMiddle) return run(BallRhs<true, 0, kInline>{*this});
    if (q_ == 2) return run(BallRhs<false, 2, kInline>{*this});
    run(BallRhs<false, 0, kInline>{*this});
  }

 private:
  static double IntPow(double u, int n) {
    double r = 1.0;
    for (int i = 0; i < n; ++i) r *= u;
    return r;
  }

  const ContactDynamics& dyn_;
  const ContactBody& body_;
  double g_;
  const PlateModel* plate_;
  Scales sc_;
  int n_state_;
  HertzDamper hertz_damper_;  // the law's force, if it is this form (inline_force_)
  bool inline_force_;
  bool continues_;
  size_t s0_;
  // Constant factors of the right-hand side (multiplications instead of divisions per call).
  double inv_mass_;     // 1/m*, 1/kg
  double accel_scale_;  // T/V: physical acceleration -> scaled
  double power_scale_;  // T/E: physical power -> scaled
  bool positive_branch_ = true;
  Phase phase_ = Phase::kMiddle;
  int q_ = 1;
};

}  // namespace bouncecal::contact_system
