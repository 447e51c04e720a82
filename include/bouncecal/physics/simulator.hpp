// bouncecal/physics/simulator.hpp — a ball bouncing on a surface under any contact law.
//
// Simulates only what the scene turns on: flights are closed-form (flight.hpp: no, linear or
// quadratic drag, buoyancy), never integrated; contacts are integrated with an adaptive
// integrator whose end and branch switches are located on dense output
// (contact_integrator.hpp), or solved in closed form for laws that have one. Stops when the
// ball comes to rest, when the law sticks, at the horizon or after max_impacts, and says which.
//
//   Simulation sim = Simulate(scene, *law, law->ParameterValues(), SimulatorOptions{});
//   for (const SimImpact& i : sim.impacts) ... i.time_s, i.v_in_m_s
//
// Model (documented choices):
//  - Initial condition: released from rest at scene.drop.height_m (at t = first_impact_time_s
//    minus the fall time, so the first impact is at first_impact_time_s), or arriving at
//    scene.drop.impact_speed_m_s at first_impact_time_s.
//  - Impact time = first touch; the contact is always simulated (its duration is part of the
//    interval to the next impact); the flight starts at separation. The ball separates at
//    delta = 0 for most laws; laws with EndRule() kForceZero (and a compliant plate) release it
//    slightly below the surface level: it then rises to the level in vacuum (a few nm,
//    drag over that distance neglected) before the closed-form flight.
//  - Gravity acts during integrated contacts (options.gravity_in_contact). The laws' closed
//    forms neglect it: they are used when the law has one, options.use_closed_form is set and
//    gravity is negligible at the requested tolerance (g t_c <= rel_tolerance v_in) or
//    switched off in contacts. Air drag and buoyancy are neglected during the contact.
//  - Surface compliance (scene.effects.surface_compliance): the plate is a mass on a spring and
//    dashpot that joins the contact integration; between impacts its motion is neglected (the
//    plate is assumed to have settled at rest when the ball returns); its energy at separation
//    is counted as dissipated in the contact.
//  - Stops: the arrival speed is below limits.rest_speed_m_s (at_rest); a geometric tail of
//    flights whose predicted total time is below options.time_resolution_s (at_rest, Zeno);
//    the ball stays in contact (stuck when the law's damping kills the rebound, at_rest when
//    gravity holds a slow ball, v_in < 10 g t_c); the next impact beyond limits.horizon_s
//    (horizon); limits.max_impacts impacts (max_impacts); an integrator step limit
//    (step_limit, with the law and the impact named in stop_detail).
//  - Energy ledger: dissipated_contact_j is the work the ball did on the contact (integrated
//    as an extra ODE variable, F y' dt) less what the law still holds internally; drag from the
//    closed-form flight speeds; balance_error_j = initial - (final + dissipated + internal) is
//    the integration error of the energy.
#pragma once

#include <span>
#include <string>
#include <vector>

#include "bouncecal/physics/contact_integrator.hpp"
#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

struct SimulatorOptions {
  double rel_tolerance = 1e-9;   // adaptive integrator tolerances (contact phase)
  double abs_tolerance = 1e-12;  // scaled internally to the contact's own units
  ContactMethod contact_method = ContactMethod::kAuto;  // contact_integrator.hpp
  bool use_closed_form = true;  // use ContactLaw::SolveContact where available
  int max_steps_per_contact = 200000;
  // Gravity acts during integrated contacts (m delta'' = m g - F). Off: contacts as in the
  // laws' closed forms (useful to compare with them).
  bool gravity_in_contact = true;
  // Zeno stop: when the predicted remaining time of a geometric tail of flights is below this.
  double time_resolution_s = 1e-9;
  // A contact whose remaining energy cannot return the ball faster than
  // max(limits.rest_speed_m_s, stuck_restitution * v_in) counts as stuck.
  double stuck_restitution = 1e-6;
  // Long tails of nearly elastic bounces (the Hunt-Crossley family's thousands of slow
  // contacts) from a contact map: each contact's outcome interpolated in the impact speed from
  // contacts integrated 100 times tighter, every panel of the map checked against three more
  // such contacts before use (src/physics/contact_map.hpp). Built only where it saves
  // integrations (restitution above ~0.995, enough impacts left) and for rel_tolerance >= 1e-11;
  // contacts near the stuck speed are integrated. Off by default (the sensitivity path and the
  // fits integrate every contact); `simulate` turns it on unless --integrate.
  bool contact_map = false;
  bool IsValid(std::string* error) const;
};

struct SimImpact {
  double time_s = 0.0;  // first touch (delta = 0)
  double v_in_m_s = 0.0;
  double v_out_m_s = 0.0;  // 0 if the ball stuck
  double contact_s = 0.0;
  double peak_overlap_m = 0.0;
  double peak_force_n = 0.0;
  int steps = 0;  // integrator steps (0 for closed form or the contact map), rejected included
  int rejected_steps = 0;
};

struct EnergyLedger {
  double initial_j = 0.0;  // potential + kinetic at the start
  double final_mechanical_j = 0.0;
  double dissipated_contact_j = 0.0;
  double dissipated_drag_j = 0.0;
  double internal_j = 0.0;       // energy still held in law state (Jiang-Liu w_r)
  double balance_error_j = 0.0;  // initial - (final + dissipated + internal)
};

enum class StopReason { kAtRest, kStuck, kHorizon, kMaxImpacts, kStepLimit };
// "at_rest", "stuck", "horizon", "max_impacts", "step_limit"
const char* StopReasonName(StopReason r);

struct Simulation {
  std::vector<SimImpact> impacts;
  EnergyLedger energy;
  StopReason stop_reason = StopReason::kAtRest;
  std::string stop_detail;  // human-readable why
  long total_steps = 0;     // the contacts' and the contact map's integrations
  // SimulatorOptions::contact_map: the impacts whose contact came from the map, and its panels
  // (accepted, and refused by their check: those speeds were integrated).
  int mapped_contacts = 0;
  int map_panels = 0;
  int map_panels_refused = 0;
};

// Throws Error(kBadParameter / kBadScene) for invalid inputs.
Simulation Simulate(const Scene& scene, const ContactLaw& law, std::span<const double> params,
                    const SimulatorOptions& options = {});

// Forward sensitivities of a simulation: the derivative of each impact's time and speeds with
// respect to theta = (the law's parameters in Parameters() order, then the first impact speed
// v_first; the first impact's time is held, as the simulator holds first_impact_time_s).
// Row k belongs to sim.impacts[k]; column j to theta_j. Valid with every scene effect (drag,
// buoyancy, surface compliance; the contact durations are part of the impact times).
struct SimulationSensitivities {
  std::vector<std::string> names;             // theta: parameter names, then "v_first_m_s"
  std::vector<std::vector<double>> time_s;    // d time_s / d theta_j
  std::vector<std::vector<double>> v_in_m_s;  // d v_in_m_s / d theta_j
  std::vector<std::vector<double>> v_out_m_s;
  std::vector<std::vector<double>> contact_s;
};

// Simulate, with the sensitivities computed alongside (the contacts are integrated in forward-
// sensitivity arithmetic on the value's own step sequence, so the impacts are those Simulate
// returns; flights by the exact derivatives of their closed forms; event times by the implicit
// function theorem). Contacts the simulator solves in closed form get their derivatives from
// the same contact integrated without gravity (what the closed form describes). At most
// kMaxSensitivityParameters (contact_dynamics.hpp) parameters, else Error(kBadParameter). About
// 5-10x the cost of Simulate (bench_simulate), for all P + 1 derivatives at once.
Simulation SimulateWithSensitivities(const Scene& scene, const ContactLaw& law,
                                     std::span<const double> params,
                                     const SimulatorOptions& options,
                                     SimulationSensitivities* sensitivities);

// One contact starting at delta = 0 with speed v_in (no gravity unless g_m_s2 != 0); uses the
// law's closed form when allowed (see above). A stuck contact returns stuck = true and
// restitution 0; the step limit throws Error(kBadParameter) naming the law.
ContactOutcome SimulateContact(const ContactLaw& law, std::span<const double> params,
                               const ContactBody& body, double v_in_m_s, double g_m_s2,
                               const SimulatorOptions& options = {}, int* steps = nullptr);

}  // namespace bouncecal
