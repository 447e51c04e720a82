// bouncecal/simulator.hpp — a ball bouncing on a surface under any contact law.
//
// Simulates only what the scene turns on: flights are closed-form (flight.hpp), contacts are
// integrated with an adaptive integrator whose start and end are located on dense output (or
// solved in closed form for laws that have one). Stops when the ball comes to rest, when the
// law sticks, or at the horizon, and says which.
//
//   Simulation sim = Simulate(scene, *law, SimulatorOptions{});
//   for (const SimImpact& i : sim.impacts) ... i.time_s, i.v_in_m_s
#pragma once

#include <span>
#include <string>
#include <vector>

#include "bouncecal/contact_law.hpp"
#include "bouncecal/scene.hpp"

namespace bouncecal {

struct SimulatorOptions {
  double rel_tolerance = 1e-9;    // adaptive integrator tolerances (contact phase)
  double abs_tolerance = 1e-12;   // scaled internally to the contact's own units
  bool use_closed_form = true;    // use ContactLaw::SolveContact where available
  int max_steps_per_contact = 200000;
  bool IsValid(std::string* error) const;
};

struct SimImpact {
  double time_s = 0.0;          // first touch (delta = 0)
  double v_in_m_s = 0.0;
  double v_out_m_s = 0.0;       // 0 if the ball stuck
  double contact_s = 0.0;
  double peak_overlap_m = 0.0;
  double peak_force_n = 0.0;
  int steps = 0;                // integrator steps (0 for closed form)
};

struct EnergyLedger {
  double initial_j = 0.0;       // potential + kinetic at the start
  double final_mechanical_j = 0.0;
  double dissipated_contact_j = 0.0;
  double dissipated_drag_j = 0.0;
  double internal_j = 0.0;      // energy still held in law state (Jiang-Liu w_r)
  double balance_error_j = 0.0; // initial - (final + dissipated + internal)
};

enum class StopReason { kAtRest, kStuck, kHorizon, kMaxImpacts };
const char* StopReasonName(StopReason r);  // "at_rest", "stuck", "horizon", "max_impacts"

struct Simulation {
  std::vector<SimImpact> impacts;
  EnergyLedger energy;
  StopReason stop_reason = StopReason::kAtRest;
  std::string stop_detail;      // human-readable why
  long total_steps = 0;
};

// Throws Error(kBadParameter / kBadScene) for invalid inputs.
Simulation Simulate(const Scene& scene, const ContactLaw& law, std::span<const double> params,
                    const SimulatorOptions& options = {});

// One contact starting at delta = 0 with speed v_in (no gravity unless g_m_s2 != 0).
ContactOutcome SimulateContact(const ContactLaw& law, std::span<const double> params,
                               const ContactBody& body, double v_in_m_s, double g_m_s2,
                               const SimulatorOptions& options = {}, int* steps = nullptr);

}  // namespace bouncecal
