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
#include <bit>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>

#include "physics/scalar.hpp"

namespace bouncecal::dopri5 {

// A step's error norm squared, as num / den (num <= den accepts the step): what the integrator
// needs without the square root and the division that would delay the next step.
struct ErrorSquared {
  double num, den;
};

using scalar::Value;
template <class T>
double ValueOf(const T& x) {
  return Value(x);
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

// out = x + h (c_1 k_1 + ... + c_M k_M), component by component, in one pass: for a ceres::Jet
// the value and the derivative parts are summed separately over raw arrays (Jet operators would
// create and copy a temporary per operation: 40 % of a sensitivity run before this).
template <size_t M>
inline void Combine(double& out, const double& x, double h, const std::array<double, M>& c,
                    const std::array<const double*, M>& k) {
  double sum = 0.0;
  for (size_t m = 0; m < M; ++m) sum += c[m] * *k[m];
  out = x + h * sum;
}
template <size_t M, class J>
inline void Combine(J& out, const J& x, double h, const std::array<double, M>& c,
                    const std::array<const J*, M>& k) {
  double sum = 0.0;
  for (size_t m = 0; m < M; ++m) sum += c[m] * k[m]->a;
  constexpr int kN = static_cast<int>(decltype(x.v)::RowsAtCompileTime);
  double v[kN];
  const double* xv = x.v.data();
  for (int j = 0; j < kN; ++j) v[j] = xv[j];
  for (size_t m = 0; m < M; ++m) {
    const double s = h * c[m];
    const double* kv = k[m]->v.data();
    for (int j = 0; j < kN; ++j) v[j] += s * kv[j];
  }
  out.a = x.a + h * sum;
  double* ov = out.v.data();
  for (int j = 0; j < kN; ++j) ov[j] = v[j];
}

// One integrator: the stages of the last step are kept for its dense output.
// Sys: void operator()(const State& x, State& dxdt, double t) const.
template <class T, size_t N>
class Stepper {
 public:
  using State = std::array<T, N>;

  // One step of size h from (t, x) with f = rhs(x, t): x1 = x(t + h), f1 = rhs(x1, t + h)
  // (first same as last), err = the value part of the embedded error estimate. Only the first
  // n components are computed (the rest of x1, f1 are copied as zero) — except for small
  // double states, where all N are (components beyond n stay 0: their x and rhs are 0), so
  // that the loops have a fixed length the compiler unrolls.
  template <class Sys>
  void Step(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
            State& f1, std::array<double, N>& err, size_t n_active) {
    if constexpr (kFixedWidth) return StepFixed(sys, x, f, t, h, x1, f1, err);
    const size_t n = Width(n_active);
    State tmp{};
    for (size_t i = 0; i < n; ++i) Combine<1>(tmp[i], x[i], h, {kA21}, {&f[i]});
    sys(tmp, k2_, t + kC2 * h);
    for (size_t i = 0; i < n; ++i) Combine<2>(tmp[i], x[i], h, {kA31, kA32}, {&f[i], &k2_[i]});
    sys(tmp, k3_, t + kC3 * h);
    for (size_t i = 0; i < n; ++i) {
      Combine<3>(tmp[i], x[i], h, {kA41, kA42, kA43}, {&f[i], &k2_[i], &k3_[i]});
    }
    sys(tmp, k4_, t + kC4 * h);
    for (size_t i = 0; i < n; ++i) {
      Combine<4>(tmp[i], x[i], h, {kA51, kA52, kA53, kA54}, {&f[i], &k2_[i], &k3_[i], &k4_[i]});
    }
    sys(tmp, k5_, t + kC5 * h);
    for (size_t i = 0; i < n; ++i) {
      Combine<5>(tmp[i], x[i], h, {kA61, kA62, kA63, kA64, kA65},
                 {&f[i], &k2_[i], &k3_[i], &k4_[i], &k5_[i]});
    }
    sys(tmp, k6_, t + h);
    x1 = State{};
    for (size_t i = 0; i < n; ++i) {
      Combine<5>(x1[i], x[i], h, {kB1, kB3, kB4, kB5, kB6},
                 {&f[i], &k3_[i], &k4_[i], &k5_[i], &k6_[i]});
    }
    sys(x1, f1, t + h);
    err.fill(0.0);
    for (size_t i = 0; i < n; ++i) {
      err[i] = h * (kE1 * ValueOf(f[i]) + kE3 * ValueOf(k3_[i]) + kE4 * ValueOf(k4_[i]) +
                    kE5 * ValueOf(k5_[i]) + kE6 * ValueOf(k6_[i]) + kE7 * ValueOf(f1[i]));
    }
  }

  // The interface the contact integrator uses (shared with dop853::Stepper): the step keeps
  // its error estimate, SquaredError gives the square of its RMS norm with per-component scales
  // sk (atol + rtol size; <= 1 accepts the step), Dense takes the system and the step's start
  // (unused here: the extension needs no extra stages).
  template <class Sys>
  void Step(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
            State& f1, size_t n_active, unsigned /*stage_inputs: all computed*/ = ~0u) {
    Step(sys, x, f, t, h, x1, f1, err_, n_active);
  }
  ErrorSquared SquaredError(const std::array<double, N>& sk, size_t n) const {
    double sum = 0.0;
    for (size_t i = 0; i < n; ++i) {
      const double r = err_[i] / sk[i];
      sum += r * r;
    }
    return {sum, static_cast<double>(n)};
  }
  template <class Sys>
  void Dense(const Sys&, double, double theta, const State& x, const State& x1, const State& f,
             const State& f1, double h, State& out, size_t n_active) const {
    Dense(theta, x, x1, f, f1, h, out, n_active);
  }

  // The continuous extension of the last Step (x -> x1 over h, derivatives f, f1) at
  // theta = (t' - t) / h in [0, 1].
  void Dense(double theta, const State& x, const State& x1, const State& f, const State& f1,
             double h, State& out, size_t n_active) const {
    const size_t n = Width(n_active);
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
  // Step for small double states: the same sums in the same order as Combine, written as
  // whole-array loops of fixed length (unrolled and vectorised: a third of a step's
  // instructions before).
  template <class Sys>
  void StepFixed(const Sys& sys, const State& x, const State& f, double t, double h, State& x1,
                 State& f1, std::array<double, N>& err) {
    State tmp;
    for (size_t i = 0; i < N; ++i) tmp[i] = x[i] + h * (kA21 * f[i]);
    sys(tmp, k2_, t + kC2 * h);
    for (size_t i = 0; i < N; ++i) tmp[i] = x[i] + h * (kA31 * f[i] + kA32 * k2_[i]);
    sys(tmp, k3_, t + kC3 * h);
    for (size_t i = 0; i < N; ++i) {
      tmp[i] = x[i] + h * (kA41 * f[i] + kA42 * k2_[i] + kA43 * k3_[i]);
    }
    sys(tmp, k4_, t + kC4 * h);
    for (size_t i = 0; i < N; ++i) {
      tmp[i] = x[i] + h * (kA51 * f[i] + kA52 * k2_[i] + kA53 * k3_[i] + kA54 * k4_[i]);
    }
    sys(tmp, k5_, t + kC5 * h);
    for (size_t i = 0; i < N; ++i) {
      tmp[i] =
          x[i] + h * (kA61 * f[i] + kA62 * k2_[i] + kA63 * k3_[i] + kA64 * k4_[i] + kA65 * k5_[i]);
    }
    sys(tmp, k6_, t + h);
    for (size_t i = 0; i < N; ++i) {
      x1[i] = x[i] + h * (kB1 * f[i] + kB3 * k3_[i] + kB4 * k4_[i] + kB5 * k5_[i] + kB6 * k6_[i]);
    }
    sys(x1, f1, t + h);
    for (size_t i = 0; i < N; ++i) {
      err[i] = h * (kE1 * f[i] + kE3 * k3_[i] + kE4 * k4_[i] + kE5 * k5_[i] + kE6 * k6_[i] +
                    kE7 * f1[i]);
    }
  }

  static constexpr bool kFixedWidth = std::is_same_v<T, double> && N <= 4;
  static size_t Width(size_t n_active) { return kFixedWidth ? N : n_active; }

  State k2_{}, k3_{}, k4_{}, k5_{}, k6_{};
  std::array<double, N> err_{};
};

// log2 (to 0.01) and exp2 (to 0.3 %) for the step-size controller: exponent from the bits, a
// quadratic on the mantissa (exact at both ends of [1, 2)). A step-size heuristic needs no
// more; libm's pow, log2 and exp2 were 10-13 % of a Hertz contact's time.
inline float ApproxLog2(float x) {  // x > 0, normal
  const std::uint32_t bits = std::bit_cast<std::uint32_t>(x);
  const int e = static_cast<int>((bits >> 23) & 0xffu) - 127;  // x = (1 + t) 2^e
  const float t = std::bit_cast<float>((bits & 0x7fffffu) | 0x3f800000u) - 1.0f;
  return static_cast<float>(e) + t * (4.0f / 3.0f - t / 3.0f);
}
inline float ApproxExp2(float y) {  // |y| < 126
  // floor(y) without the library call (|y| < 126: the truncation is exact).
  float n = static_cast<float>(static_cast<int>(y));
  if (n > y) n -= 1.0f;
  const float f = y - n;  // 2^f on [0, 1): 1 + f (0.6565 + 0.3435 f), in [1, 2)
  const float m = 1.0f + f * (0.6565f + 0.3435f * f);
  const std::uint32_t e = static_cast<std::uint32_t>(static_cast<int>(n) + 127) << 23;
  return std::bit_cast<float>((std::bit_cast<std::uint32_t>(m) & 0x7fffffu) | e) *
         (m >= 2.0f ? 2.0f : 1.0f);
}

// PI step-size control (HNW §IV.2, eq. 2.43c; as in Hairer's DOPRI5 and DOP853) for a method of
// order kOrder: after a step with error norm err (accepted if <= 1), the factor to multiply h by:
//   accepted: clamp(0.9 err^-(1/kOrder - 0.75 beta) err_prev^beta, 1/kMinFactorInverse,
//             kMaxFactorInt), no growth right after a rejection;
//   rejected: max(1/kMinFactorInverse, 0.9 err^-(1/kOrder - 0.75 beta)).
// The powers are ApproxExp2 of ApproxLog2 (within 0.4 %: a step factor needs no more).
// beta = 0.04 for both (Hairer's DOP853 defaults to 0: 0.04 halved the rejected steps of the
// Hertz contacts in bench_simulate, 0.08 made the steps collapse).
template <int kOrder, int kMinFactorInverse, int kMaxFactorInt>
class PiController {
 public:
  // Factor for the next step; remembers this step's error.
  double Accepted(double err) { return AcceptedLog2(Log2(err)); }
  // The same from the squared norm num / den: log2(err) = (log2 num - log2 den) / 2.
  double Accepted(const ErrorSquared& e) {
    return AcceptedLog2(0.5f * (Log2(e.num) - Log2(e.den)));
  }
  double Rejected(double err) {
    last_rejected_ = true;
    const float log_err = ApproxLog2(static_cast<float>(std::min(err, 1e30)));
    return std::max(kMinFactor, kSafety * ApproxExp2(-kExponentF * log_err));
  }
  void Reset() {
    previous_log_ = kInitialLog;
    last_rejected_ = false;
  }

 private:
  static float Log2(double x) { return ApproxLog2(static_cast<float>(std::clamp(x, 1e-30, 1e30))); }
  double AcceptedLog2(float log_err) {  // log_err in +-100
    const float log_prev = previous_log_;
    previous_log_ = std::max(log_err, kInitialLog);  // err_prev >= 1e-4
    // 0.9 err^-(1/kOrder - 0.75 beta) err_prev^beta as one power of two: no division on the
    // path from one step to the next.
    double fac = kSafety * ApproxExp2(kBetaF * log_prev - kExponentF * log_err);  // h_new / h
    fac = std::clamp(fac, kMinFactor, kMaxFactor);
    if (last_rejected_) fac = std::min(fac, 1.0);
    last_rejected_ = false;
    return fac;
  }
  static constexpr double kBeta = 0.04;
  static constexpr float kBetaF = static_cast<float>(kBeta);
  static constexpr float kExponentF = static_cast<float>(1.0 / kOrder - 0.75 * kBeta);
  static constexpr double kSafety = 0.9;
  static constexpr double kMinFactor = 1.0 / kMinFactorInverse, kMaxFactor = kMaxFactorInt;
  static constexpr float kInitialLog = -13.287712f;  // log2(1e-4): the memory at the start
  float previous_log_ = kInitialLog;
  bool last_rejected_ = false;
};

// dopri5's: factors in [0.2, 10].
using Controller = PiController<5, 5, 10>;

// The method as the contact integrator sees it.
struct Method {
  template <class T, size_t N>
  using Stepper = dopri5::Stepper<T, N>;
  using Controller = dopri5::Controller;
  static constexpr int kOrder = 5;
};

}  // namespace bouncecal::dopri5
