// bouncecal/acoustic/plausibility.hpp — is a tracked sequence the bouncing of this ball?
//
// The tracker (sequence.hpp) accepts any chain whose intervals shrink smoothly. Handling noise,
// echoes, a metronome or a single click in dither can form such chains. This stage removes the
// members and sequences that the physics of a bouncing ball rules out, and says where and why
// with coded warnings:
//   sigma_removed      a member whose timing sigma is not finite or so large (above
//                      max_sigma_fraction of its shorter interval) that it carries no timing;
//   low_snr_removed    a member below min_snr_db, when set (local SNR of the whitened onset,
//                      timing.hpp);
//   phantom_removed    a member far quieter than the members after it, or a whole sequence far
//                      quieter or louder than the best-supported one at the same speed (below);
//   not_shrinking      a sequence whose intervals do not shrink on average (removed).
// Removing a member from inside a sequence leaves a gap of two flights: it is flagged like a
// missed impact (Sequence::missed_after).
//
// The level model. The sound of an impact grows with the impact speed v (the force pulse's
// impulse is 2 m v e/(1+e)..., its radiated level ~ v^a; the synthetic corpus renders a = 1;
// fitting level against the preceding flight time on the five real recordings gives a = 0.6 to
// 2.1: limiters and clipping flatten the loud impacts). Speeds fall along a sequence
// (v_in,k+1 = e v_in,k). So an earlier member is never quieter than the later ones beyond the
// bounce-to-bounce level scatter (impact spot, spin, microphone directivity), which is at most
// about 5 dB on the real recordings (15 dB on the synthetic corpus, whose tail impacts
// sit on ringing). A member more than level_tolerance_db below the median level of the next
// level_reference_members members is not an impact of this ball. Across sequences of one
// recording (one ball, one surface, one microphone), the level at a given speed is the same:
// with v proportional to the preceding flight time T (v = g T / 2 without drag),
// C = median over members of (level_dB - 20 log10 T) is a sequence's level at unit speed; a
// sequence whose C lies more than sequence_level_tolerance_db from the best-supported sequence's
// (the largest sum of member weights, CandidateWeight) is not this ball: below it, handling taps
// before the drop; above it, a chain of re-triggers in a loud impact's ringing (it takes that
// impact's level at the speed of millisecond flights). The tolerances are four times the largest
// scatter seen on real recordings; phantoms seen so far are 30-50 dB away.
//
//   std::vector<Warning> w = EnforcePlausibility(&sequences, PlausibilityOptions{});
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"

namespace bouncecal {

struct PlausibilityOptions {
  std::optional<double> min_snr_db;  // when set, members below are removed (detect.hpp: unset)
  // A member whose sigma exceeds this fraction of its shorter interval says nothing about e
  // (sigma_e / e ~ 2 sigma / T = 20 %): removed.
  double max_sigma_fraction = 0.1;
  double level_tolerance_db = 20.0;           // earlier member vs later members
  int level_reference_members = 3;            // how many later members set the reference
  double sequence_level_tolerance_db = 20.0;  // vs the best-supported sequence, same speed
  // Largest geometric mean of the interval ratios dt_k / dt_(k-1) of a sequence's regular steps
  // (MeanIntervalRatio): every impact loses energy, and the most elastic pair measured (a steel
  // ball on an amorphous-metal plate, e ~ 0.985) still shrinks its intervals by 1.5 % a bounce;
  // a metronome or ringing re-triggers repeat one interval to within their timing noise (ratio
  // 1). 0.995 lies a third of the way from the most elastic ball to a metronome.
  double max_mean_ratio = 0.995;
  int min_sequence_impacts = 3;
  bool IsValid(std::string* error) const;
};

// Edits *sequences in place (members removed, sequences that no longer qualify dropped) and
// returns the warnings. Sequence indices in messages are those of the input. Throws
// Error(kBadParameter) for invalid options.
std::vector<Warning> EnforcePlausibility(std::vector<Sequence>* sequences,
                                         const PlausibilityOptions& options);

// The stages, usable separately (each returns its warnings; `label` names the sequence in
// messages):
std::vector<Warning> RemoveUntimedMembers(Sequence* s, const PlausibilityOptions& o,
                                          const std::string& label);
std::vector<Warning> RemoveLowSnrMembers(Sequence* s, const PlausibilityOptions& o,
                                         const std::string& label);
std::vector<Warning> RemoveQuietEarlierMembers(Sequence* s, const PlausibilityOptions& o,
                                               const std::string& label);
// Level at unit speed C (dB) of a sequence (see above); NaN with fewer than 2 members.
double LevelAtUnitSpeedDb(const Sequence& s);
// Geometric mean of dt_k / dt_(k-1) over the regular steps (ratios that involve an interval
// flagged in missed_after or irregular_after left out; NaN with none).
double MeanIntervalRatio(const Sequence& s);

}  // namespace bouncecal
