// The detect pipeline: the analysed window -> the candidate signals -> every signal detected
// block by block -> the best signal -> the result and its warnings.
// See include/bouncecal/acoustic/detect.hpp.
#include "bouncecal/acoustic/detect.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>

#include "blocks.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "detect_signal.hpp"
#include "signals.hpp"

namespace bouncecal {
namespace {

// Warnings of one sequence's flags (missed and irregular intervals).
void FlagWarnings(const std::vector<Sequence>& seqs, std::vector<Warning>* out) {
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    const Sequence& q = seqs[s];
    for (int k : q.missed_after)
      out->push_back({"missed_impact",
                      "sequence " + std::to_string(s) + ": an impact seems missing after impact " +
                          std::to_string(k) +
                          " (t = " + FormatFixed(q.impacts[static_cast<std::size_t>(k)].time_s, 4) +
                          " s); its interval is about two expected ones",
                      k,
                      "listen to the impacts kept (detect --click-track FILE.wav); a bounce heard "
                      "there but not kept can be added in an --impacts file (detect --json)"});
    for (int k : q.irregular_after) {
      const auto& im = q.impacts;
      const std::size_t j = static_cast<std::size_t>(k);
      const double d = im[j + 1].time_s - im[j].time_s;
      const double d0 = j > 0 ? im[j].time_s - im[j - 1].time_s : 0.0;
      out->push_back(
          {"irregular_interval",
           "sequence " + std::to_string(s) + ": the interval after impact " + std::to_string(k) +
               " (t = " + FormatFixed(im[j].time_s, 4) + " s: " + FormatFixed(d, 4) + " s" +
               (j > 0 ? " after " + FormatFixed(d0, 4) + " s" : std::string()) +
               ") breaks the smooth ratio pattern (spin or an uneven spot?); the "
               "sequence continues through it",
           k, "nothing to do if the ball hit an uneven spot; drop it on a flat, hard floor"});
    }
  }
}

// The analysed window: frames [i0, i1) of the recording.
struct Window {
  std::int64_t i0 = 0, i1 = 0;
  std::string text;  // "[start, end) s" when not the whole recording, for messages; else empty
};

// "[start, end) s".
std::string WindowText(const DetectOptions& options) {
  // Appended piece by piece: GCC 12's -Wrestrict misreads "[" + std::string inlined here.
  std::string window = "[";
  window += FormatGeneral(options.start_s) + ", ";
  window += options.end_s ? FormatGeneral(*options.end_s) : std::string("end");
  window += ") s";
  return window;
}

// Refuses a window that starts after the recording ends (its length known).
void CheckWindowStart(const AudioInfo& info, const DetectOptions& options) {
  const double duration_s = info.duration_s();
  if (options.start_s >= duration_s)
    throw Error(ErrorCode::kNoBounces, info.path + ": the window " + WindowText(options) +
                                           " starts after the recording ends (" +
                                           FormatFixed(duration_s, 3) + " s)");
}

// A recording whose header gives no length (kUnknownFrames) is read to its end: the window
// then ends there, and its start is checked once the length is known.
Window AnalysisWindow(const AudioInfo& info, const DetectOptions& options) {
  const double rate = info.sample_rate_hz;
  const bool known = info.frames != kUnknownFrames;
  const std::int64_t frames = known ? info.frames : std::numeric_limits<std::int64_t>::max();
  if (known) CheckWindowStart(info, options);
  const std::string window = WindowText(options);
  Window w;
  w.i0 = static_cast<std::int64_t>(std::ceil(options.start_s * rate));
  w.i1 = options.end_s
             ? std::min(frames, static_cast<std::int64_t>(std::ceil(*options.end_s * rate)))
             : frames;
  const bool windowed = options.start_s > 0.0 || options.end_s.has_value();
  if (windowed) w.text = window;
  return w;
}

// The chosen signal's impacts and sequences in res, and the warnings of the whole detection
// (after the reader's, already in res).
void Finish(SignalDetection chosen, const DetectOptions& options, DetectionResult* out) {
  DetectionResult& res = *out;
  const AudioInfo& info = res.audio;
  const double rate = info.sample_rate_hz;
  res.candidates = std::move(chosen.candidates);
  res.sequences = std::move(chosen.sequences);
  if (!options.refine) {
    for (Impact& im : res.candidates) CoarsenToHop(&im, chosen.hop_samples, rate);
    for (Sequence& q : res.sequences)
      for (Impact& im : q.impacts) CoarsenToHop(&im, chosen.hop_samples, rate);
  }
  res.main_sequence = LongestSequence(res.sequences);
  for (const ClippingReport& c : res.clipping)
    if (c.clipped())
      res.warnings.push_back({"clipped",
                              "channel " + std::to_string(c.channel) + " is clipped (" +
                                  std::to_string(c.clipped_samples) +
                                  " samples at its extreme value); onsets are still usable, "
                                  "amplitudes are not",
                              -1, "record the next drop at a lower input gain"});
  if (info.lossy) {
    const double delay_ms = 1e3 * static_cast<double>(info.codec_delay_samples) / rate;
    res.warnings.push_back(
        {"codec_delay",
         "decoded from lossy " + info.subtype + " (" + info.format + "): " +
             (info.codec_delay_samples > 0
                  ? std::to_string(info.codec_delay_samples) + " priming samples (" +
                        FormatFixed(delay_ms, 2) + " ms) " +
                        (info.codec_delay_trimmed
                             ? "were trimmed as the file says"
                             : "are declared but were not trimmed: times are late by that much")
                  : std::string("no codec delay stated")) +
             "; lossy coding smears onsets (pre-echo), so a constant offset of up to a few ms "
             "is possible (intervals are not)",
         -1, "record in WAV or FLAC (a phone's uncompressed or lossless setting) if you can"});
  }
  ChannelChoiceWarning(res, &res.warnings);
  res.warnings.insert(res.warnings.end(), chosen.warnings.begin(), chosen.warnings.end());
  FlagWarnings(res.sequences, &res.warnings);
}

}  // namespace

bool DetectOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(hop_s >= 0.0) || hop_s > 0.05)
    return fail("DetectOptions::hop_s = " + std::to_string(hop_s) + ": must be in [0, 0.05] s");
  if (min_sequence_impacts < 3)
    return fail("DetectOptions::min_sequence_impacts = " + std::to_string(min_sequence_impacts) +
                ": must be >= 3");
  if (!(min_interval_s > 0.0) || min_interval_s > 1.0)
    return fail("DetectOptions::min_interval_s = " + std::to_string(min_interval_s) +
                ": must be in (0, 1] s");
  if (lpc_order < 0 || lpc_order > 256)
    return fail("DetectOptions::lpc_order = " + std::to_string(lpc_order) + ": must be 0..256");
  if (channel.kind == ChannelSelection::Kind::kIndex && channel.index < 0)
    return fail("DetectOptions::channel.index must be >= 0");
  if (!(start_s >= 0.0) || !std::isfinite(start_s))
    return fail("DetectOptions::start_s = " + FormatGeneral(start_s) +
                ": must be a finite time >= 0 s");
  if (end_s && (!std::isfinite(*end_s) || !(*end_s > start_s)))
    return fail("DetectOptions::end_s = " + FormatGeneral(*end_s) +
                ": must be a finite time after start_s = " + FormatGeneral(start_s) + " s");
  if (!(max_block_s >= 4.0) || !std::isfinite(max_block_s))
    return fail("DetectOptions::max_block_s = " + FormatGeneral(max_block_s) +
                ": must be a finite time >= 4 s");
  if (threads < 0 || threads > 256)
    return fail("DetectOptions::threads = " + std::to_string(threads) +
                ": must be 0 (automatic) to 256");
  if (min_snr_db && (!std::isfinite(*min_snr_db) || std::fabs(*min_snr_db) > 120.0))
    return fail("DetectOptions::min_snr_db = " + FormatGeneral(*min_snr_db) +
                ": must be in [-120, 120] dB");
  return true;
}

DetectionResult DetectImpacts(const Audio& audio, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (audio.channels.empty() || audio.channels.front().empty())
    throw Error(ErrorCode::kNotAudio, audio.info.path + ": no samples");
  AudioReader reader(audio);
  return DetectImpacts(reader, options);
}

DetectionResult DetectImpactsInFile(const std::string& path, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  AudioReader reader(path);
  return DetectImpacts(reader, options);
}

DetectionResult DetectImpacts(AudioReader& reader, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  const AudioInfo& info = reader.info();
  DetectionResult res;
  const bool length_known = info.frames != kUnknownFrames;
  if (info.channels < 1 || (length_known && info.frames <= 0))
    throw Error(ErrorCode::kNotAudio, info.path + ": no samples");
  const Window window = AnalysisWindow(info, options);
  const std::vector<int> choices = CandidateSignals(options.channel, info);
  std::vector<SignalAcrossBlocks> signals(choices.size());
  DetectBlocks(&reader, window.i0, window.i1, choices, options, &signals);
  if (!length_known) CheckWindowStart(reader.info(), options);
  res.audio = reader.info();  // the length, once read to the end
  res.start_s = static_cast<double>(window.i0) / info.sample_rate_hz;
  res.end_s = static_cast<double>(std::min(window.i1, res.audio.frames)) / info.sample_rate_hz;
  res.clipping = reader.clipping();
  res.warnings = reader.warnings();
  Finish(ChooseSignal(choices, &signals, window.text, &res), options, &res);
  return res;
}

SequenceChoice ParseSequenceChoice(const std::string& text) {
  SequenceChoice c;
  if (text == "main") return c;
  if (text == "all") {
    c.kind = SequenceChoice::Kind::kAll;
    return c;
  }
  if (!text.empty() && text.size() < 7 &&
      std::all_of(text.begin(), text.end(), [](unsigned char ch) { return std::isdigit(ch); })) {
    c.kind = SequenceChoice::Kind::kIndex;
    c.index = std::stoi(text);
    return c;
  }
  throw Error(ErrorCode::kUsage,
              "sequence choice '" + text + "': expected main, all or a 0-based sequence index");
}

std::vector<int> ChooseSequences(const std::vector<Sequence>& sequences,
                                 const SequenceChoice& choice, const std::string& name) {
  const int n = static_cast<int>(sequences.size());
  switch (choice.kind) {
    case SequenceChoice::Kind::kMain:
      return n > 0 ? std::vector<int>{LongestSequence(sequences)} : std::vector<int>{};
    case SequenceChoice::Kind::kAll: {
      std::vector<int> all(static_cast<std::size_t>(n));
      for (int s = 0; s < n; ++s) all[static_cast<std::size_t>(s)] = s;
      return all;
    }
    case SequenceChoice::Kind::kIndex:
      if (choice.index >= n)
        throw Error(ErrorCode::kUsage, name + ": sequence " + std::to_string(choice.index) +
                                           " requested, but there " + (n == 1 ? "is " : "are ") +
                                           std::to_string(n) + " sequence" + (n == 1 ? "" : "s") +
                                           " (0-based)");
      return {choice.index};
  }
  return {};
}

}  // namespace bouncecal
