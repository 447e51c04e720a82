// The synth presets and Synthesize: a preset's scene, truth and rendering options, rendered.
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

using namespace synth;  // NOLINT: the wing's shared helpers

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
      if (error)
        *error = "drop at " + FormatGeneral(d.first_impact_s, 10) + " s: invalid time or height";
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
                                    m.description + " + " + FormatGeneral(shift, 10));
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
                  "drop at " + FormatGeneral(d.first_impact_s, 10) +
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

}  // namespace bouncecal
