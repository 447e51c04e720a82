// Real impact sounds re-placed at the exact times of a physical bounce schedule, over the room's
// synthesised noise (see include/bouncecal/synth/realsound.hpp).
#include "bouncecal/synth/realsound.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/fractional_delay.hpp"
#include "bouncecal/physics/scene.hpp"
#include "random.hpp"

namespace bouncecal {
namespace {

// Random streams of the renderer (apart from RoomNoise's and synth's).
enum Purpose : std::uint64_t { kCutChoice = 201, kNoiseSeed = 202 };

// Longest render: 40 minutes (~0.9 GB of working samples at 48 kHz) — a 600-drop dropper-rig
// file is ~20 minutes.
constexpr double kMaxDuration_s = 2400.0;
// Output peak ceiling: the whole file is scaled down when the mix would pass it (16-bit files
// saturate at full scale).
constexpr double kPeakCeiling = 0.99;

const char* CutChoiceName(CutChoice c) { return c == CutChoice::kPerImpact ? "impact" : "drop"; }

// The schedule's spec in synth's terms (PlanDrops and DropTruth take a SynthSpec).
SynthSpec ScheduleSpec(const RealSoundSpec& spec) {
  SynthSpec s;
  s.name = spec.name;
  s.scene = spec.scene;
  s.restitution = spec.restitution;
  s.truth = spec.truth;
  s.drops = {SynthDrop{spec.drops.first_impact_s, std::nullopt}};
  return s;
}

// Which cut each impact of each drop plays: identical drops (not varied) draw from one stream, so
// every copy plays the same cuts.
std::vector<std::vector<int>> ChooseCuts(const RealSoundSpec& spec, const SoundSource& src,
                                         const std::vector<std::vector<TruthImpact>>& truth) {
  const int n_cuts = static_cast<int>(src.cuts.size());
  std::vector<std::vector<int>> out;
  for (std::size_t d = 0; d < truth.size(); ++d) {
    synth_random::Rng rng =
        synth_random::Stream(spec.seed, kCutChoice, spec.drops.varied() ? d : 0);
    auto draw = [&] { return std::min(n_cuts - 1, static_cast<int>(rng.Uniform() * n_cuts)); };
    std::vector<int> cuts(truth[d].size());
    if (spec.cut_choice == CutChoice::kOnePerDrop) {
      const int c = spec.cut >= 0 ? spec.cut : draw();
      std::fill(cuts.begin(), cuts.end(), c);
    } else {
      for (int& c : cuts) c = draw();
    }
    out.push_back(std::move(cuts));
  }
  return out;
}

// Keeps the window [start, start + length) of the samples and the impacts whose onset is in it,
// on the window's clock. Returns the window's start (s, a whole number of samples).
double ApplyClip(const RealSoundSpec& spec, double rate, std::vector<double>* x, RealSoundResult* r,
                 std::vector<std::vector<double>>* peaks) {
  if (!spec.clip_start_s) return 0.0;
  const auto a = static_cast<std::int64_t>(std::llround(*spec.clip_start_s * rate));
  const auto n = static_cast<std::int64_t>(std::llround(
      spec.clip_length_s.value_or(static_cast<double>(x->size()) / rate - *spec.clip_start_s) *
      rate));
  const std::int64_t b = std::min<std::int64_t>(a + n, static_cast<std::int64_t>(x->size()));
  if (a < 0 || b - a < 1)
    throw Error(ErrorCode::kBadParameter,
                "realsound: clip [" + FormatGeneral(*spec.clip_start_s, 8) + " s, +" +
                    FormatGeneral(spec.clip_length_s.value_or(0.0), 8) +
                    " s] lies outside the render (" +
                    FormatGeneral(static_cast<double>(x->size()) / rate, 8) + " s)");
  *x = std::vector<double>(x->begin() + a, x->begin() + b);
  const double offset = static_cast<double>(a) / rate, end = static_cast<double>(b - a) / rate;
  RealSoundResult kept;
  std::vector<std::vector<double>> kept_peaks;
  for (std::size_t d = 0; d < r->truth.size(); ++d) {
    std::vector<TruthImpact> t;
    std::vector<int> c;
    std::vector<double> g, p;
    for (std::size_t k = 0; k < r->truth[d].size(); ++k) {
      TruthImpact i = r->truth[d][k];
      i.time_s -= offset;
      if (i.time_s < 0.0 || i.time_s >= end) continue;
      t.push_back(i);
      c.push_back(r->cut_of_impact[d][k]);
      g.push_back(r->gain_of_impact[d][k]);
      p.push_back((*peaks)[d][k]);
    }
    if (t.empty()) continue;
    kept_peaks.push_back(std::move(p));
    kept.truth.push_back(std::move(t));
    kept.cut_of_impact.push_back(std::move(c));
    kept.gain_of_impact.push_back(std::move(g));
  }
  if (kept.truth.empty())
    throw Error(ErrorCode::kBadParameter, "realsound: the clip holds no impact onset");
  r->truth = std::move(kept.truth);
  r->cut_of_impact = std::move(kept.cut_of_impact);
  r->gain_of_impact = std::move(kept.gain_of_impact);
  *peaks = std::move(kept_peaks);
  return offset;
}

}  // namespace

bool RealSoundSpec::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "realsound: " + m;
    return false;
  };
  std::string e;
  if (!scene.IsValid(&e) || !restitution.IsValid(&e) || !truth.IsValid(&e) || !drops.IsValid(&e))
    return fail(e);
  if (cut < -1) return fail("cut = " + std::to_string(cut) + " (expected >= -1)");
  if (!(amplitude_exponent >= 0.0 && amplitude_exponent <= 4.0))
    return fail("amplitude_exponent = " + FormatGeneral(amplitude_exponent, 8) +
                " (expected 0..4)");
  if (!(noise_gain_db >= -120.0 && noise_gain_db <= 60.0))
    return fail("noise_gain_db = " + FormatGeneral(noise_gain_db, 8) + " (expected -120..60 dB)");
  if (!(tail_s >= 0.0 && tail_s <= 60.0))
    return fail("tail_s = " + FormatGeneral(tail_s, 8) + " (expected 0..60 s)");
  if (clip_length_s && !clip_start_s) return fail("clip_length_s without clip_start_s");
  if (clip_start_s && !(*clip_start_s >= 0.0 && std::isfinite(*clip_start_s)))
    return fail("clip_start_s = " + FormatGeneral(*clip_start_s, 8) + " (expected >= 0)");
  if (clip_length_s && !(*clip_length_s > 0.0 && std::isfinite(*clip_length_s)))
    return fail("clip_length_s = " + FormatGeneral(*clip_length_s, 8) + " (expected > 0)");
  return true;
}

RealSoundSpec RealSoundSpecFor(const SoundSource& source) {
  RealSoundSpec spec;
  spec.name = source.name;
  namespace fs = std::filesystem;
  // The recording's own scene file (ball, drag) when it has one; its drop height only when the
  // file gives one, else the height estimated from the marks.
  const fs::path toml = fs::path(source.path).parent_path() / (source.name + ".toml");
  std::error_code ec;
  bool height_given = false;
  if (fs::exists(toml, ec)) {
    spec.scene = LoadSceneFile(toml.string());
    for (const std::string& key : SceneFileKeys(toml.string()))
      height_given = height_given || key == "drop.height_m";
  }
  if (!height_given) spec.scene.drop.height_m = source.height_estimate_m;
  spec.scene.drop.impact_speed_m_s.reset();
  spec.restitution = RestitutionModel::Constant(source.e_estimate);
  spec.drops.first_impact_s = 0.5;
  return spec;
}

RealSoundResult RenderRealSound(const SoundSource& src, const RealSoundSpec& spec) {
  std::string err;
  if (!spec.IsValid(&err)) throw Error(ErrorCode::kBadParameter, err);
  if (spec.cut >= static_cast<int>(src.cuts.size()))
    throw Error(ErrorCode::kBadParameter, "realsound: cut " + std::to_string(spec.cut) + " of " +
                                              src.name + " (it has " +
                                              std::to_string(src.cuts.size()) + " cuts)");
  const double rate = src.sample_rate_hz;
  const SynthSpec schedule = ScheduleSpec(spec);
  RealSoundResult r;
  for (const SynthDrop& d : PlanDrops(schedule, spec.drops))
    r.truth.push_back(DropTruth(schedule, d));
  double last = 0.0;
  for (const auto& d : r.truth) last = std::max(last, d.back().time_s);
  const double duration = last + spec.tail_s;
  if (duration > kMaxDuration_s)
    throw Error(ErrorCode::kBadParameter, "realsound: the schedule lasts " +
                                              FormatGeneral(duration, 8) + " s (at most " +
                                              FormatGeneral(kMaxDuration_s, 8) + " s)");
  r.cut_of_impact = ChooseCuts(spec, src, r.truth);
  for (std::size_t d = 0; d < r.truth.size(); ++d) {
    r.gain_of_impact.emplace_back();
    for (std::size_t k = 0; k < r.truth[d].size(); ++k) {
      const RealSoundCut& c = src.cuts[static_cast<std::size_t>(r.cut_of_impact[d][k])];
      r.gain_of_impact[d].push_back(
          std::pow(r.truth[d][k].v_in_m_s / c.speed_m_s, spec.amplitude_exponent));
    }
  }
  std::vector<double> x(static_cast<std::size_t>(std::ceil(duration * rate)), 0.0);
  std::vector<std::vector<double>> peaks(r.truth.size());  // each impact's own clean peak
  for (std::size_t d = 0; d < r.truth.size(); ++d)
    for (std::size_t k = 0; k < r.truth[d].size(); ++k) {
      const RealSoundCut& c = src.cuts[static_cast<std::size_t>(r.cut_of_impact[d][k])];
      peaks[d].push_back(fractional_delay::AddDelayed(
          c.samples, c.onset_index, r.truth[d][k].time_s * rate, r.gain_of_impact[d][k], &x));
    }
  const double noise_gain = spec.noise ? std::pow(10.0, spec.noise_gain_db / 20.0) : 0.0;
  if (spec.noise) src.noise.AddTo(noise_gain, spec.seed ^ kNoiseSeed, &x);
  r.clip_offset_s = ApplyClip(spec, rate, &x, &r, &peaks);
  double peak = 0.0;
  for (double v : x) peak = std::max(peak, std::fabs(v));
  r.output_gain = peak > kPeakCeiling ? kPeakCeiling / peak : 1.0;
  Recording& rec = r.recording;
  rec.sample_rate_hz = rate;
  rec.channels.assign(1, std::vector<float>(x.size()));
  for (std::size_t i = 0; i < x.size(); ++i)
    rec.channels[0][i] = static_cast<float>(x[i] * r.output_gain);
  rec.noise_rms = src.noise.rms() * noise_gain * r.output_gain;
  for (std::size_t d = 0; d < r.truth.size(); ++d) {
    rec.drops.emplace_back();
    for (std::size_t k = 0; k < r.truth[d].size(); ++k) {
      RenderedImpact ri;
      ri.truth = r.truth[d][k];
      ri.onset_s = ri.truth.time_s;
      ri.amplitude = peaks[d][k] * r.output_gain;
      ri.snr_db = rec.noise_rms > 0.0 ? 20.0 * std::log10(ri.amplitude / rec.noise_rms) : 999.0;
      ri.channel_amplitude = {ri.amplitude};
      ri.channel_snr_db = {ri.snr_db};
      rec.clean_peak = std::max(rec.clean_peak, ri.amplitude);
      rec.drops.back().push_back(ri);
    }
  }
  return r;
}

nlohmann::json RealSoundTruthJson(const SoundSource& src, const RealSoundSpec& spec,
                                  const RealSoundResult& r) {
  using nlohmann::json;
  RenderOptions ro;  // the shared keys of synth's document (one channel, no latency)
  ro.sample_rate_hz = src.sample_rate_hz;
  ro.amplitude_exponent = spec.amplitude_exponent;
  ro.tail_s = spec.tail_s;
  ro.seed = spec.seed;
  json j = TruthJson(spec.scene, ro, r.recording, spec.name);
  j["generator"] = std::string("bouncecal realsound ") + BOUNCECAL_VERSION;
  j["time_convention"] =
      "time_s = onset_s: the instant the placed cut's reference onset is heard (sample n at "
      "n/rate, t = 0 at sample 0): the hand mark of the reference cut (cuts[0]) and, for the "
      "other cuts, their hand mark plus their alignment lag against it";
  j["render"] = {{"latency_s", 0.0},
                 {"channels", json::array({{{"gain", 1.0}, {"delay_s", 0.0}}})},
                 {"amplitude_exponent", spec.amplitude_exponent},
                 {"noise", spec.noise ? "room" : "none"},
                 {"noise_rms", r.recording.noise_rms},
                 {"tail_s", spec.tail_s},
                 {"interpolation", "Kaiser-windowed sinc, 32 taps each side, beta 8"}};
  j["truth_source"] = "restitution";
  j["restitution"] = spec.restitution.ToJson();
  j["truth_options"] = {{"min_interval_s", spec.truth.min_interval_s},
                        {"scatter_e", spec.truth.scatter_e},
                        {"scatter_seed", spec.truth.scatter_seed}};
  j["drop_plan"] = {{"drops", spec.drops.drops},
                    {"first_impact_s", spec.drops.first_impact_s},
                    {"gap_min_s", spec.drops.gap_min_s},
                    {"gap_max_s", spec.drops.gap_max_s},
                    {"height_spread", spec.drops.height_spread},
                    {"e_spread", spec.drops.e_spread},
                    {"seed", spec.drops.seed},
                    {"identical", !spec.drops.varied()}};
  json cuts = json::array();
  for (const RealSoundCut& c : src.cuts)
    cuts.push_back({{"mark", c.mark},
                    {"k", src.marks[static_cast<std::size_t>(c.mark)].k},
                    {"mark_s", c.mark_s},
                    {"onset_s", c.onset_s},
                    {"lag_s", c.lag_s},
                    {"correlation", c.correlation},
                    {"speed_m_s", c.speed_m_s},
                    {"peak", c.peak},
                    {"length_s", static_cast<double>(c.samples.size()) / src.sample_rate_hz}});
  json noise = src.noise.ToJson();
  noise["gain_db"] = spec.noise ? json(spec.noise_gain_db) : json(nullptr);
  j["realsound"] = {
      {"recording", std::filesystem::path(src.path).filename().string()},
      {"channel", src.channel},
      {"cuts", cuts},
      {"alignment_sigma_s", src.alignment_sigma_s ? json(*src.alignment_sigma_s) : json(nullptr)},
      {"onset_convention",
       "cuts share the reference cut's hand mark (+-0.2 ms, a constant offset for the whole "
       "file); with cut_choice \"drop\" every interval is exact, with \"impact\" intervals are "
       "exact to alignment_sigma_s"},
      {"cut_choice", CutChoiceName(spec.cut_choice)},
      {"cut", spec.cut},
      {"noise", noise},
      {"output_gain", r.output_gain},
      {"clip_start_s", spec.clip_start_s ? json(r.clip_offset_s) : json(nullptr)}};
  for (std::size_t d = 0; d < r.truth.size(); ++d)
    for (std::size_t k = 0; k < r.truth[d].size(); ++k) {
      j["drops"][d]["impacts"][k]["cut"] = r.cut_of_impact[d][k];
      j["drops"][d]["impacts"][k]["gain"] = r.gain_of_impact[d][k] * r.output_gain;
    }
  return j;
}

}  // namespace bouncecal
