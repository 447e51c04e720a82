// Onset detection: the detector's set-up and its stages in order (whitening, novelty, threshold,
// peaks, AIC refinement, rise onsets, template pass). See include/bouncecal/acoustic/onsets.hpp.
#include "bouncecal/acoustic/onsets.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <utility>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/parallel.hpp"
#include "bouncecal/core/stats.hpp"
#include "onset_constants.hpp"
#include "spectra.hpp"

namespace bouncecal {
// Robust rms of x from the median absolute value (Gaussian: rms = median|x| / 0.6745),
// on at most ~16k samples spread over x.
double RobustRms(const std::vector<float>& x) {
  if (x.empty()) return 0.0;
  const std::size_t step = std::max<std::size_t>(1, x.size() / 16384);
  std::vector<double> a;
  a.reserve(x.size() / step + 1);
  for (std::size_t i = 0; i < x.size(); i += step) a.push_back(std::fabs(x[i]));
  return UpperMedian(std::move(a)) / 0.6745;
}

namespace {

// The rise (RawRiseDb): the mean square over [i, i + after) against [i - before, i - guard).
// One millisecond holds a hard impact's attack (contact 20-150 us) and its first response; 3 ms
// before (beyond a guard for the onset's own timing error) holds the decaying sound of what came
// earlier, even at a low plate mode's period.
constexpr double kRiseAfterS = 0.001, kRiseBeforeS = 0.0035, kRiseGuardS = 0.0005;
// The mean square of x over [a, b) (clamped to x; 0 when empty).
double MeanSquare(const std::vector<float>& x, long a, long b) {
  const long n = static_cast<long>(x.size());
  a = std::clamp(a, 0L, n), b = std::clamp(b, 0L, n);
  double e = 0.0;
  for (long k = a; k < b; ++k)
    e += static_cast<double>(x[static_cast<std::size_t>(k)]) * x[static_cast<std::size_t>(k)];
  return b > a ? e / static_cast<double>(b - a) : 0.0;
}
// The mean square of the millisecond after sample i (the rise's window after the onset).
double AfterWindow(const std::vector<float>& x, double rate_hz, long i) {
  return MeanSquare(x, i, i + std::lround(kRiseAfterS * rate_hz) + 1);
}

// Whether the millisecond after sample i holds more energy than every millisecond of the
// kRingingS before it (up to the rise's guard): a new attack rises above the envelope of what
// rings, not only above its mean. Plate modes a few tens of hertz apart beat, and their ringing
// re-rises by 6-14 dB over a 3-ms mean 10-50 ms after a loud impact (the real rubber ball of
// ../shared/recordings: 82 rise onsets there, 64 of them inside such ringing, none above its
// envelope over 20 ms; synth rubber-wood's impacts, 100-550 ms apart: all 43 above it).
constexpr double kRingingS = 0.02;
bool AboveRecentRinging(const std::vector<float>& x, double rate_hz, long i) {
  const long w = std::lround(kRiseAfterS * rate_hz);
  const double after = AfterWindow(x, rate_hz, i);
  const long step = std::max(1L, w / 4);
  for (long j = i - std::lround(kRingingS * rate_hz);
       j + w <= i - std::lround(kRiseGuardS * rate_hz); j += step)
    if (AfterWindow(x, rate_hz, j) >= after) return false;
  return true;
}

int NearestPowerOfTwo(double v) {
  int p = 1;
  while (p * 2 <= v * std::numbers::sqrt2) p *= 2;
  return p;
}

}  // namespace

double RawRiseDb(const std::vector<float>& x, double rate_hz, double t_s) {
  const long i = std::lround(t_s * rate_hz);
  const double post = AfterWindow(x, rate_hz, i);
  const double pre = MeanSquare(x, i - std::lround(kRiseBeforeS * rate_hz),
                                i - std::lround(kRiseGuardS * rate_hz));
  return 10.0 * std::log10((post + 1e-30) / (pre + 1e-30));
}

bool OnsetOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(hop_s >= 0.0) || hop_s > 0.05)
    return fail("OnsetOptions::hop_s = " + std::to_string(hop_s) + ": must be in [0, 0.05] s");
  if (lpc_order < 0 || lpc_order > 256)
    return fail("OnsetOptions::lpc_order = " + std::to_string(lpc_order) + ": must be 0..256");
  if (!(threshold_mads > 0.0)) return fail("OnsetOptions::threshold_mads must be > 0");
  if (!(min_novelty_db >= 0.0)) return fail("OnsetOptions::min_novelty_db must be >= 0");
  if (!(median_window_s > 0.0)) return fail("OnsetOptions::median_window_s must be > 0");
  if (!(min_gap_s >= 0.0)) return fail("OnsetOptions::min_gap_s must be >= 0");
  if (!(min_rise_db >= 0.0)) return fail("OnsetOptions::min_rise_db must be >= 0 (0: off)");
  if (!(aic_pre_s > 0.0) || !(aic_post_s > 0.0))
    return fail("OnsetOptions::aic_pre_s and aic_post_s must be > 0");
  if (!(sigma_floor_s >= 0.0)) return fail("OnsetOptions::sigma_floor_s must be >= 0");
  if (threads < 0 || threads > 256)
    return fail("OnsetOptions::threads = " + std::to_string(threads) + ": must be 0..256");
  if (aic_upsample < 1 || aic_upsample > 64)
    return fail("OnsetOptions::aic_upsample = " + std::to_string(aic_upsample) + ": must be 1..64");
  if (!(template_s >= 1e-4) || template_s > 0.02)
    return fail("OnsetOptions::template_s must be in [1e-4, 0.02] s");
  if (!(template_threshold > 0.0)) return fail("OnsetOptions::template_threshold must be > 0");
  if (!(template_timing_ncc > 0.0))
    return fail("OnsetOptions::template_timing_ncc must be > 0 (>= 1: AIC timing only)");
  return true;
}

OnsetDetector::OnsetDetector(const OnsetOptions& options, double rate_hz)
    : options_(options), rate_hz_(rate_hz) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz))
    throw Error(ErrorCode::kBadParameter,
                "OnsetDetector: sample rate " + std::to_string(rate_hz) + " Hz must be > 0");
  hop_ = HopSamples(options, rate_hz);
  window_ = std::max(16, 4 * hop_);
  fft_ = std::make_unique<Fft>(window_);
  template_len_ = std::max(8, static_cast<int>(std::lround(options.template_s * rate_hz)));
  int corr_n = 256;
  while (corr_n < 8 * template_len_) corr_n *= 2;
  corr_ = std::make_unique<Correlator>(corr_n);
}

OnsetDetector::~OnsetDetector() = default;

int OnsetDetector::Threads() const { return ResolveThreads(options_.threads); }

int OnsetDetector::HopSamples(const OnsetOptions& options, double rate_hz) {
  const double hop_target = options.hop_s > 0.0 ? options.hop_s * rate_hz : 0.00033 * rate_hz;
  return std::max(1, NearestPowerOfTwo(hop_target));
}

void CoarsenToHop(Impact* impact, int hop_samples, double rate_hz) {
  const double hop = static_cast<double>(std::max(1, hop_samples));
  const double frame = std::floor(impact->time_s * rate_hz / hop);
  impact->time_s = (frame + 0.5) * hop / rate_hz;
  impact->sigma_s = hop / std::sqrt(12.0) / rate_hz;  // uniform over one hop
}

OnsetResult OnsetDetector::Detect(const std::vector<float>& x) const {
  OnsetResult res = DetectRefined(x);
  if (!options_.refine)
    for (Impact& im : res.onsets) CoarsenToHop(&im, hop_, rate_hz_);
  return res;
}

OnsetResult OnsetDetector::DetectRefined(const std::vector<float>& x) const {
  OnsetResult res;
  res.hop_samples = hop_;
  res.window_samples = window_;
  res.rate_hz = rate_hz_;
  res.sigma_floor_s = std::max(options_.sigma_floor_s, options_.sigma_floor_samples / rate_hz_);
  res.whitened = Whiten(x, options_.lpc_order, Threads());
  res.noise_rms = RobustRms(res.whitened);
  if (res.whitened.size() < static_cast<std::size_t>(window_ + hop_)) return res;
  res.novelty_db = Novelty(res.whitened);
  res.threshold_db = Threshold(res.novelty_db);
  const std::vector<std::size_t> peaks = Peaks(res.novelty_db, res.threshold_db);
  std::vector<long> window_lo, window_hi;
  res.onsets = RefinePeaks(x, peaks, res, &window_lo, &window_hi);
  // The template: the strongest of the flux's onsets (BuildTemplate).
  double template_onset_s = std::numeric_limits<double>::quiet_NaN();
  for (std::size_t i = 0, best = 0; i < res.onsets.size(); ++i)
    if (i == 0 || res.onsets[i].snr_db > res.onsets[best].snr_db)
      best = i, template_onset_s = res.onsets[i].time_s;
  if (options_.min_rise_db > 0.0) {
    std::vector<Impact> rise = RiseOnsets(x, res, res.onsets, &window_lo, &window_hi);
    if (!rise.empty()) {
      // Both kinds in time order, each with its AIC window (the template pass reads them so).
      res.onsets.insert(res.onsets.end(), rise.begin(), rise.end());
      std::vector<std::size_t> order(res.onsets.size());
      for (std::size_t k = 0; k < order.size(); ++k) order[k] = k;
      std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return res.onsets[a].time_s < res.onsets[b].time_s;
      });
      std::vector<Impact> onsets;
      std::vector<long> lo, hi;
      for (std::size_t k : order) {
        onsets.push_back(res.onsets[k]);
        lo.push_back(window_lo[k]);
        hi.push_back(window_hi[k]);
      }
      res.onsets = std::move(onsets);
      window_lo = std::move(lo);
      window_hi = std::move(hi);
    }
  }
  TemplatePass(x, window_lo, window_hi, template_onset_s, &res);
  return res;
}

std::vector<Impact> OnsetDetector::RiseOnsets(const std::vector<float>& x, const OnsetResult& res,
                                              const std::vector<Impact>& flux,
                                              std::vector<long>* window_lo,
                                              std::vector<long>* window_hi) const {
  // The rise at the start of every STFT frame (the novelty's grid), then its peaks.
  const std::size_t frames = res.novelty_db.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  // The windows' mean squares (RawRiseDb's windows, clamped alike), their sums slid from frame to
  // frame and summed anew every kExactFrames frames (the slide's rounding stays ~1e-16 of the
  // loudest sum, far below the background it is compared with).
  constexpr std::size_t kExactFrames = 256;
  const long n = static_cast<long>(x.size());
  auto sum_squares = [&](long a, long b) {  // four running sums: the adds need not wait
    a = std::clamp(a, 0L, n), b = std::clamp(b, 0L, n);
    const float* p = x.data();
    double e0 = 0.0, e1 = 0.0, e2 = 0.0, e3 = 0.0;
    long k = a;
    for (; k + 4 <= b; k += 4) {
      e0 += static_cast<double>(p[k]) * p[k];
      e1 += static_cast<double>(p[k + 1]) * p[k + 1];
      e2 += static_cast<double>(p[k + 2]) * p[k + 2];
      e3 += static_cast<double>(p[k + 3]) * p[k + 3];
    }
    for (; k < b; ++k) e0 += static_cast<double>(p[k]) * p[k];
    return (e0 + e1) + (e2 + e3);
  };
  auto count = [&](long a, long b) {
    return static_cast<double>(std::max(0L, std::clamp(b, 0L, n) - std::clamp(a, 0L, n)));
  };
  const long w_after = std::lround(kRiseAfterS * rate_hz_) + 1;
  const long w_before = std::lround(kRiseBeforeS * rate_hz_);
  const long w_guard = std::lround(kRiseGuardS * rate_hz_);
  const long h = static_cast<long>(hop);
  std::vector<double> after(frames), before(frames), rise(frames);
  double sa = 0.0, sb = 0.0;
  for (std::size_t t = 0; t < frames; ++t) {
    const long i = static_cast<long>(t) * h;
    if (t % kExactFrames == 0) {
      sa = sum_squares(i, i + w_after);
      sb = sum_squares(i - w_before, i - w_guard);
    } else {
      sa += sum_squares(i - h + w_after, i + w_after) - sum_squares(i - h, i);
      sb += sum_squares(i - h - w_guard, i - w_guard) - sum_squares(i - h - w_before, i - w_before);
    }
    const double ca = count(i, i + w_after), cb = count(i - w_before, i - w_guard);
    after[t] = ca > 0.0 ? std::max(sa, 0.0) / ca : 0.0;
    before[t] = cb > 0.0 ? std::max(sb, 0.0) / cb : 0.0;
  }
  // Both windows' power floored by the background (the median of the windows before, over every
  // fourth frame), as the flux's: silence and digital zeros do not turn tiny increases into large
  // rises.
  std::vector<double> sample;  // every fourth frame, as the flux threshold's medians
  for (std::size_t t = 0; t < frames; t += 4) sample.push_back(before[t]);
  const double floor_power = std::max(UpperMedian(std::move(sample)), 1e-30);
  for (std::size_t t = 0; t < frames; ++t)
    rise[t] = 10.0 * std::log10((after[t] + floor_power) / (before[t] + floor_power));
  // Peaks: local maxima of at least min_rise_db (absolute: the impact's own energy at least three
  // times what rang before), above their own running median + threshold_mads MAD (the median and
  // MAD over median_window_s around them, every fourth frame, as the flux's threshold; computed at
  // these maxima only), stronger ones kept within min_gap_s.
  const std::size_t win = std::max<std::size_t>(
      16, static_cast<std::size_t>(options_.median_window_s * rate_hz_ / static_cast<double>(hop)));
  const std::size_t gap =
      static_cast<std::size_t>(options_.min_gap_s * rate_hz_ / static_cast<double>(hop));
  std::vector<std::size_t> peaks;
  SlidingSample around;
  for (std::size_t t = 1; t + 1 < frames; ++t) {
    if (rise[t] < options_.min_rise_db || rise[t] < rise[t - 1] || rise[t] <= rise[t + 1]) continue;
    const std::size_t lo = t > win / 2 ? t - win / 2 : 0;
    around.Set(rise, lo, std::min(frames, lo + win), 4);
    const double med = around.Median();
    if (rise[t] <= med + options_.threshold_mads * 1.4826 * around.Mad(med)) continue;
    if (!peaks.empty() && t - peaks.back() <= gap) {
      if (rise[t] > rise[peaks.back()]) peaks.back() = t;
      continue;
    }
    peaks.push_back(t);
  }
  std::vector<double> known;
  for (const Impact& im : flux) known.push_back(im.time_s);
  std::sort(known.begin(), known.end());
  auto explained = [&](double t) {
    auto it = std::lower_bound(known.begin(), known.end(), t);
    return (it != known.end() && *it - t < options_.min_gap_s) ||
           (it != known.begin() && t - *(it - 1) < options_.min_gap_s);
  };
  const std::size_t nw = static_cast<std::size_t>(window_);
  const std::size_t pre =
      std::max<std::size_t>(nw, static_cast<std::size_t>(options_.aic_pre_s * rate_hz_));
  const std::size_t post =
      std::max<std::size_t>(nw / 2, static_cast<std::size_t>(options_.aic_post_s * rate_hz_));
  std::vector<Impact> out;
  for (std::size_t t : peaks) {
    // The rise peaks where its millisecond starts at the onset: the AIC window around it.
    const std::size_t centre = t * hop + hop;
    if (explained(static_cast<double>(t * hop) / rate_hz_)) continue;
    Impact im = Refine(x, res, centre, false);
    // The AIC pick (on the whitened signal) may leave the attack (a soft impact's is not in the
    // whitened signal): where the recording does not rise by min_rise_db there, the AIC pick is
    // made on the recording itself (rubber-wood: 1.1 ms late at the rise's own frame, 0.4-0.6 ms
    // late on the whitened pick's failures; the timing stage re-times every member).
    if (RawRiseDb(x, rate_hz_, im.time_s) < options_.min_rise_db) {
      const std::size_t b = centre > pre ? centre - pre : 0;
      const AicPick p = PickAic(x, b, std::min(x.size(), centre + post), options_.aic_upsample);
      if (p.valid) {
        im.time_s = p.index / rate_hz_;
        im.sigma_s = std::hypot(p.sigma / rate_hz_, res.sigma_floor_s);
      } else {
        im.time_s = static_cast<double>(t * hop) / rate_hz_;
        CoarsenToHop(&im, hop_, rate_hz_);
      }
    }
    // The rise locates an attack within its millisecond at best (a soft attack lasts that long):
    // sigma at least that window's uniform spread, whatever the AIC curvature says.
    im.sigma_s = std::max(im.sigma_s, kRiseAfterS / std::sqrt(12.0));
    if (explained(im.time_s) || !AboveRecentRinging(x, rate_hz_, std::lround(im.time_s * rate_hz_)))
      continue;
    out.push_back(im);
    window_lo->push_back(static_cast<long>(centre) - static_cast<long>(pre));
    window_hi->push_back(static_cast<long>(centre + post));
  }
  return out;
}

}  // namespace bouncecal
