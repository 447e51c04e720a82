// The bounce simulator: closed-form flights, integrated (or closed-form) contacts, clean stops.
// The model and its documented choices are in include/bouncecal/physics/simulator.hpp.
#include "bouncecal/physics/simulator.hpp"

#include <cmath>
#include <limits>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/contact_integrator.hpp"
#include "bouncecal/physics/flight.hpp"

namespace bouncecal {
namespace {

std::string Num(double v) {
  std::ostringstream os;
  os.precision(6);
  os << v;
  return os.str();
}

// The law's closed form for this contact, when allowed (see simulator.hpp).
std::optional<ContactOutcome> ClosedForm(const ContactLaw& law, std::span<const double> p,
                                         const ContactBody& body, double v_in, double g,
                                         const SimulatorOptions& options, bool plate) {
  if (!options.use_closed_form || plate) return std::nullopt;
  if (g != 0.0 && options.gravity_in_contact) {
    const auto tc = law.ContactTime(p, body, v_in);
    // Gravity changes the rebound speed by about g t_c: negligible only below the tolerance.
    if (!tc || !std::isfinite(*tc) || g * *tc > options.rel_tolerance * v_in) return std::nullopt;
  }
  return law.SolveContact(p, body, v_in);
}

ContactRunOptions RunOptions(const SimulatorOptions& options, double stuck_speed_m_s) {
  ContactRunOptions r;
  r.rel_tolerance = options.rel_tolerance;
  r.abs_tolerance = options.abs_tolerance;
  r.max_steps = options.max_steps_per_contact;
  r.stuck_speed_m_s = stuck_speed_m_s;
  return r;
}

// One contact, closed form or integrated, in the integrator's result format.
ContactRun OneContact(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                      double v_in, double g, const PlateModel* plate,
                      const SimulatorOptions& options, double stuck_speed_m_s) {
  const double g_contact = options.gravity_in_contact ? g : 0.0;
  if (auto cf = ClosedForm(law, p, body, v_in, g_contact, options, plate != nullptr)) {
    ContactRun r;
    r.closed_form = true;
    r.contact_time_scale_s = cf->contact_time_s;
    r.peak_overlap_m = cf->peak_overlap_m;
    r.peak_force_n = cf->peak_force_n;
    const double m = body.mass_kg;
    if (cf->stuck || !(cf->restitution > 0.0) || cf->restitution * v_in <= stuck_speed_m_s) {
      r.end = ContactRun::End::kStuck;
      r.detail =
          law.Name() + ": closed form gives no rebound (restitution " + Num(cf->restitution) + ")";
      r.contact_s = std::isfinite(cf->contact_time_s) ? cf->contact_time_s : 0.0;
      r.work_j = 0.5 * m * v_in * v_in;
      return r;
    }
    r.end = ContactRun::End::kSeparated;
    r.v_out_m_s = cf->restitution * v_in;
    r.contact_s = cf->contact_time_s;
    r.separation_depth_m = cf->end_overlap_m;
    // elastic_end_j stays 0: what the law holds at separation is lost with it (the ledger
    // counts all of work_j as dissipated), and the closed form has no end state to ask.
    // Without gravity the ball's energy balance gives the work done on the contact exactly.
    r.work_j = 0.5 * m * (v_in * v_in - r.v_out_m_s * r.v_out_m_s);
    r.ball_energy_end_j = 0.5 * m * r.v_out_m_s * r.v_out_m_s;
    return r;
  }
  return RunContact(law, p, body, v_in, g_contact, plate, RunOptions(options, stuck_speed_m_s));
}

}  // namespace

bool SimulatorOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& msg) {
    if (error) *error = msg;
    return false;
  };
  if (!(rel_tolerance > 0.0 && rel_tolerance < 1.0)) {
    return fail("rel_tolerance = " + Num(rel_tolerance) + " must be in (0, 1)");
  }
  if (!(abs_tolerance > 0.0 && abs_tolerance < 1.0)) {
    return fail("abs_tolerance = " + Num(abs_tolerance) + " must be in (0, 1)");
  }
  if (rel_tolerance < 1e-15) return fail("rel_tolerance = " + Num(rel_tolerance) + " < 1e-15");
  if (max_steps_per_contact < 10) {
    return fail("max_steps_per_contact = " + std::to_string(max_steps_per_contact) +
                " must be >= 10");
  }
  if (!(time_resolution_s >= 0.0) || !std::isfinite(time_resolution_s)) {
    return fail("time_resolution_s = " + Num(time_resolution_s) + " must be finite and >= 0");
  }
  if (!(stuck_restitution >= 0.0 && stuck_restitution < 1.0)) {
    return fail("stuck_restitution = " + Num(stuck_restitution) + " must be in [0, 1)");
  }
  return true;
}

const char* StopReasonName(StopReason r) {
  switch (r) {
    case StopReason::kAtRest:
      return "at_rest";
    case StopReason::kStuck:
      return "stuck";
    case StopReason::kHorizon:
      return "horizon";
    case StopReason::kMaxImpacts:
      return "max_impacts";
    case StopReason::kStepLimit:
      return "step_limit";
  }
  return "unknown";
}

ContactOutcome SimulateContact(const ContactLaw& law, std::span<const double> params,
                               const ContactBody& body, double v_in_m_s, double g_m_s2,
                               const SimulatorOptions& options, int* steps) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "simulator: " + why);
  if (!law.IsValid(params, body, &why)) throw Error(ErrorCode::kBadParameter, why);
  if (!(v_in_m_s > 0.0) || !std::isfinite(v_in_m_s)) {
    throw Error(ErrorCode::kBadParameter,
                "impact speed v_in = " + Num(v_in_m_s) + " m/s must be positive and finite");
  }
  if (!(g_m_s2 >= 0.0) || !std::isfinite(g_m_s2)) {
    throw Error(ErrorCode::kBadParameter,
                "gravity g = " + Num(g_m_s2) + " m/s^2 must be finite and >= 0");
  }
  SimulatorOptions o = options;
  o.gravity_in_contact = true;  // the caller's g is what it asks for
  const ContactRun r = OneContact(law, params, body, v_in_m_s, g_m_s2, nullptr, o,
                                  options.stuck_restitution * v_in_m_s);
  if (steps) *steps = r.steps;
  if (r.end == ContactRun::End::kStepLimit) throw Error(ErrorCode::kBadParameter, r.detail);
  ContactOutcome out;
  out.restitution = r.v_out_m_s / v_in_m_s;
  out.contact_time_s = r.contact_s;
  out.peak_overlap_m = r.peak_overlap_m;
  out.peak_force_n = r.peak_force_n;
  out.end_overlap_m = r.end == ContactRun::End::kSeparated ? r.separation_depth_m : 0.0;
  out.stuck = r.end == ContactRun::End::kStuck;
  return out;
}

Simulation Simulate(const Scene& scene, const ContactLaw& law, std::span<const double> params,
                    const SimulatorOptions& options) {
  std::string why;
  if (!scene.IsValid(&why)) throw Error(ErrorCode::kBadScene, why);
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "simulator: " + why);
  const double m = scene.ball.Mass();
  const ContactBody body = ContactBody::BallOnRigidWall(m, scene.ball.Radius());
  if (!law.IsValid(params, body, &why)) throw Error(ErrorCode::kBadParameter, why);

  PlateModel plate_model;
  const PlateModel* plate = nullptr;
  if (scene.effects.surface_compliance) {
    plate_model = {scene.surface.mass_kg, scene.surface.stiffness_n_m, scene.surface.damping_n_s_m};
    if (!(plate_model.mass_kg > 0.0) || !(plate_model.stiffness_n_m > 0.0) ||
        !(plate_model.damping_n_s_m >= 0.0) || !std::isfinite(plate_model.mass_kg) ||
        !std::isfinite(plate_model.stiffness_n_m) || !std::isfinite(plate_model.damping_n_s_m)) {
      throw Error(ErrorCode::kBadScene,
                  "surface compliance needs surface mass_kg > 0, stiffness_n_m > 0 and "
                  "damping_n_s_m >= 0 (got " +
                      Num(plate_model.mass_kg) + ", " + Num(plate_model.stiffness_n_m) + ", " +
                      Num(plate_model.damping_n_s_m) + ")");
    }
    plate = &plate_model;
  }

  const FlightModel flight = FlightModel::FromScene(scene);
  const double g = flight.gravity_m_s2();
  const bool has_drag = flight.drag() != DragModel::kNone;
  const SimulationLimits& lim = scene.limits;
  Simulation sim;
  EnergyLedger& en = sim.energy;

  // Initial condition.
  double v = 0.0;
  if (scene.drop.impact_speed_m_s) {
    v = *scene.drop.impact_speed_m_s;
    en.initial_j = 0.5 * m * v * v;
  } else {
    const double h = scene.drop.height_m.value_or(0.0);
    v = flight.FallArrivalSpeed(h);
    en.initial_j = m * g * h;  // potential energy in g_eff (buoyancy is conservative)
    if (has_drag) en.dissipated_drag_j = en.initial_j - 0.5 * m * v * v;
  }
  double t = scene.drop.first_impact_time_s;

  auto stop = [&](StopReason reason, const std::string& detail, double final_j) {
    sim.stop_reason = reason;
    sim.stop_detail = detail;
    en.final_mechanical_j = final_j;
    en.balance_error_j = en.initial_j - (en.final_mechanical_j + en.dissipated_contact_j +
                                         en.dissipated_drag_j + en.internal_j);
    return sim;
  };

  while (true) {
    const int k = static_cast<int>(sim.impacts.size());
    if (k >= lim.max_impacts) {
      return stop(StopReason::kMaxImpacts,
                  std::to_string(k) + " impacts simulated (limits.max_impacts)", 0.5 * m * v * v);
    }
    if (!(v > lim.rest_speed_m_s) || v == 0.0) {
      return stop(StopReason::kAtRest,
                  "arrival speed " + Num(v) + " m/s at impact " + std::to_string(k) +
                      " is below rest_speed_m_s = " + Num(lim.rest_speed_m_s),
                  0.5 * m * v * v);
    }
    const double stuck_speed = std::max(lim.rest_speed_m_s, options.stuck_restitution * v);
    const ContactRun c = OneContact(law, params, body, v, g, plate, options, stuck_speed);
    sim.total_steps += c.steps;
    SimImpact imp;
    imp.time_s = t;
    imp.v_in_m_s = v;
    imp.v_out_m_s = c.end == ContactRun::End::kSeparated ? c.v_out_m_s : 0.0;
    imp.contact_s = c.contact_s;
    imp.peak_overlap_m = c.peak_overlap_m;
    imp.peak_force_n = c.peak_force_n;
    imp.steps = c.steps;
    sim.impacts.push_back(imp);

    if (c.end != ContactRun::End::kSeparated) {
      // Ball held in the contact: what is left is mechanical (ball, law's elastic, plate).
      en.dissipated_contact_j += c.work_j - c.elastic_end_j - c.plate_end_j - c.internal_end_j;
      en.internal_j += c.internal_end_j;
      const double final_j = c.ball_energy_end_j + c.elastic_end_j + c.plate_end_j;
      const std::string where = " at impact " + std::to_string(k) + " (t = " + Num(t) + " s)";
      if (c.end == ContactRun::End::kStepLimit) {
        return stop(StopReason::kStepLimit, c.detail + where, final_j);
      }
      const bool gravity_holds = v < 10.0 * g * c.contact_time_scale_s;
      return stop(
          gravity_holds ? StopReason::kAtRest : StopReason::kStuck,
          (gravity_holds ? "gravity holds the slow ball on the surface: " : "") + c.detail + where,
          final_j);
    }
    // Separated: the law's leftover elastic energy and the plate's energy are dissipated.
    en.dissipated_contact_j += c.work_j - c.internal_end_j;
    en.internal_j += c.internal_end_j;

    // From the separation point (separation_depth_m below the surface level) to the level,
    // in vacuum (see simulator.hpp), then the closed-form flight.
    const double v_sep = c.v_out_m_s;
    const double v0_sq = v_sep * v_sep - 2.0 * g * c.separation_depth_m;
    if (!(v0_sq > 0.0)) {
      return stop(StopReason::kAtRest,
                  "the ball separates " + Num(c.separation_depth_m) + " m below the surface at " +
                      Num(v_sep) + " m/s and cannot rise above it (impact " + std::to_string(k) +
                      ")",
                  0.5 * m * v0_sq);
    }
    const double v0 = std::sqrt(v0_sq);
    const double t_launch = t + c.contact_s + (g > 0.0 ? (v_sep - v0) / g : 0.0);
    const double flight_s = flight.FlightTime(v0);
    const double v_next = flight.ArrivalSpeed(v0);
    const double t_next = t_launch + flight_s;
    if (t_next > lim.horizon_s) {
      double h = 0.0, vel = v0;
      if (lim.horizon_s > t_launch) flight.State(v0, lim.horizon_s - t_launch, &h, &vel);
      const double final_j = m * g * h + 0.5 * m * vel * vel;
      if (has_drag) en.dissipated_drag_j += 0.5 * m * v0 * v0 - final_j;
      return stop(
          StopReason::kHorizon,
          "next impact at " + Num(t_next) + " s is beyond horizon_s = " + Num(lim.horizon_s),
          final_j);
    }
    if (has_drag) en.dissipated_drag_j += 0.5 * m * (v0 * v0 - v_next * v_next);

    // Zeno: with restitution e < 1 the remaining flights form (at most) a geometric series
    // T e / (1 - e) (flight time is proportional to, or grows slower than, the launch speed).
    const double e = v0 / v;
    if (e < 1.0 && flight_s * e / (1.0 - e) < options.time_resolution_s) {
      t = t_next;
      v = v_next;
      return stop(StopReason::kAtRest,
                  "Zeno tail: the remaining flights after impact " + std::to_string(k) +
                      " last less than time_resolution_s = " + Num(options.time_resolution_s) +
                      " s in total",
                  0.5 * m * v * v);
    }
    t = t_next;
    v = v_next;
  }
}

}  // namespace bouncecal
