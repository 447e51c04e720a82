// Test-recording renderer: exact truth from e(v) and closed-form flights, and a realistic
// recording of it (see include/bouncecal/synth/synth.hpp for the model and the time convention).
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
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/bundled_scenes.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "random.hpp"

namespace bouncecal {
namespace {

using cd = std::complex<double>;

std::string Num(double v) {
  std::ostringstream o;
  o.precision(10);
  o << v;
  return o.str();
}

using synth_random::Rng;
using synth_random::Stream;

enum Purpose : std::uint64_t {
  kNoise = 1,
  kHum = 2,
  kDistractor = 3,
  kModeSpread = 4,
  kScatter = 5
};

bool Finite(double v) { return std::isfinite(v); }

// ---- the sound of one impact ---------------------------------------------------------------
//
// Contact force: a half-sine pulse of unit area (scaled by the impact strength A),
//   f(s) = (pi / (2 tau)) sin(pi s / tau), 0 <= s <= tau.
// Each mode is a damped oscillator with unit impulse response h(t) = g Im(exp(lambda t)),
// lambda = -1/decay + i 2 pi freq. Its response to the pulse, t after the onset, is exact:
//   y(t) = g A Im(exp(lambda t) F(min(t, tau))),  F(u) = int_0^u f(s) exp(-lambda s) ds
//        = (pi / (2 tau)) [beta - exp(-lambda u)(lambda sin(beta u) + beta cos(beta u))]
//          / (lambda^2 + beta^2),  beta = pi / tau.
// For t >= tau it is a free damped sinusoid of complex amplitude F(tau), which lets all impacts
// of one mode be summed by a single recursion over the samples.
cd PulseIntegral(cd lambda, double tau_s, double u_s) {
  if (tau_s <= 1e-12) return cd(1.0, 0.0);  // an impulse
  const double beta = M_PI / tau_s;
  const cd num = beta - std::exp(-lambda * u_s) *
                            (lambda * std::sin(beta * u_s) + beta * std::cos(beta * u_s));
  return (M_PI / (2.0 * tau_s)) * num / (lambda * lambda + beta * beta);
}

// Area of the unit half-sine pulse between a and b (s after the onset), clamped to [0, tau].
double PulseArea(double tau_s, double a, double b) {
  if (tau_s <= 1e-12) return (a < 0.0 && b >= 0.0) ? 1.0 : 0.0;
  a = std::clamp(a, 0.0, tau_s);
  b = std::clamp(b, 0.0, tau_s);
  // int (pi/2tau) sin(pi s/tau) ds = -(1/2) cos(pi s / tau)
  return 0.5 * (std::cos(M_PI * a / tau_s) - std::cos(M_PI * b / tau_s));
}

// The direct click: the contact force itself as a microphone sampling it with a one-sample
// integration window (a causal box anti-alias filter): sample n holds the average force over
// (t_n - 1/rate, t_n]. Scaled by kClickRefRate_s so that a short pulse at 48 kHz gives a
// one-sample click of height click_gain * A.
constexpr double kClickRefRate_s = 1.0 / 48000.0;

struct Event {
  double onset_s;  // in this channel
  double tau_s;
  double strength;  // A
};

bool ModeAudible(const Mode& m, double rate_hz) {
  // The recorder's anti-alias filter removes modes near and above Nyquist.
  return m.freq_hz > 0.0 && m.freq_hz < 0.45 * rate_hz && m.gain != 0.0 && m.decay_s > 0.0;
}

// Adds the clean sound of the events (any order) to out (sample n at t = n / rate).
void RenderEvents(const std::vector<Event>& events_in, const std::vector<Mode>& modes,
                  double click_gain, double rate_hz, std::vector<double>* out) {
  const auto n_samples = static_cast<std::int64_t>(out->size());
  if (n_samples == 0 || events_in.empty()) return;
  std::vector<Event> events = events_in;
  std::sort(events.begin(), events.end(), [](const Event& a, const Event& b) {
    return a.onset_s + a.tau_s < b.onset_s + b.tau_s;
  });
  const double dt = 1.0 / rate_hz;
  auto first_sample_after = [&](double t) {  // smallest n with n * dt > t
    return static_cast<std::int64_t>(std::floor(t * rate_hz)) + 1;
  };
  for (const Mode& m : modes) {
    if (!ModeAudible(m, rate_hz)) continue;
    const cd lambda(-1.0 / m.decay_s, 2.0 * M_PI * m.freq_hz);
    const cd step = std::exp(lambda * dt);
    // During each contact: direct evaluation.
    for (const Event& e : events) {
      const std::int64_t n0 = std::max<std::int64_t>(0, first_sample_after(e.onset_s));
      for (std::int64_t n = n0; n < n_samples; ++n) {
        const double t = static_cast<double>(n) * dt - e.onset_s;
        if (t >= e.tau_s) break;
        (*out)[static_cast<std::size_t>(n)] +=
            m.gain * e.strength * (std::exp(lambda * t) * PulseIntegral(lambda, e.tau_s, t)).imag();
      }
    }
    // After each contact: one running complex amplitude for all impacts.
    cd state(0.0, 0.0);
    std::size_t next = 0;
    std::int64_t n = 0;
    // Skip the silent start.
    if (!events.empty()) {
      n = std::max<std::int64_t>(0, first_sample_after(events[0].onset_s + events[0].tau_s) - 1);
    }
    for (; n < n_samples; ++n) {
      state *= step;
      const double t = static_cast<double>(n) * dt;
      while (next < events.size() && events[next].onset_s + events[next].tau_s <= t) {
        const Event& e = events[next];
        state += e.strength * PulseIntegral(lambda, e.tau_s, e.tau_s) *
                 std::exp(lambda * (t - e.onset_s));
        ++next;
      }
      (*out)[static_cast<std::size_t>(n)] += m.gain * state.imag();
      if (next == events.size() && std::abs(state) < 1e-14) break;
    }
  }
  if (click_gain != 0.0) {
    for (const Event& e : events) {
      const std::int64_t n0 = std::max<std::int64_t>(0, first_sample_after(e.onset_s));
      for (std::int64_t n = n0; n < n_samples; ++n) {
        const double t = static_cast<double>(n) * dt - e.onset_s;
        if (t - dt >= e.tau_s) break;
        (*out)[static_cast<std::size_t>(n)] +=
            click_gain * e.strength * PulseArea(e.tau_s, t - dt, t) * rate_hz * kClickRefRate_s;
      }
    }
  }
}

// A distractor: a noise burst with a 0.3 ms attack and a few ms decay through a resonator
// (centre freq, Q ~ 4): tonal-free and slow-attacked, unlike a contact click.
void RenderDistractor(const Distractor& d, double decay_s, double rate_hz, Rng* rng,
                      std::vector<double>* out) {
  const auto n_samples = static_cast<std::int64_t>(out->size());
  const double dt = 1.0 / rate_hz;
  const double attack_s = 3e-4;
  const auto n0 = static_cast<std::int64_t>(std::floor(d.time_s * rate_hz)) + 1;
  const auto len = static_cast<std::int64_t>((attack_s + 6.0 * decay_s) * rate_hz);
  // Two-pole resonator y = x + 2 r cos(w) y1 - r^2 y2.
  const double w = 2.0 * M_PI * d.freq_hz / rate_hz;
  const double r = std::exp(-M_PI * (d.freq_hz / 4.0) / rate_hz);
  const double a1 = 2.0 * r * std::cos(w), a2 = -r * r;
  std::vector<double> burst(static_cast<std::size_t>(std::max<std::int64_t>(len, 1)));
  double y1 = 0, y2 = 0, peak = 0;
  for (std::size_t i = 0; i < burst.size(); ++i) {
    const double t = static_cast<double>(i + 1) * dt;
    const double env = t < attack_s ? t / attack_s : std::exp(-(t - attack_s) / decay_s);
    const double y = env * rng->Normal() + a1 * y1 + a2 * y2;
    y2 = y1;
    y1 = y;
    burst[i] = y;
    peak = std::max(peak, std::fabs(y));
  }
  if (peak <= 0) return;
  for (std::size_t i = 0; i < burst.size(); ++i) {
    const std::int64_t n = n0 + static_cast<std::int64_t>(i);
    if (n < 0 || n >= n_samples) continue;
    (*out)[static_cast<std::size_t>(n)] += d.amplitude * burst[i] / peak;
  }
}

void FillNoise(NoiseColor color, Rng* rng, std::vector<double>* noise) {
  if (color == NoiseColor::kWhite) {
    for (double& v : *noise) v = rng->Normal();
    return;
  }
  // Pink (1/f) noise: Paul Kellet's refined filter of white noise (accurate to +-0.05 dB above
  // 9.2 Hz at 44.1 kHz; music-dsp archive, "pink noise generation").
  double b0 = 0, b1 = 0, b2 = 0, b3 = 0, b4 = 0, b5 = 0, b6 = 0;
  for (double& v : *noise) {
    const double w = rng->Normal();
    b0 = 0.99886 * b0 + w * 0.0555179;
    b1 = 0.99332 * b1 + w * 0.0750759;
    b2 = 0.96900 * b2 + w * 0.1538520;
    b3 = 0.86650 * b3 + w * 0.3104856;
    b4 = 0.55000 * b4 + w * 0.5329522;
    b5 = -0.7616 * b5 - w * 0.0168980;
    v = b0 + b1 + b2 + b3 + b4 + b5 + b6 + w * 0.5362;
    b6 = w * 0.115926;
  }
}

double Rms(const std::vector<double>& x) {
  double s = 0;
  for (double v : x) s += v * v;
  return x.empty() ? 0.0 : std::sqrt(s / static_cast<double>(x.size()));
}

nlohmann::json ModesJson(const std::vector<Mode>& modes) {
  nlohmann::json a = nlohmann::json::array();
  for (const Mode& m : modes) {
    a.push_back({{"freq_hz", m.freq_hz}, {"decay_s", m.decay_s}, {"gain", m.gain}});
  }
  return a;
}

}  // namespace

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
      if (!(e0 >= 0.0 && e0 <= 1.0)) return fail("e = " + Num(e0) + " (expected 0 <= e <= 1)");
      break;
    case Kind::kPowerLaw:
      if (!(e0 >= 0.0 && e0 <= 1.0)) return fail("e0 = " + Num(e0) + " (expected 0..1)");
      if (!(c >= 0.0 && Finite(c))) return fail("c = " + Num(c) + " (expected >= 0)");
      if (!(p > 0.0 && Finite(p))) return fail("p = " + Num(p) + " (expected > 0)");
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
    return fail("min_interval_s = " + Num(min_interval_s) + " (expected > 0)");
  }
  if (!Finite(rest_speed_m_s)) return fail("rest_speed_m_s is not finite");
  if (contact_s && !(*contact_s >= 0.0 && *contact_s < 0.1)) {
    return fail("contact_s = " + Num(*contact_s) + " (expected 0 <= contact_s < 0.1 s)");
  }
  if (!(scatter_e >= 0.0 && scatter_e < 0.5)) {
    return fail("scatter_e = " + Num(scatter_e) + " (expected 0 <= scatter_e < 0.5)");
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
    throw Error(ErrorCode::kBadScene, "drop: first impact speed " + Num(v_in) + " m/s is not > 0");
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
      throw Error(ErrorCode::kBadParameter, "restitution model gives e = " + Num(e_model) +
                                                " at v = " + Num(v_in) + " m/s (expected 0..1)");
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
                "truth options: contact_s = " + Num(*options.contact_s) +
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

// ---- plate presets ---------------------------------------------------------------------------
// Mode sets chosen to sound like the named objects (frequencies of thin-plate/dish modes spread
// roughly as (n + 1/2)^2, decays shorter for higher modes); they are rendering presets, not
// measurements.
std::vector<Mode> PlateModes(const std::string& preset) {
  if (preset == "copper-dish") {
    return {{1210, 0.90, 1.0},  {2870, 0.65, 0.8},  {4730, 0.45, 0.7},  {6810, 0.30, 0.55},
            {9260, 0.20, 0.45}, {12150, 0.13, 0.4}, {15540, 0.08, 0.3}, {19100, 0.05, 0.25}};
  }
  if (preset == "glass") {
    return {{2430, 0.40, 1.0},  {5120, 0.30, 0.8},   {8870, 0.22, 0.7}, {13480, 0.15, 0.5},
            {19760, 0.10, 0.4}, {27100, 0.07, 0.35}, {36200, 0.05, 0.3}};
  }
  if (preset == "wood-table") {
    return {{185, 0.080, 1.0},  {420, 0.060, 0.9},  {960, 0.040, 0.7}, {1830, 0.025, 0.5},
            {3310, 0.015, 0.4}, {5240, 0.010, 0.3}, {8100, 0.006, 0.2}};
  }
  if (preset == "floor") {
    return {{95, 0.050, 1.0},
            {260, 0.030, 0.7},
            {710, 0.020, 0.5},
            {1620, 0.010, 0.35},
            {3400, 0.006, 0.25}};
  }
  std::string known;
  for (const auto& n : PlatePresetNames()) known += (known.empty() ? "" : ", ") + n;
  throw Error(ErrorCode::kBadParameter,
              "plate modes '" + preset + "': unknown preset (known: " + known + ")");
}

std::vector<std::string> PlatePresetNames() {
  return {"copper-dish", "glass", "wood-table", "floor"};
}

// ---- rendering -------------------------------------------------------------------------------

bool RenderOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "render options: " + m;
    return false;
  };
  if (!(sample_rate_hz >= 8000.0 && sample_rate_hz <= 384000.0) ||
      std::fabs(sample_rate_hz - std::round(sample_rate_hz)) > 1e-9) {
    return fail("sample_rate_hz = " + Num(sample_rate_hz) +
                " (expected a whole number of Hz from 8000 to 384000)");
  }
  if (channels.empty() || channels.size() > 64) {
    return fail("channels: " + std::to_string(channels.size()) + " (expected 1 to 64)");
  }
  for (std::size_t c = 0; c < channels.size(); ++c) {
    if (!(channels[c].gain > 0.0 && Finite(channels[c].gain))) {
      return fail("channel " + std::to_string(c) + " gain = " + Num(channels[c].gain) +
                  " (expected > 0)");
    }
    if (!(channels[c].delay_s >= 0.0 && channels[c].delay_s < 1.0)) {
      return fail("channel " + std::to_string(c) + " delay_s = " + Num(channels[c].delay_s) +
                  " (expected 0 <= delay < 1 s)");
    }
    if (!(channels[c].mode_spread_db >= 0.0 && channels[c].mode_spread_db <= 40.0)) {
      return fail("channel " + std::to_string(c) +
                  " mode_spread_db = " + Num(channels[c].mode_spread_db) + " (expected 0..40 dB)");
    }
  }
  for (const auto* list : {&plate_modes, &ball_modes}) {
    for (const Mode& m : *list) {
      if (!(m.freq_hz > 0 && Finite(m.freq_hz) && m.decay_s > 0 && m.decay_s <= 10 &&
            Finite(m.gain))) {
        return fail("mode {" + Num(m.freq_hz) + " Hz, " + Num(m.decay_s) + " s, gain " +
                    Num(m.gain) + "} (expected freq > 0, 0 < decay <= 10 s, finite gain)");
      }
    }
  }
  bool audible = click_gain != 0.0;
  for (const auto* list : {&plate_modes, &ball_modes}) {
    for (const Mode& m : *list) audible = audible || ModeAudible(m, sample_rate_hz);
  }
  if (!audible) return fail("no click and no mode below 0.45 * sample rate: nothing to hear");
  if (!(click_gain >= 0.0 && Finite(click_gain))) return fail("click_gain must be >= 0");
  if (!(amplitude_exponent >= 0.0 && amplitude_exponent <= 4.0)) {
    return fail("amplitude_exponent = " + Num(amplitude_exponent) + " (expected 0..4)");
  }
  if (!(peak_level > 0.0 && peak_level <= 1.0)) {
    return fail("peak_level = " + Num(peak_level) + " (expected 0 < peak <= 1)");
  }
  if (snr_db && !(*snr_db > -20.0 && *snr_db < 200.0)) {
    return fail("snr_db = " + Num(*snr_db) + " (expected -20 < SNR < 200 dB)");
  }
  if (!(hum_hz == 0.0 || (hum_hz >= 10.0 && hum_hz <= 1000.0))) {
    return fail("hum_hz = " + Num(hum_hz) + " (expected 0 = off, or 10..1000 Hz)");
  }
  if (!(hum_db <= 20.0 && Finite(hum_db))) return fail("hum_db = " + Num(hum_db));
  if (distractors < 0 || distractors > 10000) {
    return fail("distractors = " + std::to_string(distractors) + " (expected 0..10000)");
  }
  if (!(distractor_db <= 20.0 && Finite(distractor_db))) {
    return fail("distractor_db = " + Num(distractor_db));
  }
  if (clip_level && !(*clip_level > 0.0 && *clip_level <= 1.0)) {
    return fail("clip_level = " + Num(*clip_level) + " (expected 0 < level <= 1)");
  }
  for (const Echo& e : echoes) {
    if (!(e.delay_s > 0.0 && e.delay_s < 1.0 && e.gain >= 0.0 && e.gain <= 1.0)) {
      return fail("echo {" + Num(e.delay_s) + " s, gain " + Num(e.gain) +
                  "} (expected 0 < delay < 1 s, 0 <= gain <= 1)");
    }
  }
  if (!(latency_s >= 0.0 && latency_s < 1.0)) {
    return fail("latency_s = " + Num(latency_s) + " (expected 0 <= latency < 1 s)");
  }
  if (!(tail_s >= 0.0 && tail_s <= 60.0)) return fail("tail_s = " + Num(tail_s));
  if (!(duration_s >= 0.0 && duration_s <= 3600.0)) {
    return fail("duration_s = " + Num(duration_s) + " (expected 0 = auto, or up to 3600 s)");
  }
  return true;
}

double Recording::duration_s() const {
  if (channels.empty() || sample_rate_hz <= 0) return 0.0;
  return static_cast<double>(channels[0].size()) / sample_rate_hz;
}

namespace {

// The latest onset of any impact in any channel (s); throws Error(kBadParameter) naming the
// first impact whose time, speeds or contact time are not physical.
double CheckImpacts(const std::vector<std::vector<TruthImpact>>& drops,
                    const RenderOptions& options) {
  double last_onset = 0.0;
  for (std::size_t d = 0; d < drops.size(); ++d) {
    for (std::size_t k = 0; k < drops[d].size(); ++k) {
      const TruthImpact& i = drops[d][k];
      const std::string where =
          "impact " + std::to_string(k) + " of drop " + std::to_string(d) + ": ";
      if (!(i.time_s >= 0.0 && Finite(i.time_s))) {
        throw Error(ErrorCode::kBadParameter, where + "time_s = " + Num(i.time_s));
      }
      if (!(i.v_in_m_s > 0.0 && Finite(i.v_in_m_s)) || !(i.v_out_m_s >= 0.0) ||
          !Finite(i.v_out_m_s)) {
        throw Error(ErrorCode::kBadParameter,
                    where + "speeds " + Num(i.v_in_m_s) + ", " + Num(i.v_out_m_s) + " m/s");
      }
      if (!(i.contact_s >= 0.0 && i.contact_s < 0.1)) {
        throw Error(ErrorCode::kBadParameter, where + "contact_s = " + Num(i.contact_s));
      }
      last_onset = std::max(last_onset, i.time_s);
    }
  }
  double max_delay = 0.0;
  for (const ChannelSpec& c : options.channels) max_delay = std::max(max_delay, c.delay_s);
  return last_onset + options.latency_s + max_delay;
}

// The recording's length (s): duration_s, or the last onset plus tail_s.
double RecordingLength(double last_onset, std::size_t impact_count, const RenderOptions& options) {
  if (impact_count == 0 && !(options.duration_s > 0)) {
    throw Error(ErrorCode::kBadParameter,
                "render: no impacts; give duration_s to render noise, hum and distractors only");
  }
  if (options.duration_s > 0 && last_onset >= options.duration_s) {
    throw Error(ErrorCode::kBadParameter,
                "render options: duration_s = " + Num(options.duration_s) +
                    " ends before the last impact at " + Num(last_onset) + " s");
  }
  return options.duration_s > 0 ? options.duration_s : last_onset + options.tail_s;
}

// Each channel's modes: the plate's and the ball's, with the channel's random gain spread.
std::vector<std::vector<Mode>> ChannelModes(const RenderOptions& options) {
  std::vector<Mode> modes = options.plate_modes;
  modes.insert(modes.end(), options.ball_modes.begin(), options.ball_modes.end());
  std::vector<std::vector<Mode>> channel_modes(options.channels.size(), modes);
  for (std::size_t c = 0; c < options.channels.size(); ++c) {
    if (options.channels[c].mode_spread_db > 0.0) {
      Rng rng = Stream(options.seed, kModeSpread, c);
      for (Mode& m : channel_modes[c]) {
        m.gain *= std::pow(10.0, rng.Normal() * options.channels[c].mode_spread_db / 20.0);
      }
    }
  }
  return channel_modes;
}

// An impact's sound strength (unit scale): v_in^amplitude_exponent.
double Strength(const TruthImpact& i, const RenderOptions& options) {
  return std::pow(i.v_in_m_s, options.amplitude_exponent);
}

// The clean sound of every impact and its echoes, per channel, at unit scale.
std::vector<std::vector<double>> RenderClean(const std::vector<std::vector<TruthImpact>>& drops,
                                             const std::vector<std::vector<Mode>>& channel_modes,
                                             std::size_t n_samples, const RenderOptions& options) {
  const std::size_t nch = options.channels.size();
  std::vector<std::vector<double>> clean(nch, std::vector<double>(n_samples, 0.0));
  for (std::size_t c = 0; c < nch; ++c) {
    std::vector<Event> events;
    for (const auto& drop : drops) {
      for (const TruthImpact& i : drop) {
        const double onset = i.time_s + options.latency_s + options.channels[c].delay_s;
        events.push_back(Event{onset, i.contact_s, Strength(i, options)});
        for (const Echo& echo : options.echoes) {
          events.push_back(
              Event{onset + echo.delay_s, i.contact_s, Strength(i, options) * echo.gain});
        }
      }
    }
    RenderEvents(events, channel_modes[c], options.click_gain, options.sample_rate_hz, &clean[c]);
  }
  return clean;
}

// Per-impact truth: each impact's own clean peak in each channel (rendered alone over its first
// 5 ms), scaled like the mix, its SNR and whether it clips.
std::vector<std::vector<RenderedImpact>> ImpactTruth(
    const std::vector<std::vector<TruthImpact>>& drops,
    const std::vector<std::vector<Mode>>& channel_modes, double scale, double noise_rms,
    const RenderOptions& options) {
  const double rate = options.sample_rate_hz;
  const double window_s = 5e-3;
  std::vector<std::vector<RenderedImpact>> out;
  for (const auto& drop : drops) {
    std::vector<RenderedImpact> rd;
    for (const TruthImpact& i : drop) {
      RenderedImpact r;
      r.truth = i;
      r.onset_s = i.time_s + options.latency_s + options.channels[0].delay_s;
      for (std::size_t c = 0; c < options.channels.size(); ++c) {
        const double onset = i.time_s + options.latency_s + options.channels[c].delay_s;
        const double t0 = std::floor(onset * rate) / rate;
        std::vector<double> own(
            static_cast<std::size_t>(std::ceil((window_s + i.contact_s) * rate)) + 2, 0.0);
        RenderEvents({Event{onset - t0, i.contact_s, Strength(i, options)}}, channel_modes[c],
                     options.click_gain, rate, &own);
        double pk = 0.0;
        for (double v : own) pk = std::max(pk, std::fabs(v));
        const double amplitude = pk * scale * options.channels[c].gain;
        r.channel_amplitude.push_back(amplitude);
        r.channel_snr_db.push_back(noise_rms > 0 ? 20.0 * std::log10(amplitude / noise_rms)
                                                 : 999.0);
      }
      r.amplitude = r.channel_amplitude[0];
      r.snr_db = r.channel_snr_db[0];
      r.clipped = options.clip_level && r.amplitude > *options.clip_level;
      rd.push_back(r);
    }
    out.push_back(std::move(rd));
  }
  return out;
}

// Distractors: uniform times at least 10 ms from every onset, amplitudes up to distractor_db.
std::vector<Distractor> PlaceDistractors(const std::vector<std::vector<RenderedImpact>>& drops,
                                         double duration, const RenderOptions& options) {
  Rng rng = Stream(options.seed, kDistractor);
  std::vector<double> onsets;
  for (const auto& d : drops) {
    for (const auto& r : d) onsets.push_back(r.onset_s);
  }
  std::vector<Distractor> out;
  for (int k = 0; k < options.distractors; ++k) {
    Distractor d;
    for (int attempt = 0; attempt < 200; ++attempt) {
      d.time_s = rng.Uniform(0.02 * duration, 0.98 * duration);
      bool clear = true;
      for (double o : onsets) clear = clear && std::fabs(o - d.time_s) > 0.010;
      if (clear) break;
    }
    d.amplitude = options.peak_level *
                  std::pow(10.0, (options.distractor_db - rng.Uniform(0.0, 12.0)) / 20.0);
    d.freq_hz = rng.Uniform(0.03, 0.3) * options.sample_rate_hz;
    out.push_back(d);
  }
  return out;
}

// Mains hum: the fundamental and four harmonics below 0.45 rate, random phases (one draw for
// every channel).
void AddHum(double gain, const RenderOptions& options, std::vector<double>* x) {
  if (!(options.hum_hz > 0)) return;
  Rng hum_rng = Stream(options.seed, kHum);
  double hum_phase[5];
  for (double& ph : hum_phase) ph = hum_rng.Uniform(0.0, 2.0 * M_PI);
  static constexpr double kHumHarmonics[5] = {1.0, 0.5, 0.35, 0.2, 0.12};
  const double rate = options.sample_rate_hz;
  const double a = options.peak_level * std::pow(10.0, options.hum_db / 20.0) * gain;
  for (int h = 0; h < 5; ++h) {
    const double f = options.hum_hz * (h + 1);
    if (f >= 0.45 * rate) break;
    const double w = 2.0 * M_PI * f / rate;
    for (std::size_t n = 0; n < x->size(); ++n) {
      (*x)[n] += a * kHumHarmonics[h] * std::sin(w * static_cast<double>(n) + hum_phase[h]);
    }
  }
}

// Channel c of the recording: the scaled clean sound, hum, distractors, noise, clipping.
std::vector<float> MixChannel(std::size_t c, const std::vector<double>& clean, double scale,
                              double noise_rms, const std::vector<Distractor>& distractors,
                              const RenderOptions& options) {
  const std::size_t n_samples = clean.size();
  const double gain = options.channels[c].gain;
  std::vector<double> x(n_samples);
  for (std::size_t n = 0; n < n_samples; ++n) x[n] = clean[n] * scale * gain;
  AddHum(gain, options, &x);
  for (std::size_t k = 0; k < distractors.size(); ++k) {
    Distractor d = distractors[k];
    d.time_s += options.channels[c].delay_s - options.channels[0].delay_s;
    d.amplitude *= gain;
    Rng drng = Stream(options.seed, kDistractor, k + 1);
    RenderDistractor(d, 2e-3 + 4e-3 * static_cast<double>(k % 3) / 2.0, options.sample_rate_hz,
                     &drng, &x);
  }
  if (noise_rms > 0) {
    Rng nrng = Stream(options.seed, kNoise, c);
    std::vector<double> noise(n_samples);
    FillNoise(options.noise_color, &nrng, &noise);
    const double k = noise_rms / Rms(noise);
    for (std::size_t n = 0; n < n_samples; ++n) x[n] += k * noise[n];
  }
  if (options.clip_level) {
    const double l = *options.clip_level;
    for (double& v : x) v = std::clamp(v, -l, l);
  }
  return std::vector<float>(x.begin(), x.end());
}

}  // namespace

Recording RenderRecording(const std::vector<std::vector<TruthImpact>>& drops,
                          const RenderOptions& options) {
  std::string err;
  if (!options.IsValid(&err)) throw Error(ErrorCode::kBadParameter, err);
  const double last_onset = CheckImpacts(drops, options);
  std::size_t impact_count = 0;
  for (const auto& d : drops) impact_count += d.size();
  const double duration = RecordingLength(last_onset, impact_count, options);
  const auto n_samples = static_cast<std::size_t>(std::ceil(duration * options.sample_rate_hz));
  if (n_samples == 0) throw Error(ErrorCode::kBadParameter, "render options: empty recording");

  const std::vector<std::vector<Mode>> channel_modes = ChannelModes(options);
  const std::vector<std::vector<double>> clean =
      RenderClean(drops, channel_modes, n_samples, options);
  double unit_peak = 0.0;
  for (const auto& ch : clean) {
    for (double v : ch) unit_peak = std::max(unit_peak, std::fabs(v));
  }
  if (impact_count > 0 && !(unit_peak > 0.0)) {
    throw Error(ErrorCode::kBadParameter, "render: the impacts make no sound");
  }
  // Without impacts the levels (noise, hum, distractors) stay relative to peak_level.
  const double scale = impact_count > 0 ? options.peak_level / unit_peak : 0.0;

  Recording rec;
  rec.sample_rate_hz = options.sample_rate_hz;
  rec.clean_peak = options.peak_level;
  rec.noise_rms =
      options.snr_db ? options.peak_level * std::pow(10.0, -*options.snr_db / 20.0) : 0.0;
  rec.drops = ImpactTruth(drops, channel_modes, scale, rec.noise_rms, options);
  rec.distractors = PlaceDistractors(rec.drops, duration, options);
  for (std::size_t c = 0; c < clean.size(); ++c) {
    rec.channels.push_back(MixChannel(c, clean[c], scale, rec.noise_rms, rec.distractors, options));
  }
  return rec;
}

// ---- presets -------------------------------------------------------------------------------

bool SynthSpec::IsValid(std::string* error) const {
  std::string e;
  if (!scene.IsValid(&e) || !restitution.IsValid(&e) || !truth.IsValid(&e) || !render.IsValid(&e)) {
    if (error) *error = e;
    return false;
  }
  if (drops.empty()) {
    if (error) *error = "no drops";
    return false;
  }
  for (const SynthDrop& d : drops) {
    if (!(d.first_impact_s >= 0.0 && Finite(d.first_impact_s)) ||
        (d.height_m && !(*d.height_m > 0.0 && Finite(*d.height_m)))) {
      if (error) *error = "drop at " + Num(d.first_impact_s) + " s: invalid time or height";
      return false;
    }
  }
  return true;
}

namespace {

// Each preset's scene file in data/scenes/ (bundled_scenes.hpp): the one source of its ball,
// surface, drop and effects. What stays here is the rest of the recipe: e(v), the truth
// options, the render settings and the drop placement.
struct PresetRow {
  const char* name;
  const char* scene_file;  // data/scenes/<scene_file>.toml
};
constexpr PresetRow kPresets[] = {
    {"steel-copper", "steel-copper"},   {"glass-glass", "glass-glass"},
    {"pingpong-wood", "pingpong-wood"}, {"rubber-wood", "rubber-wood"},
    {"phone-16k", "phone-16k"},         {"two-drops", "steel-copper"},
};

// A preset's scene is not a file the user gave: its source stays empty, as for flags.
Scene PresetScene(const std::string& scene_file) {
  Scene scene = BundledScene(scene_file);
  scene.source.clear();
  return scene;
}

}  // namespace

std::vector<std::string> SynthPresetNames() {
  std::vector<std::string> names;
  for (const PresetRow& row : kPresets) names.emplace_back(row.name);
  return names;
}

std::string SynthPresetSceneFile(const std::string& name) {
  for (const PresetRow& row : kPresets) {
    if (name == row.name) return row.scene_file;
  }
  std::string known;
  for (const auto& n : SynthPresetNames()) known += (known.empty() ? "" : ", ") + n;
  throw Error(ErrorCode::kBadParameter,
              "synth preset '" + Abbreviate(name) + "': unknown (known: " + known + ")");
}

SynthSpec SynthPreset(const std::string& name) {
  SynthSpec s;
  s.name = name;
  s.scene = PresetScene(SynthPresetSceneFile(name));  // throws for an unknown name
  s.render.seed = 1;
  if (name == "steel-copper" || name == "two-drops") {
    // Seed 002's experiment (data/scenes/steel-copper.toml) heard at 48 kHz.
    s.restitution = RestitutionModel::PowerLaw(0.935, 0.0075, 1.0);  // 0.92 at 2 m/s
    s.render.sample_rate_hz = 48000;
    s.render.plate_modes = PlateModes("copper-dish");
    s.render.click_gain = 0.3;
    s.render.snr_db = 50.0;
    s.render.hum_hz = 50.0;
    s.render.hum_db = -55.0;
    s.render.latency_s = 5e-4;  // microphone ~17 cm away
    s.render.tail_s = 2.0;
    s.drops = {SynthDrop{1.5, std::nullopt}};
    if (name == "two-drops") {
      s.render.channels = {ChannelSpec{1.0, 0.0, 0.0}, ChannelSpec{0.6, 2.5e-4, 4.0}};
      s.render.distractors = 4;
      s.render.distractor_db = -26.0;
      s.render.seed = 2;
      s.drops = {SynthDrop{0.8, std::nullopt}, SynthDrop{6.5, 0.12}};
    }
    return s;
  }
  if (name == "glass-glass") {
    s.restitution = RestitutionModel::PowerLaw(0.955, 0.01, 1.0);
    s.render.sample_rate_hz = 96000;
    s.render.plate_modes = PlateModes("glass");
    s.render.click_gain = 0.3;
    s.render.snr_db = 45.0;
    s.render.noise_color = NoiseColor::kPink;
    s.render.latency_s = 3e-4;
    s.render.tail_s = 1.0;
    s.render.seed = 3;
    s.drops = {SynthDrop{0.6, std::nullopt}};
    return s;
  }
  if (name == "pingpong-wood") {
    s.restitution = RestitutionModel::Constant(0.90);
    s.truth.contact_s = 2.5e-4;  // thin shell: much longer than Hertz for a solid sphere
    s.render.sample_rate_hz = 44100;
    s.render.plate_modes = PlateModes("wood-table");
    s.render.ball_modes = {{5600, 0.004, 0.6}, {9700, 0.003, 0.4}, {14100, 0.002, 0.25}};
    s.render.click_gain = 0.5;
    s.render.snr_db = 40.0;
    s.render.noise_color = NoiseColor::kPink;
    s.render.hum_hz = 60.0;
    s.render.hum_db = -45.0;
    s.render.latency_s = 8e-4;
    s.render.tail_s = 0.8;
    s.render.seed = 4;
    s.drops = {SynthDrop{0.7, std::nullopt}};
    return s;
  }
  if (name == "rubber-wood") {
    s.restitution = RestitutionModel::PowerLaw(0.90, 0.012, 1.0);
    s.truth.contact_s = 1.4e-3;
    s.render.sample_rate_hz = 44100;
    s.render.plate_modes = PlateModes("wood-table");
    s.render.click_gain = 0.3;
    s.render.snr_db = 40.0;
    s.render.latency_s = 6e-4;
    s.render.tail_s = 0.8;
    s.render.seed = 5;
    s.drops = {SynthDrop{0.5, std::nullopt}};
    return s;
  }
  if (name == "phone-16k") {
    // A phone on the table: glass marble on wood, 16 kHz, noisy, hum, clipped, stray clicks.
    s.restitution = RestitutionModel::Constant(0.85);
    s.truth.min_interval_s = 0.004;
    s.render.sample_rate_hz = 16000;
    s.render.plate_modes = PlateModes("wood-table");
    s.render.click_gain = 0.4;
    s.render.snr_db = 28.0;
    s.render.noise_color = NoiseColor::kPink;
    s.render.hum_hz = 50.0;
    s.render.hum_db = -30.0;
    s.render.clip_level = 0.25;
    s.render.echoes = {Echo{6.0e-3, 0.3}};  // the table edge / a wall near the phone
    s.render.distractors = 6;
    s.render.distractor_db = -20.0;
    s.render.latency_s = 4e-4;
    s.render.tail_s = 0.8;
    s.render.seed = 6;
    s.drops = {SynthDrop{0.9, std::nullopt}};
    return s;
  }
  throw Error(ErrorCode::kInternal, "synth preset '" + name + "': in kPresets but no recipe");
}

const char* TruthSourceName(TruthSource s) {
  return s == TruthSource::kLaw ? "law" : "restitution";
}

namespace {

// The restitution model with e shifted by `shift` (a varied drop).
RestitutionModel Shifted(const RestitutionModel& m, double shift) {
  if (shift == 0.0) return m;
  switch (m.kind) {
    case RestitutionModel::Kind::kConstant:
      return RestitutionModel::Constant(m.e0 + shift);
    case RestitutionModel::Kind::kPowerLaw:
      return RestitutionModel::PowerLaw(m.e0 + shift, m.c, m.p);
    case RestitutionModel::Kind::kFunction:
      break;
  }
  const std::function<double(double)> f = m.function;
  return RestitutionModel::Function([f, shift](double v) { return f(v) + shift; },
                                    m.description + " + " + Num(shift));
}

}  // namespace

std::vector<TruthImpact> DropTruth(const SynthSpec& spec, const SynthDrop& d) {
  Scene scene = spec.scene;
  scene.drop.first_impact_time_s = d.first_impact_s;
  if (d.height_m) {
    scene.drop.height_m = *d.height_m;
    scene.drop.impact_speed_m_s.reset();
  }
  TruthOptions truth = spec.truth;
  if (d.scatter_seed) truth.scatter_seed = *d.scatter_seed;
  if (spec.truth_source == TruthSource::kLaw) {
    if (d.e_shift != 0.0)
      throw Error(ErrorCode::kBadParameter,
                  "drop at " + Num(d.first_impact_s) +
                      " s: an e shift needs restitution truth (the law sets e)");
    return ImpactsFromLaw(scene, truth);
  }
  return ImpactsFromRestitution(scene, Shifted(spec.restitution, d.e_shift), truth);
}

SynthResult Synthesize(const SynthSpec& spec) {
  std::string err;
  if (!spec.IsValid(&err)) throw Error(ErrorCode::kBadParameter, "synth: " + err);
  SynthResult r;
  for (const SynthDrop& d : spec.drops) r.truth.push_back(DropTruth(spec, d));
  r.recording = RenderRecording(r.truth, spec.render);
  return r;
}

nlohmann::json TruthJson(const SynthSpec& spec, const SynthResult& result) {
  nlohmann::json j = TruthJson(spec.scene, spec.render, result.recording, spec.name);
  j["truth_source"] = TruthSourceName(spec.truth_source);
  nlohmann::json truth_opts = {{"min_interval_s", spec.truth.min_interval_s},
                               {"scatter_e", spec.truth.scatter_e},
                               {"scatter_seed", spec.truth.scatter_seed}};
  if (spec.truth_source == TruthSource::kLaw) {
    const std::unique_ptr<ContactLaw> law = CreateLaw(spec.scene.law, spec.scene);
    const std::vector<double> values = law->ParameterValues();
    nlohmann::json params = nlohmann::json::object(), units = nlohmann::json::object();
    for (std::size_t i = 0; i < law->Parameters().size(); ++i) {
      params[law->Parameters()[i].name] = values.at(i);
      units[law->Parameters()[i].name] = law->Parameters()[i].unit;
    }
    j["law"] = {{"name", law->Name()},
                {"formula", law->Formula()},
                {"parameters", params},
                {"units", units},
                {"expression", spec.scene.law.expression},
                {"simulator", "bouncecal::Simulate, default SimulatorOptions"}};
    truth_opts["contact_s"] = "law";
  } else {
    j["restitution"] = spec.restitution.ToJson();
    truth_opts["contact_s"] =
        spec.truth.contact_s ? nlohmann::json(*spec.truth.contact_s) : nlohmann::json("hertz");
  }
  j["truth_options"] = truth_opts;
  // A varied drop (PlanDrops) says how it differs; other drops keep their two-key form.
  for (std::size_t d = 0; d < spec.drops.size() && d < j["drops"].size(); ++d) {
    const SynthDrop& sd = spec.drops[d];
    if (!sd.scatter_seed && sd.e_shift == 0.0) continue;
    const std::optional<double> h = sd.height_m ? sd.height_m : spec.scene.drop.height_m;
    j["drops"][d]["height_m"] = h ? nlohmann::json(*h) : nlohmann::json(nullptr);
    j["drops"][d]["e_shift"] = sd.e_shift;
    j["drops"][d]["scatter_seed"] = sd.scatter_seed.value_or(spec.truth.scatter_seed);
  }
  double e_min = std::numeric_limits<double>::infinity(), e_max = -e_min;
  for (const auto& d : result.truth) {
    for (const TruthImpact& t : d) {
      // A last impact the simulator ended as stuck/at rest has v_out = 0: not a restitution.
      if (!(t.v_out_m_s > 0.0)) continue;
      e_min = std::min(e_min, t.e());
      e_max = std::max(e_max, t.e());
    }
  }
  if (e_min <= e_max) j["e_range"] = {e_min, e_max};
  return j;
}

nlohmann::json TruthJson(const Scene& sc, const RenderOptions& ro, const Recording& rec,
                         const std::string& name) {
  using nlohmann::json;
  json j;
  j["generator"] = std::string("bouncecal synth ") + BOUNCECAL_VERSION;
  j["sample_rate_hz"] = rec.sample_rate_hz;
  j["channels"] = rec.channels.size();
  j["frames"] = rec.channels.empty() ? 0 : rec.channels[0].size();
  j["duration_s"] = rec.duration_s();
  j["time_convention"] =
      "time_s: first touch on the file's clock (t = 0 at sample 0, sample n at n/rate); "
      "onset_s = time_s + latency_s + channel[0].delay_s: first instant of the contact force "
      "pulse as heard in channel 0; channel c hears it at time_s + latency_s + channel[c].delay_s";
  j["preset"] = name;
  j["seed"] = ro.seed;
  json scene;
  scene["ball"] = {{"diameter_m", sc.ball.diameter_m},
                   {"mass_kg", sc.ball.Mass()},
                   {"density_kg_m3", sc.ball.Density()},
                   {"material", sc.ball.material}};
  scene["surface"] = {{"material", sc.surface.material}};
  json drop;
  if (sc.drop.height_m) drop["height_m"] = *sc.drop.height_m;
  if (sc.drop.impact_speed_m_s) drop["impact_speed_m_s"] = *sc.drop.impact_speed_m_s;
  scene["drop"] = drop;
  scene["effects"] = {{"drag", DragModelName(sc.effects.drag)},
                      {"buoyancy", sc.effects.buoyancy},
                      {"contact_duration", sc.effects.contact_duration}};
  scene["environment"] = {{"g_m_s2", sc.environment.g_m_s2},
                          {"air_density_kg_m3", sc.environment.air_density_kg_m3},
                          {"drag_coefficient", sc.environment.drag_coefficient}};
  j["scene"] = scene;
  j["scene_toml"] = SceneToToml(sc);
  json render;
  json chans = json::array();
  for (const ChannelSpec& c : ro.channels) {
    chans.push_back(
        {{"gain", c.gain}, {"delay_s", c.delay_s}, {"mode_spread_db", c.mode_spread_db}});
  }
  json echoes = json::array();
  for (const Echo& e : ro.echoes) echoes.push_back({{"delay_s", e.delay_s}, {"gain", e.gain}});
  render["echoes"] = echoes;
  render["channels"] = chans;
  render["plate_modes"] = ModesJson(ro.plate_modes);
  render["ball_modes"] = ModesJson(ro.ball_modes);
  render["click_gain"] = ro.click_gain;
  render["amplitude_exponent"] = ro.amplitude_exponent;
  render["peak_level"] = ro.peak_level;
  render["snr_db"] = ro.snr_db ? json(*ro.snr_db) : json(nullptr);
  render["noise"] = ro.noise_color == NoiseColor::kPink ? "pink" : "white";
  render["noise_rms"] = rec.noise_rms;
  render["hum_hz"] = ro.hum_hz;
  render["hum_db"] = ro.hum_db;
  render["distractors"] = ro.distractors;
  render["distractor_db"] = ro.distractor_db;
  render["clip_level"] = ro.clip_level ? json(*ro.clip_level) : json(nullptr);
  render["latency_s"] = ro.latency_s;
  render["tail_s"] = ro.tail_s;
  j["render"] = render;
  json drops = json::array();
  for (const auto& d : rec.drops) {
    json impacts = json::array();
    int index = 0;
    for (const RenderedImpact& r : d) {
      impacts.push_back({{"index", index++},
                         {"time_s", r.truth.time_s},
                         {"onset_s", r.onset_s},
                         {"v_in_m_s", r.truth.v_in_m_s},
                         {"v_out_m_s", r.truth.v_out_m_s},
                         {"e", r.truth.e()},
                         {"contact_s", r.truth.contact_s},
                         {"amplitude", r.amplitude},
                         {"snr_db", r.snr_db},
                         {"amplitude_per_channel", r.channel_amplitude},
                         {"snr_db_per_channel", r.channel_snr_db},
                         {"clipped", r.clipped}});
    }
    drops.push_back({{"impacts", impacts}});
  }
  j["drops"] = drops;
  json distractors = json::array();
  for (const Distractor& d : rec.distractors) {
    distractors.push_back(
        {{"time_s", d.time_s}, {"amplitude", d.amplitude}, {"freq_hz", d.freq_hz}});
  }
  j["distractors"] = distractors;
  return j;
}

TruthFile LoadTruth(const std::string& path) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw Error(ErrorCode::kInputMissing, path + ": no such file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot be opened for reading");
  TruthFile t;
  try {
    t.document = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw Error(ErrorCode::kBadParameter, path + ": not JSON (" + e.what() + ")");
  }
  const nlohmann::json& j = t.document;
  std::string key;
  try {
    key = "generator";
    const std::string generator = j.at(key).get<std::string>();
    if (generator.rfind("bouncecal synth", 0) != 0 &&
        generator.rfind("bouncecal realsound", 0) != 0) {
      throw Error(ErrorCode::kBadParameter,
                  path + ": not a bouncecal synth or realsound truth file");
    }
    key = "sample_rate_hz";
    t.sample_rate_hz = j.at(key).get<double>();
    key = "render.latency_s";
    t.latency_s = j.at("render").at("latency_s").get<double>();
    key = "drops";
    for (const auto& d : j.at("drops")) {
      std::vector<RenderedImpact> drop;
      for (const auto& i : d.at("impacts")) {
        RenderedImpact r;
        key = "drops[].impacts[]";
        r.truth.time_s = i.at("time_s").get<double>();
        r.truth.v_in_m_s = i.at("v_in_m_s").get<double>();
        r.truth.v_out_m_s = i.at("v_out_m_s").get<double>();
        r.truth.contact_s = i.at("contact_s").get<double>();
        r.onset_s = i.at("onset_s").get<double>();
        r.amplitude = i.at("amplitude").get<double>();
        r.snr_db = i.at("snr_db").get<double>();
        r.clipped = i.at("clipped").get<bool>();
        if (i.contains("amplitude_per_channel")) {
          r.channel_amplitude = i.at("amplitude_per_channel").get<std::vector<double>>();
          r.channel_snr_db = i.at("snr_db_per_channel").get<std::vector<double>>();
        }
        drop.push_back(r);
      }
      t.drops.push_back(std::move(drop));
    }
    key = "distractors";
    for (const auto& d : j.at("distractors")) {
      t.distractors.push_back(Distractor{d.at("time_s").get<double>(),
                                         d.at("amplitude").get<double>(),
                                         d.at("freq_hz").get<double>()});
    }
  } catch (const nlohmann::json::exception& e) {
    throw Error(ErrorCode::kBadParameter,
                path + ": " + key + ": missing or of the wrong type (" + e.what() + ")");
  }
  return t;
}

}  // namespace bouncecal
