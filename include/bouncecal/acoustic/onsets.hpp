// bouncecal/acoustic/onsets.hpp — impact onsets in one channel: whitening, spectral novelty,
// adaptive threshold, peak picking and sub-sample change-point refinement.
//
// An impact is a short broadband click on top of plate ringing that can last a second. The
// detector therefore works on the *whitened* signal: one linear predictor (order ~32) fitted to
// the whole recording (Levinson-Durbin on the autocorrelation) predicts the stationary ringing
// away; its prediction error keeps the clicks. On the whitened signal:
//   1. a short-hop STFT (FFTW, plans made once in the constructor and reused) gives a relative
//      spectral flux: the half-wave rectified per-bin power increase divided by the previous
//      frame's power (level-independent), in dB;
//   2. an adaptive threshold (running median + k * MAD) and peak picking with a minimum gap give
//      coarse onsets;
//   3. each onset is refined on the waveform with an AIC change-point picker (Maeda 1985;
//      Zhang, Thurber & Rowe 2003, BSSA 93(5), eq. 2) with parabolic interpolation of the AIC
//      minimum, and gets a timing uncertainty sigma_s from the AIC curvature (AIC ~ -2 log L, so
//      the 1-sigma half width is where AIC rises by 1) plus a floor;
//   4. onsets the flux missed, where the recorded (not whitened) signal's energy rises above its
//      own running median + k * MAD, and by at least OnsetOptions::min_rise_db: a soft impact
//      (rubber: 1-2 ms of contact) sounds in the plate's low modes, which the whitening predicts
//      away, but it still rises above what rang before;
//   5. the whitened waveform of the strongest onset is a template: every onset whose normalised
//      cross-correlation with it reaches template_timing_ncc is timed by the lag of the NCC peak
//      relative to the template (level-independent and 3-10x more consistent than per-impact AIC
//      picks, which move with the level and jump on weak onsets); the template's own AIC pick
//      anchors these times. The template also finds onsets the flux missed.
//
//   OnsetDetector det(OnsetOptions{}, rate_hz);       // makes the FFTW plans
//   OnsetResult r = det.Detect(samples);               // r.onsets sorted by time
//
// Common mistakes: the times are *onsets* (first arriving sound), not peaks; sigma_s is a
// per-impact estimate, not including a constant offset (microphone distance) that cancels in
// intervals. An OnsetDetector is not thread-safe; use one per thread.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {

struct OnsetOptions {
  double hop_s = 0.0;            // STFT hop; 0 = auto (power of two samples nearest 0.33 ms)
  int lpc_order = 48;            // whitening predictor order (0 = no whitening)
  double threshold_mads = 4.0;   // threshold = running median + threshold_mads * MAD
  double min_novelty_db = 2.5;   // and at least this flux (dB) above the running median
  double median_window_s = 0.3;  // running-median window of the adaptive threshold
  double min_gap_s = 0.0015;     // peaks closer than this: keep the stronger
  // A second source of onsets, the energy rise of the recorded signal (RawRiseDb, one value per
  // STFT frame): a soft ball (rubber: 1-2 ms of contact) excites little but the plate's low
  // modes, which the whitening predicts away, yet its impacts still rise above what rang before.
  // A rise peak of at least min_rise_db and above the rise's own running median + threshold_mads
  // MAD, that no flux onset explains (none within min_gap_s), is an onset too. min_rise_db: the
  // impact's own energy at least 3 times what rang before it (6 dB); the rise of white noise
  // spreads by ~1 dB (1 ms at 44.1 kHz: 44 samples), so noise alone rarely reaches it where the
  // MAD rule does not already ask more. 0: no rise onsets.
  double min_rise_db = 6.0;
  bool refine = true;          // sub-sample timing; false: each onset reported at the centre of its
                               // STFT hop (CoarsenToHop) -- the same onsets, frame-resolution times
  double aic_pre_s = 0.002;    // AIC window before the coarse onset
  double aic_post_s = 0.0008;  // AIC window after the coarse onset
  double sigma_floor_s = 2e-6;        // sigma floor (quadrature), s ...
  double sigma_floor_samples = 0.25;  // ... or this many samples, whichever is larger
  int aic_upsample = 1;               // band-limited upsampling of the AIC window (1 = none)
  double template_s = 0.0015;         // template length (whitened strongest impact)
  double template_threshold = 0.4;    // NCC above which a template match is a candidate (>= 1: off)
  double template_timing_ncc = 0.4;   // NCC from which the template lag times an onset (>= 1: AIC)
  // Threads Detect may use (0: hardware concurrency, core/parallel.hpp); the onsets do not depend
  // on the count. One OnsetDetector may serve several threads' Detect calls at once.
  int threads = 1;
  bool IsValid(std::string* error) const;
};

struct OnsetResult {
  std::vector<Impact> onsets;        // sorted by time_s
  std::vector<float> whitened;       // prediction error, same length as the input
  std::vector<double> novelty_db;    // one value per STFT frame
  std::vector<double> threshold_db;  // one value per STFT frame
  int hop_samples = 0;
  int window_samples = 0;
  double noise_rms = 0.0;  // robust rms of the whitened signal
  // The template (whitened waveform of the strongest onset), for FindByTemplate. Empty if none.
  std::vector<double> template_wave;
  long template_start = 0;        // sample of `whitened` where the template starts
  double template_onset_s = 0.0;  // onset time of the template's impact
  double rate_hz = 0.0;
  double sigma_floor_s = 0.0;  // timing floor used for these onsets
};

// A template to match: `wave` starts at sample `start` of result.whitened and belongs to the
// impact whose onset is onset_s (a match starting at sample l is an onset at
// onset_s + (l - start) / rate_hz). TemplateOf is the result's own (its strongest onset's);
// TemplateAt cuts one from the whitened signal at an onset, with the lead of the result's own
// template, empty when it would leave the signal.
struct MatchTemplate {
  std::vector<double> wave;
  long start = 0;
  double onset_s = 0.0;
};
MatchTemplate TemplateOf(const OnsetResult& result);
MatchTemplate TemplateAt(const OnsetResult& result, double onset_s);

// Guided search (the tracker knows where the next impact should be): the best normalised
// cross-correlation of the template with the whitened signal for onsets within
// [t_center_s - half_window_s, t_center_s + half_window_s]. Near the noise level (NCC ~0.35) a
// noise peak can match as well as the impact, so positions are ranked by
// NCC - edge_penalty * ((t - t_center_s) / half_window_s)^2 (the prediction is best at the
// centre). Returns true and fills *out (time from the NCC peak, parabolic interpolation; sigma
// from the NCC; score = NCC; amplitude from `samples`) when the chosen NCC reaches min_ncc.
bool FindByTemplate(const OnsetResult& result, const MatchTemplate& tpl,
                    const std::vector<float>& samples, double t_center_s, double half_window_s,
                    double min_ncc, Impact* out, double edge_penalty = 0.0);

// The spread of the template's NCC with the whitened signal where it meets no impact: 1.4826 x
// the median absolute deviation over (at most max_positions evenly spaced) template positions of
// [t0_s, t1_s). 0 when the stretch is too short or outside the signal.
double NccNoiseSpread(const OnsetResult& result, const MatchTemplate& tpl, double t0_s, double t1_s,
                      int max_positions);

// The energy rise of x at t_s (Impact::rise_db), dB: the mean square of the millisecond after
// t_s over that of [t_s - 3.5 ms, t_s - 0.5 ms) (the guard: the onset's own timing error).
double RawRiseDb(const std::vector<float>& x, double rate_hz, double t_s);

// Linear predictor a[1..order] (a[0] = 1) of the prediction-error filter
// e[n] = sum_j a[j] x[n-j], from the autocorrelation r[0..order] by Levinson-Durbin
// (Makhoul 1975, Proc. IEEE 63(4), eqs. 38-45). r[0] must be > 0.
std::vector<double> LevinsonDurbin(const std::vector<double>& r, int order);

// Fits the predictor to x (autocorrelation method, over all of x: the fit, hence the whitening,
// does not depend on where x starts beyond the audio cut off) and returns the prediction error
// (same length; the first `order` samples use the available past). `threads` share the work;
// the result does not depend on their number.
std::vector<float> Whiten(const std::vector<float>& x, int order, int threads = 1);

// Robust rms of x from the median absolute value (Gaussian: rms = median|x| / 0.6745), on at
// most ~16k samples spread over x (OnsetResult::noise_rms of the whitened signal).
double RobustRms(const std::vector<float>& x);

// The prediction error of x under the predictor a (a[0] = 1; LevinsonDurbin's), as Whiten
// computes it (the first samples use the available past).
std::vector<float> PredictionError(const std::vector<float>& x, const std::vector<double>& a,
                                   int threads = 1);

// Frame-resolution timing (OnsetOptions::refine = false): moves the onset to the centre of the
// hop of hop_samples that contains it; sigma_s = hop / sqrt(12) (uniform within the hop).
// Detection itself does not change: onsets are located (SNR, template, tracking) at full
// resolution either way, so refinement off degrades timing only.
void CoarsenToHop(Impact* impact, int hop_samples, double rate_hz);

struct AicPick {
  double index = 0.0;  // sub-sample index of the first sample of the new regime
  double sigma = 0.0;  // 1-sigma uncertainty, samples
  // Standard deviation (samples) of the change point's posterior over the window: AIC is
  // -2 log L + const, so with a flat prior the weights are exp(-(AIC_k - AIC_min) / 2). Unlike
  // `sigma` (the curvature at the minimum) it sees rival minima elsewhere in the window.
  double spread = 0.0;
  bool valid = false;  // false if the window is too short or flat
};
// AIC change-point picker on x[begin, end): AIC(k) = k log var(x[begin..k]) +
// (n-k-1) log var(x[k+1..end)) (Maeda 1985), parabolic interpolation of the minimum.
// upsample > 1: the window is first interpolated band-limited (windowed sinc) by that factor,
// so the change point is located on a finer grid than the samples.
AicPick PickAic(const std::vector<float>& x, std::size_t begin, std::size_t end, int upsample = 1);

// The values v[lo], v[lo + stride], ... (indices below hi) of a window that slides forward over
// v, kept sorted: moving to a window of the same phase (lo - previous lo a multiple of stride)
// that overlaps the previous one removes the values that left and inserts the ones that came,
// instead of selecting from all of them again (the adaptive threshold's running median and
// MAD). Median() and Mad() are the values nth_element selects: the (size / 2)-th smallest (0-based)
// of the values, and of |value - centre|.
class SlidingSample {
 public:
  void Set(const std::vector<double>& v, std::size_t lo, std::size_t hi, std::size_t stride);
  std::size_t size() const { return sorted_.size(); }
  double Median() const;            // 0 when empty
  double Mad(double centre) const;  // (size / 2)-th smallest |value - centre|, 0 when empty

 private:
  std::vector<double> sorted_;
  std::vector<double> leaving_, coming_, merged_;  // scratch of a slide
  std::size_t lo_ = 0, hi_ = 0, stride_ = 0;
  bool valid_ = false;
};

class OnsetDetector {
 public:
  // Throws Error(kBadParameter) if options are invalid or rate_hz <= 0.
  OnsetDetector(const OnsetOptions& options, double rate_hz);
  ~OnsetDetector();
  OnsetDetector(const OnsetDetector&) = delete;
  OnsetDetector& operator=(const OnsetDetector&) = delete;

  OnsetResult Detect(const std::vector<float>& samples) const;

  int hop_samples() const { return hop_; }
  int window_samples() const { return window_; }
  // The STFT hop a detector with these options uses at rate_hz (samples, a power of two).
  static int HopSamples(const OnsetOptions& options, double rate_hz);

 private:
  // The threads a stage may use (OnsetOptions::threads resolved).
  int Threads() const;
  // The stages of Detect, in order, each in a file of its own: whitening (Whiten,
  // whitening.cpp), then
  OnsetResult DetectRefined(const std::vector<float>& samples) const;
  std::vector<double> Novelty(const std::vector<float>& whitened) const;  // flux, dB (novelty.cpp)
  std::vector<double> Threshold(const std::vector<double>& novelty) const;  // adaptive (peaks.cpp)
  double BlockThreshold(const std::vector<double>& novelty, std::size_t centre, std::size_t win,
                        SlidingSample* window) const;
  // The rise onsets (OnsetOptions::min_rise_db) no onset of `flux` explains, refined, with the
  // samples their AIC windows span appended to *window_lo, *window_hi (onsets.cpp).
  std::vector<Impact> RiseOnsets(const std::vector<float>& samples, const OnsetResult& res,
                                 const std::vector<Impact>& flux, std::vector<long>* window_lo,
                                 std::vector<long>* window_hi) const;
  std::vector<std::size_t> Peaks(const std::vector<double>& novelty,
                                 const std::vector<double>& threshold) const;  // frames (peaks.cpp)
  // AIC refinement and measures at each peak's coarse onset (aic.cpp); *window_lo, *window_hi:
  // the onset samples each one's AIC window spans.
  std::vector<Impact> RefinePeaks(const std::vector<float>& samples,
                                  const std::vector<std::size_t>& peaks, const OnsetResult& res,
                                  std::vector<long>* window_lo, std::vector<long>* window_hi) const;
  Impact Refine(const std::vector<float>& samples, const OnsetResult& res, std::size_t centre,
                bool tight) const;
  // Template pass: build, score, time the clear matches, search blind (template_search.cpp).
  struct TemplateMatch;
  struct NccWindow;
  struct NccChunks;
  struct BlindCandidate;
  // The template is cut at the onset at template_onset_s (the strongest of the flux's: a rise
  // onset, a soft impact, is no template for the rest), or, when NaN, the strongest of all.
  void TemplatePass(const std::vector<float>& samples, const std::vector<long>& window_lo,
                    const std::vector<long>& window_hi, double template_onset_s,
                    OnsetResult* res) const;
  bool BuildTemplate(OnsetResult* res, double template_onset_s, TemplateMatch* m) const;
  std::pair<long, long> TimingStarts(const TemplateMatch& m, long lo, long hi, double time_s) const;
  void TimeWithTemplate(const TemplateMatch& m, const std::function<double(long)>& ncc, long lo,
                        long hi, Impact* im) const;
  void BlindScan(const TemplateMatch& m, NccChunks* chunks, std::size_t chunk,
                 std::vector<BlindCandidate>* found) const;
  void AddBlindCandidates(const std::vector<float>& samples, const TemplateMatch& m,
                          NccChunks* chunks, const std::vector<BlindCandidate>& found,
                          OnsetResult* res) const;
  struct Fft;
  struct Correlator;
  OnsetOptions options_;
  double rate_hz_;
  int hop_ = 0;
  int window_ = 0;
  std::unique_ptr<Fft> fft_;
  int template_len_ = 0;
  std::unique_ptr<Correlator> corr_;
};

}  // namespace bouncecal
