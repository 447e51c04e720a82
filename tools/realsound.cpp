// realsound — test recordings made of real impact sounds at exact times (synth/realsound.hpp).
//
//   build/realsound --source ../shared/recordings/eeps_pingpong.wav -o pp.wav
//       one drop with the recording's own e and height (estimated from its hand marks), its
//       loudest clean impact sound at every impact, over its room's synthesised noise;
//       pp.wav and pp.truth.json (the format of `bouncecal synth`'s truth file)
//   build/realsound --source REC.wav -o x.flac --drops 12 --gap 1.0,3.0 --vary-height 0.3
//       --vary-e 0.02 --scatter-e 0.004 --cut-choice impact   (one command line)
//       twelve varied drops, each impact a cut drawn at random
//   build/realsound --source REC.wav -o rig.wav --drops 100 --gap 0.1,1.3
//       a dropper rig: one drop copied 100 times with random gaps between copies
//   build/realsound --source REC.wav --list
//       the cuts, their alignment, the noise model and the schedule estimates
//
// Options (defaults in brackets):
//   --source WAV          the recording (WAV.impacts.csv beside it; WAV.toml gives the scene)
//   -o, --output FILE     audio (.wav .flac); the truth goes to <stem>.truth.json
//   --force               replace existing outputs
//   --seed N [1]          cut choices, noise, gaps and drop variation
//   --drops N [1]         drops in the file (1..1000)
//   --gap S | MIN,MAX     last impact of a drop -> first impact of the next [1.5]
//   --vary-height F       varied drops: height x U(1-F, 1+F) [0: identical drops]
//   --vary-e D            varied drops: e + U(-D, D) [0]
//   --height M            drop height [the scene file's, else estimated from the marks]
//   --e E                 constant restitution [estimated from the marks]
//   --e0 E0 --e-slope C [--e-power P]   e = e0 - c v^p
//   --scatter-e S         per-bounce scatter of e [0]
//   --drag none|linear|quadratic   air drag of the schedule [the scene file's, else none]
//   --scene FILE          scene file for the schedule (ball, drag, height)
//   --first-impact S      first impact of the first drop [0.5]
//   --min-interval S      stop a drop before an interval shorter than this [0.002]
//   --cut-choice drop|impact   one cut per drop (exact intervals) or one per impact [drop]
//   --cut N               the cut with --cut-choice drop; -1: drawn per drop [0 = the loudest]
//   --max-cuts N          the loudest clean impacts cut from the recording [5]
//   --amplitude-exponent A   amplitude ~ v^A [1]
//   --noise-db DB         room noise DB louder (+) or quieter (-) than recorded [0]
//   --no-noise            no noise (the clean sound alone)
//   --tail S              recording after the last impact [1.0]
//   --clip-start S [--clip-length S]   keep only this window (a clip starting mid-sequence)
//   --subtype PCM_16|PCM_24|FLOAT [PCM_24]
// Exit codes: those of bouncecal (docs/cli.md "Exit codes"); 2 for a bad command line.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/scene.hpp"
#include "bouncecal/synth/realsound.hpp"

namespace fs = std::filesystem;
using namespace bouncecal;

namespace {

// The value flags and the plain flags the program knows.
const std::vector<std::string> kValueFlags = {"--source",       "-o",
                                              "--output",       "--seed",
                                              "--drops",        "--gap",
                                              "--vary-height",  "--vary-e",
                                              "--height",       "--e",
                                              "--e0",           "--e-slope",
                                              "--e-power",      "--scatter-e",
                                              "--drag",         "--scene",
                                              "--first-impact", "--min-interval",
                                              "--cut-choice",   "--cut",
                                              "--max-cuts",     "--amplitude-exponent",
                                              "--noise-db",     "--tail",
                                              "--clip-start",   "--clip-length",
                                              "--subtype"};
const std::vector<std::string> kPlainFlags = {"--force", "--list", "--no-noise", "--help"};

struct Args {
  std::map<std::string, std::string> values;
  std::map<std::string, bool> flags;
  bool Has(const std::string& k) const { return values.count(k) > 0; }
  const std::string& Get(const std::string& k) const { return values.at(k); }
};

[[noreturn]] void Usage(const std::string& why) {
  throw Error(ErrorCode::kUsage, "realsound: " + why + " (see the top of tools/realsound.cpp)");
}

Args Parse(int argc, char** argv) {
  Args a;
  for (int i = 1; i < argc; ++i) {
    std::string k = argv[i];
    if (k == "--output") k = "-o";
    const bool value = std::find(kValueFlags.begin(), kValueFlags.end(), k) != kValueFlags.end();
    const bool plain = std::find(kPlainFlags.begin(), kPlainFlags.end(), k) != kPlainFlags.end();
    if (plain) {
      a.flags[k] = true;
    } else if (value) {
      if (i + 1 >= argc) Usage(k + " needs a value");
      a.values[k] = argv[++i];
    } else {
      Usage("unknown argument '" + Abbreviate(k) + "'");
    }
  }
  return a;
}

double Number(const Args& a, const std::string& k) {
  const std::string& s = a.Get(k);
  char* end = nullptr;
  const double v = std::strtod(s.c_str(), &end);
  if (s.empty() || *end != '\0' || !std::isfinite(v))
    Usage(k + " '" + Abbreviate(s) + "' is not a number");
  return v;
}

int Integer(const Args& a, const std::string& k) {
  const double v = Number(a, k);
  if (v != std::floor(v) || std::fabs(v) > 1e9) Usage(k + " '" + a.Get(k) + "' is not an integer");
  return static_cast<int>(v);
}

// The schedule and render settings from the flags, on top of the source's own (RealSoundSpecFor).
RealSoundSpec SpecFromArgs(const Args& a, const SoundSource& src) {
  RealSoundSpec spec = RealSoundSpecFor(src);
  if (a.Has("--scene")) {
    const std::optional<double> h = spec.scene.drop.height_m;
    spec.scene = LoadSceneFile(a.Get("--scene"));
    bool given = false;
    for (const std::string& key : SceneFileKeys(a.Get("--scene")))
      given = given || key == "drop.height_m";
    if (!given) spec.scene.drop.height_m = h;
  }
  if (a.Has("--height")) spec.scene.drop.height_m = Number(a, "--height");
  spec.scene.drop.impact_speed_m_s.reset();
  if (a.Has("--drag") && !ParseDragModel(a.Get("--drag"), &spec.scene.effects.drag))
    Usage("--drag '" + a.Get("--drag") + "': expected none, linear or quadratic");
  if (a.Has("--e") && (a.Has("--e0") || a.Has("--e-slope"))) Usage("give --e or --e0/--e-slope");
  if (a.Has("--e")) spec.restitution = RestitutionModel::Constant(Number(a, "--e"));
  if (a.Has("--e0") || a.Has("--e-slope"))
    spec.restitution =
        RestitutionModel::PowerLaw(a.Has("--e0") ? Number(a, "--e0") : src.e_estimate,
                                   a.Has("--e-slope") ? Number(a, "--e-slope") : 0.0,
                                   a.Has("--e-power") ? Number(a, "--e-power") : 1.0);
  if (a.Has("--seed")) {
    const double s = Number(a, "--seed");
    if (s < 0 || s != std::floor(s)) Usage("--seed must be a whole number >= 0");
    spec.seed = static_cast<std::uint64_t>(s);
  }
  spec.drops.seed = spec.seed;
  spec.truth.scatter_seed = spec.seed;
  if (a.Has("--scatter-e")) spec.truth.scatter_e = Number(a, "--scatter-e");
  if (a.Has("--min-interval")) spec.truth.min_interval_s = Number(a, "--min-interval");
  if (a.Has("--drops")) spec.drops.drops = Integer(a, "--drops");
  if (a.Has("--gap")) {
    const std::string g = a.Get("--gap");
    const auto comma = g.find(',');
    Args one;
    one.values["--gap"] = g.substr(0, comma);
    spec.drops.gap_min_s = spec.drops.gap_max_s = Number(one, "--gap");
    if (comma != std::string::npos) {
      one.values["--gap"] = g.substr(comma + 1);
      spec.drops.gap_max_s = Number(one, "--gap");
    }
  }
  if (a.Has("--vary-height")) spec.drops.height_spread = Number(a, "--vary-height");
  if (a.Has("--vary-e")) spec.drops.e_spread = Number(a, "--vary-e");
  if (a.Has("--first-impact")) spec.drops.first_impact_s = Number(a, "--first-impact");
  if (a.Has("--cut-choice")) {
    const std::string& c = a.Get("--cut-choice");
    if (c != "drop" && c != "impact") Usage("--cut-choice '" + c + "': expected drop or impact");
    spec.cut_choice = c == "drop" ? CutChoice::kOnePerDrop : CutChoice::kPerImpact;
  }
  if (a.Has("--cut")) spec.cut = Integer(a, "--cut");
  if (a.Has("--amplitude-exponent")) spec.amplitude_exponent = Number(a, "--amplitude-exponent");
  if (a.Has("--noise-db")) spec.noise_gain_db = Number(a, "--noise-db");
  if (a.flags.count("--no-noise")) spec.noise = false;
  if (a.Has("--tail")) spec.tail_s = Number(a, "--tail");
  if (a.Has("--clip-start")) spec.clip_start_s = Number(a, "--clip-start");
  if (a.Has("--clip-length")) spec.clip_length_s = Number(a, "--clip-length");
  return spec;
}

void List(const SoundSource& s) {
  std::printf("%s: %.0f Hz, channel %d, %zu marks\n", s.path.c_str(), s.sample_rate_hz, s.channel,
              s.marks.size());
  std::printf("schedule estimate: e %.4f, drop height %.3f m\n", s.e_estimate, s.height_estimate_m);
  std::printf("noise: %.1f dBFS RMS from %.2f s of quiet (frame %d, %d frames)\n",
              20.0 * std::log10(s.noise.rms()), s.noise.quiet_s(), s.noise.frame(),
              s.noise.frames_used());
  if (s.alignment_sigma_s)
    std::printf("alignment sigma: %.1f us (closure of the pairwise lags)\n",
                *s.alignment_sigma_s * 1e6);
  else
    std::printf("alignment sigma: - (fewer than 3 cuts; one cut per drop is exact)\n");
  std::printf("%4s %4s %10s %10s %8s %6s %8s %7s %8s\n", "cut", "k", "mark_s", "onset_s", "lag_us",
              "ncc", "v_m_s", "peak", "len_ms");
  for (std::size_t i = 0; i < s.cuts.size(); ++i) {
    const RealSoundCut& c = s.cuts[i];
    std::printf("%4zu %4d %10.5f %10.6f %8.1f %6.3f %8.3f %7.3f %8.1f\n", i,
                s.marks[static_cast<std::size_t>(c.mark)].k, c.mark_s, c.onset_s, c.lag_s * 1e6,
                c.correlation, c.speed_m_s, c.peak,
                1e3 * static_cast<double>(c.samples.size()) / s.sample_rate_hz);
  }
}

int Run(int argc, char** argv) {
  const Args a = Parse(argc, argv);
  if (a.flags.count("--help")) {
    std::printf(
        "usage: realsound --source REC.wav -o OUT.wav [options]; see tools/realsound.cpp\n");
    return 0;
  }
  if (!a.Has("--source")) Usage("give the recording with --source REC.wav");
  SoundSourceOptions so;
  if (a.Has("--max-cuts")) so.max_cuts = Integer(a, "--max-cuts");
  const SoundSource src = LoadSoundSource(a.Get("--source"), so);
  if (a.flags.count("--list")) {
    List(src);
    return 0;
  }
  if (!a.Has("-o")) Usage("give the output with -o OUT.wav");
  const std::string out = a.Get("-o");
  const std::string truth_path = fs::path(out).replace_extension(".truth.json").string();
  const WriteOptions wo{.force = a.flags.count("--force") > 0, .inputs = {a.Get("--source")}};
  CheckOutputPath(out, wo);
  CheckOutputPath(truth_path, wo);
  const RealSoundSpec spec = SpecFromArgs(a, src);
  const RealSoundResult r = RenderRealSound(src, spec);
  const nlohmann::json truth = RealSoundTruthJson(src, spec, r);
  WriteAudio(out, r.recording.channels, r.recording.sample_rate_hz,
             AudioWriteOptions{a.Has("--subtype") ? a.Get("--subtype") : "PCM_24"});
  try {
    WriteFileAtomically(truth_path, DumpJson(truth, 1) + "\n", wo);
  } catch (...) {
    std::error_code ec;
    fs::remove(out, ec);  // never one file without the other
    throw;
  }
  std::size_t impacts = 0;
  for (const auto& d : r.truth) impacts += d.size();
  std::printf("wrote %s (%.0f Hz, %.2f s, %zu impacts in %zu drops, cuts of %s) and %s\n",
              out.c_str(), r.recording.sample_rate_hz, r.recording.duration_s(), impacts,
              r.truth.size(), src.name.c_str(), truth_path.c_str());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(argc, argv);
  } catch (const Error& e) {
    const std::string m = e.what();
    std::fprintf(stderr, "%s%s\n", m.rfind("realsound:", 0) == 0 ? "" : "realsound: ", m.c_str());
    return e.exit_code();
  } catch (const std::exception& e) {
    std::fprintf(stderr, "realsound: internal error: %s\n", e.what());
    return 1;
  }
}
