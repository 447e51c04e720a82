// `bouncecal detect FILE`: recording -> impact onsets -> bounce sequences.
//
//   bouncecal detect drop.wav                      # table on stdout
//   bouncecal detect drop.wav --channel 1 --json   # JSON contract below
//   bouncecal detect drop.wav --csv                # one row per impact of every sequence
//
// --json: {"file", "sample_rate_hz", "channels", "channel_used" (null = mix), "duration_s",
//   "clipping": [{"channel", "clipped_samples", "peak"}], "impacts": [main sequence impacts],
//   "sequences": [{"impacts": [{"time_s", "sigma_s", "amplitude", "snr_db", "score",
//   "clipped"}...], "missed_after": [...], "end_reason"}...], "main_sequence", "n_candidates",
//   "warnings": [...]}.
// --csv: sequence,index,time_s,sigma_s,amplitude,snr_db,score,clipped
// Errors: one line on stderr, exit code from error.hpp, nothing on stdout.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "commands.hpp"
#include "output.hpp"

namespace bouncecal::cli {
namespace {

struct DetectFlags {
  std::string file;
  std::string channel = "auto";
  double hop_ms = 0.0;
  bool no_refine = false;
  bool json = false;
  bool csv = false;
};

nlohmann::json ImpactJson(const Impact& i) {
  return {{"time_s", i.time_s}, {"sigma_s", i.sigma_s}, {"amplitude", i.amplitude},
          {"snr_db", i.snr_db}, {"score", i.score},     {"clipped", i.clipped}};
}

std::string Format(const char* fmt, double a) {
  char buf[64];
  std::snprintf(buf, sizeof buf, fmt, a);
  return buf;
}

void Run(const DetectFlags& f) {
  if (f.json && f.csv) throw Error(ErrorCode::kUsage, "--json and --csv exclude each other");
  if (!(f.hop_ms >= 0.0) || f.hop_ms > 50.0)
    throw Error(ErrorCode::kUsage,
                "--hop-ms " + Format("%g", f.hop_ms) + ": must be in [0, 50] (0 = auto)");
  DetectOptions opt;
  opt.channel = ParseChannelSelection(f.channel);
  opt.hop_s = f.hop_ms * 1e-3;
  opt.refine = !f.no_refine;
  const Audio audio = ReadAudio(f.file);
  const DetectionResult r = DetectImpacts(audio, opt);
  PrintWarnings(r.warnings);

  if (f.json) {
    nlohmann::json j;
    j["file"] = f.file;
    j["sample_rate_hz"] = r.audio.sample_rate_hz;
    j["channels"] = r.audio.channels;
    j["channel_used"] = r.channel >= 0 ? nlohmann::json(r.channel) : nlohmann::json();
    j["duration_s"] = r.audio.duration_s();
    j["clipping"] = nlohmann::json::array();
    for (const ClippingReport& c : r.clipping)
      j["clipping"].push_back(
          {{"channel", c.channel}, {"clipped_samples", c.clipped_samples}, {"peak", c.peak}});
    j["impacts"] = nlohmann::json::array();
    for (const Impact& i : r.main().impacts) j["impacts"].push_back(ImpactJson(i));
    j["sequences"] = nlohmann::json::array();
    for (const Sequence& s : r.sequences) {
      nlohmann::json q;
      q["impacts"] = nlohmann::json::array();
      for (const Impact& i : s.impacts) q["impacts"].push_back(ImpactJson(i));
      q["missed_after"] = s.missed_after;
      q["end_reason"] = s.end_reason;
      j["sequences"].push_back(q);
    }
    j["main_sequence"] = r.main_sequence;
    j["n_candidates"] = r.candidates.size();
    j["warnings"] = WarningsJson(r.warnings);
    std::cout << j.dump(2) << "\n";
    return;
  }
  if (f.csv) {
    std::cout << "sequence,index,time_s,sigma_s,amplitude,snr_db,score,clipped\n";
    for (std::size_t s = 0; s < r.sequences.size(); ++s) {
      const auto& imps = r.sequences[s].impacts;
      for (std::size_t k = 0; k < imps.size(); ++k) {
        const Impact& i = imps[k];
        char buf[256];
        std::snprintf(buf, sizeof buf, "%zu,%zu,%.9f,%.3e,%.6g,%.2f,%.3f,%d\n", s, k, i.time_s,
                      i.sigma_s, i.amplitude, i.snr_db, i.score, i.clipped ? 1 : 0);
        std::cout << buf;
      }
    }
    return;
  }
  std::printf("%s: %.0f Hz, %d channel(s), %.3f s, listening to %s\n", f.file.c_str(),
              r.audio.sample_rate_hz, r.audio.channels, r.audio.duration_s(),
              r.channel >= 0 ? ("channel " + std::to_string(r.channel)).c_str() : "the mix");
  std::printf("%zu onset candidates, %zu sequence(s); main = sequence %d\n", r.candidates.size(),
              r.sequences.size(), r.main_sequence);
  for (std::size_t s = 0; s < r.sequences.size(); ++s) {
    const Sequence& q = r.sequences[s];
    std::printf("\nsequence %zu: %zu impacts, ended: %s\n", s, q.impacts.size(),
                q.end_reason.c_str());
    std::printf("  %3s %12s %9s %11s %9s %7s %6s\n", "k", "time_s", "sigma_us", "interval_s",
                "amplitude", "snr_db", "score");
    for (std::size_t k = 0; k < q.impacts.size(); ++k) {
      const Impact& i = q.impacts[k];
      const std::string interval =
          k == 0 ? "-" : Format("%.6f", i.time_s - q.impacts[k - 1].time_s);
      std::printf("  %3zu %12.6f %9.2f %11s %9.4f %7.1f %6.2f%s\n", k, i.time_s, i.sigma_s * 1e6,
                  interval.c_str(), i.amplitude, i.snr_db, i.score, i.clipped ? "  clipped" : "");
      for (int m : q.missed_after)
        if (m == static_cast<int>(k)) std::printf("      (an impact seems missing here)\n");
    }
  }
}

}  // namespace

void RegisterDetect(CLI::App& app) {
  auto flags = std::make_shared<DetectFlags>();
  CLI::App* sub =
      app.add_subcommand("detect", "Find the impacts and bounce sequences in a recording");
  sub->add_option("FILE", flags->file, "Recording (any format libsndfile reads)")->required();
  sub->add_option("--channel", flags->channel, "Channel: N (0-based), mix or auto")
      ->default_val("auto");
  sub->add_option("--hop-ms", flags->hop_ms, "STFT hop in ms (0 = auto, ~0.33 ms)")
      ->default_val(0.0);
  sub->add_flag("--no-refine", flags->no_refine, "Skip the sub-sample change-point refinement");
  sub->add_flag("--json", flags->json, "JSON on stdout");
  sub->add_flag("--csv", flags->csv, "CSV on stdout");
  sub->callback([flags]() { Run(*flags); });
}

}  // namespace bouncecal::cli
