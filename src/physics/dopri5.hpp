// physics/dopri5.hpp — the Dormand-Prince 5(4) Runge-Kutta pair with its continuous extension
// and a PI step-size controller, for the contact integrator (internal header).
//
// Tableau: Dormand & Prince, J. Comput. Appl. Math. 6 (1980) 19; continuous extension of order
// 4 and the PI controller (beta = 0.04, safety 0.9, step ratio in [0.2, 10]) as in Hairer,
// Norsett & Wanner, Solving ODEs I, 2nd ed. (1993), §II.5 (Table 5.2), §II.6 (eq. 6.12) and
// §IV.2 (eq. 2.43c). Written here rather than taken from Boost.Odeint because the contact
// integrator needs what odeint's controlled stepper does not offer: states in forward-
// sensitivity arithmetic (ceres::Jet) whose error control uses the values only, a
// mixed absolute/relative norm, and a PI controller (fewer rejected steps than odeint's
// I controller). Boost.Odeint stays the independent reference (tests/law_oracle.hpp); the
// tableau is checked against it and for its order in tests/contact_integrator_test.cpp.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>

namespace bouncecal::dopri5 {

inline double ValueOf(double x) { return x; }
template <class J>
double ValueOf(const J& x) {
  return x.a;
}

// Butcher tableau (HNW Table II.5.2) and the error weights e_i = b_i - b^_i.
inline constexpr double kC2 = 1.0 / 5, kC3 = 3.0 / 10, kC4 = 4.0 / 5, kC5 = 8.0 / 9;
inline constexpr double kA21 = 1.0 / 5;
inline constexpr double kA31 = 3.0 / 40, kA32 = 9.0 / 40;
inline constexpr double kA41 = 44.0 / 45, kA42 = -56.0 / 15, kA43 = 32.0 / 9;
inline constexpr double kA51 = 19372.0 / 6561, kA52 = -25360.0 / 2187, kA53 = 64448.0 / 6561,
                        kA54 = -212.0 / 729;
inline constexpr double kA61 = 9017.0 / 3168, kA62 = -355.0 / 33, kA63 = 46732.0 / 5247,
                        kA64 = 49.0 / 176, kA65 = -5103.0 / 18656;
inline constexpr double kB1 = 35.0 / 384, kB3 = 500.0 / 1113, kB4 = 125.0 / 192,
                        kB5 = -2187.0 / 6784, kB6 = 11.0 / 84;
inline constexpr double kE1 = 71.0 / 57600, kE3 = -71.0 / 16695, kE4 = 71.0 / 1920,
                        kE5 = -17253.0 / 339200, kE6 = 22.0 / 525, kE7 = -1.0 / 40;
// Continuous extension (HNW §II.6, dense output of DOPRI5).
inline constexpr double kD1 = -12715105075.0 / 11282082432, kD3 = 87487479700.0 / 32700410799,
                        kD4 = -10690763975.0 / 1880347072, kD5 = 701980252875.0 / 199316789632,
                        kD6 = -1453857185.0 / 822651844, kD7 = 69997945.0 / 29380423;

// One integrator: the stages of the last step are kept for its dense output.
// Sys: void operator()(const State& x, State& dxdt, double t) const.
template <class T, size_t N>
class Stepper {
 public:
  using State = std::array<T, N>;

  // One step of size h from (t, x) with f = rhs(x, t): x1 = x(t + h), f1 = rhs(x1, t + h)
  // (first same as last), err = the value part of the embedded error estimate. Only the first
  // n components are computed (the rest of x1, f1 are copied as zero).
  template <class Sys>
  void Step(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
            State& f1, std::array<double, N>& err, size_t n) {
    State tmp{};
    for (size_t i = 0; i < n; ++i) tmp[i] = x[i] + h * (kA21 * f[i]);
    sys(tmp, k2_, t + kC2 * h);
    for (size_t i = 0; i < n; ++i) tmp[i] = x[i] + h * (kA31 * f[i] + kA32 * k2_[i]);
    sys(tmp, k3_, t + kC3 * h);
    for (size_t i = 0; i < n; ++i) {
      tmp[i] = x[i] + h * (kA41 * f[i] + kA42 * k2_[i] + kA43 * k3_[i]);
    }
    sys(tmp, k4_, t + kC4 * h);
    for (size_t i = 0; i < n; ++i) {
      tmp[i] = x[i] + h * (kA51 * f[i] + kA52 * k2_[i] + kA53 * k3_[i] + kA54 * k4_[i]);
    }
    sys(tmp, k5_, t + kC5 * h);
    for (size_t i = 0; i < n; ++i) {
      tmp[i] = x[i] + h * (kA61 * f[i] + kA62 * k2_[i] + kA63 * k3_[i] + kA64 * k4_[i] +
                           kA65 * k5_[i]);
    }
    sys(tmp, k6_, t + h);
    x1 = State{};
    for (size_t i = 0; i < n; ++i) {
      x1[i] = x[i] + h * (kB1 * f[i] + kB3 * k3_[i] + kB4 * k4_[i] + kB5 * k5_[i] + kB6 * k6_[i]);
    }
    sys(x1, f1, t + h);
    err.fill(0.0);
    for (size_t i = 0; i < n; ++i) {
      err[i] = h * (kE1 * ValueOf(f[i]) + kE3 * ValueOf(k3_[i]) + kE4 * ValueOf(k4_[i]) +
                    kE5 * ValueOf(k5_[i]) + kE6 * ValueOf(k6_[i]) + kE7 * ValueOf(f1[i]));
    }
  }

  // The continuous extension of the last Step (x -> x1 over h, derivatives f, f1) at
  // theta = (t' - t) / h in [0, 1].
  void Dense(double theta, const State& x, const State& x1, const State& f, const State& f1,
             double h, State& out, size_t n) const {
    const double theta1 = 1.0 - theta;
    out = State{};
    for (size_t i = 0; i < n; ++i) {
      const T diff = x1[i] - x[i];
      const T bspl = h * f[i] - diff;
      const T r4 = diff - h * f1[i] - bspl;
      const T r5 = h * (kD1 * f[i] + kD3 * k3_[i] + kD4 * k4_[i] + kD5 * k5_[i] + kD6 * k6_[i] +
                        kD7 * f1[i]);
      out[i] = x[i] + theta * (diff + theta1 * (bspl + theta * (r4 + theta1 * r5)));
    }
  }

 private:
  State k2_{}, k3_{}, k4_{}, k5_{}, k6_{};
};

// PI step-size control (HNW §IV.2, eq. 2.43c; as in Hairer's DOPRI5): after a step with error
// norm err (accepted if <= 1), the factor to multiply h by.
class Controller {
 public:
  // Factor for the next step; updates the memory of the last accepted error.
  double Accepted(double err) {
    double fac = Factor(err);
    if (last_rejected_) fac = std::min(fac, 1.0);
    previous_term_ = std::pow(static_cast<float>(std::max(err, 1e-4)), kBetaF);
    last_rejected_ = false;
    return fac;
  }
  double Rejected(double err) {
    last_rejected_ = true;
    const double grow = std::pow(static_cast<float>(std::min(err, 1e30)), kExponentF);
    return 1.0 / std::min(1.0 / kMinFactor, grow / kSafety);
  }
  void Reset() {
    previous_term_ = kInitialTerm;
    last_rejected_ = false;
  }

 private:
  static constexpr double kBeta = 0.04;
  static constexpr double kExponent = 0.2 - 0.75 * kBeta;
  static constexpr float kExponentF = static_cast<float>(kExponent);
  static constexpr float kBetaF = static_cast<float>(kBeta);
  static constexpr double kSafety = 0.9;
  static constexpr double kMinFactor = 0.2, kMaxFactor = 10.0;
  double Factor(double err) const {
    // Single precision is plenty for a step-size heuristic and twice as fast as pow.
    const double fac = std::pow(static_cast<float>(std::max(err, 1e-30)), kExponentF) /
                       previous_term_ / kSafety;  // h_new = h / fac
    return 1.0 / std::clamp(fac, 1.0 / kMaxFactor, 1.0 / kMinFactor);
  }
  // previous accepted error^beta (the memory of the PI controller); 1e-4^beta at the start.
  static constexpr double kInitialTerm = 0.69183097091893653;  // 1e-4^0.04
  double previous_term_ = kInitialTerm;
  bool last_rejected_ = false;
};

}  // namespace bouncecal::dopri5
