#include "detect_flags.hpp"

#include <cmath>
#include <cstdio>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "output.hpp"

namespace bouncecal::cli {
namespace {}  // namespace

void AddDetectFlags(CLI::App* sub, DetectFlags* f) {
  sub->add_option("--channel", f->channel,
                  "channel: N (0-based), mix, or auto (every channel and the mix are detected; "
                  "the one whose bounce sequence scores best is used)")
      ->capture_default_str();
  sub->add_option("--start", f->start_s, "analyse from this time (s; times stay file times)");
  sub->add_option("--end", f->end_s, "analyse up to this time (s)");
  sub->add_option("--sequence", f->sequence,
                  "which bounce sequence: main (the longest), all (each a separate drop), or N "
                  "(0-based)")
      ->capture_default_str();
  sub->add_option("--min-snr-db", f->min_snr_db,
                  "remove sequence members below this local SNR (dB; default: no cut)");
  sub->add_option("--impacts", f->impacts,
                  "impact times from FILE instead of detection (detect --json output, CSV with a "
                  "time_s column, Audacity labels, or one time per line); one per recording");
  sub->add_option("--threads", f->threads,
                  "threads for detection (0 = one per core, at most 8; the result is the same "
                  "for any count)")
      ->capture_default_str();
}

DetectOptions MakeDetectOptions(const DetectFlags& f) {
  DetectOptions o;
  o.channel = ParseChannelSelection(f.channel);
  if (f.start_s) {
    if (!std::isfinite(*f.start_s) || *f.start_s < 0.0)
      throw Error(ErrorCode::kUsage,
                  "--start " + FormatGeneral(*f.start_s) + ": must be a time >= 0 s");
    o.start_s = *f.start_s;
  }
  if (f.end_s) {
    if (!std::isfinite(*f.end_s) || !(*f.end_s > o.start_s))
      throw Error(ErrorCode::kUsage, "--end " + FormatGeneral(*f.end_s) +
                                         ": must be a time after --start (" +
                                         FormatGeneral(o.start_s) + " s)");
    o.end_s = *f.end_s;
  }
  if (f.min_snr_db) {
    if (!std::isfinite(*f.min_snr_db) || std::fabs(*f.min_snr_db) > 120.0)
      throw Error(ErrorCode::kUsage,
                  "--min-snr-db " + FormatGeneral(*f.min_snr_db) + ": must be in [-120, 120] dB");
    o.min_snr_db = *f.min_snr_db;
  }
  if (f.threads < 0 || f.threads > 256)
    throw Error(ErrorCode::kUsage,
                "--threads " + std::to_string(f.threads) + ": must be 0 (automatic) to 256");
  o.threads = f.threads;
  ParseSequenceChoice(f.sequence);  // kUsage naming the text
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  return o;
}

DropInputOptions MakeDropInputOptions(const DetectFlags& f) {
  DropInputOptions o;
  o.detect = MakeDetectOptions(f);
  o.sequence = ParseSequenceChoice(f.sequence);
  o.impacts_files = f.impacts;
  return o;
}

std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DetectFlags& flags) {
  const DropInputOptions o = MakeDropInputOptions(flags);
  return WithFlagText([&] { return bouncecal::PairInputs(recordings, o); });
}

LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DetectFlags& flags) {
  const DropInputOptions o = MakeDropInputOptions(flags);
  return WithFlagText([&] { return bouncecal::LoadRecording(recording, audio, impacts_file, o); });
}

std::vector<Drop> DropsOf(const std::string& recording, const std::string& impacts_file,
                          const DetectFlags& flags) {
  const DropInputOptions o = MakeDropInputOptions(flags);
  return WithFlagText([&] { return bouncecal::DropsOf(recording, impacts_file, o); });
}

std::vector<Drop> LoadDrops(const std::vector<std::string>& recordings, const DetectFlags& flags) {
  const DropInputOptions o = MakeDropInputOptions(flags);
  return WithFlagText([&] { return bouncecal::LoadDrops(recordings, o); });
}

std::vector<std::string> InputFiles(const std::vector<std::string>& recordings,
                                    const DetectFlags& flags, const std::string& scene_file) {
  std::vector<std::string> files = recordings;
  files.insert(files.end(), flags.impacts.begin(), flags.impacts.end());
  if (!scene_file.empty()) files.push_back(scene_file);
  return files;
}

}  // namespace bouncecal::cli
