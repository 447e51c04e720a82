// Exact vertical flight between impacts: docs/physics.md §2.
//
// Equations of motion (z up, v = dz/dt, g = effective gravity incl. buoyancy):
//   vacuum:     dv/dt = -g
//   quadratic:  dv/dt = -g - (g / v_t^2) v |v|          (v_t = terminal speed)
//   linear:     dv/dt = -g - r v                          (r = 3 pi mu d / m, v_t = g / r)
// Added mass of the displaced air is neglected (rho_air / rho_ball ~ 1e-4 for steel).
//
// Every closed form below is written so that it stays accurate for v0 -> 0 and v0 >> v_t and
// reduces smoothly to the vacuum result as v_t -> infinity (atan/asinh/log1p/expm1 forms and
// short series where a difference of nearly equal terms would cancel).
//
// Quadratic drag, x = v0 / v_t (e.g. Timoshenko & Young, "Advanced Dynamics", §2; docs/physics.md
// §2):
//   t_up   = (v_t/g) atan(x)                 apex H = (v_t^2 / 2g) ln(1 + x^2)
//   t_down = (v_t/g) acosh(exp(gH/v_t^2)) = (v_t/g) asinh(x)      (since exp(gH/v_t^2) =
//   sqrt(1+x^2)) v_in   = v_t sqrt(1 - exp(-2gH/v_t^2)) = v0 / sqrt(1 + x^2)
// Linear drag, x = v0 / v_t:
//   t_up = ln(1 + x) / r,  H = (v_t / r) (x - ln(1 + x))
//   fall from rest for time s, y = r s: distance (v_t / r) phi(y), phi(y) = y - 1 + exp(-y),
//   speed v_t (1 - exp(-y)); the descent time solves phi(y) = x - ln(1 + x) (monotone 1-D solve).
#include "bouncecal/physics/flight.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"

namespace bouncecal {
namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kEps = std::numeric_limits<double>::epsilon();

// phi(y) = y - 1 + exp(-y) = y + expm1(-y), accurate for small y (series) and large y.
double Phi(double y) {
  if (std::abs(y) < 0.125) {
    // y^2/2 - y^3/6 + y^4/24 - ... ; 14 terms give full precision for |y| < 1/8.
    double term = 0.5 * y * y;
    double sum = term;
    for (int n = 3; n <= 16; ++n) {
      term *= -y / n;
      sum += term;
    }
    return sum;
  }
  return y + std::expm1(-y);
}

// psi(x) = x - ln(1 + x), accurate for small x (series) and large x.
double Psi(double x) {
  if (std::abs(x) < 0.125) {
    // x^2/2 - x^3/3 + x^4/4 - ...
    double power = x * x;
    double sum = 0.0;
    double sign = 1.0;
    for (int n = 2; n <= 20; ++n) {
      sum += sign * power / n;
      power *= x;
      sign = -sign;
    }
    return sum;
  }
  return x - std::log1p(x);
}

// ln cosh(b) for b >= 0 without overflow or cancellation.
double LogCosh(double b) {
  if (b < 1.0) {
    const double s = std::sinh(0.5 * b);
    return std::log1p(2.0 * s * s);
  }
  return b + std::log1p(std::exp(-2.0 * b)) - std::log(2.0);
}

// Ratios that tend to 1 as x -> 0, evaluated without underflow (series below 1e-8, where the
// next term is < 1e-16 relative).
double AtanRatio(double x) { return x < 1e-8 ? 1.0 - x * x / 3.0 : std::atan(x) / x; }
double AsinhRatio(double x) { return x < 1e-8 ? 1.0 - x * x / 6.0 : std::asinh(x) / x; }
double Log1pRatio(double x) { return x < 1e-8 ? 1.0 - 0.5 * x : std::log1p(x) / x; }
// ln(1 + x^2) without overflow of x^2.
double Log1pSquare(double x) {
  return x > 1e100 ? 2.0 * std::log(x) + std::log1p(1.0 / (x * x)) : std::log1p(x * x);
}

// Safeguarded Newton for an increasing function F on [lo, hi] with F(lo) <= 0 <= F(hi):
// Newton steps from z0, bisection whenever a step leaves the bracket or does not shrink it
// fast enough. Converges to machine precision (the bracket or step reaches a few ulp).
template <typename Residual>
double SolveIncreasing(Residual&& residual, double lo, double hi, double z0) {
  assert(lo <= hi);
  double z = std::clamp(z0, lo, hi);
  double last_step = hi - lo;
  for (int iter = 0; iter < 200; ++iter) {
    double f = 0.0;
    double df = 0.0;
    residual(z, &f, &df);
    if (f == 0.0) return z;
    if (f < 0.0) {
      lo = z;
    } else {
      hi = z;
    }
    double next = (df > 0.0 && std::isfinite(df)) ? z - f / df : std::nan("");
    const bool newton_ok = std::isfinite(next) && next > lo && next < hi &&
                           std::abs(next - z) <= 0.5 * last_step + 4.0 * kEps * std::abs(z);
    if (!newton_ok) next = 0.5 * (lo + hi);
    last_step = std::abs(next - z);
    z = next;
    if (last_step <= 2.0 * kEps * std::abs(z) || hi - lo <= 2.0 * kEps * std::abs(z) ||
        last_step == 0.0) {
      return z;
    }
  }
  return z;
}

// Descent variable y = r * t_down of a linear-drag fall through the scaled height psi >= 0:
// phi(y) = psi. Solved as sqrt(2 phi(y)) = sqrt(2 psi), which is ~linear near 0 and concave;
// bracket: phi(y) <= y^2/2  =>  y >= sqrt(2 psi);  phi(y) >= y - 1  =>  y <= psi + 1.
double LinearDescentY(double psi) {
  if (psi <= 0.0) return 0.0;
  const double s = std::sqrt(2.0 * psi);
  // Series y = s + s^2/6 + O(s^3) (phi(y) = y^2/2 - y^3/6 + ...), exact to < 1e-16 here; also
  // keeps phi(y) ~ y^2/2 from underflowing for tiny heights.
  if (psi < 1e-30) return s + s * s / 6.0;
  const double lo = s;
  const double hi = std::max(s, psi + 1.0);
  auto residual = [s](double y, double* f, double* df) {
    const double p = Phi(y);
    const double root = std::sqrt(2.0 * p);
    *f = root - s;
    // d/dy sqrt(2 phi) = phi'(y) / sqrt(2 phi), phi'(y) = 1 - exp(-y) = -expm1(-y).
    *df = root > 0.0 ? -std::expm1(-y) / root : 1.0;
  };
  return SolveIncreasing(residual, lo, hi, lo);
}

// The same descent variable for a launch at x = v0 / v_t: phi(y) = psi(x). For tiny x,
// y = x - x^2/6 + O(x^3) (psi(x) = x^2/2 - x^3/3 + ...), which avoids the underflow of x^2.
double LinearDescentYForLaunch(double x) {
  return x < 1e-8 ? x - x * x / 6.0 : LinearDescentY(Psi(x));
}

// A flight input must be finite and >= 0. The message names the quantity and where it comes
// from (the scene's drop, or a rebound), not this class's functions: users never call them.
void CheckFinite(double value, const char* what, const char* unit) {
  if (!std::isfinite(value) || value < 0.0) {
    throw Error(ErrorCode::kBadParameter,
                std::string("ball flight: ") + what + " = " + FormatGeneral(value) + " " + unit +
                    " must be a finite number >= 0 (check the drop height or impact speed, "
                    "environment.g_m_s2 and the contact law's parameters)");
  }
}

}  // namespace

FlightModel FlightModel::Vacuum(double g_eff_m_s2) {
  if (!(g_eff_m_s2 > 0.0) || !std::isfinite(g_eff_m_s2)) {
    throw Error(ErrorCode::kBadParameter,
                "flight: effective gravity must be finite and > 0 m/s^2 (got " +
                    std::to_string(g_eff_m_s2) + ")");
  }
  return FlightModel(DragModel::kNone, g_eff_m_s2, 0.0);
}

FlightModel FlightModel::Quadratic(double g_eff_m_s2, double terminal_speed_m_s) {
  FlightModel vac = Vacuum(g_eff_m_s2);
  // A terminal speed above 1e100 m/s changes no result in double precision for any physical
  // speed (relative effect (v0/v_t)^2), but its square would overflow: treat it as no drag.
  if (terminal_speed_m_s > 1e100) return vac;
  if (!(terminal_speed_m_s > 0.0) || !std::isfinite(terminal_speed_m_s)) {
    throw Error(ErrorCode::kBadParameter, "flight: terminal speed must be > 0 m/s (got " +
                                              std::to_string(terminal_speed_m_s) + ")");
  }
  return FlightModel(DragModel::kQuadratic, g_eff_m_s2, terminal_speed_m_s);
}

FlightModel FlightModel::Linear(double g_eff_m_s2, double rate_per_s) {
  FlightModel vac = Vacuum(g_eff_m_s2);
  // No drag, or so little that v_t = g / rate exceeds 1e100 m/s (see Quadratic).
  if (rate_per_s == 0.0 || (rate_per_s > 0.0 && g_eff_m_s2 / rate_per_s > 1e100)) return vac;
  if (!(rate_per_s > 0.0) || !std::isfinite(rate_per_s)) {
    throw Error(ErrorCode::kBadParameter,
                "flight: linear drag rate must be finite and >= 0 1/s (got " +
                    std::to_string(rate_per_s) + ")");
  }
  return FlightModel(DragModel::kLinear, g_eff_m_s2, rate_per_s);
}

FlightModel FlightModel::FromScene(const Scene& scene) {
  const double g = scene.EffectiveGravity();
  const Ball& ball = scene.ball;
  const Environment& env = scene.environment;
  switch (scene.effects.drag) {
    case DragModel::kNone:
      return Vacuum(g);
    case DragModel::kQuadratic: {
      // v_t = sqrt(2 m g_eff / (rho_a C_d A)), A = pi d^2 / 4 (docs/physics.md §2).
      const double area_m2 = M_PI * ball.diameter_m * ball.diameter_m / 4.0;
      const double denom = env.air_density_kg_m3 * env.drag_coefficient * area_m2;
      if (denom <= 0.0) return Vacuum(g);  // no air: no drag
      return Quadratic(g, std::sqrt(2.0 * ball.Mass() * g / denom));
    }
    case DragModel::kLinear: {
      // Stokes drag F = 3 pi mu d v  =>  rate = 3 pi mu d / m.
      const double rate = 3.0 * M_PI * env.air_viscosity_pa_s * ball.diameter_m / ball.Mass();
      return Linear(g, rate);
    }
  }
  return Vacuum(g);
}

double FlightModel::terminal_speed_m_s() const {
  switch (drag_) {
    case DragModel::kNone:
      return kInf;
    case DragModel::kQuadratic:
      return p_;
    case DragModel::kLinear:
      return g_ / p_;
  }
  return kInf;
}

double FlightModel::RiseTime(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return v0_m_s / g_;
    case DragModel::kQuadratic:
      return v0_m_s / g_ * AtanRatio(v0_m_s / p_);
    case DragModel::kLinear:
      return v0_m_s / g_ * Log1pRatio(v0_m_s * p_ / g_);
  }
  return 0.0;
}

double FlightModel::ApexHeight(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return v0_m_s * v0_m_s / (2.0 * g_);
    case DragModel::kQuadratic: {
      const double x = v0_m_s / p_;
      if (x < 1e-8) return v0_m_s * v0_m_s / (2.0 * g_) * (1.0 - 0.5 * x * x);
      return p_ * p_ / (2.0 * g_) * Log1pSquare(x);
    }
    case DragModel::kLinear: {
      const double vt = g_ / p_;
      const double x = v0_m_s / vt;
      // psi(x) = x^2/2 (1 - 2x/3 + ...): v0^2/(2g) form for tiny x (no underflow of x^2).
      if (x < 1e-8) return v0_m_s * v0_m_s / (2.0 * g_) * (1.0 - 2.0 * x / 3.0);
      return vt / p_ * Psi(x);
    }
  }
  return 0.0;
}

double FlightModel::FlightTime(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return 2.0 * v0_m_s / g_;
    case DragModel::kQuadratic: {
      const double x = v0_m_s / p_;
      return v0_m_s / g_ * (AtanRatio(x) + AsinhRatio(x));
    }
    case DragModel::kLinear: {
      const double x = v0_m_s * p_ / g_;
      if (x < 1e-8) return v0_m_s / g_ * (2.0 - 2.0 * x / 3.0);  // (ln(1+x) + y) / r, series
      return (std::log1p(x) + LinearDescentYForLaunch(x)) / p_;
    }
  }
  return 0.0;
}

double FlightModel::ArrivalSpeed(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return v0_m_s;
    case DragModel::kQuadratic: {
      const double x = v0_m_s / p_;
      return v0_m_s / std::hypot(1.0, x);
    }
    case DragModel::kLinear: {
      const double vt = g_ / p_;
      const double x = v0_m_s / vt;
      if (x < 1e-8) return v0_m_s * (1.0 - 2.0 * x / 3.0);  // v_t (y - y^2/2), y = x - x^2/6
      const double y = LinearDescentYForLaunch(x);
      return -vt * std::expm1(-y);
    }
  }
  return 0.0;
}

double FlightModel::FlightTimeDerivative(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return 2.0 / g_;
    case DragModel::kQuadratic: {
      // d/dv0 (v_t/g)(atan x + asinh x) = (1/g)(1/(1+x^2) + 1/sqrt(1+x^2)).
      const double x = v0_m_s / p_;
      const double h = std::hypot(1.0, x);
      return (1.0 / (h * h) + 1.0 / h) / g_;
    }
    case DragModel::kLinear: {
      // T = (ln(1+x) + y(x)) / r, phi(y) = psi(x), x = v0 r / g:
      // dT/dv0 = (1/g) (1/(1+x) + psi'(x)/phi'(y)), psi' = x/(1+x), phi' = 1 - exp(-y).
      const double x = v0_m_s * p_ / g_;
      if (x == 0.0) return 2.0 / g_;
      const double y = LinearDescentYForLaunch(x);
      const double dphi = -std::expm1(-y);
      const double ratio = dphi > 0.0 ? (x / (1.0 + x)) / dphi : 1.0;
      return (1.0 / (1.0 + x) + ratio) / g_;
    }
  }
  return 0.0;
}

double FlightModel::ArrivalSpeedDerivative(double v0_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  switch (drag_) {
    case DragModel::kNone:
      return 1.0;
    case DragModel::kQuadratic: {
      // d/dv0 [v0 (1 + x^2)^(-1/2)] = (1 + x^2)^(-3/2).
      const double h = std::hypot(1.0, v0_m_s / p_);
      return 1.0 / (h * h * h);
    }
    case DragModel::kLinear: {
      // v_in = v_t (1 - e^{-y}), phi(y) = psi(x): dv_in/dv0 = e^{-y} psi'(x) / phi'(y).
      const double x = v0_m_s * p_ / g_;
      if (x == 0.0) return 1.0;
      const double y = LinearDescentYForLaunch(x);
      const double dphi = -std::expm1(-y);
      return dphi > 0.0 ? std::exp(-y) * (x / (1.0 + x)) / dphi : 1.0;
    }
  }
  return 1.0;
}

double FlightModel::LaunchSpeedForFlightTime(double flight_time_s) const {
  CheckFinite(flight_time_s, "the flight time", "s");
  if (flight_time_s == 0.0) return 0.0;
  switch (drag_) {
    case DragModel::kNone:
      return 0.5 * g_ * flight_time_s;
    case DragModel::kQuadratic: {
      // With u = asinh(x): g T / v_t = u + gd(u), gd(u) = atan(sinh u) (Gudermannian), whose
      // derivative 1 + sech(u) lies in (1, 2]: Newton is well conditioned for every T.
      // Bracket: u <= u + gd(u) <= 2u  =>  tau/2 <= u <= tau.
      const double tau = g_ * flight_time_s / p_;
      // Small tau: v0 = (gT/2)(1 + tau^2/16 + O(tau^4)) (series of the relation above).
      if (tau < 1e-5) return 0.5 * g_ * flight_time_s * (1.0 + tau * tau / 16.0);
      auto residual = [tau](double u, double* f, double* df) {
        *f = u + std::atan(std::sinh(u)) - tau;
        *df = 1.0 + 1.0 / std::cosh(u);
      };
      const double u = SolveIncreasing(residual, 0.5 * tau, tau, 0.5 * tau);
      return p_ * std::sinh(u);
    }
    case DragModel::kLinear: {
      // r T = ln(1+x) + y(x). Drag shortens the flight (x >= r T / 2) and, since phi(y) <= y,
      // y >= psi(x) so r T >= x: bracket [rT/2, rT].
      const double rt = p_ * flight_time_s;
      // Small rT: v0 = (gT/2)(1 + rT/6 + O((rT)^2)).
      if (rt < 1e-8) return 0.5 * g_ * flight_time_s * (1.0 + rt / 6.0);
      auto residual = [rt](double x, double* f, double* df) {
        const double y = LinearDescentYForLaunch(x);
        *f = std::log1p(x) + y - rt;
        const double dphi = -std::expm1(-y);
        const double ratio = dphi > 0.0 ? (x / (1.0 + x)) / dphi : 1.0;
        *df = 1.0 / (1.0 + x) + ratio;
      };
      const double x = SolveIncreasing(residual, 0.5 * rt, rt, 0.5 * rt);
      return x * g_ / p_;
    }
  }
  return 0.0;
}

double FlightModel::FallTime(double height_m) const {
  CheckFinite(height_m, "the drop height", "m");
  switch (drag_) {
    case DragModel::kNone:
      return std::sqrt(2.0 * height_m / g_);
    case DragModel::kQuadratic: {
      // t = (v_t/g) acosh(exp(q)), q = g h / v_t^2; acosh(exp(q)) = asinh(sqrt(expm1(2q))).
      const double q = g_ * height_m / (p_ * p_);
      // Small q: t = sqrt(2h/g) (1 + q/6 + O(q^2)) (cosh b = e^q), no underflow of q.
      if (q < 1e-8) return std::sqrt(2.0 * height_m / g_) * (1.0 + q / 6.0);
      const double b = q > 300.0 ? q + std::log(2.0) : std::asinh(std::sqrt(std::expm1(2.0 * q)));
      return p_ / g_ * b;
    }
    case DragModel::kLinear: {
      // phi(r t) = h r / v_t.
      // phi(r t) = h r / v_t; for tiny s = r sqrt(2h/g): t = sqrt(2h/g) (1 + s/6).
      const double vt = g_ / p_;
      const double s = p_ * std::sqrt(2.0 * height_m / g_);
      if (s < 1e-15) return std::sqrt(2.0 * height_m / g_) * (1.0 + s / 6.0);
      return LinearDescentY(height_m * p_ / vt) / p_;
    }
  }
  return 0.0;
}

double FlightModel::FallArrivalSpeed(double height_m) const {
  CheckFinite(height_m, "the drop height", "m");
  switch (drag_) {
    case DragModel::kNone:
      return std::sqrt(2.0 * g_ * height_m);
    case DragModel::kQuadratic: {
      // v = v_t sqrt(1 - exp(-2 g h / v_t^2)).
      const double q = g_ * height_m / (p_ * p_);
      if (q < 1e-8) return std::sqrt(2.0 * g_ * height_m) * (1.0 - 0.5 * q);
      return p_ * std::sqrt(-std::expm1(-2.0 * q));
    }
    case DragModel::kLinear: {
      const double vt = g_ / p_;
      const double s = p_ * std::sqrt(2.0 * height_m / g_);
      if (s < 1e-15) return std::sqrt(2.0 * g_ * height_m) * (1.0 - s / 3.0);
      return -vt * std::expm1(-LinearDescentY(height_m * p_ / vt));
    }
  }
  return 0.0;
}

void FlightModel::State(double v0_m_s, double t_s, double* height_m, double* velocity_m_s) const {
  CheckFinite(v0_m_s, "the launch speed", "m/s");
  CheckFinite(t_s, "the time since launch", "s");
  double z = 0.0;
  double v = 0.0;
  switch (drag_) {
    case DragModel::kNone:
      z = v0_m_s * t_s - 0.5 * g_ * t_s * t_s;
      v = v0_m_s - g_ * t_s;
      break;
    case DragModel::kQuadratic: {
      const double vt = p_;
      const double x = v0_m_s / vt;
      const double t_up = RiseTime(v0_m_s);
      if (t_s <= t_up) {
        // v = v_t tan(atan x - a), z = (v_t^2/g) ln(cos(atan x - a)/cos(atan x)),
        // cos(atan x - a)/cos(atan x) = cos a + x sin a, a = g t / v_t.
        const double a = g_ * t_s / vt;
        const double sa = std::sin(0.5 * a);
        z = vt * vt / g_ * std::log1p(x * std::sin(a) - 2.0 * sa * sa);
        const double ta = std::tan(a);
        v = vt * (x - ta) / (1.0 + x * ta);
      } else {
        // Fall from rest at the apex for s = t - t_up: v = -v_t tanh(b), fallen (v_t^2/g) ln cosh
        // b.
        const double b = g_ * (t_s - t_up) / vt;
        z = ApexHeight(v0_m_s) - vt * vt / g_ * LogCosh(b);
        v = -vt * std::tanh(b);
      }
      break;
    }
    case DragModel::kLinear: {
      const double r = p_;
      const double vt = g_ / r;
      const double x = v0_m_s / vt;
      const double t_up = RiseTime(v0_m_s);
      if (t_s <= t_up) {
        // v = (v0 + v_t) e^{-rt} - v_t,  z = v0 t - (v0 + v_t) phi(r t) / r.
        const double a = r * t_s;
        z = v0_m_s * t_s - (v0_m_s + vt) * Phi(a) / r;
        v = v0_m_s + (v0_m_s + vt) * std::expm1(-a);
      } else {
        const double y = r * (t_s - t_up);
        z = vt / r * (Psi(x) - Phi(y));
        v = vt * std::expm1(-y);
      }
      break;
    }
  }
  if (height_m != nullptr) *height_m = z;
  if (velocity_m_s != nullptr) *velocity_m_s = v;
}

}  // namespace bouncecal
