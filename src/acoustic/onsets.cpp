// Onset detection: the detector's set-up and its stages in order (whitening, novelty, threshold,
// peaks, AIC refinement, template pass). See include/bouncecal/acoustic/onsets.hpp.
#include "bouncecal/acoustic/onsets.hpp"

#include <algorithm>
#include <cmath>
#include <memory>
#include <numbers>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/parallel.hpp"
#include "bouncecal/core/stats.hpp"
#include "spectra.hpp"

namespace bouncecal {
namespace {

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

int NearestPowerOfTwo(double v) {
  int p = 1;
  while (p * 2 <= v * std::numbers::sqrt2) p *= 2;
  return p;
}

}  // namespace

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
  TemplatePass(x, window_lo, window_hi, &res);
  return res;
}

}  // namespace bouncecal
