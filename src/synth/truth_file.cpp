// The truth file of a synthetic recording (NAME.truth.json): writing and reading.
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
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/bundled_scenes.hpp"
#include "bouncecal/physics/flight.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "synth/synth_internal.hpp"

namespace bouncecal {

using namespace synth;  // NOLINT: the wing's shared helpers

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