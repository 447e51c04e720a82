// bouncecal/synth/synth.hpp — deterministic test recordings of a bouncing ball, with exact truth.
//
// Two stages, usable separately:
//  1. Truth: ImpactsFromRestitution() turns a scene (ball, drop height, drag/buoyancy, contact
//     duration) and a restitution model e(v) into exact impact times and speeds, using the
//     closed-form flights of flight.hpp. (The simulator produces the same TruthImpact list from
//     a contact law; the renderer does not care where the list came from.)
//  2. Sound: RenderRecording() renders one or several drops as a realistic recording — a
//     half-sine contact force pulse of the impact's contact duration driving plate modes
//     (ringing up to ~1 s, overlapping later impacts) and the ball's own modes, a direct
//     broadband click, white/pink noise at a requested SNR, mains hum, distractor clicks,
//     hard clipping, several channels with their own gain and delay, a propagation latency.
//
//   SynthSpec spec = SynthPreset("steel-copper");
//   spec.render.seed = 7;
//   SynthResult r = Synthesize(spec);                      // truth + audio
//   WriteAudio("x.wav", r.recording.channels, r.recording.sample_rate_hz);
//   WriteFileAtomically("x.truth.json", DumpJson(TruthJson(spec, r), 2));
//
// Time convention (the one thing to get right when comparing with a detector):
//   TruthImpact::time_s is the instant of first touch on the scene's clock, which is the file's
//   clock (t = 0 at the first sample). The sound of that impact starts in channel c at
//       onset_s(c) = time_s + render.latency_s + channel[c].delay_s,
//   the first instant of the contact force pulse as heard by that channel. Sample n is the
//   signal at t = n / rate (so a pulse starting at 0.5/rate begins half-way between samples
//   0 and 1). RenderedImpact::onset_s stores onset_s(0).
// Everything random comes from RenderOptions::seed through a fixed generator (SplitMix64 +
// Box–Muller): the same options give bit-identical samples on every platform.
#pragma once

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

// One impact of the ball on the plate.
struct TruthImpact {
  double time_s = 0.0;     // first touch (onset of the contact), s on the file's clock
  double v_in_m_s = 0.0;   // arrival speed (> 0)
  double v_out_m_s = 0.0;  // rebound speed (>= 0)
  double contact_s = 0.0;  // contact duration (length of the rendered force pulse)
  double e() const { return v_in_m_s > 0 ? v_out_m_s / v_in_m_s : 0.0; }
};

// Coefficient of restitution as a function of the impact speed v (m/s).
struct RestitutionModel {
  enum class Kind { kConstant, kPowerLaw, kFunction };
  Kind kind = Kind::kConstant;
  double e0 = 0.9;  // constant value, or e(0) of the power law
  double c = 0.0;   // power law e = e0 - c * v^p
  double p = 1.0;
  std::function<double(double)> function;  // kFunction
  std::string description;                 // kFunction: shown in the truth JSON

  static RestitutionModel Constant(double e);
  static RestitutionModel PowerLaw(double e0, double c, double p);
  static RestitutionModel Function(std::function<double(double)> e_of_v, std::string description);
  // e(v); for kFunction the caller's value (checked by ImpactsFromRestitution to lie in [0, 1]).
  double operator()(double v_m_s) const;
  bool IsValid(std::string* error) const;
  nlohmann::json ToJson() const;
};

struct TruthOptions {
  // Stop when the next flight (onset to onset) would be shorter than this.
  double min_interval_s = 0.002;
  // Stop when the rebound speed falls below this; <= 0: the scene's limits.rest_speed_m_s.
  double rest_speed_m_s = 0.0;
  // Contact duration of every impact; unset: Hertz estimate from the scene's materials.
  std::optional<double> contact_s;
  // Per-bounce restitution scatter of a real ball (docs/physics.md §6): each bounce's e is
  // e(v_in) + scatter_e * N(0, 1), clamped to [0, 1], the normal deviates drawn from
  // scatter_seed (same seed -> same bounces). 0: every bounce follows e(v) exactly.
  double scatter_e = 0.0;
  std::uint64_t scatter_seed = 1;
  bool IsValid(std::string* error) const;
};

// Hertz contact duration of the ball on a flat of the surface material at impact speed v:
// HertzContactTime (kinematics.hpp), tau = 2.87 (m*^2 / (R* E*^2 v))^(1/5) (docs/physics.md §2.3;
// Johnson, Contact Mechanics, eq. 11.24), R* = R, 1/E* = (1-nu_b^2)/E_b + (1-nu_s^2)/E_s, m* = m
// (the reduced mass m M / (m + M) with effects.surface_compliance and a plate of mass M).
// Throws Error(kBadScene) when a material has no Young's modulus.
double HertzContactDuration(const Scene& scene, double v_m_s);

// Exact impact list of one drop: release from rest at scene.drop.height_m (silent; or arrival at
// scene.drop.impact_speed_m_s), first impact at scene.drop.first_impact_time_s, then
// v_out = e(v_in) v_in, flight time and arrival speed from FlightModel::FromScene(scene). When
// scene.effects.contact_duration, each onset-to-onset interval is contact_s + flight time;
// otherwise the flight time alone (contact_s is still reported: it shapes the click).
// Stops per TruthOptions, at scene.limits.max_impacts or past scene.limits.horizon_s.
// Throws Error(kBadScene / kBadParameter) for an invalid scene, model or options.
std::vector<TruthImpact> ImpactsFromRestitution(const Scene& scene, const RestitutionModel& model,
                                                const TruthOptions& options = {});

// Exact impact list of one drop under the scene's contact law (scene.law, created with
// CreateLaw from law_registry.hpp; parameters not given take the law's defaults), computed by
// the contact-law simulator (Simulate in simulator.hpp, default SimulatorOptions): the same
// physics `bouncecal simulate` and `bouncecal calibrate` use, so calibrating the same law on a
// recording rendered from this list recovers its parameters. The simulator always simulates
// the contact, so each onset-to-onset interval is the contact time plus the flight (whatever
// scene.effects.contact_duration says), and each impact's contact_s is the law's contact time.
// The list is cut as ImpactsFromRestitution cuts it: it ends with the first impact whose next
// interval would be shorter than options.min_interval_s or whose rebound speed is below the
// rest speed (or where the simulator stopped: at rest, stuck, horizon, max_impacts).
// options.contact_s must be unset (the law sets the contact durations).
// With options.scatter_e > 0 the sequence is built bounce by bounce instead: each contact
// simulated alone (SimulateContact, gravity on; its e plus the scatter deviate, its contact
// time), then the exact flight to the next impact (flight.hpp). No surface compliance then.
// Throws Error(kBadScene / kBadParameter) for an invalid scene, law, parameter or options.
std::vector<TruthImpact> ImpactsFromLaw(const Scene& scene, const TruthOptions& options = {});

// A damped mode: unit impulse response gain * exp(-t/decay_s) * sin(2 pi freq_hz t).
struct Mode {
  double freq_hz = 1000.0;
  double decay_s = 0.1;  // amplitude time constant
  double gain = 1.0;
};
// Plate presets: "copper-dish" (steel ball on a copper dish), "glass", "wood-table", "floor".
std::vector<Mode> PlateModes(const std::string& preset);
std::vector<std::string> PlatePresetNames();

struct ChannelSpec {
  double gain = 1.0;
  double delay_s = 0.0;  // extra arrival delay of this channel (>= 0)
  // Microphones at different places hear the modes in different proportions: each mode's gain
  // in this channel is scaled by 10^(N(0,1) * mode_spread_db / 20), drawn from the seed.
  double mode_spread_db = 0.0;
};

// A reflection (wall, floor, table edge): a delayed, scaled copy of every impact's sound.
// It is heard as a second, weaker "impact" delay_s after the real one.
struct Echo {
  double delay_s = 0.005;
  double gain = 0.3;
};

enum class NoiseColor { kWhite, kPink };

struct RenderOptions {
  double sample_rate_hz = 48000.0;  // 8 kHz .. 384 kHz
  std::vector<ChannelSpec> channels{ChannelSpec{}};
  std::vector<Mode> plate_modes = PlateModes("copper-dish");
  std::vector<Mode> ball_modes;  // the ball's own ringing (optional)
  // Direct click: the force pulse itself, averaged over each sample period (causal, so the
  // sound never starts before the onset). A pulse much shorter than a sample gives, at 48 kHz,
  // a one-sample click of click_gain * v_in^a, on the scale where a mode of gain 1 struck by
  // the same impulse rings with amplitude v_in^a. Higher rates resolve a taller, narrower click.
  double click_gain = 0.3;
  // Impulse of each impact ~ v_in^a (a = 1: momentum transfer; the amplitude of the modes
  // follows). The contact duration (TruthImpact::contact_s) shapes the spectrum: a long, soft
  // pulse (rubber, ~1.4 ms) barely excites modes above ~1/contact_s.
  double amplitude_exponent = 1.0;
  double peak_level = 0.5;  // the clean signal (all channels / their gains) peaks at this
  // Noise: snr_db = 20 log10(peak_level / noise RMS) where peak_level is the clean peak of a
  // gain-1 channel; the noise (microphone/preamp) has the same RMS in every channel, so a
  // channel with gain g has an SNR of snr_db + 20 log10(g). Unset = no noise.
  std::optional<double> snr_db = 60.0;
  NoiseColor noise_color = NoiseColor::kWhite;
  double hum_hz = 0.0;               // 0 = no hum; 50 or 60 (+ harmonics 2..5)
  double hum_db = -40.0;             // hum fundamental amplitude relative to peak_level
  int distractors = 0;               // clicks at random times with another spectrum
  double distractor_db = -20.0;      // their amplitude relative to peak_level (max)
  std::optional<double> clip_level;  // hard clip at +-clip_level (absolute)
  std::vector<Echo> echoes;          // reflections (none by default)
  double latency_s = 0.0;            // propagation latency added to every onset
  double tail_s = 1.5;               // recording continues after the last onset
  double duration_s = 0.0;           // 0 = last onset + tail_s
  std::uint64_t seed = 1;
  bool IsValid(std::string* error) const;
};

struct RenderedImpact {
  TruthImpact truth;
  double onset_s = 0.0;    // time_s + latency_s + channels[0].delay_s
  double amplitude = 0.0;  // peak |x| of this impact's own clean sound in channel 0
  double snr_db = 0.0;     // 20 log10(amplitude / noise RMS in channel 0); 999 without noise
  bool clipped = false;    // its clean peak exceeds the clip level (channel 0)
  std::vector<double> channel_amplitude;  // amplitude in each channel
  std::vector<double> channel_snr_db;     // snr_db in each channel
};

struct Distractor {
  double time_s = 0.0;  // onset in channel 0
  double amplitude = 0.0;
  double freq_hz = 0.0;  // centre frequency of its resonance
};

struct Recording {
  double sample_rate_hz = 0.0;
  std::vector<std::vector<float>> channels;  // channels[c][frame]
  std::vector<std::vector<RenderedImpact>> drops;
  std::vector<Distractor> distractors;
  double clean_peak = 0.0;  // peak of the clean signal (= peak_level)
  double noise_rms = 0.0;   // broadband noise RMS before channel gain
  double duration_s() const;
};

// Renders the drops (each a list of impacts in time order) into a recording. With no impacts
// at all (and options.duration_s > 0) it renders only noise, hum and distractors, at the levels
// they would have next to impacts peaking at peak_level. Throws Error(kBadParameter) for
// invalid options or impacts (negative times, NaN, ...).
Recording RenderRecording(const std::vector<std::vector<TruthImpact>>& drops,
                          const RenderOptions& options);
inline Recording RenderRecording(const std::vector<TruthImpact>& one_drop,
                                 const RenderOptions& options) {
  return RenderRecording(std::vector<std::vector<TruthImpact>>{one_drop}, options);
}

// A complete recipe for a test recording: scene + e(v) + render settings + drop placement.
struct SynthDrop {
  SynthDrop() = default;
  SynthDrop(double first_impact, std::optional<double> height, double shift = 0.0,
            std::optional<std::uint64_t> seed = std::nullopt)
      : first_impact_s(first_impact), height_m(height), e_shift(shift), scatter_seed(seed) {}
  double first_impact_s = 1.0;     // file time of the drop's first impact
  std::optional<double> height_m;  // overrides scene.drop.height_m for this drop
  // A varied drop (PlanDrops): its restitution shifted by e_shift (e0 of the constant or power
  // law; added to a function's value), its own per-bounce scatter seed. Restitution truth only.
  double e_shift = 0.0;
  std::optional<std::uint64_t> scatter_seed;
};
// Where the truth impacts come from: the restitution model e(v) (ImpactsFromRestitution), or
// the scene's contact law through the simulator (ImpactsFromLaw; restitution is then unused).
enum class TruthSource { kRestitution, kLaw };
const char* TruthSourceName(TruthSource s);  // "restitution", "law"

struct SynthSpec {
  std::string name;  // preset name or "custom"
  Scene scene;
  RestitutionModel restitution;
  TruthSource truth_source = TruthSource::kRestitution;
  TruthOptions truth;
  RenderOptions render;
  std::vector<SynthDrop> drops{SynthDrop{}};
  bool IsValid(std::string* error) const;
};

// Benchmark-corpus presets: "steel-copper", "glass-glass", "pingpong-wood", "rubber-wood",
// "phone-16k", "two-drops". The scene (ball, surface, drop, effects) is the bundled scene file
// SynthPresetSceneFile(name) (data/scenes/NAME.toml, bundled_scenes.hpp; source left empty);
// e(v), the truth options, the render settings and the drops are the preset's own. Throws
// Error(kBadParameter) for an unknown name.
SynthSpec SynthPreset(const std::string& name);
std::vector<std::string> SynthPresetNames();
// The bundled scene file (BundledSceneNames) a preset takes its scene from ("two-drops":
// "steel-copper"). Throws Error(kBadParameter) for an unknown name.
std::string SynthPresetSceneFile(const std::string& name);

struct SynthResult {
  std::vector<std::vector<TruthImpact>> truth;  // per drop
  Recording recording;
};
// Several drops in one file, placed one after another: each drop's first impact comes a gap
// after the previous drop's last impact, the gap drawn uniformly from [gap_min_s, gap_max_s].
// Identical drops (both spreads 0: one drop repeated, as an automated dropper repeats it; with
// scatter_e every copy bounces the same way) or varied ones: each drop's height times
// U(1 - height_spread, 1 + height_spread), its e shifted by U(-e_spread, +e_spread), its own
// scatter seed. Everything random comes from seed.
struct DropPlan {
  int drops = 1;                // 1 .. kMaxDrops
  double first_impact_s = 0.5;  // the first drop's first impact
  double gap_min_s = 1.5;       // last impact of one drop -> first impact of the next
  double gap_max_s = 1.5;       // >= gap_min_s (equal: a fixed gap)
  double height_spread = 0.0;   // relative, in [0, 1)
  double e_spread = 0.0;        // absolute, in [0, 0.5)
  std::uint64_t seed = 1;
  static constexpr int kMaxDrops = 1000;
  bool varied() const { return height_spread > 0.0 || e_spread > 0.0; }
  bool IsValid(std::string* error) const;
};
// The drops of the plan for spec's scene, restitution and truth options (each drop's length from
// its own truth). Throws Error(kBadParameter) for an invalid plan, e_spread with law truth, or
// a drop whose shifted e leaves [0, 1].
std::vector<SynthDrop> PlanDrops(const SynthSpec& spec, const DropPlan& plan);

// Truth for every drop (from spec.truth_source), then RenderRecording.
SynthResult Synthesize(const SynthSpec& spec);
// The truth of one drop of spec at file time first_impact_s (height: the drop's override).
std::vector<TruthImpact> DropTruth(const SynthSpec& spec, const SynthDrop& drop);

// The ground-truth document written beside the audio (stable keys):
// {"generator": "bouncecal synth <version>", "sample_rate_hz", "channels", "duration_s",
//  "time_convention", "preset", "seed", "scene": {...}, "scene_toml", "truth_source",
//  "restitution": {...} (truth_source "restitution") or "law": {"name", "parameters": {NAME:
//  value, every parameter the law was created with}, "units": {NAME: unit}, "expression"}
//  (truth_source "law"), "truth_options", "e_range": [min, max] over the impacts
//  with a rebound (v_out > 0),
//  "render": {...}, "drops": [{"impacts": [{"index", "time_s", "onset_s", "v_in_m_s",
//  "v_out_m_s", "e", "contact_s", "amplitude", "snr_db", "clipped", "amplitude_per_channel",
//  "snr_db_per_channel"}...]} (a varied drop of PlanDrops adds "height_m", "e_shift",
//  "scatter_seed")], "distractors": [...]}
nlohmann::json TruthJson(const SynthSpec& spec, const SynthResult& result);
// The same document for impacts that came from elsewhere (e.g. the contact-law simulator):
// everything but "restitution" and "truth_options"; add your own keys to say where the
// impacts came from. name goes to "preset".
nlohmann::json TruthJson(const Scene& scene, const RenderOptions& render,
                         const Recording& recording, const std::string& name);

// A truth file read back (LoadTruth): what a benchmark needs to score a detector.
struct TruthFile {
  double sample_rate_hz = 0.0;
  double latency_s = 0.0;
  std::vector<std::vector<RenderedImpact>> drops;  // onset_s, amplitude, snr_db, truth...
  std::vector<Distractor> distractors;
  nlohmann::json document;  // the whole JSON
};
// Reads a truth JSON written by `bouncecal synth` / TruthJson. Throws Error(kInputMissing) for
// a missing/unreadable file and Error(kBadParameter) naming the file and the key when the
// document is not a truth file.
TruthFile LoadTruth(const std::string& path);

}  // namespace bouncecal
