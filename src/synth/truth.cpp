// Exact truth of a synthetic drop: impact times and speeds from a restitution model or a
// contact law, with closed-form flights (see include/bouncecal/synth/synth.hpp).
#include "bouncecal/synth/synth.hpp"

#include "bouncecal/fit/kinematics.hpp"

#include <algorithm>
#include <cmath>
#include <complex>
#include <filesystem>
#include <fstream>
#include <limits>
#include <memory>
#include <sstream>
#include <utility>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/bundled_scenes.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "synth/synth_internal.hpp"

namespace bouncecal {

using namespace synth;  // NOLINT: the wing's shared helpers

// ---- restitution model ---------------------------------------------------------------------

RestitutionModel RestitutionModel::Constant(double e) {
  RestitutionModel m;
  m.kind = Kind::kConstant;
  m.e0 = e;
  return m;
}
RestitutionModel RestitutionModel::PowerLaw(double e0_value, double c_value, double p_value) {
  RestitutionModel m;
  m.kind = Kind::kPowerLaw;
  m.e0 = e0_value;
  m.c = c_value;
  m.p = p_value;
  return m;
}
RestitutionModel RestitutionModel::Function(std::function<double(double)> e_of_v,
                                            std::string text) {
  RestitutionModel m;
  m.kind = Kind::kFunction;
  m.function = std::move(e_of_v);
  m.description = std::move(text);
  return m;
}

double RestitutionModel::operator()(double v_m_s) const {
  switch (kind) {
    case Kind::kConstant:
      return e0;
    case Kind::kPowerLaw:
      return e0 - c * std::pow(std::max(v_m_s, 0.0), p);
    case Kind::kFunction:
      return function ? function(v_m_s) : std::nan("");
  }
  return std::nan("");
}

bool RestitutionModel::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "restitution: " + m;
    return false;
  };
  switch (kind) {
    case Kind::kConstant:
      if (!(e0 >= 0.0 && e0 <= 1.0))
        return fail("e = " + FormatGeneral(e0, 10) + " (expected 0 <= e <= 1)");
      break;
    case Kind::kPowerLaw:
      if (!(e0 >= 0.0 && e0 <= 1.0))
        return fail("e0 = " + FormatGeneral(e0, 10) + " (expected 0..1)");
      if (!(c >= 0.0 && Finite(c))) return fail("c = " + FormatGeneral(c, 10) + " (expected >= 0)");
      if (!(p > 0.0 && Finite(p))) return fail("p = " + FormatGeneral(p, 10) + " (expected > 0)");
      break;
    case Kind::kFunction:
      if (!function) return fail("no function given");
      break;
  }
  return true;
}

nlohmann::json RestitutionModel::ToJson() const {
  switch (kind) {
    case Kind::kConstant:
      return {{"model", "constant"}, {"e", e0}};
    case Kind::kPowerLaw:
      return {
          {"model", "power-law"}, {"formula", "e = e0 - c*v^p"}, {"e0", e0}, {"c", c}, {"p", p}};
    case Kind::kFunction:
      return {{"model", "function"}, {"description", description}};
  }
  return {};
}

bool TruthOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(min_interval_s > 0.0 && Finite(min_interval_s))) {
    return fail("min_interval_s = " + FormatGeneral(min_interval_s, 10) + " (expected > 0)");
  }
  if (!Finite(rest_speed_m_s)) return fail("rest_speed_m_s is not finite");
  if (contact_s && !(*contact_s >= 0.0 && *contact_s < 0.1)) {
    return fail("contact_s = " + FormatGeneral(*contact_s, 10) +
                " (expected 0 <= contact_s < 0.1 s)");
  }
  if (!(scatter_e >= 0.0 && scatter_e < 0.5)) {
    return fail("scatter_e = " + FormatGeneral(scatter_e, 10) + " (expected 0 <= scatter_e < 0.5)");
  }
  return true;
}

double HertzContactDuration(const Scene& scene, double v_m_s) {
  // One Hertz formula for the whole project (kinematics.hpp); no contact without a speed.
  if (!(v_m_s > 0.0)) return 0.0;
  return HertzContactTime(scene, v_m_s);
}

std::vector<TruthImpact> ImpactsFromRestitution(const Scene& scene, const RestitutionModel& model,
                                                const TruthOptions& options) {
  std::string err;
  if (!scene.IsValid(&err)) throw Error(ErrorCode::kBadScene, err);
  if (!model.IsValid(&err)) throw Error(ErrorCode::kBadParameter, err);
  if (!options.IsValid(&err)) throw Error(ErrorCode::kBadParameter, "truth options: " + err);
  const FlightModel flight = FlightModel::FromScene(scene);
  double v_in = 0.0;
  if (scene.drop.impact_speed_m_s) {
    v_in = *scene.drop.impact_speed_m_s;
  } else {
    v_in = flight.FallArrivalSpeed(scene.drop.height_m.value_or(0.0));
  }
  if (!(v_in > 0.0)) {
    throw Error(ErrorCode::kBadScene,
                "drop: first impact speed " + FormatGeneral(v_in, 10) + " m/s is not > 0");
  }
  const double rest =
      options.rest_speed_m_s > 0 ? options.rest_speed_m_s : scene.limits.rest_speed_m_s;
  const double t_first = scene.drop.first_impact_time_s;
  // Without a given contact duration and without materials, the click is an impulse.
  bool hertz_ok = true;
  if (!options.contact_s) {
    try {
      HertzContactDuration(scene, 1.0);
    } catch (const Error&) {
      if (scene.effects.contact_duration) throw;
      hertz_ok = false;
    }
  }
  std::vector<TruthImpact> out;
  double t = t_first;
  Rng scatter = Stream(options.scatter_seed, kScatter);
  for (int k = 0; k < scene.limits.max_impacts; ++k) {
    const double e_model = model(v_in);
    if (!(e_model >= 0.0 && e_model <= 1.0)) {
      throw Error(ErrorCode::kBadParameter,
                  "restitution model gives e = " + FormatGeneral(e_model, 10) +
                      " at v = " + FormatGeneral(v_in, 10) + " m/s (expected 0..1)");
    }
    const double e = options.scatter_e > 0.0
                         ? std::clamp(e_model + options.scatter_e * scatter.Normal(), 0.0, 1.0)
                         : e_model;
    TruthImpact imp;
    imp.time_s = t;
    imp.v_in_m_s = v_in;
    imp.v_out_m_s = e * v_in;
    imp.contact_s = options.contact_s ? *options.contact_s
                                      : (hertz_ok ? HertzContactDuration(scene, v_in) : 0.0);
    out.push_back(imp);
    if (imp.v_out_m_s < rest) break;
    const double interval =
        flight.FlightTime(imp.v_out_m_s) + (scene.effects.contact_duration ? imp.contact_s : 0.0);
    if (interval < options.min_interval_s) break;
    if (t + interval - t_first > scene.limits.horizon_s) break;
    t += interval;
    v_in = flight.ArrivalSpeed(imp.v_out_m_s);
  }
  return out;
}

namespace {

// ImpactsFromLaw with per-bounce scatter: contacts one by one, exact flights between them.
std::vector<TruthImpact> ImpactsFromLawWithScatter(const Scene& scene, const ContactLaw& law,
                                                   const std::vector<double>& params,
                                                   const TruthOptions& options) {
  if (scene.effects.surface_compliance) {
    throw Error(ErrorCode::kBadParameter,
                "truth options: scatter_e with truth from the law needs a rigid surface (the "
                "surface compliance couples successive contacts)");
  }
  const FlightModel flight = FlightModel::FromScene(scene);
  const ContactBody body = BodyFromScene(scene);
  double v_in = scene.drop.impact_speed_m_s
                    ? *scene.drop.impact_speed_m_s
                    : flight.FallArrivalSpeed(scene.drop.height_m.value_or(0.0));
  const double rest =
      options.rest_speed_m_s > 0 ? options.rest_speed_m_s : scene.limits.rest_speed_m_s;
  const double t_first = scene.drop.first_impact_time_s;
  Rng scatter = Stream(options.scatter_seed, kScatter);
  std::vector<TruthImpact> out;
  double t = t_first;
  for (int k = 0; k < scene.limits.max_impacts && v_in > 0.0; ++k) {
    const ContactOutcome c =
        SimulateContact(law, params, body, v_in, scene.EffectiveGravity(), SimulatorOptions{});
    const double e =
        c.stuck ? 0.0 : std::clamp(c.restitution + options.scatter_e * scatter.Normal(), 0.0, 1.0);
    TruthImpact imp;
    imp.time_s = t;
    imp.v_in_m_s = v_in;
    imp.v_out_m_s = e * v_in;
    imp.contact_s = c.contact_time_s;
    out.push_back(imp);
    if (imp.v_out_m_s < rest || c.stuck) break;
    const double interval = c.contact_time_s + flight.FlightTime(imp.v_out_m_s);
    if (interval < options.min_interval_s) break;
    if (t + interval - t_first > scene.limits.horizon_s) break;
    t += interval;
    v_in = flight.ArrivalSpeed(imp.v_out_m_s);
  }
  return out;
}

}  // namespace

std::vector<TruthImpact> ImpactsFromLaw(const Scene& scene, const TruthOptions& options) {
  std::string err;
  if (!scene.IsValid(&err)) throw Error(ErrorCode::kBadScene, err);
  if (!options.IsValid(&err)) throw Error(ErrorCode::kBadParameter, "truth options: " + err);
  if (options.contact_s) {
    throw Error(ErrorCode::kBadParameter,
                "truth options: contact_s = " + FormatGeneral(*options.contact_s, 10) +
                    " cannot be used with truth from the contact law (the law '" + scene.law.name +
                    "' gives each impact's contact duration)");
  }
  const std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);
  const std::vector<double> params = law->ParameterValues();
  if (options.scatter_e > 0.0) return ImpactsFromLawWithScatter(scene, *law, params, options);
  const Simulation sim = Simulate(scene, *law, params);
  if (sim.impacts.empty()) {
    throw Error(ErrorCode::kBadScene, "law " + scene.law.name + ": the simulation has no impact (" +
                                          StopReasonName(sim.stop_reason) + ")");
  }
  const double rest =
      options.rest_speed_m_s > 0 ? options.rest_speed_m_s : scene.limits.rest_speed_m_s;
  std::vector<TruthImpact> out;
  for (std::size_t k = 0; k < sim.impacts.size(); ++k) {
    const SimImpact& s = sim.impacts[k];
    TruthImpact imp;
    imp.time_s = s.time_s;
    imp.v_in_m_s = s.v_in_m_s;
    imp.v_out_m_s = s.v_out_m_s;
    imp.contact_s = s.contact_s;
    out.push_back(imp);
    // The same cuts as ImpactsFromRestitution: rebound below the rest speed, next interval
    // (onset to onset) shorter than min_interval_s.
    if (imp.v_out_m_s < rest) return out;
    if (k + 1 < sim.impacts.size() &&
        sim.impacts[k + 1].time_s - s.time_s < options.min_interval_s) {
      return out;
    }
  }
  // The simulation ended before any cut: fine unless it gave up.
  if (sim.stop_reason == StopReason::kStepLimit) {
    throw Error(
        ErrorCode::kBadParameter,
        "law " + scene.law.name + ": the simulation stopped early (" + sim.stop_detail + ")");
  }
  return out;
}

}  // namespace bouncecal
