// The guided search (internal to the library, src/): the tracker knows where the impacts of a
// sequence should be, so the template looks there for the ones the blind pass missed — in the
// gaps the tracker flagged and along the tail, from the sequence's own trend of log r.
//
//   ExtendByTemplate(onsets, x, duration_s, track_options, GuidedOptions{}, &sequences);
//
// Each look is the best match (FindByTemplate, onsets.hpp) of the sequence's own template (the
// whitened waveform of its strongest member) in a window around the predicted time, with a p-value:
// the chance that noise alone ranks as well somewhere in that window. A match joins when its own
// p-value is small, inside a run of looks whose combined p-value (Fisher) noise alone rarely
// reaches. The tail stops at its first unheard impact (past it the flight the looks were made from
// spans two bounces) or where no run is significant: the noise won or the ball stopped. The tail is
// searched in the recording's whitened signal or in a copy whitened by the room noise's own
// spectrum with the sequence's members cancelled (each member's sound, the sequence's impact
// response scaled, subtracted), whichever the tail's last members stand out in more: the first
// whitens a ringing plate's ringing away, the second keeps a soft ball's thud above the noise
// where the first flattens it. Each rule is pinned to a factor of 2 by tests/guided_rules_test.cpp.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/acoustic/sequence.hpp"

namespace bouncecal {

struct GuidedOptions {
  // The window spans `reach` spreads of the predicted time on each side (TrackOptions::max_z),
  // the spread of log r the sequence's own but at least min_ratio_spread (a quarter of
  // TrackOptions::scatter_sigma: real balls scatter by >= 0.005 in e).
  double reach = 4.0;
  double min_ratio_spread = 0.005;
  // Ranking penalty at the window's edge (NCC units): near the noise level a noise peak 0.4 ms
  // from the prediction matched as well as the impact (corpus: NCC 0.37 vs 0.36, a 433 us error).
  double edge_penalty = 0.15;
  // A match joins when noise alone would match as well in at most one window of twenty (its own
  // p-value), inside a run of looks that noise alone explains with probability at most
  // false_alarm (Fisher's combination of their p-values).
  double member_p = 0.05;
  double false_alarm = 0.01;
  // The trend of log r: a straight line through the last trend_flights regular ratios (e drifts
  // steadily with the impact speed, and with drag; six flights span a few percent of it).
  std::size_t trend_flights = 6;
  // Right after a member, the next flight may be longer than the one before only within this many
  // sigmas of the two impacts' timing noise (e <= 1, TrackOptions::max_ratio): the sigma rule.
  double ratio_slack_sigmas = 3.0;
  // The noise-whitened signal the tail may be searched in (guided_search.cpp, NoiseWhitened): its
  // predictor's order (the recording's whitening's, DetectOptions::lpc_order), fitted on the
  // quietest noise_frames share of the recording's 20-ms frames (room noise wherever impacts
  // and their ringing fill less than three quarters of the recording).
  int lpc_order = 48;
  double noise_frames = 0.25;
  // false: the tail is searched in the recording's whitened signal only (as before 2026-12-08;
  // the rule tests of tests/guided_rules_test.cpp pin the look's rules there).
  bool noise_signal = true;
  bool IsValid(std::string* error) const;
};

// Fills the flagged gaps of every sequence and extends its tail (up to the next sequence's first
// impact, or the end of the signal at duration_s) with template matches. `onsets` is the onset
// detection of x (its whitened signal and template). Throws Error(kBadParameter) for invalid
// options.
void ExtendByTemplate(const OnsetResult& onsets, const std::vector<float>& x, double duration_s,
                      const TrackOptions& to, const GuidedOptions& go,
                      std::vector<Sequence>* sequences);

}  // namespace bouncecal
