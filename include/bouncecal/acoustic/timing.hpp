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
//   5. each member is timed by the lag of its normalised cross-correlation (NCC) peak with the
//      template (band-limited interpolation of the correlation around the peak); a member that
//      does not match (NCC < min_template_ncc) is timed by its own AIC pick;
//   6. sigma from the timing-error model below.
//
// Sigma model (per impact, in samples, combined in quadrature; constants calibrated once against
// exact truth on every synthetic preset, tools/bench_detect "Timing uncertainty calibration"):
//   noise:     a delay estimate of a waveform a*h moves by <n, h'> / (a |h'|^2) under additive
//              noise n (first order; its variance is the Cramer-Rao bound in white noise, Kay,
//              Fundamentals of Statistical Signal Processing I, 1993, eq. 3.36). The spread of
//              <n, h'> is measured, not assumed white: 1.4826 median |<w, h'>| over the template
//              positions of the noise window before the onset; times noise_gain;
//   shape:     impacts of one ball differ in shape with their speed: the Hertz contact duration
//              grows as v^(-1/5) (Johnson, Contact Mechanics, eq. 11.24), so a quieter impact's
//              attack is longer and its best match to the template slides later. The slide is
//              proportional to |ln a| (a: the member's amplitude relative to the template):
//              shape_s_per_neper |ln a|. (A residual-energy mismatch term, |y - a h|^2 spread over
//              the template, was tried: its calibrated gain was 0 once this term was in.)
//   ambiguity: a rival correlation peak inside the lag search window, outside the chosen one's
//              main lobe, within the NCC's noise (s_c = spread(<n, h>) / (|h| |y|), measured like
//              the noise term) of it, wins with probability p = erfc((c1 - c2) / (2 s_c)) / 2
//              and then moves the time by the lag difference dl: sqrt(p) |dl|, times
//              ambiguity_gain;
//   cycle slip: r = (member's own AIC pick) - (final time) over the template-timed members is
//              fitted by EM as a Gaussian (the AIC's own scatter, sigma_aic) plus a uniform over
//              the AIC window (one of the two slipped by a ringing period). A member gains
//              q P(slip | r) (r - mu)^2, where q is the probability that the template matches
//              at least as well at the AIC's position (best NCC c_alt within sigma_aic of it)
//              as at the chosen lag: q = erfc((c - c_alt) / (2 s)) / 2 with
//              s = hypot(s_c, s_shape). s_shape is the shape mismatch measured on the sequence:
//              W = median over members of max(0, 1 - ncc^2 - E_n / |y|^2) (the share of a
//              member's energy neither the template nor the noise explains; E_n = L noise_rms^2),
//              taken to project on the template as the local noise does:
//              s_shape = s_c sqrt(W |y|^2 / E_n). Well-matched sequences (steel, W ~ 0.03) keep
//              the gate shut, so the AIC's own jumps on earlier ringing do not count; poorly
//              matched ones (superball, ping-pong: W ~ 0.8) count a slip the AIC points to with
//              q up to 1/2 when the two NCCs are within s of each other. The time is not moved
//              (which of the two slipped is not decided by these measures), only sigma grows;
//   resolution: resolution_s (and resolution_samples): interpolation of the correlation peak;
//   template member: its lag to itself is exact, but it is one of the shapes the others are
//              matched to, and the sequence's offset rests on the others' lags: its sigma is at
//              least hypot(median of the others' sigma without ambiguity, 1.25 x median of their
//              sigma / sqrt(n)) (the median's standard error);
//   AIC-timed members (no template match): hypot(sigma_aic, the pick's change-point posterior
//              spread) plus the fitted slip share of the window's uniform variance (width^2/12);
//              with too few template-timed members to fit sigma_aic: the AIC window's width /
//              sqrt(12) (the pick can land anywhere in it), times aic_sigma_gain.
//
//   TimingResult t = TimeSequence(samples, rate_hz, &sequence, TimingOptions{});
//
// Common mistakes: the times are onsets relative to the template's own onset pick, which carries
// a constant offset (microphone distance, attack shape) that cancels in intervals; sigma_s does
// not include that constant.
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
  double min_template_ncc = 0.2;  // below: AIC timing (sigma: see the cycle-slip model)
  // Sigma model constants, calibrated against exact truth on the six synthetic presets x 8 seeds
  // (tools/bench_detect --quick --seeds 8 --dump, a grid search minimising the largest
  // |log RMS(err/sigma)| over the presets): RMS(err/sigma) 0.81-1.18 on every preset.
  double noise_gain = 0.6;  // the robust projected-noise spread overstates the noise
  // Cycle slips: the EM fit's starting share of slipped members, and the gain on the slip term.
  double ambiguity_gain = 1.5;
  double slip_prior = 0.1;
  double slip_gain = 1.0;
  double shape_s_per_neper = 3e-6;  // s per neper of level difference to the template
  double resolution_samples = 0.0;
  double resolution_s = 2e-6;
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
  double sigma_noise = 0.0;  // model parts, samples
  double sigma_resolution = 0.0;
  double sigma_ambiguity = 0.0;
  double sigma_slip = 0.0;      // cycle-slip term (template members) / slip share (AIC members)
  double aic_residual = 0.0;    // own AIC pick - final time - the sequence's mean (samples)
  double ncc_at_aic = -2.0;     // best NCC with the template near the AIC's lag (-2: not measured)
  double slip_q = 0.0;          // probability the template matches at least as well there
  double slip_posterior = 0.0;  // P(slip | aic_residual) of the sequence's slip mixture
  double sigma_shape = 0.0;
  double level_ratio = 1.0;  // the member's amplitude relative to the template (fitted scale)
  double noise_rms = 0.0;    // local whitened noise floor
};

struct TimingResult {
  int template_member = -1;          // index in the sequence of the template impact
  std::vector<double> predictor;     // a[0..order], a[0] = 1
  std::vector<TimingDetail> detail;  // one per member
  double aic_sigma_samples = 0.0;    // fitted scatter of the AIC picks about the template's (0:
                                     // too few members to fit)
  double slip_prior = 0.0;           // fitted share of cycle slips
  double shape_mismatch = 0.0;       // W: median share of a member's energy the template and the
                                     // noise leave unexplained (0: shapes match)
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
