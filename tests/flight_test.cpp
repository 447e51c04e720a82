// Tests for the exact vertical flight (flight.hpp): vacuum oracles, drag limits, the inverse,
// energy, and a brute-force RK4 integration of the equations of motion.
#include "bouncecal/physics/flight.hpp"

#include <cmath>
#include <functional>
#include <vector>

#include <gtest/gtest.h>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

constexpr double kG = 9.8;

std::vector<FlightModel> AllModels() {
  return {FlightModel::Vacuum(kG), FlightModel::Quadratic(kG, 9.0),
          FlightModel::Quadratic(kG, 42.5), FlightModel::Linear(kG, 0.5),
          FlightModel::Linear(kG, 3.0)};
}

std::vector<double> Speeds() {
  std::vector<double> v;
  for (double e = -7; e <= 3.01; e += 0.5) v.push_back(std::pow(10.0, e));
  return v;
}

// Acceleration of the model's ODE (docs/physics.md §2), written independently of flight.cpp.
double Accel(const FlightModel& f, double v) {
  const double g = f.gravity_m_s2();
  switch (f.drag()) {
    case DragModel::kNone:
      return -g;
    case DragModel::kQuadratic: {
      const double vt = f.terminal_speed_m_s();
      return -g - g / (vt * vt) * v * std::abs(v);
    }
    case DragModel::kLinear:
      return -g - g / f.terminal_speed_m_s() * v;
  }
  return 0.0;
}

struct RkState {
  double z, v;
};

RkState Rk4Step(const FlightModel& f, RkState s, double h) {
  const double k1z = s.v, k1v = Accel(f, s.v);
  const double k2z = s.v + 0.5 * h * k1v, k2v = Accel(f, s.v + 0.5 * h * k1v);
  const double k3z = s.v + 0.5 * h * k2v, k3v = Accel(f, s.v + 0.5 * h * k2v);
  const double k4z = s.v + h * k3v, k4v = Accel(f, s.v + h * k3v);
  return {s.z + h / 6 * (k1z + 2 * k2z + 2 * k3z + k4z),
          s.v + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)};
}

struct Rk4Flight {
  double flight_time_s, apex_m, arrival_m_s;
};

// Integrates from z = 0, v = v0 with a fixed tiny step until z returns to 0; the crossing is
// located by bisection on the size of the last RK4 step (a 4th-order map), not "the first step
// that crossed". The apex is located the same way on v = 0.
Rk4Flight BruteForce(const FlightModel& f, double v0, int steps) {
  const double h = 2.0 * v0 / f.gravity_m_s2() / steps;  // vacuum flight time / steps
  RkState s{0.0, v0};
  double t = 0.0;
  double apex = 0.0;
  bool apex_found = false;
  for (int i = 0; i < 10 * steps; ++i) {
    RkState n = Rk4Step(f, s, h);
    if (!apex_found && n.v <= 0.0) {
      double lo = 0.0, hi = h;
      for (int k = 0; k < 100; ++k) {
        const double mid = 0.5 * (lo + hi);
        (Rk4Step(f, s, mid).v > 0.0 ? lo : hi) = mid;
      }
      apex = Rk4Step(f, s, 0.5 * (lo + hi)).z;
      apex_found = true;
    }
    if (n.z <= 0.0 && t > 0.0) {
      double lo = 0.0, hi = h;
      for (int k = 0; k < 100; ++k) {
        const double mid = 0.5 * (lo + hi);
        (Rk4Step(f, s, mid).z > 0.0 ? lo : hi) = mid;
      }
      const double dt = 0.5 * (lo + hi);
      return {t + dt, apex, -Rk4Step(f, s, dt).v};
    }
    s = n;
    t += h;
  }
  ADD_FAILURE() << "RK4 flight did not land";
  return {0, 0, 0};
}

TEST(FlightTest, VacuumOracles) {
  const FlightModel f = FlightModel::Vacuum(kG);
  EXPECT_EQ(f.drag(), DragModel::kNone);
  EXPECT_TRUE(std::isinf(f.terminal_speed_m_s()));
  for (double v0 : Speeds()) {
    EXPECT_DOUBLE_EQ(f.FlightTime(v0), 2 * v0 / kG);
    EXPECT_DOUBLE_EQ(f.RiseTime(v0), v0 / kG);
    EXPECT_DOUBLE_EQ(f.ApexHeight(v0), v0 * v0 / (2 * kG));
    EXPECT_DOUBLE_EQ(f.ArrivalSpeed(v0), v0);
    EXPECT_DOUBLE_EQ(f.FlightTimeDerivative(v0), 2 / kG);
  }
  // Seed 002: the unheard first interval dt0 = 2 sqrt(2h/g) = 0.4040 s for h = 0.2 m (the paper
  // truncates 0.40406 s).
  EXPECT_NEAR(2 * f.FallTime(0.2), 0.40406, 1e-5);
  EXPECT_DOUBLE_EQ(f.FallArrivalSpeed(0.2), std::sqrt(2 * kG * 0.2));
  double z = 0, v = 0;
  f.State(2.0, 0.1, &z, &v);
  EXPECT_DOUBLE_EQ(z, 0.2 - 0.5 * kG * 0.01);
  EXPECT_DOUBLE_EQ(v, 2.0 - kG * 0.1);
}

TEST(FlightTest, QuadraticDragClosedFormsFromPhysicsMd) {
  // docs/physics.md §2, written literally: t_up = (v_t/g) atan(v0/v_t), H = (v_t^2/2g)
  // ln(1+v0^2/v_t^2), t_down = (v_t/g) acosh(exp(gH/v_t^2)), v_in = v_t sqrt(1 - exp(-2gH/v_t^2)).
  const double vt = 9.0;
  const FlightModel f = FlightModel::Quadratic(kG, vt);
  for (double v0 : {0.3, 2.0, 8.0, 30.0}) {
    const double t_up = vt / kG * std::atan(v0 / vt);
    const double h = vt * vt / (2 * kG) * std::log(1 + v0 * v0 / (vt * vt));
    const double t_down = vt / kG * std::acosh(std::exp(kG * h / (vt * vt)));
    const double v_in = vt * std::sqrt(1 - std::exp(-2 * kG * h / (vt * vt)));
    EXPECT_NEAR(f.RiseTime(v0), t_up, 1e-14 * t_up);
    EXPECT_NEAR(f.ApexHeight(v0), h, 1e-13 * h);
    EXPECT_NEAR(f.FlightTime(v0), t_up + t_down, 1e-12 * (t_up + t_down));
    EXPECT_NEAR(f.ArrivalSpeed(v0), v_in, 1e-12 * v_in);
    EXPECT_NEAR(f.FallTime(h), t_down, 1e-12 * t_down);
    EXPECT_NEAR(f.FallArrivalSpeed(h), v_in, 1e-12 * v_in);
  }
}

TEST(FlightTest, DragVanishingReproducesVacuum) {
  const FlightModel vac = FlightModel::Vacuum(kG);
  for (double vt : {1e4, 1e6}) {
    const FlightModel q = FlightModel::Quadratic(kG, vt);
    const FlightModel l = FlightModel::Linear(kG, kG / vt);
    for (double v0 : {1e-6, 0.01, 2.0, 10.0}) {
      // Relative drag effect ~ v0/v_t (linear) or (v0/v_t)^2 (quadratic).
      const double tol_l = 2 * v0 / vt + 1e-14, tol_q = 2 * (v0 / vt) * (v0 / vt) + 1e-14;
      EXPECT_NEAR(q.FlightTime(v0) / vac.FlightTime(v0), 1.0, tol_q);
      EXPECT_NEAR(l.FlightTime(v0) / vac.FlightTime(v0), 1.0, tol_l);
      EXPECT_NEAR(q.ApexHeight(v0) / vac.ApexHeight(v0), 1.0, tol_q);
      EXPECT_NEAR(l.ApexHeight(v0) / vac.ApexHeight(v0), 1.0, tol_l);
      EXPECT_NEAR(q.ArrivalSpeed(v0) / v0, 1.0, tol_q);
      EXPECT_NEAR(l.ArrivalSpeed(v0) / v0, 1.0, tol_l);
      EXPECT_NEAR(q.FlightTimeDerivative(v0) * kG / 2, 1.0, tol_q);
      EXPECT_NEAR(l.FlightTimeDerivative(v0) * kG / 2, 1.0, tol_l);
    }
  }
  // No air: FromScene gives the vacuum model.
  EXPECT_EQ(FlightModel::Linear(kG, 0.0).drag(), DragModel::kNone);
}

TEST(FlightTest, InverseRoundTripToMachinePrecision) {
  for (const FlightModel& f : AllModels()) {
    double worst = 0.0;
    for (double v0 : Speeds()) {
      const double t = f.FlightTime(v0);
      const double back = f.LaunchSpeedForFlightTime(t);
      worst = std::max(worst, std::abs(back - v0) / v0);
      EXPECT_NEAR(f.FlightTime(back), t, 4e-15 * t);
    }
    EXPECT_LT(worst, 1e-14) << DragModelName(f.drag()) << " v_t " << f.terminal_speed_m_s();
    EXPECT_EQ(f.LaunchSpeedForFlightTime(0.0), 0.0);
  }
}

TEST(FlightTest, FlightTimeIsMonotoneAndDerivativeMatchesDifferences) {
  for (const FlightModel& f : AllModels()) {
    double prev = -1.0;
    for (double v0 : Speeds()) {
      const double t = f.FlightTime(v0);
      EXPECT_GT(t, prev);
      prev = t;
      const double h = 1e-5 * v0;
      const double fd = (f.FlightTime(v0 + h) - f.FlightTime(v0 - h)) / (2 * h);
      EXPECT_NEAR(f.FlightTimeDerivative(v0), fd, 1e-7 * fd) << v0;
      const double fa = (f.ArrivalSpeed(v0 + h) - f.ArrivalSpeed(v0 - h)) / (2 * h);
      EXPECT_NEAR(f.ArrivalSpeedDerivative(v0), fa, 1e-7 * std::abs(fa) + 1e-12) << v0;
    }
    EXPECT_NEAR(f.FlightTimeDerivative(0.0), 2 / kG, 1e-12);
    EXPECT_EQ(f.ArrivalSpeedDerivative(0.0), 1.0);
  }
}

TEST(FlightTest, DragLosesEnergyAndShortensFlights) {
  const FlightModel vac = FlightModel::Vacuum(kG);
  for (const FlightModel& f : AllModels()) {
    if (f.drag() == DragModel::kNone) continue;
    for (double v0 : {0.01, 0.5, 2.0, 20.0, 500.0}) {
      EXPECT_LT(f.ArrivalSpeed(v0), v0);
      EXPECT_LE(f.ArrivalSpeed(v0), f.terminal_speed_m_s());
      EXPECT_LT(f.FlightTime(v0), vac.FlightTime(v0));
      EXPECT_LT(f.ApexHeight(v0), vac.ApexHeight(v0));
      // The way down takes longer than the way up.
      EXPECT_GT(f.FlightTime(v0) - f.RiseTime(v0), f.RiseTime(v0));
    }
    // Far above terminal speed the ball comes back at (nearly) terminal speed.
    EXPECT_NEAR(f.ArrivalSpeed(1e4) / f.terminal_speed_m_s(), 1.0, 1e-3);
  }
}

TEST(FlightTest, MatchesBruteForceRk4) {
  for (const FlightModel& f : AllModels()) {
    for (double v0 : {0.05, 2.0, 15.0}) {
      const Rk4Flight rk = BruteForce(f, v0, 40000);
      EXPECT_NEAR(f.FlightTime(v0), rk.flight_time_s, 1e-9 * rk.flight_time_s)
          << DragModelName(f.drag()) << " v0 " << v0;
      EXPECT_NEAR(f.ApexHeight(v0), rk.apex_m, 1e-9 * rk.apex_m);
      EXPECT_NEAR(f.ArrivalSpeed(v0), rk.arrival_m_s, 1e-9 * rk.arrival_m_s);
    }
  }
}

TEST(FlightTest, FallFromRestMatchesRk4) {
  for (const FlightModel& f : AllModels()) {
    for (double h : {1e-4, 0.2, 5.0}) {
      // Integrate from rest downward until the fall distance reaches h.
      const int steps = 40000;
      const double dt = std::sqrt(2 * h / f.gravity_m_s2()) * 1.5 / steps;
      RkState s{h, 0.0};
      double t = 0.0;
      for (int i = 0; i < 10 * steps; ++i) {
        RkState n = Rk4Step(f, s, dt);
        if (n.z <= 0.0) {
          double lo = 0.0, hi = dt;
          for (int k = 0; k < 100; ++k) {
            const double mid = 0.5 * (lo + hi);
            (Rk4Step(f, s, mid).z > 0.0 ? lo : hi) = mid;
          }
          const double tau = 0.5 * (lo + hi);
          t += tau;
          EXPECT_NEAR(f.FallTime(h), t, 1e-9 * t);
          EXPECT_NEAR(f.FallArrivalSpeed(h), -Rk4Step(f, s, tau).v, 1e-9 * std::abs(n.v));
          break;
        }
        s = n;
        t += dt;
      }
    }
  }
}

TEST(FlightTest, StateIsConsistentWithTheFlight) {
  for (const FlightModel& f : AllModels()) {
    for (double v0 : {1e-4, 2.0, 25.0}) {
      const double t_up = f.RiseTime(v0), t_flight = f.FlightTime(v0);
      double z = 0, v = 0;
      f.State(v0, 0.0, &z, &v);
      EXPECT_EQ(z, 0.0);
      EXPECT_NEAR(v, v0, 1e-15 * v0);
      f.State(v0, t_up, &z, &v);
      EXPECT_NEAR(z, f.ApexHeight(v0), 1e-12 * f.ApexHeight(v0));
      EXPECT_NEAR(v, 0.0, 1e-12 * v0);
      f.State(v0, t_flight, &z, &v);
      EXPECT_NEAR(z, 0.0, 1e-12 * f.ApexHeight(v0));
      EXPECT_NEAR(v, -f.ArrivalSpeed(v0), 1e-12 * v0);
      // dz/dt = v inside the flight (central difference).
      for (double frac : {0.2, 0.7}) {
        const double t = frac * t_flight, h = 1e-6 * t_flight;
        double z1, z2, vm;
        f.State(v0, t - h, &z1, nullptr);
        f.State(v0, t + h, &z2, nullptr);
        f.State(v0, t, nullptr, &vm);
        EXPECT_NEAR((z2 - z1) / (2 * h), vm, 1e-6 * v0);
      }
    }
  }
}

TEST(FlightTest, ExtremeSpeedsStayFiniteAndAccurate) {
  // v0 -> 0 (down to 1e-300: series forms, no underflow of x^2) and v0 >> v_t.
  const std::vector<FlightModel> models = {
      FlightModel::Quadratic(kG, 9.0),  FlightModel::Linear(kG, 0.5),
      FlightModel::Quadratic(kG, 1e-3), FlightModel::Linear(kG, 1e3),
      FlightModel::Quadratic(kG, 1e90), FlightModel::Linear(kG, 1e-90)};
  for (const FlightModel& f : models) {
    for (double v0 : {1e-300, 1e-150, 1e-20, 1e-9}) {
      // Far below terminal speed: the vacuum flight to relative order v0/v_t (linear drag) or
      // (v0/v_t)^2 (quadratic).
      const double tol = 4 * v0 / f.terminal_speed_m_s() + 1e-13;
      EXPECT_NEAR(f.FlightTime(v0) / (2 * v0 / kG), 1.0, tol) << v0;
      EXPECT_NEAR(f.RiseTime(v0) / (v0 / kG), 1.0, tol) << v0;
      EXPECT_NEAR(f.ArrivalSpeed(v0) / v0, 1.0, tol) << v0;
      EXPECT_NEAR(f.LaunchSpeedForFlightTime(f.FlightTime(v0)) / v0, 1.0, 1e-14) << v0;
      EXPECT_NEAR(f.FlightTimeDerivative(v0) * kG / 2, 1.0, tol);
      EXPECT_NEAR(f.ArrivalSpeedDerivative(v0), 1.0, 2 * tol);
    }
    EXPECT_NEAR(f.ApexHeight(1e-20) / (1e-40 / (2 * kG)), 1.0, 1e-12);
    EXPECT_NEAR(f.FallTime(1e-300) / std::sqrt(2e-300 / kG), 1.0, 1e-12);
    EXPECT_NEAR(f.FallArrivalSpeed(1e-300) / std::sqrt(2 * kG * 1e-300), 1.0, 1e-12);
    for (double v0 : {1e3, 1e20, 1e300}) {
      const double t = f.FlightTime(v0);
      EXPECT_TRUE(std::isfinite(t) && t > 0) << v0;
      EXPECT_FALSE(std::isnan(f.ApexHeight(v0))) << v0;  // may overflow: H > 1e308 m
      EXPECT_LE(f.ArrivalSpeed(v0), std::min(v0, f.terminal_speed_m_s()) * (1 + 1e-15));
      double z = 0, v = 0;
      f.State(v0, 0.5 * t, &z, &v);
      EXPECT_FALSE(std::isnan(z) || std::isnan(v)) << v0;
    }
    EXPECT_NEAR(f.LaunchSpeedForFlightTime(f.FlightTime(1e20)) / 1e20, 1.0, 1e-13);
  }
  // Drag too weak to matter in double precision is dropped (its square would overflow).
  EXPECT_EQ(FlightModel::Quadratic(kG, 1e200).drag(), DragModel::kNone);
  EXPECT_EQ(FlightModel::Linear(kG, 1e-200).drag(), DragModel::kNone);
}

TEST(FlightTest, FromSceneUsesTheSceneEffects) {
  Scene s;  // 1 cm steel ball, drag off
  EXPECT_EQ(FlightModel::FromScene(s).drag(), DragModel::kNone);
  EXPECT_EQ(FlightModel::FromScene(s).gravity_m_s2(), 9.8);
  s.effects.drag = DragModel::kQuadratic;
  const FlightModel q = FlightModel::FromScene(s);
  const double area = M_PI * 0.01 * 0.01 / 4, mass = 7800 * M_PI * 1e-6 / 6;
  const double vt = std::sqrt(2 * mass * 9.8 / (1.2 * 0.47 * area));
  EXPECT_NEAR(q.terminal_speed_m_s(), vt, 1e-12 * vt);
  // docs/physics.md §2: a 1 cm steel ball at 2 m/s feels drag/gravity ~ 0.2 %.
  EXPECT_NEAR((2 / vt) * (2 / vt), 0.002, 0.0005);
  s.effects.drag = DragModel::kLinear;
  const FlightModel l = FlightModel::FromScene(s);
  EXPECT_NEAR(kG / l.terminal_speed_m_s(), 3 * M_PI * 1.81e-5 * 0.01 / mass, 1e-15);
  s.effects.buoyancy = true;
  EXPECT_NEAR(FlightModel::FromScene(s).gravity_m_s2(), 9.8 * (1 - 1.2 / 7800), 1e-14);
}

TEST(FlightTest, InvalidInputsThrow) {
  EXPECT_THROW(FlightModel::Vacuum(0.0), Error);
  EXPECT_THROW(FlightModel::Vacuum(std::nan("")), Error);
  EXPECT_THROW(FlightModel::Quadratic(kG, -1.0), Error);
  EXPECT_THROW(FlightModel::Linear(kG, -0.1), Error);
  const FlightModel f = FlightModel::Quadratic(kG, 9.0);
  try {
    f.FlightTime(-1.0);
    FAIL() << "negative v0 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  }
  EXPECT_THROW(f.LaunchSpeedForFlightTime(std::nan("")), Error);
  EXPECT_THROW(f.FallTime(-0.1), Error);
}

}  // namespace
}  // namespace bouncecal
