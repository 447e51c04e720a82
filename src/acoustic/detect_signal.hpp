// The detection of one candidate signal (a channel or the mix, over one block of the recording)
// (internal to the library, src/): onsets -> tracking -> guided search -> timing ->
// plausibility -> re-timing.
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/onsets.hpp"

namespace bouncecal {

// Everything one candidate signal yields.
struct SignalDetection {
  std::vector<Impact> candidates;
  std::vector<Sequence> sequences;
  std::vector<Warning> warnings;
  int hop_samples = 0;
  double score = 0.0;
  std::string failure;  // why no sequence (empty when there is one)
};

// The energy rise of x at t_s (Impact::rise_db), dB: the mean square of the millisecond after
// t_s over that of [t_s - 3.5 ms, t_s - 0.5 ms) (the guard: the onset's own timing error).
double RawRiseDb(const std::vector<float>& x, double rate_hz, double t_s);

// The sum of the tracker weights of a sequence's members (ChannelScore::score).
double SequenceScore(const Sequence& q);
// The index of the longest sequence (the first of equals), -1 for none.
int LongestSequence(const std::vector<Sequence>& seqs);

// The onset detector's options in a detection with `options`.
OnsetOptions OnsetOptionsOf(const DetectOptions& options);

// The stages of one signal x at rate_hz (times are seconds from x's start).
SignalDetection DetectInSignal(const std::vector<float>& x, double rate_hz,
                               const DetectOptions& options);

}  // namespace bouncecal
