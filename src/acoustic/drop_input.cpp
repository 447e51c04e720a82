// Recordings or impact-time files -> the chosen drops (drop_input.hpp).
#include "bouncecal/acoustic/drop_input.hpp"

#include <algorithm>
#include <cstdio>
#include <iterator>
#include <limits>
#include <optional>

#include "bouncecal/acoustic/impacts_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"

namespace bouncecal {
namespace {

// Times from a file keep the detector's window: impacts outside it are dropped, and so are
// sequences left with fewer than 3 impacts.
void ApplyWindow(const std::string& impacts_file, const DetectOptions& opt,
                 std::vector<Sequence>* sequences) {
  const double lo = opt.start_s, hi = opt.end_s.value_or(1e300);
  std::vector<Sequence> kept;
  for (Sequence& q : *sequences) {
    std::vector<Impact> in;
    for (const Impact& i : q.impacts)
      if (i.time_s >= lo && i.time_s < hi) in.push_back(i);
    if (in.size() >= 3) {
      q.impacts = std::move(in);
      kept.push_back(std::move(q));
    }
  }
  if (kept.empty()) {
    throw Error(ErrorCode::kNoBounces,
                impacts_file + ": no sequence of 3 or more impacts in the window [" +
                    FormatGeneral(lo) + ", " +
                    (opt.end_s ? FormatGeneral(*opt.end_s) : std::string("end")) + ") s");
  }
  *sequences = std::move(kept);
}

}  // namespace

std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DropInputOptions& options) {
  const std::vector<std::string>& impacts = options.impacts_files;
  std::vector<std::pair<std::string, std::string>> out;
  if (impacts.empty()) {
    for (const auto& r : recordings) out.push_back({r, ""});
  } else if (recordings.empty()) {
    for (const auto& i : impacts) out.push_back({"", i});
  } else if (impacts.size() == recordings.size()) {
    for (std::size_t k = 0; k < recordings.size(); ++k) out.push_back({recordings[k], impacts[k]});
  } else {
    throw Error(ErrorCode::kUsage, "DropInputOptions::impacts_files given " +
                                       std::to_string(impacts.size()) + " time(s) for " +
                                       std::to_string(recordings.size()) +
                                       " recordings: give one per recording, in the same order");
  }
  if (out.empty()) throw Error(ErrorCode::kUsage, "no recording given");
  if (std::count(recordings.begin(), recordings.end(), std::string("-")) > 1)
    throw Error(ErrorCode::kUsage,
                "standard input (-) is given more than once: it can be read only once");
  return out;
}

LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DropInputOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  const DetectOptions& opt = options.detect;
  LoadedRecording out;
  out.name = recording.empty() ? impacts_file : recording;
  out.impacts_file = impacts_file;
  if (impacts_file.empty()) {
    // Without samples in memory the recording is read block by block.
    out.result = audio ? DetectImpacts(*audio, opt) : DetectImpactsInFile(recording, opt);
  } else {
    std::optional<AudioInfo> info;
    if (audio) {
      info = audio->info;
      out.result.warnings = audio->warnings;
    } else if (!recording.empty()) {
      AudioReader reader(recording);  // every sample is checked, none is kept
      reader.Skip(std::numeric_limits<std::int64_t>::max());
      info = reader.info();
      out.result.warnings = reader.warnings();
    }
    ImpactsFileOptions io;
    if (info) io.duration_s = info->duration_s();
    ImpactsFile f = ReadImpactsFile(impacts_file, io);
    if (info) out.result.audio = *info;
    out.result.sequences = std::move(f.sequences);
    if (opt.start_s > 0.0 || opt.end_s) ApplyWindow(impacts_file, opt, &out.result.sequences);
    int best = 0;
    for (std::size_t s = 1; s < out.result.sequences.size(); ++s)
      if (out.result.sequences[s].impacts.size() >
          out.result.sequences[static_cast<std::size_t>(best)].impacts.size())
        best = static_cast<int>(s);
    out.result.main_sequence = best;
  }
  out.chosen = ChooseSequences(out.result.sequences, options.sequence, out.name);
  return out;
}

std::vector<RecordingDrop> DropsOf(const std::string& recording, const std::string& impacts_file,
                                   const DropInputOptions& options) {
  std::vector<RecordingDrop> drops;
  LoadedRecording r = LoadRecording(recording, nullptr, impacts_file, options);
  for (std::size_t c = 0; c < r.chosen.size(); ++c) {
    const int s = r.chosen[c];
    RecordingDrop d;
    d.name = r.chosen.size() > 1 ? r.name + "#" + std::to_string(s) : r.name;
    d.sequence = r.result.sequences[static_cast<std::size_t>(s)];
    if (c == 0) d.warnings = r.result.warnings;
    drops.push_back(std::move(d));
  }
  return drops;
}

std::vector<RecordingDrop> LoadDrops(const std::vector<std::string>& recordings,
                                     const DropInputOptions& options) {
  std::vector<RecordingDrop> drops;
  for (const auto& [rec, imp] : PairInputs(recordings, options)) {
    std::vector<RecordingDrop> d = DropsOf(rec, imp, options);
    drops.insert(drops.end(), std::make_move_iterator(d.begin()), std::make_move_iterator(d.end()));
  }
  return drops;
}

}  // namespace bouncecal
