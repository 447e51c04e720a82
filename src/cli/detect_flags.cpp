#include "detect_flags.hpp"

#include <cmath>
#include <cstdio>
#include <iterator>

#include "bouncecal/acoustic/impacts_file.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal::cli {
namespace {

std::string Num(double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

}  // namespace

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
                  "remove sequence members below this local SNR (dB; default -3)");
  sub->add_option("--impacts", f->impacts,
                  "impact times from FILE instead of detection (detect --json output, CSV with a "
                  "time_s column, Audacity labels, or one time per line); one per recording");
}

DetectOptions MakeDetectOptions(const DetectFlags& f) {
  DetectOptions o;
  o.channel = ParseChannelSelection(f.channel);
  if (f.start_s) {
    if (!std::isfinite(*f.start_s) || *f.start_s < 0.0)
      throw Error(ErrorCode::kUsage, "--start " + Num(*f.start_s) + ": must be a time >= 0 s");
    o.start_s = *f.start_s;
  }
  if (f.end_s) {
    if (!std::isfinite(*f.end_s) || !(*f.end_s > o.start_s))
      throw Error(ErrorCode::kUsage, "--end " + Num(*f.end_s) + ": must be a time after --start (" +
                                         Num(o.start_s) + " s)");
    o.end_s = *f.end_s;
  }
  if (f.min_snr_db) {
    if (!std::isfinite(*f.min_snr_db) || std::fabs(*f.min_snr_db) > 120.0)
      throw Error(ErrorCode::kUsage,
                  "--min-snr-db " + Num(*f.min_snr_db) + ": must be in [-120, 120] dB");
    o.min_snr_db = *f.min_snr_db;
  }
  ParseSequenceChoice(f.sequence);  // kUsage naming the text
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  return o;
}

std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DetectFlags& f) {
  std::vector<std::pair<std::string, std::string>> out;
  if (f.impacts.empty()) {
    for (const auto& r : recordings) out.push_back({r, ""});
  } else if (recordings.empty()) {
    for (const auto& i : f.impacts) out.push_back({"", i});
  } else if (f.impacts.size() == recordings.size()) {
    for (std::size_t k = 0; k < recordings.size(); ++k)
      out.push_back({recordings[k], f.impacts[k]});
  } else {
    throw Error(ErrorCode::kUsage, "--impacts given " + std::to_string(f.impacts.size()) +
                                       " time(s) for " + std::to_string(recordings.size()) +
                                       " recordings: give one per recording, in the same order");
  }
  if (out.empty()) throw Error(ErrorCode::kUsage, "no recording given");
  return out;
}

LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DetectFlags& flags) {
  const DetectOptions opt = MakeDetectOptions(flags);
  LoadedRecording out;
  out.name = recording.empty() ? impacts_file : recording;
  out.impacts_file = impacts_file;
  Audio read;
  if (!audio && !recording.empty()) {
    read = ReadAudio(recording);
    audio = &read;
  }
  if (impacts_file.empty()) {
    out.result = DetectImpacts(*audio, opt);
  } else {
    ImpactsFileOptions io;
    if (audio) io.duration_s = audio->info.duration_s();
    ImpactsFile f = ReadImpactsFile(impacts_file, io);
    if (audio) out.result.audio = audio->info;
    out.result.sequences = std::move(f.sequences);
    // The window applies to times from a file too.
    if (flags.start_s || flags.end_s) {
      const double lo = opt.start_s, hi = opt.end_s.value_or(1e300);
      std::vector<Sequence> kept;
      for (Sequence& q : out.result.sequences) {
        std::vector<Impact> in;
        for (const Impact& i : q.impacts)
          if (i.time_s >= lo && i.time_s < hi) in.push_back(i);
        if (in.size() >= 3) {
          q.impacts = std::move(in);
          kept.push_back(std::move(q));
        }
      }
      if (kept.empty())
        throw Error(ErrorCode::kNoBounces, impacts_file +
                                               ": no sequence of 3 or more impacts in "
                                               "the window [" +
                                               Num(lo) + ", " +
                                               (opt.end_s ? Num(*opt.end_s) : std::string("end")) +
                                               ") s");
      out.result.sequences = std::move(kept);
    }
    int best = 0;
    for (std::size_t s = 1; s < out.result.sequences.size(); ++s)
      if (out.result.sequences[s].impacts.size() >
          out.result.sequences[static_cast<std::size_t>(best)].impacts.size())
        best = static_cast<int>(s);
    out.result.main_sequence = best;
  }
  out.chosen = ChooseSequences(out.result.sequences, ParseSequenceChoice(flags.sequence), out.name);
  return out;
}

std::vector<Drop> DropsOf(const std::string& recording, const std::string& impacts_file,
                          const DetectFlags& flags) {
  std::vector<Drop> drops;
  LoadedRecording r = LoadRecording(recording, nullptr, impacts_file, flags);
  for (std::size_t c = 0; c < r.chosen.size(); ++c) {
    const int s = r.chosen[c];
    Drop d;
    d.name = r.chosen.size() > 1 ? r.name + "#" + std::to_string(s) : r.name;
    d.sequence = r.result.sequences[static_cast<std::size_t>(s)];
    if (c == 0) d.warnings = r.result.warnings;
    drops.push_back(std::move(d));
  }
  return drops;
}

std::vector<Drop> LoadDrops(const std::vector<std::string>& recordings, const DetectFlags& flags) {
  std::vector<Drop> drops;
  for (const auto& [rec, imp] : PairInputs(recordings, flags)) {
    std::vector<Drop> d = DropsOf(rec, imp, flags);
    drops.insert(drops.end(), std::make_move_iterator(d.begin()), std::make_move_iterator(d.end()));
  }
  return drops;
}

}  // namespace bouncecal::cli
