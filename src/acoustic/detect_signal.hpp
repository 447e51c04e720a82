// The detection of one candidate signal (a channel or the mix, over one block of the recording)
// (internal to the library, src/): onsets -> tracking -> guided search -> timing ->
// plausibility -> re-timing.
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/acoustic/sequence.hpp"

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

// A member that does not rise (Impact::rise_db <= 0) inside the sound of an attack that began
// within the rise's window before it (kAttackReachS = RawRiseDb's 3.5 ms: what its rise compared
// with), by a candidate that is not itself a member, rises by kAttackRiseDb (OnsetOptions::
// min_rise_db's 6 dB) or more, and is not more than kAttackLevelDb below the member (the level
// scatter of one ball's impacts, plausibility.hpp, is at most ~5 dB; a precursor far quieter than
// the attack is another sound: the real basketball's, 19 dB below), is that attack's ringing:
// the member is moved to the attack. (The real rubber ball: two members were its attacks' second
// peaks, 3.06 ms late, chosen by the tracker over the attacks when a longer tail made the ratios
// smoother that way; the hand marks are at the attacks.)
constexpr double kAttackReachS = 0.0035, kAttackRiseDb = 6.0, kAttackLevelDb = 6.0;
// candidates: sorted by time_s (as the onset detector gives them).
void MoveMembersToTheirAttacks(const std::vector<Impact>& candidates, const TrackOptions& to,
                               std::vector<Sequence>* sequences);

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
