// bouncecal/acoustic/sequence.hpp — from onset candidates to the bounce sequences of a recording.
//
// A ball bouncing on a plate hits it at t_0 < t_1 < ... with intervals d_k = t_{k+1} - t_k whose
// ratios r_k = d_k / d_{k-1} are the restitution coefficients e_k <= 1 (docs/physics.md §3:
// without drag the rebound flight of speed v lasts 2v/g, so r_k = e_k), changing slowly from
// bounce to bounce. A recording may hold many drops of one ball, one after another. The tracker
// finds all of them together, as the best-scoring set of non-overlapping sequences, by one
// dynamic programme over the candidates in time order (Viterbi-like, a beam of states per
// candidate; the state is the last two members and the smoothed log ratio).
//
// Score: a log-likelihood ratio, "impact of this ball" against "clutter", summed over members:
//   member value = (CandidateWeight - clutter_weight)                 what the sound says
//                + log( p(t | the sequence's prediction) / rho(t) )   where it is
// rho(t) is the local rate of candidates (per second, measured around t: ringing and noisy
// stretches have more). The prediction of the next interval is d_k * exp(trend), the trend an
// exponential average of log r; its spread ratio_sigma (bounce-to-bounce scatter of e) plus the
// candidates' timing sigma. A well-predicted weak candidate in a quiet stretch is strong evidence
// (a sequence's tail), a loud click off the prediction is none. Steps:
//   regular      |log(r / trend)| <= max_z spreads, r <= 1 + timing noise (e <= 1);
//   missed       1..max_missed impacts unheard: the gap is d (r + r^2 + ... + r^(m+1)) within
//                max_z spreads of that sum, each missing flight resolvable; missed_penalty each;
//                flagged in missed_after;
//   irregular    one step off the pattern (spin, an uneven spot) after >= 3 regular ones, r up to
//                max_irregular_ratio, irregular_penalty; the trend carries on; irregular_after;
//   first ratio  (the third member) any r in [min_ratio, 1]: value log(1 / (d dlog r rho)).
// A member may not be louder than the one before by more than max_level_rise_db (the earlier
// impact is the faster one, plausibility.hpp). A drop starts after a release: a new sequence's
// first member comes at least half its first interval after the previous sequence's last member
// (the ball fell from rest for d_0 / (2e) >= d_0 / 2), and its first interval is longer than the
// previous sequence's last one (released from above its last bounce), so a sequence never
// continues into the next drop and a drop is not cut in two. A sequence must earn more than
// start_cost to be reported. The work is linear in the number of candidates: each candidate
// keeps at most beam states, each state looks at most at window_candidates candidates per
// window (the strongest), and a new sequence at most at start_candidates predecessors.
//
//   std::vector<Sequence> s = TrackSequences(candidates, duration_s, TrackOptions{});
//
// Sequence::end_reason: "resolved_limit" (the next interval would be < 1.5 min_interval_s),
// "end_of_file", "next_drop" (another sequence starts before the next two impacts), "snr_limit"
// (the next impact was expected inside the file but no acceptable candidate was there).
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {

struct TrackOptions {
  double min_interval_s = 0.003;  // impacts closer than this are not resolvable
  double max_interval_s = 3.0;    // longest flight considered (h = g T^2 / 8 ~ 11 m)
  double min_ratio = 0.2;         // smallest e: below it a drop has at most 3 resolvable impacts
  // Largest regular ratio: e <= 1 (energy is lost at every impact), widened by the timing noise
  // of the three members (3 sigma of log r from their sigma_s).
  double max_ratio = 1.0;
  // The trend of log e along a sequence (a Kalman filter, local level model): each bounce's log e
  // scatters about it by scatter_sigma (real balls: sigma_e 0.005-0.03, docs/benchmarks.md
  // "Calibration on real recordings") and the trend itself drifts by drift_sigma per bounce (e
  // changes with the impact speed: the steepest real case, the superball's 0.835 -> 0.94 in 30
  // bounces, drifts 0.004; 2.5 times that).
  double scatter_sigma = 0.02;
  double drift_sigma = 0.01;
  double max_z = 4.0;  // a regular step lies within this many spreads of the prediction
  // A sequence's intervals shrink on average (the geometric mean of its regular ratios at most
  // this): the physics of PlausibilityOptions::max_mean_ratio, applied while tracking so that a
  // metronome-like chain never takes an impact away from a real sequence.
  double max_mean_ratio = 0.995;
  // Irregular steps (spin, an uneven spot): prior odds ~1 in 20 bounces (e^-3; the real
  // superball of ../shared/recordings: 1 in 33), ratio up to 1.15 and |log(r / trend)| <= 0.4
  // (the largest irregular step of the five real recordings: 1.09 and 0.25).
  double max_irregular_ratio = 1.15;
  double max_irregular_log_jump = 0.4;
  double irregular_penalty = 3.0;
  // An earlier member is faster, so not much quieter; nor much louder than its speed explains
  // (plausibility.hpp: the level model; 4 times the largest level scatter of the real recordings).
  double max_level_rise_db = 20.0;
  int max_missed = 3;  // impacts that may go unheard in one gap
  // Per unheard impact: -log P(unheard), P = Phi(-snr / level_sigma_db) from the SNR of the
  // quieter of the two members around the gap, at least missed_penalty (a quiet gap). The
  // level scatter from bounce to bounce: at most ~5 dB on the real recordings (plausibility.hpp),
  // so a 2-sigma of 5 dB.
  double missed_penalty = 1.5;
  double level_sigma_db = 2.5;
  // ... and at most this: the onset detector misses about 1 % of the impacts well above its
  // floor (tools/bench_detect: recall 0.99 at SNR >= 20 dB), so a loud gap costs log(100).
  double max_missed_penalty = 4.6;
  // A candidate's weight above which it is more likely an impact than clutter: measured on the
  // five shared recordings (clutter: q90 0.76-1.3; impacts: q10 0.9-1.65) and the synth corpus.
  double clutter_weight = 1.0;
  // Prior rate of drop starts: one per 10 s of recording (a hand drop takes longer, a dropper rig
  // ~2 s: a factor 5 either way moves a sequence's score by 1.6).
  double drop_rate_hz = 0.1;
  double density_window_s = 1.0;  // the clutter rate rho(t): candidates within +-half of this
  // A drop releases the ball from at least this height (m): two orders of magnitude below the
  // seed papers' 5 cm - 2.5 m; shorter first flights are a plate's buzz or clusters of echoes.
  double min_drop_height_m = 1e-3;
  int min_sequence_impacts = 3;  // fewer impacts: not a bounce sequence
  // Bounded fan-in (cost, not physics: doubling each changes no sequence of the scoreboard's
  // corpus, tools/scoreboard).
  int beam = 16;               // states kept per candidate (new pairs and longer, each)
  int window_candidates = 32;  // candidates looked at per predicted window (the strongest)
  int start_candidates = 16;   // predecessors looked at for a new sequence (the strongest)
  bool IsValid(std::string* error) const;
};

// Weight of a candidate: 0.5 + clamp(snr_db / 20, 0, 2) + 0.5 * clamp(score, 0, 1)
// + clamp(rise_db / 40, 0, 0.75) (a new attack rises above what rang before it).
double CandidateWeight(const Impact& candidate);

// candidates: sorted by time_s. duration_s: length of the recording (for end_reason).
// Returns the sequences in time order; each has >= min_sequence_impacts impacts.
std::vector<Sequence> TrackSequences(const std::vector<Impact>& candidates, double duration_s,
                                     const TrackOptions& options);

}  // namespace bouncecal
