// The bounce simulator: closed-form flights, integrated (or closed-form) contacts, clean stops.
// The model and its documented choices are in include/bouncecal/physics/simulator.hpp.
// One loop serves Simulate (scalar type double) and SimulateWithSensitivities (SensitivityJet:
// every time and speed carries its derivatives with respect to the law's parameters and the
// first impact speed).
#include "bouncecal/physics/simulator.hpp"

#include <cmath>
#include <limits>
#include <optional>
#include <sstream>
#include <type_traits>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/contact_integrator.hpp"
#include "bouncecal/physics/flight.hpp"
#include "physics/contact_map.hpp"
#include "physics/scalar.hpp"

namespace bouncecal {
namespace {

using Jet = SensitivityJet;

double Val(double x) { return x; }
double Val(const Jet& x) { return x.a; }
using scalar::Quotient;

// The flight's closed forms in either scalar type (the Jet by their exact derivatives).
double FlightTimeOf(const FlightModel& f, double v0) { return f.FlightTime(v0); }
Jet FlightTimeOf(const FlightModel& f, const Jet& v0) {
  Jet out(f.FlightTime(v0.a));
  out.v = f.FlightTimeDerivative(v0.a) * v0.v;
  return out;
}
double ArrivalSpeedOf(const FlightModel& f, double v0) { return f.ArrivalSpeed(v0); }
Jet ArrivalSpeedOf(const FlightModel& f, const Jet& v0) {
  Jet out(f.ArrivalSpeed(v0.a));
  out.v = f.ArrivalSpeedDerivative(v0.a) * v0.v;
  return out;
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

ContactRunOptions RunOptions(const SimulatorOptions& options, double stuck_speed_m_s,
                             const std::string& label) {
  ContactRunOptions r;
  r.rel_tolerance = options.rel_tolerance;
  r.abs_tolerance = options.abs_tolerance;
  r.method = options.contact_method;
  r.max_steps = options.max_steps_per_contact;
  r.stuck_speed_m_s = stuck_speed_m_s;
  r.label = label;
  return r;
}

// The closed-form contact in the integrator's result format.
ContactRun FromClosedForm(const ContactLaw& law, const ContactOutcome& cf, const ContactBody& body,
                          double v_in, double stuck_speed_m_s) {
  ContactRun r;
  r.closed_form = true;
  r.contact_time_scale_s = cf.contact_time_s;
  r.peak_overlap_m = cf.peak_overlap_m;
  r.peak_force_n = cf.peak_force_n;
  const double m = body.mass_kg;
  if (cf.stuck || !(cf.restitution > 0.0) || cf.restitution * v_in <= stuck_speed_m_s) {
    r.end = ContactRun::End::kStuck;
    r.detail = law.Name() + ": closed form gives no rebound (restitution " +
               FormatGeneral(cf.restitution) + ")";
    r.contact_s = std::isfinite(cf.contact_time_s) ? cf.contact_time_s : 0.0;
    r.work_j = 0.5 * m * v_in * v_in;
    return r;
  }
  r.end = ContactRun::End::kSeparated;
  r.v_out_m_s = cf.restitution * v_in;
  r.contact_s = cf.contact_time_s;
  r.separation_depth_m = cf.end_overlap_m;
  // elastic_end_j stays 0: what the law holds at separation is lost with it (the ledger
  // counts all of work_j as dissipated), and the closed form has no end state to ask.
  // Without gravity the ball's energy balance gives the work done on the contact exactly.
  r.work_j = 0.5 * m * (v_in * v_in - r.v_out_m_s * r.v_out_m_s);
  r.ball_energy_end_j = 0.5 * m * r.v_out_m_s * r.v_out_m_s;
  return r;
}

// One contact (closed form or integrated) in the integrator's result format, with its outcome
// in scalar type T: for T = Jet, the derivatives of v_out, contact time and separation depth
// with respect to theta (chained through the derivatives of v_in).
template <class T>
struct Contact {
  ContactRun run;
  T v_out, contact_s, depth;
};

template <class T>
Contact<T> OneContact(const ContactLaw& law, std::span<const double> p,
                      const ContactDynamics& dynamics, const ContactBody& body, const T& v_in,
                      double g, const PlateModel* plate, const SimulatorOptions& options,
                      double stuck_speed_m_s) {
  constexpr bool kSensitive = std::is_same_v<T, Jet>;
  const double v = Val(v_in);
  const double g_contact = options.gravity_in_contact ? g : 0.0;
  const ContactRunOptions ro = RunOptions(options, stuck_speed_m_s, law.Name());
  ContactSensitivity sens;
  Contact<T> c;
  if (auto cf = ClosedForm(law, p, body, v, g_contact, options, plate != nullptr)) {
    c.run = FromClosedForm(law, *cf, body, v, stuck_speed_m_s);
    if (kSensitive && c.run.end == ContactRun::End::kSeparated) {
      // Derivatives of what the closed form describes: the contact without gravity.
      RunContact(dynamics, body, cf->contact_time_s, v, 0.0, nullptr, ro, &sens);
    }
  } else {
    const double t_c = EstimateContactTime(law, p, dynamics, body, v);
    c.run = RunContact(dynamics, body, t_c, v, g_contact, plate, ro, kSensitive ? &sens : nullptr);
  }
  c.v_out = T(c.run.v_out_m_s);
  c.contact_s = T(c.run.contact_s);
  c.depth = T(c.run.separation_depth_m);
  if constexpr (kSensitive) {
    const int np = static_cast<int>(p.size());
    for (int j = 0; j < kSensitivityDirections; ++j) {
      const double dv = v_in.v[j];
      const double own = j < np;  // the law's own parameters enter directly
      c.v_out.v[j] = own * sens.v_out[j] + sens.v_out[np] * dv;
      c.contact_s.v[j] = own * sens.contact_s[j] + sens.contact_s[np] * dv;
      c.depth.v[j] = own * sens.separation_depth_m[j] + sens.separation_depth_m[np] * dv;
    }
  }
  return c;
}

}  // namespace

bool SimulatorOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& msg) {
    if (error) *error = msg;
    return false;
  };
  if (!(rel_tolerance > 0.0 && rel_tolerance < 1.0)) {
    return fail("rel_tolerance = " + FormatGeneral(rel_tolerance) + " must be in (0, 1)");
  }
  if (!(abs_tolerance > 0.0 && abs_tolerance < 1.0)) {
    return fail("abs_tolerance = " + FormatGeneral(abs_tolerance) + " must be in (0, 1)");
  }
  if (rel_tolerance < 1e-15)
    return fail("rel_tolerance = " + FormatGeneral(rel_tolerance) + " < 1e-15");
  if (max_steps_per_contact < 10) {
    return fail("max_steps_per_contact = " + std::to_string(max_steps_per_contact) +
                " must be >= 10");
  }
  if (!(time_resolution_s >= 0.0) || !std::isfinite(time_resolution_s)) {
    return fail("time_resolution_s = " + FormatGeneral(time_resolution_s) +
                " must be finite and >= 0");
  }
  if (!(stuck_restitution >= 0.0 && stuck_restitution < 1.0)) {
    return fail("stuck_restitution = " + FormatGeneral(stuck_restitution) + " must be in [0, 1)");
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
    throw Error(ErrorCode::kBadParameter, "impact speed v_in = " + FormatGeneral(v_in_m_s) +
                                              " m/s must be positive and finite");
  }
  if (!(g_m_s2 >= 0.0) || !std::isfinite(g_m_s2)) {
    throw Error(ErrorCode::kBadParameter,
                "gravity g = " + FormatGeneral(g_m_s2) + " m/s^2 must be finite and >= 0");
  }
  SimulatorOptions o = options;
  o.gravity_in_contact = true;  // the caller's g is what it asks for
  const std::unique_ptr<ContactDynamics> dynamics = law.Dynamics(params, body);
  const ContactRun r = OneContact<double>(law, params, *dynamics, body, v_in_m_s, g_m_s2, nullptr,
                                          o, options.stuck_restitution * v_in_m_s)
                           .run;
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

namespace {

// What one simulation needs besides the loop: checked inputs, the law prepared, the flights.
struct Setup {
  ContactBody body;
  PlateModel plate_model;
  const PlateModel* plate = nullptr;
  std::unique_ptr<ContactDynamics> dynamics;
};

Setup Prepare(const Scene& scene, const ContactLaw& law, std::span<const double> params,
              const SimulatorOptions& options) {
  std::string why;
  if (!scene.IsValid(&why)) throw Error(ErrorCode::kBadScene, why);
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "simulator: " + why);
  Setup s;
  s.body = ContactBody::BallOnRigidWall(scene.ball.Mass(), scene.ball.Radius());
  if (!law.IsValid(params, s.body, &why)) throw Error(ErrorCode::kBadParameter, why);
  if (scene.effects.surface_compliance) {
    s.plate_model = {scene.surface.mass_kg, scene.surface.stiffness_n_m,
                     scene.surface.damping_n_s_m};
    const PlateModel& pm = s.plate_model;
    if (!(pm.mass_kg > 0.0) || !(pm.stiffness_n_m > 0.0) || !(pm.damping_n_s_m >= 0.0) ||
        !std::isfinite(pm.mass_kg) || !std::isfinite(pm.stiffness_n_m) ||
        !std::isfinite(pm.damping_n_s_m)) {
      throw Error(ErrorCode::kBadScene,
                  "surface compliance needs surface mass_kg > 0, stiffness_n_m > 0 and "
                  "damping_n_s_m >= 0 (got " +
                      FormatGeneral(pm.mass_kg) + ", " + FormatGeneral(pm.stiffness_n_m) + ", " +
                      FormatGeneral(pm.damping_n_s_m) + ")");
    }
    s.plate = &s.plate_model;
  }
  s.dynamics = law.Dynamics(params, s.body);
  return s;
}

// The contact map of a simulation: its contacts integrated as the loop integrates them.
ContactMap MakeMap(const Setup& setup, const ContactLaw& law, std::span<const double> params,
                   double g, const SimulatorOptions& options, const SimulationLimits& lim) {
  const double g_contact = options.gravity_in_contact ? g : 0.0;
  return ContactMap(
      [&setup, &law, params, g_contact](double v_in, const ContactRunOptions& o) {
        const double t_c = EstimateContactTime(law, params, *setup.dynamics, setup.body, v_in);
        return RunContact(*setup.dynamics, setup.body, t_c, v_in, g_contact, setup.plate, o);
      },
      RunOptions(options, 0.0, law.Name()), setup.body.mass_kg, lim.rest_speed_m_s,
      options.stuck_restitution);
}

// The map's outcome for a contact at v_in it serves (not one the law's closed form solves),
// given the latest ratio of successive arrival speeds (0: none yet) and the impacts left.
std::optional<ContactRun> MappedContact(ContactMap* map, const Setup& setup, const ContactLaw& law,
                                        std::span<const double> params, double g,
                                        const SimulatorOptions& options, double v_in,
                                        double stuck_speed, double last_ratio, int left) {
  if (!(last_ratio > 0.0)) return std::nullopt;
  // The contacts left down to half this speed at the latest ratio, within the limit.
  const double expected =
      last_ratio < 1.0 ? std::min<double>(left, std::log(2.0) / -std::log(last_ratio)) : left;
  // The closed form is asked only where the map could serve (OneContact asks it otherwise).
  const double g_contact = options.gravity_in_contact ? g : 0.0;
  if (!map->MayServe(v_in, expected) ||
      ClosedForm(law, params, setup.body, v_in, g_contact, options, setup.plate != nullptr)) {
    return std::nullopt;
  }
  return map->Find(v_in, stuck_speed, expected);
}

template <class T>
void RecordSensitivities(const T& t, const T& v, const Contact<T>& c, size_t directions,
                         SimulationSensitivities* out) {
  if constexpr (std::is_same_v<T, Jet>) {
    auto row = [&](const Jet& x) {
      return std::vector<double>(x.v.data(), x.v.data() + directions);
    };
    out->time_s.push_back(row(t));
    out->v_in_m_s.push_back(row(v));
    out->v_out_m_s.push_back(row(c.v_out));
    out->contact_s.push_back(row(c.contact_s));
  }
}

// The bounce loop in scalar type T (see the top of this file): the drop, then contact and
// flight, impact after impact, until a stage stops the run (each Stop... stage returns true
// once it has called Stop).
template <class T>
class BounceRun {
 public:
  BounceRun(const Scene& scene, const ContactLaw& law, std::span<const double> params,
            const SimulatorOptions& options, SimulationSensitivities* sens)
      : scene_(scene),
        law_(law),
        params_(params),
        options_(options),
        sens_(sens),
        setup_(Prepare(scene, law, params, options)),
        m_(setup_.body.mass_kg),
        flight_(FlightModel::FromScene(scene)),
        g_(flight_.gravity_m_s2()),
        has_drag_(flight_.drag() != DragModel::kNone),
        lim_(scene.limits) {}

  Simulation Run() {
    Drop();
    for (;;) {
      if (StopBeforeContact()) break;
      const Contact<T> contact = NextContact();
      Record(contact);
      if (StopInContact(contact)) break;
      if (StopInFlight(contact)) break;
    }
    return std::move(sim_);
  }

 private:
  // The first impact's speed and time; for the sensitivities, direction P (after the
  // parameters) is v_first. The contact map (SimulatorOptions::contact_map), for the plain
  // path only.
  void Drop() {
    EnergyLedger& en = sim_.energy;
    if (scene_.drop.impact_speed_m_s) {
      v_ = T(*scene_.drop.impact_speed_m_s);
      en.initial_j = 0.5 * m_ * Val(v_) * Val(v_);
    } else {
      const double h = scene_.drop.height_m.value_or(0.0);
      v_ = T(flight_.FallArrivalSpeed(h));
      en.initial_j = m_ * g_ * h;  // potential energy in g_eff (buoyancy is conservative)
      if (has_drag_) en.dissipated_drag_j = en.initial_j - 0.5 * m_ * Val(v_) * Val(v_);
    }
    if constexpr (std::is_same_v<T, Jet>) v_.v[static_cast<int>(params_.size())] = 1.0;
    t_ = T(scene_.drop.first_impact_time_s);
    if (std::is_same_v<T, double> && options_.contact_map)
      map_ = MakeMap(setup_, law_, params_, g_, options_, lim_);
  }

  // Ends the run: the reason, its detail and the mechanical energy left.
  void Stop(StopReason reason, const std::string& detail, double final_j) {
    EnergyLedger& en = sim_.energy;
    if (map_) {
      sim_.total_steps += map_->steps();
      sim_.map_panels = map_->panels();
      sim_.map_panels_refused = map_->refused();
    }
    sim_.stop_reason = reason;
    sim_.stop_detail = detail;
    en.final_mechanical_j = final_j;
    en.balance_error_j = en.initial_j - (en.final_mechanical_j + en.dissipated_contact_j +
                                         en.dissipated_drag_j + en.internal_j);
  }

  // The impact limit, or a ball at rest.
  bool StopBeforeContact() {
    k_ = static_cast<int>(sim_.impacts.size());
    vv_ = Val(v_);
    if (k_ >= lim_.max_impacts) {
      Stop(StopReason::kMaxImpacts, std::to_string(k_) + " impacts simulated (limits.max_impacts)",
           0.5 * m_ * vv_ * vv_);
      return true;
    }
    if (!(vv_ > lim_.rest_speed_m_s) || vv_ == 0.0) {
      Stop(StopReason::kAtRest,
           "arrival speed " + FormatGeneral(vv_) + " m/s at impact " + std::to_string(k_) +
               " is below rest_speed_m_s = " + FormatGeneral(lim_.rest_speed_m_s),
           0.5 * m_ * vv_ * vv_);
      return true;
    }
    return false;
  }

  // The contact at speed vv_: from the contact map when it serves, else integrated (or closed
  // form).
  Contact<T> NextContact() {
    const double stuck_speed = std::max(lim_.rest_speed_m_s, options_.stuck_restitution * vv_);
    const std::optional<ContactRun> mapped =
        map_ ? MappedContact(&*map_, setup_, law_, params_, g_, options_, vv_, stuck_speed,
                             last_ratio_, lim_.max_impacts - k_)
             : std::nullopt;
    if (mapped) ++sim_.mapped_contacts;
    return mapped ? Contact<T>{*mapped, T(mapped->v_out_m_s), T(mapped->contact_s),
                               T(mapped->separation_depth_m)}
                  : OneContact<T>(law_, params_, *setup_.dynamics, setup_.body, v_, g_,
                                  setup_.plate, options_, stuck_speed);
  }

  void Record(const Contact<T>& contact) {
    const ContactRun& c = contact.run;
    sim_.total_steps += c.steps;
    SimImpact imp;
    imp.time_s = Val(t_);
    imp.v_in_m_s = vv_;
    imp.v_out_m_s = c.end == ContactRun::End::kSeparated ? c.v_out_m_s : 0.0;
    imp.contact_s = c.contact_s;
    imp.peak_overlap_m = c.peak_overlap_m;
    imp.peak_force_n = c.peak_force_n;
    imp.steps = c.steps;
    imp.rejected_steps = c.rejected;
    sim_.impacts.push_back(imp);
    if (sens_) RecordSensitivities(t_, v_, contact, params_.size() + 1, sens_);
  }

  // A ball held in the contact (at rest, stuck, or the step limit); else the contact's energy.
  bool StopInContact(const Contact<T>& contact) {
    const ContactRun& c = contact.run;
    EnergyLedger& en = sim_.energy;
    if (c.end != ContactRun::End::kSeparated) {
      // Ball held in the contact: what is left is mechanical (ball, law's elastic, plate).
      en.dissipated_contact_j += c.work_j - c.elastic_end_j - c.plate_end_j - c.internal_end_j;
      en.internal_j += c.internal_end_j;
      const double final_j = c.ball_energy_end_j + c.elastic_end_j + c.plate_end_j;
      const std::string where =
          " at impact " + std::to_string(k_) + " (t = " + FormatGeneral(Val(t_)) + " s)";
      if (c.end == ContactRun::End::kStepLimit) {
        Stop(StopReason::kStepLimit, c.detail + where, final_j);
        return true;
      }
      const bool gravity_holds = vv_ < 10.0 * g_ * c.contact_time_scale_s;
      Stop(gravity_holds ? StopReason::kAtRest : StopReason::kStuck,
           (gravity_holds ? "gravity holds the slow ball on the surface: " : "") + c.detail + where,
           final_j);
      return true;
    }
    // Separated: the law's leftover elastic energy and the plate's energy are dissipated.
    en.dissipated_contact_j += c.work_j - c.internal_end_j;
    en.internal_j += c.internal_end_j;
    return false;
  }

  // From the separation point (separation_depth_m below the surface level) to the level, in
  // vacuum (see simulator.hpp), then the closed-form flight to the next impact: stops when the
  // ball cannot rise, past the horizon, or in a Zeno tail.
  bool StopInFlight(const Contact<T>& contact) {
    const ContactRun& c = contact.run;
    EnergyLedger& en = sim_.energy;
    const T& v_sep = contact.v_out;
    const T v0_sq = v_sep * v_sep - 2.0 * g_ * contact.depth;
    if (!(Val(v0_sq) > 0.0)) {
      Stop(StopReason::kAtRest,
           "the ball separates " + FormatGeneral(c.separation_depth_m) +
               " m below the surface at " + FormatGeneral(c.v_out_m_s) +
               " m/s and cannot rise above it (impact " + std::to_string(k_) + ")",
           0.5 * m_ * Val(v0_sq));
      return true;
    }
    using std::sqrt;
    const T v0 = sqrt(v0_sq);
    const T t_launch = t_ + contact.contact_s + (g_ > 0.0 ? Quotient(v_sep - v0, g_) : T(0.0));
    const T flight_s = FlightTimeOf(flight_, v0);
    const T v_next = ArrivalSpeedOf(flight_, v0);
    const T t_next = t_launch + flight_s;
    const double v0v = Val(v0);
    if (Val(t_next) > lim_.horizon_s) {
      double h = 0.0, vel = v0v;
      if (lim_.horizon_s > Val(t_launch))
        flight_.State(v0v, lim_.horizon_s - Val(t_launch), &h, &vel);
      const double final_j = m_ * g_ * h + 0.5 * m_ * vel * vel;
      if (has_drag_) en.dissipated_drag_j += 0.5 * m_ * v0v * v0v - final_j;
      Stop(StopReason::kHorizon,
           "next impact at " + FormatGeneral(Val(t_next)) +
               " s is beyond horizon_s = " + FormatGeneral(lim_.horizon_s),
           final_j);
      return true;
    }
    if (has_drag_) en.dissipated_drag_j += 0.5 * m_ * (v0v * v0v - Val(v_next) * Val(v_next));

    // Zeno: with restitution e < 1 the remaining flights form (at most) a geometric series
    // T e / (1 - e) (flight time is proportional to, or grows slower than, the launch speed).
    const double e = v0v / vv_;
    last_ratio_ = Val(v_next) / vv_;
    t_ = t_next;
    v_ = v_next;
    if (e < 1.0 && Val(flight_s) * e / (1.0 - e) < options_.time_resolution_s) {
      Stop(StopReason::kAtRest,
           "Zeno tail: the remaining flights after impact " + std::to_string(k_) +
               " last less than time_resolution_s = " + FormatGeneral(options_.time_resolution_s) +
               " s in total",
           0.5 * m_ * Val(v_) * Val(v_));
      return true;
    }
    return false;
  }

  const Scene& scene_;
  const ContactLaw& law_;
  std::span<const double> params_;
  const SimulatorOptions& options_;
  SimulationSensitivities* sens_;
  Setup setup_;
  const double m_;
  const FlightModel flight_;
  const double g_;
  const bool has_drag_;
  const SimulationLimits& lim_;
  Simulation sim_;
  T v_{0.0};  // the next impact's speed and time
  T t_{0.0};
  std::optional<ContactMap> map_;
  double last_ratio_ = 0.0;  // the latest arrival speed over the one before (0: none yet)
  int k_ = 0;                // the next impact's index
  double vv_ = 0.0;          // Val(v_) at its start
};

}  // namespace

Simulation Simulate(const Scene& scene, const ContactLaw& law, std::span<const double> params,
                    const SimulatorOptions& options) {
  return BounceRun<double>(scene, law, params, options, nullptr).Run();
}

Simulation SimulateWithSensitivities(const Scene& scene, const ContactLaw& law,
                                     std::span<const double> params,
                                     const SimulatorOptions& options,
                                     SimulationSensitivities* sensitivities) {
  if (params.size() > static_cast<size_t>(kMaxSensitivityParameters)) {
    throw Error(ErrorCode::kBadParameter, "law " + law.Name() + ": sensitivities for at most " +
                                              std::to_string(kMaxSensitivityParameters) +
                                              " parameters (got " + std::to_string(params.size()) +
                                              ")");
  }
  SimulationSensitivities local;
  SimulationSensitivities* out = sensitivities ? sensitivities : &local;
  *out = SimulationSensitivities{};
  for (const ParameterSpec& spec : law.Parameters()) out->names.push_back(spec.name);
  out->names.push_back("v_first_m_s");
  return BounceRun<Jet>(scene, law, params, options, out).Run();
}

}  // namespace bouncecal
