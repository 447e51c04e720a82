// The recording of given impacts: plate and ball modes excited by each contact, distractors,
// hum, noise, clipping (see include/bouncecal/synth/synth.hpp for the model).
#include "bouncecal/synth/synth.hpp"

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
namespace {

using namespace synth;  // NOLINT: the wing's shared helpers
using cd = std::complex<double>;

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

}  // namespace

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
    return fail("sample_rate_hz = " + FormatGeneral(sample_rate_hz, 10) +
                " (expected a whole number of Hz from 8000 to 384000)");
  }
  if (channels.empty() || channels.size() > 64) {
    return fail("channels: " + std::to_string(channels.size()) + " (expected 1 to 64)");
  }
  for (std::size_t c = 0; c < channels.size(); ++c) {
    if (!(channels[c].gain > 0.0 && Finite(channels[c].gain))) {
      return fail("channel " + std::to_string(c) +
                  " gain = " + FormatGeneral(channels[c].gain, 10) + " (expected > 0)");
    }
    if (!(channels[c].delay_s >= 0.0 && channels[c].delay_s < 1.0)) {
      return fail("channel " + std::to_string(c) + " delay_s = " +
                  FormatGeneral(channels[c].delay_s, 10) + " (expected 0 <= delay < 1 s)");
    }
    if (!(channels[c].mode_spread_db >= 0.0 && channels[c].mode_spread_db <= 40.0)) {
      return fail("channel " + std::to_string(c) + " mode_spread_db = " +
                  FormatGeneral(channels[c].mode_spread_db, 10) + " (expected 0..40 dB)");
    }
  }
  for (const auto* list : {&plate_modes, &ball_modes}) {
    for (const Mode& m : *list) {
      if (!(m.freq_hz > 0 && Finite(m.freq_hz) && m.decay_s > 0 && m.decay_s <= 10 &&
            Finite(m.gain))) {
        return fail("mode {" + FormatGeneral(m.freq_hz, 10) + " Hz, " +
                    FormatGeneral(m.decay_s, 10) + " s, gain " + FormatGeneral(m.gain, 10) +
                    "} (expected freq > 0, 0 < decay <= 10 s, finite gain)");
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
    return fail("amplitude_exponent = " + FormatGeneral(amplitude_exponent, 10) +
                " (expected 0..4)");
  }
  if (!(peak_level > 0.0 && peak_level <= 1.0)) {
    return fail("peak_level = " + FormatGeneral(peak_level, 10) + " (expected 0 < peak <= 1)");
  }
  if (snr_db && !(*snr_db > -20.0 && *snr_db < 200.0)) {
    return fail("snr_db = " + FormatGeneral(*snr_db, 10) + " (expected -20 < SNR < 200 dB)");
  }
  if (!(hum_hz == 0.0 || (hum_hz >= 10.0 && hum_hz <= 1000.0))) {
    return fail("hum_hz = " + FormatGeneral(hum_hz, 10) + " (expected 0 = off, or 10..1000 Hz)");
  }
  if (!(hum_db <= 20.0 && Finite(hum_db))) return fail("hum_db = " + FormatGeneral(hum_db, 10));
  if (distractors < 0 || distractors > 10000) {
    return fail("distractors = " + std::to_string(distractors) + " (expected 0..10000)");
  }
  if (!(distractor_db <= 20.0 && Finite(distractor_db))) {
    return fail("distractor_db = " + FormatGeneral(distractor_db, 10));
  }
  if (clip_level && !(*clip_level > 0.0 && *clip_level <= 1.0)) {
    return fail("clip_level = " + FormatGeneral(*clip_level, 10) + " (expected 0 < level <= 1)");
  }
  for (const Echo& e : echoes) {
    if (!(e.delay_s > 0.0 && e.delay_s < 1.0 && e.gain >= 0.0 && e.gain <= 1.0)) {
      return fail("echo {" + FormatGeneral(e.delay_s, 10) + " s, gain " +
                  FormatGeneral(e.gain, 10) + "} (expected 0 < delay < 1 s, 0 <= gain <= 1)");
    }
  }
  if (!(latency_s >= 0.0 && latency_s < 1.0)) {
    return fail("latency_s = " + FormatGeneral(latency_s, 10) + " (expected 0 <= latency < 1 s)");
  }
  if (!(tail_s >= 0.0 && tail_s <= 60.0)) return fail("tail_s = " + FormatGeneral(tail_s, 10));
  if (!(duration_s >= 0.0 && duration_s <= 3600.0)) {
    return fail("duration_s = " + FormatGeneral(duration_s, 10) +
                " (expected 0 = auto, or up to 3600 s)");
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
        throw Error(ErrorCode::kBadParameter, where + "time_s = " + FormatGeneral(i.time_s, 10));
      }
      if (!(i.v_in_m_s > 0.0 && Finite(i.v_in_m_s)) || !(i.v_out_m_s >= 0.0) ||
          !Finite(i.v_out_m_s)) {
        throw Error(ErrorCode::kBadParameter, where + "speeds " + FormatGeneral(i.v_in_m_s, 10) +
                                                  ", " + FormatGeneral(i.v_out_m_s, 10) + " m/s");
      }
      if (!(i.contact_s >= 0.0 && i.contact_s < 0.1)) {
        throw Error(ErrorCode::kBadParameter,
                    where + "contact_s = " + FormatGeneral(i.contact_s, 10));
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
                "render options: duration_s = " + FormatGeneral(options.duration_s, 10) +
                    " ends before the last impact at " + FormatGeneral(last_onset, 10) + " s");
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

}  // namespace bouncecal
