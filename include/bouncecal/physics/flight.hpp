// bouncecal/physics/flight.hpp — exact vertical flight of a ball between impacts.
//
// Closed forms for vertical motion under gravity (with buoyancy when the scene asks) and no,
// linear (Stokes) or quadratic air drag: docs/physics.md §2. Used by analyze (to turn measured
// intervals into speeds), by the simulator (flights are never integrated numerically) and by
// the renderer. All functions are pure, thread-safe and valid for v0 from 0 to far above the
// terminal speed.
//
//   FlightModel f = FlightModel::FromScene(scene);
//   double T = f.FlightTime(2.0);               // s, up-and-down from a rebound at 2 m/s
//   double v = f.LaunchSpeedForFlightTime(T);    // m/s, inverse (monotone)
#pragma once

#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

class FlightModel {
 public:
  // No drag; gravity g_eff (m/s^2).
  static FlightModel Vacuum(double g_eff_m_s2);
  // Quadratic drag with terminal speed v_t (m/s).
  static FlightModel Quadratic(double g_eff_m_s2, double terminal_speed_m_s);
  // Linear drag dv/dt = -g - rate * v, rate = 3 pi mu d / m (1/s).
  static FlightModel Linear(double g_eff_m_s2, double rate_per_s);
  // The model the scene's effects call for (drag, buoyancy).
  static FlightModel FromScene(const Scene& scene);

  DragModel drag() const { return drag_; }
  double gravity_m_s2() const { return g_; }
  double terminal_speed_m_s() const;  // infinite for no drag

  // Up-and-down flight launched upward at v0 >= 0, back to the launch height.
  double RiseTime(double v0_m_s) const;
  double ApexHeight(double v0_m_s) const;
  double FlightTime(double v0_m_s) const;
  double ArrivalSpeed(double v0_m_s) const;                     // speed when back at launch height
  double LaunchSpeedForFlightTime(double flight_time_s) const;  // inverse of FlightTime
  // dFlightTime/dv0 (s per m/s), for error propagation.
  double FlightTimeDerivative(double v0_m_s) const;
  // dArrivalSpeed/dv0 (dimensionless), for error propagation (1 without drag).
  double ArrivalSpeedDerivative(double v0_m_s) const;

  // Fall from rest through height h >= 0.
  double FallTime(double height_m) const;
  double FallArrivalSpeed(double height_m) const;

  // Height above launch and upward velocity at time t after launching at v0 (0 <= t <= T).
  // Used by the simulator's dense output and by the renderer.
  void State(double v0_m_s, double t_s, double* height_m, double* velocity_m_s) const;

 private:
  FlightModel(DragModel d, double g, double p) : drag_(d), g_(g), p_(p) {}
  DragModel drag_;
  double g_;
  double p_;  // terminal speed (quadratic) or rate (linear)
};

}  // namespace bouncecal
