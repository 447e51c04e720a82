// `bouncecal detect FILE...`: recording -> impact onsets -> bounce sequences.
//
//   bouncecal detect drop.wav                      # table on stdout
//   bouncecal detect drop.wav --channel 1 --json   # JSON contract below
//   bouncecal detect drop.wav --csv                # one row per impact of every sequence
//   bouncecal detect a.wav b.m4a --json            # several recordings: a JSON array
//   bouncecal detect drop.wav --click-track clicks.wav   # listen to what was found
//
// --json: schema bouncecal.detect/2 (docs/schema.md; built by DetectionJson, io/schema.hpp).
//   Several recordings: an array of these objects, one per recording in order; a recording that
//   failed is a bouncecal.error/1 object {"schema", "file", "error": {"code", "exit_code",
//   "message"}}.
// --csv: sequence,index,time_s,time_sigma_s,amplitude,snr_db,score,clipped (several
//   recordings: a leading file column); numbers in shortest round-trip form, empty = unknown.
// Errors: one line on stderr, exit code from error.hpp, nothing on stdout (one recording);
// several recordings: each failure on stderr, the others printed, exit 12 if any failed.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/click_track.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "commands.hpp"
#include "detect_flags.hpp"
#include "output.hpp"

namespace bouncecal::cli {
namespace {

struct DetectArgs {
  std::vector<std::string> files;
  DetectFlags detect;
  double hop_ms = 0.0;
  bool no_refine = false;
  bool json = false;
  bool csv = false;
  std::string click_track;
  bool force = false;
};

void PrintCsv(const std::string& file, const DetectionResult& r, bool with_file) {
  for (std::size_t s = 0; s < r.sequences.size(); ++s) {
    const auto& imps = r.sequences[s].impacts;
    for (std::size_t k = 0; k < imps.size(); ++k) {
      const Impact& i = imps[k];
      if (with_file) std::cout << CsvField(file) << ",";
      std::cout << s << "," << k << "," << CsvNumber(i.time_s) << "," << CsvNumber(i.sigma_s) << ","
                << CsvNumber(i.amplitude) << "," << CsvNumber(i.snr_db) << "," << CsvNumber(i.score)
                << "," << (i.clipped ? 1 : 0) << "\n";
    }
  }
}

void PrintTable(const std::string& file, const LoadedRecording& l) {
  const DetectionResult& r = l.result;
  std::printf("%s: %.0f Hz, %d channel(s), %.3f s, %s\n", file.c_str(), r.audio.sample_rate_hz,
              r.audio.channels, r.audio.duration_s(),
              !l.impacts_file.empty() ? ("times from " + l.impacts_file).c_str()
              : r.channel >= 0 ? ("listening to channel " + std::to_string(r.channel)).c_str()
                               : "listening to the mix");
  if (r.audio.decoder == "ffmpeg")
    std::printf("decoded by FFmpeg: %s in %s%s\n", r.audio.subtype.c_str(), r.audio.format.c_str(),
                r.audio.codec_delay_samples > 0
                    ? (", " + std::to_string(r.audio.codec_delay_samples) + " priming samples " +
                       (r.audio.codec_delay_trimmed ? "trimmed" : "not trimmed"))
                          .c_str()
                    : "");
  for (const ChannelScore& c : r.channel_scores)
    std::printf("  %s: score %.1f, %d impacts%s\n",
                c.channel >= 0 ? ("channel " + std::to_string(c.channel)).c_str() : "mix", c.score,
                c.impacts, c.failure.empty() ? "" : (" (" + c.failure + ")").c_str());
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
          k == 0 ? "-" : FormatFixed(i.time_s - q.impacts[k - 1].time_s, 6);
      std::printf("  %3zu %12.6f %9.2f %11s %9.4f %7.1f %6.2f%s\n", k, i.time_s, i.sigma_s * 1e6,
                  interval.c_str(), i.amplitude, i.snr_db, i.score, i.clipped ? "  clipped" : "");
      for (int m : q.missed_after)
        if (m == static_cast<int>(k)) std::printf("      (an impact seems missing here)\n");
      for (int m : q.irregular_after)
        if (m == static_cast<int>(k)) std::printf("      (irregular interval next)\n");
    }
    for (const RemovedImpact& x : q.removed)
      std::printf("  removed: t = %.6f s, amplitude %.4f, snr %.1f dB (%s)\n", x.impact.time_s,
                  x.impact.amplitude, x.impact.snr_db, x.code.c_str());
  }
}

void WriteClickTrack(const DetectArgs& a, const Audio& audio, const LoadedRecording& l) {
  std::vector<double> times;
  for (int s : l.chosen)
    for (const Impact& i : l.result.sequences[static_cast<std::size_t>(s)].impacts)
      times.push_back(i.time_s);
  WriteAudio(a.click_track, RenderClickTrack(audio, times), audio.info.sample_rate_hz);
}

void Run(const DetectArgs& a) {
  if (a.json && a.csv) throw Error(ErrorCode::kUsage, "--json and --csv exclude each other");
  if (!(a.hop_ms >= 0.0) || a.hop_ms > 50.0)
    throw Error(ErrorCode::kUsage,
                "--hop-ms " + FormatGeneral(a.hop_ms) + ": must be in [0, 50] (0 = auto)");
  MakeDetectOptions(a.detect);  // flag errors before any work
  const auto inputs = PairInputs(a.files, a.detect);
  if (!a.click_track.empty()) {
    if (inputs.size() != 1 || inputs[0].first.empty())
      throw Error(ErrorCode::kUsage, "--click-track needs exactly one recording");
    std::vector<std::string> in = {inputs[0].first};
    if (!inputs[0].second.empty()) in.push_back(inputs[0].second);
    CheckOutputPath(a.click_track, {.force = a.force, .inputs = in});
  }
  const bool several = inputs.size() > 1;
  nlohmann::json all = nlohmann::json::array();
  bool any_failed = false;
  bool csv_header = false;
  for (std::size_t n = 0; n < inputs.size(); ++n) {
    const std::string& rec = inputs[n].first;
    const std::string& imp = inputs[n].second;
    const std::string name = rec.empty() ? imp : rec;
    try {
      // The samples are kept only for --click-track; otherwise the recording is read block by
      // block (memory independent of its length).
      std::optional<Audio> audio;
      if (!rec.empty() && !a.click_track.empty()) audio = ReadAudio(rec);
      // Options the shared flags do not cover.
      DetectFlags f = a.detect;
      LoadedRecording l;
      if (imp.empty()) {
        DetectOptions o = MakeDetectOptions(f);
        o.hop_s = a.hop_ms * 1e-3;
        o.refine = !a.no_refine;
        l.name = name;
        l.result = audio ? DetectImpacts(*audio, o) : DetectImpactsInFile(rec, o);
        l.chosen = ChooseSequences(l.result.sequences, ParseSequenceChoice(f.sequence), name);
      } else {
        l = LoadRecording(rec, audio ? &*audio : nullptr, imp, f);
      }
      PrintWarnings(l.result.warnings);
      if (a.json) {
        all.push_back(DetectionJson(
            name, l.result, {.chosen = l.chosen, .from_impacts_file = !l.impacts_file.empty()}));
      } else if (a.csv) {
        if (!csv_header)
          std::cout << (several ? "file," : "")
                    << "sequence,index,time_s,time_sigma_s,amplitude,snr_db,score,clipped\n";
        csv_header = true;
        PrintCsv(name, l.result, several);
      } else {
        if (n > 0) std::printf("\n");
        PrintTable(name, l);
      }
      if (!a.click_track.empty()) WriteClickTrack(a, *audio, l);
    } catch (const Error& e) {
      if (!several) throw;
      any_failed = true;
      std::fprintf(stderr, "bouncecal: %s\n", e.what());
      if (a.json) all.push_back(FailedInputJson(name, e.code(), e.what()));
    }
  }
  if (a.json) std::cout << DumpJson(several ? all : all[0], 2) << "\n";
  if (any_failed)
    throw Error(ErrorCode::kSomeFailed, "some recordings failed (see the messages above)");
}

}  // namespace

void RegisterDetect(CLI::App& app) {
  auto args = std::make_shared<DetectArgs>();
  CLI::App* sub =
      app.add_subcommand("detect", "Find the impacts and bounce sequences in recordings");
  sub->add_option(
      "FILE", args->files,
      "recordings (any format libsndfile or FFmpeg reads: WAV, FLAC, m4a/AAC, ...; - reads "
      "standard input)");
  AddDetectFlags(sub, &args->detect);
  sub->add_option("--hop-ms", args->hop_ms, "STFT hop in ms (0 = auto, ~0.33 ms)")
      ->default_val(0.0);
  sub->add_flag("--no-refine", args->no_refine, "Skip the sub-sample change-point refinement");
  AddOutputOption(sub, "--click-track", &args->click_track,
                  "write the recording with a click at every impact found (WAV, FLAC, ...)");
  sub->add_flag("--force", args->force, "replace an existing --click-track file");
  sub->add_flag("--json", args->json, "JSON on stdout");
  sub->add_flag("--csv", args->csv, "CSV on stdout");
  sub->callback([args]() { Run(*args); });
}

}  // namespace bouncecal::cli
