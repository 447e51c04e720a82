// bouncecal/acoustic/sequence.hpp — from onset candidates to physically possible bouncing
// sequences.
//
// A ball bouncing on a plate hits it at t_0 < t_1 < ... with intervals dt_k = t_{k+1} - t_k that
// shrink roughly geometrically: r_k = dt_k / dt_{k-1} ~ e (restitution) in (0, 1), changing
// slowly from bounce to bounce. Echoes and double triggers a few ms after an impact, ringing
// re-triggers and distractor clicks break that pattern. The tracker finds the best chain by
// dynamic programming over pairs of candidates (state = the last two impacts):
//   score = sum of candidate weights (from SNR and template score)
//           - sum of (log(r_k / r_{k-1}) / ratio_sigma)^2 / 2      (smoothness of the ratio)
// with hard limits r in [min_ratio, max_ratio], |log(r_k / r_{k-1})| <= max_log_ratio_jump,
// dt >= min_interval_s (not resolvable below). A step whose interval is about the sum of two
// expected ones (dt ~ dt_prev (e + e^2)) is accepted with a penalty and flagged as a missed
// impact; a single step off the pattern (irregular bounce) likewise, flagged as irregular. The best
// chain is taken, then the search repeats on the candidates outside the chains found so far
// (several drops in one file become separate sequences).
//
//   std::vector<Sequence> s = TrackSequences(candidates, duration_s, TrackOptions{});
//
// Sequence::end_reason: "resolved_limit" (the next interval would be < min_interval_s),
// "end_of_file", "next_drop" (another sequence starts first), "snr_limit" (the next impact
// was expected inside the file but no acceptable candidate was there).
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {

struct TrackOptions {
  double min_interval_s = 0.003;    // impacts closer than this are not resolvable
  double max_interval_s = 3.0;      // longest flight considered (h ~ 11 m)
  double min_ratio = 0.2;           // smallest plausible dt_k / dt_{k-1}
  double max_ratio = 1.02;          // largest (timing noise on e ~ 1)
  double ratio_sigma = 0.03;        // scale of the log-ratio change between bounces
  double max_log_ratio_jump = 0.2;  // hard limit on |log(r_k / r_{k-1})|
  // One step may break the pattern (spin, an uneven spot: real balls' e scatters by 0.005-0.05
  // and single intervals jump more), if the chain has 4 impacts with regular steps before it:
  // ratio up to max_irregular_ratio and |log(r_k / trend)| up to max_irregular_log_jump, at a
  // score cost of irregular_penalty (the largest weight one candidate can bring, so a chain
  // only pays it to continue through several more impacts). The trend ratio before the
  // irregular step judges the next one. Flagged in irregular_after.
  double max_irregular_ratio = 1.15;
  double max_irregular_log_jump = 0.4;
  double irregular_penalty = 3.0;
  // A step may not rise in level (Impact::amplitude) by more than this: the earlier impact is
  // the faster one (plausibility.hpp explains the level model and the 20 dB).
  double max_level_rise_db = 20.0;
  double missed_tolerance = 0.05;     // relative tolerance of the missed-impact interval
  double missed_penalty = 1.5;        // score cost of a flagged missed impact
  int min_sequence_impacts = 3;       // fewer impacts: not a bounce sequence
  double min_mean_weight = 1.0;       // the best sequence's mean candidate weight must reach this
  double min_mean_weight_more = 1.4;  // and every further sequence's (drops after the first)
  int max_predecessors = 64;          // DP fan-in per candidate (nearest earlier candidates)
  int max_sequences = 16;
  int max_candidates = 300;  // more: only the strongest (by weight) enter the DP
  bool IsValid(std::string* error) const;
};

// Weight of a candidate in the chain score: 0.5 + clamp(snr_db / 20, 0, 2) + 0.5 * score.
double CandidateWeight(const Impact& candidate);

// candidates: sorted by time_s. duration_s: length of the recording (for end_reason).
// Returns the sequences in time order; each has >= min_sequence_impacts impacts.
std::vector<Sequence> TrackSequences(const std::vector<Impact>& candidates, double duration_s,
                                     const TrackOptions& options);

}  // namespace bouncecal
