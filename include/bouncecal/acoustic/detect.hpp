// bouncecal/acoustic/detect.hpp — recording -> impacts -> bounce sequences (the acoustic half).
//
// The pipeline, per candidate signal (a channel or the mix): onset detection (onsets.hpp:
// whitening, spectral novelty on a short-hop STFT, adaptive threshold, template search) ->
// bounce-sequence tracking (sequence.hpp) -> guided search where the tracker expects impacts ->
// local timing with per-impact sigma (timing.hpp) -> physical plausibility (plausibility.hpp)
// -> re-timing of the sequences that lost members. With ChannelSelection auto and several
// channels, every channel and the mix go through it and the one whose main sequence scores
// best (ChannelScore) is used. Times are seconds from the start of the file. A recording above
// 64 kHz is low-passed and decimated to at most 64 kHz first (the impact sound lies below
// ~20 kHz; above it only noise), amplitudes staying the full-rate peaks.
//
//   DetectionResult r = DetectImpactsInFile(path, DetectOptions{});  // or DetectImpacts(audio,
//   ...) for (const Impact& i : r.main().impacts) ... i.time_s, i.sigma_s
//
// Throws Error(kSilence) for a silent recording (or window) and Error(kNoBounces) when no
// plausible sequence of at least DetectOptions::min_sequence_impacts impacts is found (the
// message says why: no candidates, intervals that do not shrink, members removed...).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/warning.hpp"

namespace bouncecal {

struct Impact {
  double time_s = 0.0;     // refined onset (first arriving sound), s from file start
  double sigma_s = 0.0;    // 1-sigma timing uncertainty, s
  double amplitude = 0.0;  // peak |x| of the impact (full scale = 1)
  double snr_db = 0.0;     // impact-to-background ratio of the whitened signal, dB
  double score = 0.0;      // detector confidence in [0, 1] (template correlation)
  bool clipped = false;    // the impact's peak is clipped
  // Energy rise of the recorded (not whitened) signal at the onset, dB: the first millisecond
  // after it over the 3.5 ms before it (RawRiseDb). A new impact adds its attack to whatever rings
  // (> 0 dB); a re-trigger inside a decaying sound does not. Set for onset candidates.
  double rise_db = 0.0;
};

// A member taken out of a sequence by the plausibility stage (plausibility.hpp), and why.
struct RemovedImpact {
  Impact impact;
  std::string code;  // the warning code: "phantom_removed", "low_snr_removed", "sigma_removed"
};

struct Sequence {
  std::vector<Impact> impacts;
  std::vector<int> missed_after;       // k: an impact seems missing between impacts k and k+1
  std::vector<int> irregular_after;    // k: interval k -> k+1 breaks the smooth ratio pattern
  std::vector<RemovedImpact> removed;  // members removed as implausible, in time order
  std::string end_reason;              // "resolved_limit", "end_of_file", "gap", ...
};

struct DetectOptions {
  ChannelSelection channel;
  double hop_s = 0.0;             // STFT hop; 0 = auto (~0.33 ms)
  bool refine = true;             // sub-sample timing (false: hop-resolution times, same impacts)
  int min_sequence_impacts = 3;   // fewer than this: not a bounce sequence
  double min_interval_s = 0.003;  // impacts closer than this are not resolvable
  bool guided_search = true;      // look again where the tracker expects the next impact
  int lpc_order = 48;             // whitening predictor order (onsets.hpp, timing.hpp)
  // Analyse only [start_s, end_s) of the recording (end_s unset: to its end). Times stay
  // seconds from the start of the file.
  double start_s = 0.0;
  std::optional<double> end_s;
  // When set, members below this local SNR (timing.hpp: rms of the whitened onset over the robust
  // noise floor before it) are removed (plausibility.hpp, low_snr_removed). Unset by default: no
  // cut. Reason (measured): noise with no onset gives 0 +- 1.2 dB, so a cut below 0 dB never
  // removes a member without an onset in steady noise; below it lie members whose "noise" is the
  // decay of the impact before (a plate's ringing, a tail). On 42 files off the scoreboard, of
  // the members below the former -3 dB cut 55 are true impacts and 1 is not; on the scoreboard
  // all are true (docs/detection-scoreboard.md). A member's evidence is its onset peak, guided
  // look p-value and template NCC, not this level. Set it (--min-snr-db 12) to keep only clear
  // impacts.
  std::optional<double> min_snr_db;
  // Recordings (windows) longer than this are detected in blocks of at most this length (and at
  // most 2^24 frames: 44 s at 384 kHz), cut at the quietest moment of each block's last quarter
  // (between drops), so that memory stays bounded whatever the length. Shorter ones are detected
  // whole. A sequence that runs across a cut gets the warning block_split.
  double max_block_s = 120.0;
  // Threads detection may use, the calling one included (0: the machine's hardware
  // concurrency, at most kMaxAutoThreads, core/parallel.hpp). The blocks of a long recording are
  // detected concurrently (at most threads + 2 blocks in memory), a single block's independent
  // stages split among the threads. The result is the same, to the bit, whatever the count.
  // Default 1: on a 2-core machine whose other core is busy two threads gain no wall time and
  // cost CPU time (docs/benchmarks.md). Callers that run several detections at once (a batch
  // on --jobs workers) need 1.
  int threads = 1;
  bool IsValid(std::string* error) const;
};

// How well one channel (or the mix) supports a bounce sequence: the detection ran on it alone.
struct ChannelScore {
  int channel = -1;    // -1 = the mix of all channels
  double score = 0.0;  // sum of the tracker weights of the main sequence's members (0: none)
  int impacts = 0;     // members of its main sequence
  double first_impact_s = 0.0;
  std::string failure;  // why nothing was found (empty if a sequence was)
};

struct DetectionResult {
  AudioInfo audio;
  int channel = -1;                          // channel used, -1 = mix
  std::vector<ChannelScore> channel_scores;  // auto on several channels: every candidate signal
  std::vector<ClippingReport> clipping;
  double start_s = 0.0;  // the analysed window [start_s, end_s)
  double end_s = 0.0;
  std::vector<Impact> candidates;   // every onset found, before tracking
  std::vector<Sequence> sequences;  // in time order
  int main_sequence = -1;           // index of the longest sequence
  std::vector<Warning> warnings;    // coded notes (clipping, missed impacts...)
  const Sequence& main() const { return sequences.at(static_cast<size_t>(main_sequence)); }
};

DetectionResult DetectImpacts(const Audio& audio, const DetectOptions& options);
// The same on a recording read block by block (memory: one block, whatever the length). Every
// sample of the file is read and checked, also outside [start_s, end_s).
DetectionResult DetectImpacts(AudioReader& reader, const DetectOptions& options);
// Opens `path` (AudioReader) and detects; what ReadAudio + DetectImpacts give, in bounded memory.
DetectionResult DetectImpactsInFile(const std::string& path, const DetectOptions& options);

// Which sequences of a recording a user wants: the main (longest) one, all of them (several
// drops in one file: separate drops for analyze/calibrate), or one by 0-based index.
struct SequenceChoice {
  enum class Kind { kMain, kAll, kIndex };
  Kind kind = Kind::kMain;
  int index = 0;
};
// "main", "all" or "0", "1", ... Throws Error(kUsage) naming the text otherwise.
SequenceChoice ParseSequenceChoice(const std::string& text);
// Indices into `sequences` (main: the longest). Throws Error(kUsage) for an index past the end,
// naming `name` (the recording) and how many sequences there are.
std::vector<int> ChooseSequences(const std::vector<Sequence>& sequences,
                                 const SequenceChoice& choice, const std::string& name);

}  // namespace bouncecal
