// `bouncecal synth`: render a test recording of a bouncing ball and its ground truth.
//
//   bouncecal synth --preset steel-copper --seed 1 -o drop.flac
//     -> drop.flac and drop.truth.json (the output path with its extension replaced)
//
// A preset gives the scene, e(v) and the render settings; --scene/scene flags replace or
// override its scene, the other flags override its render settings.
//
// Truth source (--truth-from): "restitution" renders the impacts of the preset's e(v) (or
// --restitution/--e0...); "law" simulates them with the scene's contact law (ImpactsFromLaw:
// the simulator `bouncecal simulate` and `bouncecal calibrate` use). "auto" (default) takes the
// law when one is named explicitly: a [law] table (or law key) in the --scene file, or
// --law/--set/--expression; otherwise the restitution model.
#include <unistd.h>

#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <optional>
#include <regex>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/synth/synth.hpp"
#include "commands.hpp"
#include "output.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {
namespace fs = std::filesystem;

struct SynthFlags {
  std::string preset = "steel-copper";
  SceneFlags scene;
  std::optional<double> rate_hz;
  std::optional<std::uint64_t> seed;
  std::optional<double> snr_db;
  bool no_noise = false;
  std::string noise;  // white | pink
  std::optional<int> channels;
  std::string plate;
  std::optional<double> restitution;
  std::optional<double> e0, e_slope, e_power;
  std::optional<double> contact_s;
  std::optional<double> min_interval_s;
  std::optional<double> scatter_e;
  std::optional<double> hum_hz, hum_db;
  std::optional<int> distractors;
  std::optional<double> distractor_db;
  std::optional<double> clip_level;
  std::optional<double> latency_ms;
  std::optional<double> first_impact_s;
  std::optional<int> drops;
  double drop_gap_s = 1.5;
  std::optional<double> drop_gap_max_s;  // random gaps in [drop_gap_s, this]
  std::optional<double> vary_height, vary_e;
  std::optional<double> tail_s, duration_s;
  std::string subtype;
  std::string truth_from = "auto";  // auto | restitution | law
  std::string output;
  bool force = false;
  bool json = false;
  bool list_presets = false;
};

bool AnyLawFlag(const SceneFlags& f) {
  return !f.law.empty() || !f.law_sets.empty() || !f.expression.empty();
}

bool AnySceneFlag(const SceneFlags& f) {
  return f.height_m || f.impact_speed_m_s || f.diameter_m || f.density_kg_m3 || f.mass_kg ||
         !f.material.empty() || !f.drag.empty() || f.buoyancy || f.contact_duration || f.g_m_s2 ||
         AnyLawFlag(f);
}

// True when the scene file names a contact law: a [law] / [law.parameters] table, a dotted
// law.* key or an inline law = {...} table at the top level.
bool SceneFileNamesLaw(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  static const std::regex kLawKey(R"((^|\n)[ \t]*(\[[ \t]*law[ \t]*[\].]|law[ \t]*[.=]))");
  return std::regex_search(text.str(), kLawKey);
}

TruthSource ChooseTruthSource(const SynthFlags& f) {
  if (f.truth_from == "law") return TruthSource::kLaw;
  if (f.truth_from == "restitution") return TruthSource::kRestitution;
  if (f.truth_from != "auto") {
    throw Error(ErrorCode::kBadParameter,
                "--truth-from " + f.truth_from + ": expected auto, restitution or law");
  }
  const bool law =
      AnyLawFlag(f.scene) || (!f.scene.scene_file.empty() && SceneFileNamesLaw(f.scene.scene_file));
  return law ? TruthSource::kLaw : TruthSource::kRestitution;
}

void Replace(std::string* s, const std::string& from, const std::string& to) {
  for (std::size_t at = s->find(from); at != std::string::npos;
       at = s->find(from, at + to.size())) {
    s->replace(at, from.size(), to);
  }
}

// The preset's scene with the scene flags applied (through ResolveScene, which reads a file).
Scene PresetSceneWithFlags(const SynthSpec& spec, SceneFlags flags) {
  if (!flags.scene_file.empty()) return ResolveScene(flags);
  if (!AnySceneFlag(flags)) return spec.scene;
  const fs::path tmp =
      fs::temp_directory_path() /
      ("bouncecal-synth-" + std::to_string(::getpid()) + "-" + spec.name + ".toml");
  {
    std::ofstream out(tmp);
    out << SceneToToml(spec.scene);
    if (!out) throw Error(ErrorCode::kInternal, tmp.string() + ": cannot write a temporary file");
  }
  flags.scene_file = tmp.string();
  try {
    Scene s = ResolveScene(flags);
    fs::remove(tmp);
    s.source.clear();
    return s;
  } catch (const Error& e) {
    std::error_code ec;
    fs::remove(tmp, ec);
    std::string msg = e.what();
    Replace(&msg, tmp.string(), "preset " + spec.name);
    throw Error(e.code(), msg);
  }
}

std::string TruthPath(const std::string& audio_path) {
  fs::path p(audio_path);
  p.replace_extension(".truth.json");
  return p.string();
}

// The contact law the impacts were simulated with (null: from restitution values).
nlohmann::json SimulatedLawJson(const SynthSpec& spec) {
  if (spec.truth_source != TruthSource::kLaw) return nullptr;
  const auto law = CreateLaw(spec.scene.law, spec.scene);
  return LawJson(*law, law->ParameterValues(), spec.scene.law.expression);
}

// --list-presets: one line per preset.
void ListPresets() {
  for (const std::string& n : SynthPresetNames()) {
    const SynthSpec s = SynthPreset(n);
    std::printf("%-14s %6.0f Hz  %zu ch  ball %s d=%g m on %s, drop %g m, %zu drop(s)\n", n.c_str(),
                s.render.sample_rate_hz, s.render.channels.size(), s.scene.ball.material.c_str(),
                s.scene.ball.diameter_m, s.scene.surface.material.c_str(),
                s.scene.drop.height_m.value_or(0.0), s.drops.size());
  }
}

// The preset with the scene flags applied and the truth source chosen (law or restitution
// model), refusing restitution-model flags when the law gives the truth.
SynthSpec SpecFromPresetAndScene(const SynthFlags& f) {
  SynthSpec spec = SynthPreset(f.preset);
  spec.scene = PresetSceneWithFlags(spec, f.scene);
  if (!f.scene.scene_file.empty() || AnySceneFlag(f.scene)) spec.name += "+scene";
  spec.truth_source = ChooseTruthSource(f);
  if (spec.truth_source == TruthSource::kLaw) {
    if (f.restitution || f.e0 || f.e_slope || f.e_power) {
      throw Error(ErrorCode::kBadParameter,
                  "--restitution/--e0/--e-slope/--e-power: not used when the truth comes from the "
                  "contact law " +
                      spec.scene.law.name + " (give --truth-from restitution)");
    }
    if (f.contact_s) {
      throw Error(ErrorCode::kBadParameter,
                  "--contact-s: the contact law " + spec.scene.law.name +
                      " gives each impact's contact duration (give --truth-from restitution)");
    }
    spec.truth.contact_s.reset();  // the preset's fixed duration is a restitution-model setting
    spec.name += "+law:" + spec.scene.law.name;
  }

  return spec;
}

// The renderer's options from the flags (rate, seed, noise, channels, plate, hum, distractors,
// clipping, latency, length).
void ApplyRenderFlags(const SynthFlags& f, RenderOptions* out) {
  RenderOptions& r = *out;
  if (f.rate_hz) r.sample_rate_hz = *f.rate_hz;
  if (f.seed) r.seed = *f.seed;
  if (f.snr_db) r.snr_db = *f.snr_db;
  if (f.no_noise) r.snr_db.reset();
  if (!f.noise.empty()) {
    if (f.noise == "white") {
      r.noise_color = NoiseColor::kWhite;
    } else if (f.noise == "pink") {
      r.noise_color = NoiseColor::kPink;
    } else {
      throw Error(ErrorCode::kBadParameter, "--noise " + f.noise + ": expected white or pink");
    }
  }
  if (f.channels) {
    if (*f.channels < 1 || *f.channels > 64) {
      throw Error(ErrorCode::kBadParameter,
                  "--channels " + std::to_string(*f.channels) + ": expected 1 to 64");
    }
    // Microphones progressively further away: lower gain, later arrival.
    r.channels.clear();
    for (int c = 0; c < *f.channels; ++c) {
      r.channels.push_back(ChannelSpec{1.0 / (1.0 + 0.5 * c), 2.5e-4 * c});
    }
  }
  if (!f.plate.empty()) r.plate_modes = PlateModes(f.plate);
  if (f.hum_hz) r.hum_hz = *f.hum_hz;
  if (f.hum_db) r.hum_db = *f.hum_db;
  if (f.distractors) r.distractors = *f.distractors;
  if (f.distractor_db) r.distractor_db = *f.distractor_db;
  if (f.clip_level) r.clip_level = *f.clip_level;
  if (f.latency_ms) r.latency_s = *f.latency_ms * 1e-3;
  if (f.tail_s) r.tail_s = *f.tail_s;
  if (f.duration_s) r.duration_s = *f.duration_s;
}

// The restitution model and truth settings from the flags.
void ApplyTruthFlags(const SynthFlags& f, SynthSpec* out) {
  SynthSpec& spec = *out;
  const RenderOptions& r = spec.render;
  if (f.restitution && (f.e0 || f.e_slope || f.e_power)) {
    throw Error(ErrorCode::kBadParameter, "--restitution and --e0/--e-slope/--e-power: give one");
  }
  if (f.restitution) spec.restitution = RestitutionModel::Constant(*f.restitution);
  if (f.e0 || f.e_slope || f.e_power) {
    spec.restitution = RestitutionModel::PowerLaw(
        f.e0.value_or(spec.restitution.e0),
        f.e_slope.value_or(
            spec.restitution.kind == RestitutionModel::Kind::kPowerLaw ? spec.restitution.c : 0.0),
        f.e_power.value_or(spec.restitution.p));
  }
  if (f.contact_s) spec.truth.contact_s = *f.contact_s;
  if (f.min_interval_s) spec.truth.min_interval_s = *f.min_interval_s;
  if (f.scatter_e) {
    spec.truth.scatter_e = *f.scatter_e;
    spec.truth.scatter_seed = r.seed;  // the bounces change with --seed, like the noise
  }
  if (f.first_impact_s) {
    const double shift = *f.first_impact_s - spec.drops.at(0).first_impact_s;
    for (SynthDrop& d : spec.drops) d.first_impact_s += shift;
  }
}

// --drops N with --drop-gap-max, --vary-height or --vary-e: the drop plan (synth.hpp DropPlan:
// random gaps, varied drops), drawn from --seed.
void ApplyDropPlan(const SynthFlags& f, SynthSpec* out) {
  SynthSpec& spec = *out;
  DropPlan plan;
  plan.drops = f.drops.value_or(1);
  plan.first_impact_s = spec.drops.at(0).first_impact_s;
  plan.gap_min_s = f.drop_gap_s;
  plan.gap_max_s = f.drop_gap_max_s.value_or(f.drop_gap_s);
  plan.height_spread = f.vary_height.value_or(0.0);
  plan.e_spread = f.vary_e.value_or(0.0);
  plan.seed = spec.render.seed;
  std::string why;
  if (!plan.IsValid(&why)) {
    throw Error(ErrorCode::kBadParameter,
                RenameFields(why, std::array<NameInFrontEnd, 5>{{{"drops", "--drops"},
                                                                 {"gap_min_s", "--drop-gap"},
                                                                 {"gap_max_s", "--drop-gap-max"},
                                                                 {"height_spread", "--vary-height"},
                                                                 {"e_spread", "--vary-e"}}}));
  }
  spec.drops = PlanDrops(spec, plan);
}

// --drops N: each drop starts drop_gap_s after the previous one's last impact.
void ApplyDrops(const SynthFlags& f, SynthSpec* out) {
  SynthSpec& spec = *out;
  if (f.drop_gap_max_s || f.vary_height || f.vary_e) return ApplyDropPlan(f, out);
  if (f.drops) {
    if (*f.drops < 1 || *f.drops > DropPlan::kMaxDrops) {
      throw Error(ErrorCode::kBadParameter, "--drops " + std::to_string(*f.drops) +
                                                ": expected 1 to " +
                                                std::to_string(DropPlan::kMaxDrops));
    }
    if (!(f.drop_gap_s >= 0.0)) throw Error(ErrorCode::kBadParameter, "--drop-gap must be >= 0");
    // Each drop starts drop_gap_s after the previous one's last impact.
    SynthSpec one = spec;
    one.drops.resize(1);
    const auto truth = DropTruth(spec, SynthDrop{0.0, one.drops[0].height_m});
    const double length_s = truth.back().time_s - truth.front().time_s;
    spec.drops.clear();
    for (int i = 0; i < *f.drops; ++i) {
      spec.drops.push_back(SynthDrop{one.drops[0].first_impact_s + i * (length_s + f.drop_gap_s),
                                     one.drops[0].height_m});
    }
  }
}

// Renders, writes the audio and its truth file (both or neither), and prints the summary.
void WriteAndReport(const SynthFlags& f, const SynthSpec& spec) {
  const std::string truth_path = TruthPath(f.output);
  const WriteOptions wo{.force = f.force, .inputs = {f.scene.scene_file}};
  CheckOutputPath(f.output, wo);
  CheckOutputPath(truth_path, wo);
  AudioWriteOptions ao;
  ao.subtype = f.subtype;
  if (ao.subtype.empty()) {
    std::string ext = fs::path(f.output).extension().string();
    ao.subtype = (ext == ".ogg" || ext == ".oga") ? "VORBIS" : "PCM_16";
  }

  const SynthResult result = Synthesize(spec);
  const nlohmann::json truth = TruthJson(spec, result);
  WriteAudio(f.output, result.recording.channels, result.recording.sample_rate_hz, ao);
  try {
    WriteFileAtomically(truth_path, DumpJson(truth, 2) + "\n", wo);
  } catch (...) {
    std::error_code ec;
    fs::remove(f.output, ec);  // never one file without the other
    throw;
  }

  std::size_t impacts = 0;
  for (const auto& d : result.truth) impacts += d.size();
  if (f.json) {
    nlohmann::json j = {{"schema", kSynthSchema},
                        {"audio", f.output},
                        {"truth", truth_path},
                        {"preset", spec.name},
                        {"seed", spec.render.seed},
                        {"sample_rate_hz", result.recording.sample_rate_hz},
                        {"channels", result.recording.channels.size()},
                        {"duration_s", result.recording.duration_s()},
                        {"drops", result.truth.size()},
                        {"impacts", impacts},
                        {"truth_source", TruthSourceName(spec.truth_source)}};
    j["law"] = SimulatedLawJson(spec);
    std::cout << DumpJson(j, 2) << "\n";
  } else {
    std::printf(
        "wrote %s (%s, %.0f Hz, %zu channel%s, %.2f s, %zu impact%s in %zu drop%s, seed %llu)\n",
        f.output.c_str(), ao.subtype.c_str(), result.recording.sample_rate_hz,
        result.recording.channels.size(), result.recording.channels.size() == 1 ? "" : "s",
        result.recording.duration_s(), impacts, impacts == 1 ? "" : "s", result.truth.size(),
        result.truth.size() == 1 ? "" : "s", static_cast<unsigned long long>(spec.render.seed));
    if (spec.truth_source == TruthSource::kLaw) {
      std::string params;
      for (const auto& [name, value] : truth.at("law").at("parameters").items()) {
        params += " " + name + "=" + DumpJson(value);
      }
      std::printf("impacts simulated with the contact law %s:%s\n", spec.scene.law.name.c_str(),
                  params.c_str());
    }
    if (truth.contains("e_range")) {
      std::printf("restitution e from %.5f to %.5f\n", truth["e_range"][0].get<double>(),
                  truth["e_range"][1].get<double>());
    }
    std::printf("wrote %s (ground truth)\n", truth_path.c_str());
  }
}

void Run(const SynthFlags& f) {
  if (f.list_presets) return ListPresets();
  if (f.output.empty()) throw Error(ErrorCode::kUsage, "synth: give the output file with -o FILE");
  SynthSpec spec = SpecFromPresetAndScene(f);
  ApplyRenderFlags(f, &spec.render);
  ApplyTruthFlags(f, &spec);
  ApplyDrops(f, &spec);
  std::string err;
  if (!spec.IsValid(&err)) throw Error(ErrorCode::kBadParameter, "synth: " + err);

  WriteAndReport(f, spec);
}

}  // namespace

void RegisterSynth(CLI::App& app) {
  auto flags = std::make_shared<SynthFlags>();
  CLI::App* sub = app.add_subcommand(
      "synth", "render a test recording of a bouncing ball plus its ground truth (OUT.truth.json)");
  AddOutputOption(sub, "-o,--output", &flags->output,
                  "output audio (.wav .flac .ogg .aiff); the truth goes to <stem>.truth.json");
  sub->add_flag("--force", flags->force, "replace existing output files");
  sub->add_option("--preset", flags->preset,
                  "steel-copper (default), glass-glass, pingpong-wood, rubber-wood, phone-16k, "
                  "two-drops");
  sub->add_flag("--list-presets", flags->list_presets, "list the presets and exit");
  AddSceneFlags(sub, &flags->scene, /*with_law=*/true);
  sub->add_option("--truth-from", flags->truth_from,
                  "where the impacts come from: restitution (the preset's e(v) or --restitution/"
                  "--e0...), law (the scene's contact law through the simulator, as `bouncecal "
                  "simulate`), auto (default: law when --scene has a [law] table or "
                  "--law/--set/--expression is given)");
  sub->add_option("--rate", flags->rate_hz, "sample rate, Hz (8000..384000)");
  sub->add_option("--seed", flags->seed, "random seed (same seed -> identical file)");
  sub->add_option("--snr-db", flags->snr_db, "peak-to-noise-RMS ratio of channel 0, dB");
  sub->add_flag("--no-noise", flags->no_noise, "no broadband noise");
  sub->add_option("--noise", flags->noise, "noise colour: white or pink");
  sub->add_option("--channels", flags->channels,
                  "channel count; channel c has gain 1/(1+0.5c) and delay 0.25c ms");
  sub->add_option("--plate", flags->plate, "plate modes: copper-dish, glass, wood-table, floor");
  sub->add_option("--restitution", flags->restitution, "constant restitution e");
  sub->add_option("--e0", flags->e0, "power-law restitution e = e0 - c v^p: e0");
  sub->add_option("--e-slope", flags->e_slope, "power-law restitution: c");
  sub->add_option("--e-power", flags->e_power, "power-law restitution: p");
  sub->add_option("--contact-s", flags->contact_s, "contact duration, s (default: Hertz)");
  sub->add_option("--min-interval", flags->min_interval_s,
                  "stop when the next interval would be shorter, s");
  sub->add_option("--scatter-e", flags->scatter_e,
                  "per-bounce restitution scatter of a real ball (sigma of e, e.g. 0.004)");
  sub->add_option("--hum", flags->hum_hz, "mains hum frequency (50 or 60 Hz; 0 = off)");
  sub->add_option("--hum-db", flags->hum_db, "hum level relative to the peak, dB");
  sub->add_option("--distractors", flags->distractors, "number of distractor clicks");
  sub->add_option("--distractor-db", flags->distractor_db,
                  "loudest distractor relative to the peak, dB");
  sub->add_option("--clip", flags->clip_level, "hard-clip level (fraction of full scale)");
  sub->add_option("--latency-ms", flags->latency_ms, "propagation latency, ms");
  sub->add_option("--first-impact", flags->first_impact_s, "time of the first impact, s");
  sub->add_option("--drops", flags->drops, "number of drops in the file");
  sub->add_option("--drop-gap", flags->drop_gap_s,
                  "silence between one drop's last impact and the next drop's first, s");
  sub->add_option("--drop-gap-max", flags->drop_gap_max_s,
                  "random gaps: each drawn uniformly from [--drop-gap, this], s (from --seed)");
  sub->add_option("--vary-height", flags->vary_height,
                  "varied drops: each drop's height times U(1-F, 1+F), its own scatter seed");
  sub->add_option("--vary-e", flags->vary_e, "varied drops: each drop's e shifted by U(-D, D)");
  sub->add_option("--tail", flags->tail_s, "recording after the last impact, s");
  sub->add_option("--duration", flags->duration_s, "total duration, s (default: auto)");
  sub->add_option("--subtype", flags->subtype, "PCM_16 (default), PCM_24, PCM_32, FLOAT, VORBIS");
  sub->add_flag("--json", flags->json, "print a JSON summary");
  sub->callback([flags]() { Run(*flags); });
}

}  // namespace bouncecal::cli
