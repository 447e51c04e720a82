// bouncecal/acoustic/timing.hpp — the final timing of a bounce sequence's impacts, computed only
// from the impacts' own neighbourhoods, with a per-impact uncertainty from a model of what
// limits it.
//
// Detection (onsets.hpp, sequence.hpp) finds the impacts; this stage times them. It is local and
// deterministic: nothing in it depends on audio farther than `TimingOptions::fit_window_s` from a
// member of the sequence, so cutting audio off the start or end of a recording, or processing it
// in blocks, gives the same times (to the last bit when the cut is a whole number of samples and
// the sequence's members are the same). The stages:
//   1. neighbourhood predictor: one linear predictor (Levinson-Durbin) fitted on the sum of the
//      normalised autocorrelations of short windows around every member (the background it
//      must whiten: the room noise and the ringing left by earlier impacts), so every member is
//      whitened by the same filter and impacts of one ball keep one shape;
//   2. local whitening of a short segment around each member;
//   3. local measures: SNR against the robust noise floor just before the onset, peak level;
//   4. template: the whitened waveform of the earliest member whose SNR is within 1 dB of the
//      best (the best itself changes with SNR differences of a fraction of a dB); members are
//      timed relative to it, and the sequence's constant offset is set by the trimmed mean (the
//      middle half) of (own AIC change-point pick - template time) over the 9 loudest members,
//      their picks made in a whitening fitted on their own neighbourhoods (so it depends neither
//      on which member is the template nor on the weak tail, which comes and goes with the audio
//      around the sequence);
//   5. each member is timed by the peak of its cross-correlation with the template: the integer
//      lag of the best normalised cross-correlation (NCC) near the detection's time, then the
//      sub-sample peak of the (band-limited) cross-correlation, interpolated by a Hann-windowed
//      sinc of half width 32; a member that does not match (NCC < min_template_ncc) is timed by
//      its own AIC pick;
//   6. sigma from the timing-error model below.
//
// What sigma_s is. Every number downstream is built from INTERVALS between impacts (e_k is a
// ratio of intervals, kinematics.cpp takes the impacts' sigma_s as independent). So sigma_s is
// the part of an impact's timing error that is independent from impact to impact; what is common
// to neighbours is left out, and bounded here instead:
//   - the sequence's constant offset (microphone distance, onset convention): cancels;
//   - the level-dependent shape drift: a quieter impact is a slower one, its contact lasts longer
//     (Hertz: v^(-1/5), Johnson, Contact Mechanics, eq. 11.24) and its best match slides later by
//     about shape_s_per_neper |ln a| (a: its level relative to the template; TimingDetail::
//     shape_drift). Between neighbours that is shape_s_per_neper * A |ln e| per bounce (level ~
//     v^A), the same sign on every interval: 0.3 us at e = 0.9 (A = 1), 1.1 us at e = 0.7.
//     Measured on the synthetic presets (which render the Hertz pulse): the mean interval error of
//     the loud members is +0.23 to +0.25 us, the drift predicts +0.21 to +0.26; real sounds
//     re-placed at every speed (tools/realsound.cpp, no speed-dependent shape): +0.00 +- 0.04 us.
//     Its effect on e_k is shape_s_per_neper |ln e| (1 / T_k - 1 / T_k-1), 1e-7 to 1e-6 of e.
// Pulls of intervals, err / hypot(sigma_k, sigma_k+1), are what the scoreboard and
// tools/bench_sigma check (RMS in [0.7, 1.4]); the absolute error of one impact is NOT within
// sigma_s (the drift accumulates to ~20 us over a sequence).
//
// The model (per impact, in samples, combined in quadrature):
//   noise:     the lag of the correlation peak moves by C'/(-C'') with C' = <n, h'> and
//              -C'' = a |h'|^2 - <n, h''> under additive noise n (h' and h'' band-limited
//              derivatives of the template; a the member's fitted level). The spreads of <n, h'>
//              and <n, h''> are measured, not assumed white: 1.4826 median |<w, g>| over template
//              positions in the noise window before the onset, each carried to the template's
//              window along the noise's decay (the ringing of earlier impacts decays through the
//              window: its level ~11 ms before the onset overstated the level under the template,
//              ping-pong's real-sound pulls 0.77-0.79 before, 0.92-0.96 after; a rise toward the
//              onset is the impact's lead-in and is not carried). To second order in the
//              curvature's relative noise s = spread(<n, h''>) / (a |h'|^2):
//              sigma = spread(<n, h'>) / (a |h'|^2) sqrt(1 + 3 s^2). The first factor is the
//              Cramer-Rao bound in white noise (Kay, Fundamentals of Statistical Signal
//              Processing I, 1993, eq. 3.36), times noise_gain (1: measured in white noise on
//              five real impact sounds, interval pulls 0.85-1.1); the second what a noisy
//              peak curvature adds at low SNR (s reaches 0.3-0.8 on the quietest members);
//   mismatch:  the share W of the member's energy over the template that neither the template
//              (the fitted a h) nor the local noise explains, beyond what a perfect copy of the
//              template shows at another sub-sample phase (the self-match below), moves the peak
//              like noise of that energy concentrated where h' is: mismatch_gain
//              sqrt(W |y|^2) / (a |h'|). The template member takes the median of the others' (its
//              own W is 0 by definition, but its shape departs from the typical as theirs do).
//              W's noise share keeps the noise window's own level, not carried to the template:
//              W is a difference of noisy numbers clipped at 0, and the carried level's extra
//              scatter passed into it as mismatch on copies of one sound, whose true W is 0
//              (ping-pong's real sound, one cut: pull RMS 0.95 -> 0.83);
//   ambiguity: a rival correlation peak inside the lag search window, outside the chosen one's
//              main lobe, within the NCC's noise (s_c = spread(<n, h>) / (|h| |y|), measured like
//              the noise term) of it, wins with probability p = erfc((c1 - c2) / (2 s_c)) / 2
//              and then moves the time by the lag difference dl: sqrt(p) |dl| (the mixture's
//              variance p dl^2), times ambiguity_gain (1);
//   cycle slip: r = (member's own AIC pick) - (final time) over the template-timed members is
//              fitted by EM as a Gaussian (the AIC's own scatter, sigma_aic) plus a uniform over
//              the AIC window (one of the two slipped by a ringing period). A member gains
//              q P(slip | r) (r - mu)^2, where q is the probability that the template matches
//              at least as well at the AIC's position (best NCC c_alt within sigma_aic of it,
//              on another correlation peak: lags on the chosen peak's main lobe do not count)
//              as at the chosen lag: q = erfc((c - c_alt) / (2 s)) / 2 with
//              s = hypot(s_c, s_shape). s_shape is the shape mismatch measured on the sequence:
//              the median W over the members, taken to project on the template as the local
//              noise does: s_shape = s_c sqrt(W |y|^2 / E_n) (E_n = L times the noise's
//              mean square under the template, carried along its decay as s_c is).
//              Well-matched sequences (steel, W ~ 0.03) keep the gate shut, so the AIC's own
//              jumps on earlier ringing do not count; poorly matched ones (superball, ping-pong:
//              W ~ 0.8) count a slip the AIC points to with q up to 1/2 when the two NCCs are
//              within s of each other. The time is not moved (which of the two slipped is not
//              decided by these measures), only sigma grows: the superball recording's members
//              timed 0.60-0.66 ms early (one ringing period) get sigma 0.26-0.52 ms;
//   resolution: measured per sequence, not assumed: the template member's own neighbourhood
//              delayed by 1/4, 1/2 and 3/4 sample (a 129-tap Kaiser sinc) and timed against the
//              template; the RMS error (0.0000-0.007 samples on real impact sounds). The same
//              self-match gives the share 1 - ncc^2 that the template window's cut through a
//              ringing sound leaves on a perfect copy (superball ~0.03), which W discounts;
//   AIC-timed members (no template match): hypot(sigma_aic, the pick's change-point posterior
//              spread) plus the fitted slip share of the window's uniform variance (width^2/12);
//              with too few template-timed members to fit sigma_aic: the AIC window's width /
//              sqrt(12) (the pick can land anywhere in it), times aic_sigma_gain.
// mismatch_gain is the one constant calibrated on data, on both test-recording sources
// (tools/bench_sigma: every synth preset x 4 seeds, real sounds of the five shared recordings x 4
// seeds): the smallest gain of the scan that keeps synthetic glass (the largest W) and the
// superball's real sound (W from its ringing) in [0.7, 1.4]. Interval pull RMS for
// mismatch_gain 0.11 / 0.12 / 0.13 / 0.15, glass seeds 1-4: 1.36-1.49 / 1.31-1.43 / 1.26-1.38 /
// 1.18-1.29 (seeds 1-8, highest: 1.53 / 1.47 / 1.42 / 1.33), superball seeds 1-4: 0.80-0.82 /
// 0.78-0.81 / 0.77-0.79 / 0.75-0.77: 0.13. (It was 0.11 while the noise term took the window's
// level rather than the level under the template: the superball's pulls, 0.72, held it down.)
//
//   TimingResult t = TimeSequence(samples, rate_hz, &sequence, TimingOptions{});
//
// Common mistakes: the times are onsets relative to the template's own onset pick, which carries
// a constant offset (microphone distance, attack shape) that cancels in intervals; sigma_s does
// not include that constant, nor the level-dependent drift above: judge sigma_s on intervals.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {

struct TimingOptions {
  int lpc_order = 48;          // predictor order (0: no whitening)
  double fit_before_s = 0.02;  // predictor window: this long before each member's onset ...
  double fit_after_s = 0.01;   // ... to this long after it
  double template_s = 0.0015;  // template length
  double lead_s = 1e-4;        // the template starts this long before its onset
  double search_s = 3e-4;      // lag search: +- this around the detection's time
  double aic_pre_s = 0.002;    // AIC window before / after the detection's time
  double aic_post_s = 0.0008;
  double noise_window_s = 0.02;   // SNR: noise floor from this long before the onset ...
  double noise_guard_s = 0.001;   // ... ending this long before it
  double signal_window_s = 5e-4;  // SNR: signal rms over this long after the onset
  double level_window_s = 0.003;  // Impact::amplitude: peak |x| over this long after the onset
  // Below: AIC timing (sigma: see the cycle-slip model). Measured on 42 files that are not the
  // scoreboard's: members of NCC 0.10-0.20 were 480-530 us off (median) by AIC, 32-97 us by the
  // template; at 0.2 the AIC took them. No member had NCC below 0.1 (noise alone reaches 0.15).
  double min_template_ncc = 0.1;
  // Sigma model (the header's comment says where each comes from). Gains of 1 are the terms as
  // derived; mismatch_gain is calibrated on both test-recording sources.
  double noise_gain = 1.0;      // on the Cramer-Rao-type noise term
  double ambiguity_gain = 1.0;  // on sqrt(sum p_j dl_j^2) of the rival correlation peaks
  // Cycle slips: the EM fit's starting share of slipped members, and the gain on the slip term.
  double slip_prior = 0.1;
  double slip_gain = 1.0;
  double mismatch_gain = 0.13;  // on sqrt(W |y|^2) / (a |h'|): calibrated, see above
  // The level-dependent shape drift, s per neper of level below the template: NOT in sigma_s
  // (common to neighbours), reported as TimingDetail::shape_drift. Measured on the synthetic
  // presets' Hertz pulses: 3 us per neper (loud members' mean interval error +0.23-0.25 us, this
  // predicts +0.21-0.26 us).
  double shape_s_per_neper = 3e-6;
  double aic_sigma_gain = 1.0;
  // Threads TimeSequence may use (0: hardware concurrency, core/parallel.hpp): its members are
  // timed independently; the result does not depend on the count.
  int threads = 1;
  bool IsValid(std::string* error) const;
};

// How one member was timed (for diagnostics and the benchmark's sigma calibration).
struct TimingDetail {
  bool by_template = false;  // false: AIC pick
  double ncc = 0.0;          // NCC with the template at the chosen lag
  // The model's parts (samples; sigma_s is their quadrature sum):
  double sigma_noise = 0.0;       // noise, with the curvature factor sqrt(1 + 3 s^2)
  double sigma_mismatch = 0.0;    // shape mismatch
  double sigma_resolution = 0.0;  // the sequence's measured interpolation floor
  double sigma_ambiguity = 0.0;
  double sigma_slip = 0.0;       // cycle-slip term (template members) / slip share (AIC members)
  double curvature_noise = 0.0;  // s: relative noise of the correlation peak's curvature
  double aic_residual = 0.0;     // own AIC pick - final time - the sequence's mean (samples)
  double ncc_at_aic = -2.0;      // best NCC with the template near the AIC's lag (-2: not measured)
  double slip_q = 0.0;           // probability the template matches at least as well there
  double slip_posterior = 0.0;   // P(slip | aic_residual) of the sequence's slip mixture
  double level_ratio = 1.0;      // a: the member's amplitude relative to the template (fitted)
  double noise_rms = 0.0;        // local whitened noise floor
  double noise_share = 0.0;      // the local noise's expected share of |y|^2, L noise_rms^2 / |y|^2
  // W: share of the member's energy neither the template nor the noise explains, beyond the
  // template's self-match: max(0, 1 - ncc^2 - noise_share - self-match share)
  double residual_share = 0.0;
  // Level-dependent drift relative to the template (samples, later > 0): shape_s_per_neper
  // ln(1 / level_ratio). NOT in sigma_s (common to neighbours: timing.hpp).
  double shape_drift = 0.0;
};

struct TimingResult {
  int template_member = -1;          // index in the sequence of the template impact
  std::vector<double> predictor;     // a[0..order], a[0] = 1
  std::vector<TimingDetail> detail;  // one per member
  double aic_sigma_samples = 0.0;    // fitted scatter of the AIC picks about the template's (0:
                                     // too few members to fit)
  double slip_prior = 0.0;           // fitted share of cycle slips
  double shape_mismatch = 0.0;       // median W over the members (0: shapes match)
  double resolution_samples = 0.0;   // the measured interpolation floor (sigma_resolution)
};

// Times every member of *sequence in place (time_s, sigma_s, amplitude, snr_db, score) from the
// samples of the channel it was detected in; the members' current time_s are the anchors (they
// must be within search_s of the impacts). Throws Error(kBadParameter) for invalid options or
// rate. A sequence with no members is left alone.
TimingResult TimeSequence(const std::vector<float>& samples, double rate_hz, Sequence* sequence,
                          const TimingOptions& options = {});

// Stage 1: prediction-error filter a[0..order] fitted on the normalised autocorrelations of the
// windows [anchor - before, anchor + after) (samples, clipped to the signal). Windows with no
// energy are skipped; with none left the filter is {1} (no whitening).
std::vector<double> NeighbourhoodPredictor(const std::vector<float>& x,
                                           const std::vector<long>& anchors, int order, long before,
                                           long after);

// Stage 2: e[n] = sum_j a[j] x[n - j] for n in [begin, end) (x taken as 0 before its start).
std::vector<float> WhitenSegment(const std::vector<float>& x, const std::vector<double>& a,
                                 long begin, long end);

// Band-limited peak of a sampled correlation: c[i] at integer lags, peak near index `at`
// (0 < at < size - 1). Returns the fractional index of the maximum of the windowed-sinc
// interpolant within +- 1 sample of `at`, and its value in *peak.
double InterpolatedPeak(const std::vector<double>& c, std::size_t at, double* peak);

}  // namespace bouncecal
