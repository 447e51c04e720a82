// bouncecal/acoustic/detect.hpp — recording -> impacts -> bounce sequences (the acoustic half).
//
// The pipeline: channel selection -> onset detection (onsets.hpp: whitening, spectral novelty
// on an FFTW STFT, adaptive threshold, sub-sample change-point refinement) -> bounce-sequence
// tracking (sequence.hpp). Times are seconds from the start of the file.
//
//   Audio a = ReadAudio(path);
//   DetectionResult r = DetectImpacts(a, DetectOptions{});
//   for (const Impact& i : r.main().impacts) ... i.time_s, i.sigma_s
//
// Throws Error(kSilence) for a silent recording and Error(kNoBounces) when no sequence of at
// least DetectOptions::min_sequence_impacts impacts is found.
#pragma once

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
};

struct Sequence {
  std::vector<Impact> impacts;
  std::vector<int> missed_after;  // k: an impact seems missing between impacts k and k+1
  std::string end_reason;         // "resolved_limit", "end_of_file", "gap", ...
};

struct DetectOptions {
  ChannelSelection channel;
  double hop_s = 0.0;             // STFT hop; 0 = auto (~0.33 ms)
  bool refine = true;             // sub-sample timing (false: hop-resolution times, same impacts)
  int min_sequence_impacts = 3;   // fewer than this: not a bounce sequence
  double min_interval_s = 0.003;  // impacts closer than this are not resolvable
  bool guided_search = true;      // look again where the tracker expects the next impact
  int lpc_order = 48;             // whitening predictor order (onsets.hpp)
  bool IsValid(std::string* error) const;
};

struct DetectionResult {
  AudioInfo audio;
  int channel = -1;  // channel used, -1 = mix
  std::vector<double> channel_score_db;
  std::vector<ClippingReport> clipping;
  std::vector<Impact> candidates;   // every onset found, before tracking
  std::vector<Sequence> sequences;  // in time order
  int main_sequence = -1;           // index of the longest sequence
  std::vector<Warning> warnings;    // coded notes (clipping, missed impacts...)
  const Sequence& main() const { return sequences.at(static_cast<size_t>(main_sequence)); }
};

DetectionResult DetectImpacts(const Audio& audio, const DetectOptions& options);

}  // namespace bouncecal
