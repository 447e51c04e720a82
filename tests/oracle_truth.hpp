// tests/oracle_truth.hpp — bounce sequences whose truth shares no code with the fitter's model.
//
// Each contact is integrated by the independent Boost.Odeint law oracle (law_oracle.hpp, gravity
// on during the contact, as for a real ball); the flights between contacts use the exact flight
// formulas (flight.hpp, tested against an independent RK4 in flight_test). Optional per-bounce
// restitution scatter (docs/physics.md §6) and Gaussian timing noise on the onsets. So a
// calibration round trip on these sequences cannot hide a simulator bug behind the same simulator.
#pragma once

#include <cmath>
#include <random>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "law_oracle.hpp"

namespace oracle_truth {

struct Options {
  double scatter_e = 0.0;            // per-bounce scatter of e
  double timing_sigma_s = 0.0;       // Gaussian noise added to each onset (and reported)
  double reported_sigma_s = 0.0;     // reported sigma when no noise is added (> 0 for weights)
  bool contact_in_interval = false;  // onset-to-onset intervals include the oracle contact time
  double min_interval_s = 0.004;
  int max_impacts = 200;
  double t_offset_s = 1.0;
  std::uint64_t seed = 1;
};

struct Truth {
  bouncecal::Sequence sequence;
  std::vector<double> e;     // each bounce's true e (with its scatter)
  std::vector<double> v_in;  // true arrival speeds
};

// The scene's law with its parameters (scene.law) from the scene's drop.
inline Truth Make(const bouncecal::Scene& scene, const Options& o) {
  using namespace bouncecal;
  auto law = CreateLaw(scene.law, scene);
  const std::vector<double> p = law->ParameterValues();
  const ContactBody body = BodyFromScene(scene);
  const FlightModel flight = FlightModel::FromScene(scene);
  oracle::Options oo;
  oo.g_m_s2 = scene.EffectiveGravity();
  std::mt19937_64 rng(o.seed);
  std::normal_distribution<double> z(0.0, 1.0);
  double v = scene.drop.impact_speed_m_s ? *scene.drop.impact_speed_m_s
                                         : flight.FallArrivalSpeed(*scene.drop.height_m);
  double t = o.t_offset_s;
  Truth out;
  for (int k = 0; k < o.max_impacts; ++k) {
    const oracle::Result r = oracle::Integrate(*law, p, body, v, oo);
    const double e = std::clamp(r.restitution + o.scatter_e * z(rng), 0.0, 1.0);
    Impact imp;
    imp.time_s = t;
    out.sequence.impacts.push_back(imp);
    out.e.push_back(e);
    out.v_in.push_back(v);
    const double v_out = e * v;
    const double interval =
        flight.FlightTime(v_out) + (o.contact_in_interval ? r.contact_time_s : 0.0);
    if (r.stuck || interval < o.min_interval_s) break;
    t += interval;
    v = flight.ArrivalSpeed(v_out);
  }
  for (Impact& imp : out.sequence.impacts) {
    imp.time_s += o.timing_sigma_s * z(rng);
    imp.sigma_s = o.timing_sigma_s > 0.0 ? o.timing_sigma_s : o.reported_sigma_s;
  }
  return out;
}

// The law's own e(v) (no gravity: what a calibration reports as e(v)) by the oracle.
inline double LawE(const bouncecal::Scene& scene, double v) {
  using namespace bouncecal;
  auto law = CreateLaw(scene.law, scene);
  return oracle::Integrate(*law, law->ParameterValues(), BodyFromScene(scene), v).restitution;
}

}  // namespace oracle_truth
