// Sub-sample onset refinement: the AIC change-point picker (Maeda 1985) and an onset's measures
// (time, sigma, amplitude, SNR) around a coarse onset. See include/bouncecal/acoustic/onsets.hpp.
#include <algorithm>
#include <cmath>
#include <vector>

#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/parallel.hpp"

namespace bouncecal {
namespace {

// Flux peaks refined (AIC picks) per task.
constexpr std::size_t kRefinePart = 16;

}  // namespace

namespace {

// AIC change point of y (Maeda 1985) with parabolic interpolation of the minimum; `units`
// samples of y per sample of the original signal (y may be upsampled: its AIC then counts each
// original sample `units` times, so the likelihood scale is divided by it).
AicPick AicOn(const std::vector<double>& y, double units) {
  AicPick pick;
  const std::size_t n = y.size();
  std::vector<double> s1(n + 1, 0.0), s2(n + 1, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    s1[i + 1] = s1[i] + y[i];
    s2[i + 1] = s2[i] + y[i] * y[i];
  }
  const double tiny = 1e-30 + 1e-12 * s2[n] / static_cast<double>(n);
  const std::size_t kmin = static_cast<std::size_t>(3 * units), kmax = n - kmin - 1;
  if (kmax <= kmin + 2) return pick;
  std::vector<double> aic(n, 0.0);
  auto var = [&](std::size_t a, std::size_t b) {  // variance of y[a, b)
    const double m = static_cast<double>(b - a);
    const double mu = (s1[b] - s1[a]) / m;
    return std::max((s2[b] - s2[a]) / m - mu * mu, 0.0) + tiny;
  };
  std::size_t best = kmin;
  for (std::size_t k = kmin; k <= kmax; ++k) {
    // Maeda (1985): AIC(k) = k log var(x[1..k]) + (N - k - 1) log var(x[k+1..N]).
    aic[k] = static_cast<double>(k) * std::log(var(0, k + 1)) +
             static_cast<double>(n - k - 1) * std::log(var(k + 1, n));
    if (aic[k] < aic[best]) best = k;
  }
  double delta = 0.0, curv = 0.0;
  if (best > kmin && best < kmax) {
    curv = aic[best - 1] - 2.0 * aic[best] + aic[best + 1];
    if (curv > 0.0) delta = std::clamp(0.5 * (aic[best - 1] - aic[best + 1]) / curv, -0.5, 0.5);
  }
  // The new regime starts between y[best] and y[best + 1].
  pick.index = (static_cast<double>(best) + 0.5 + delta) / units;
  // AIC ~ -2 log L (x units): the 1-sigma half width is where it rises by 1.
  pick.sigma = curv > 0.0 ? std::sqrt(2.0 * units / curv) / units : 0.5;
  // Posterior of the change point (flat prior): w_k ~ exp(-(AIC_k - AIC_min) / (2 units)).
  double sw = 0.0, sk = 0.0, skk = 0.0;
  for (std::size_t k = kmin; k <= kmax; ++k) {
    const double w = std::exp(-(aic[k] - aic[best]) / (2.0 * units));
    const double kk = static_cast<double>(k);
    sw += w;
    sk += w * kk;
    skk += w * kk * kk;
  }
  const double mean = sk / sw;
  pick.spread = std::sqrt(std::max(skk / sw - mean * mean, 0.0)) / units;
  pick.valid = true;
  return pick;
}

}  // namespace

AicPick PickAic(const std::vector<float>& x, std::size_t begin, std::size_t end, int upsample) {
  AicPick pick;
  end = std::min(end, x.size());
  if (end <= begin + 16 || upsample < 1) return pick;
  const std::size_t n = end - begin;
  const std::size_t u = static_cast<std::size_t>(upsample);
  std::vector<double> y(n * u);
  if (u == 1) {
    for (std::size_t i = 0; i < n; ++i) y[i] = x[begin + i];
  } else {
    // Band-limited interpolation: Hann-windowed sinc, half width kHalf samples, using the
    // samples around the window too (the signal continues beyond it).
    constexpr long kHalf = 8;
    const long xs = static_cast<long>(x.size());
    for (std::size_t j = 0; j < n * u; ++j) {
      const double t = static_cast<double>(begin) + static_cast<double>(j) / static_cast<double>(u);
      const long m0 = static_cast<long>(std::floor(t));
      double acc = 0.0;
      for (long m = m0 - kHalf + 1; m <= m0 + kHalf; ++m) {
        if (m < 0 || m >= xs) continue;
        const double d = t - static_cast<double>(m);
        const double sinc = std::fabs(d) < 1e-12 ? 1.0 : std::sin(M_PI * d) / (M_PI * d);
        const double win = 0.5 + 0.5 * std::cos(M_PI * d / static_cast<double>(kHalf));
        acc += x[static_cast<std::size_t>(m)] * sinc * win;
      }
      y[j] = acc;
    }
  }
  pick = AicOn(y, static_cast<double>(u));
  if (pick.valid) pick.index += static_cast<double>(begin);
  return pick;
}

std::vector<Impact> OnsetDetector::RefinePeaks(const std::vector<float>& x,
                                               const std::vector<std::size_t>& peaks,
                                               const OnsetResult& res, std::vector<long>* window_lo,
                                               std::vector<long>* window_hi) const {
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t nw = static_cast<std::size_t>(window_);
  const std::size_t pre =
      std::max<std::size_t>(nw, static_cast<std::size_t>(options_.aic_pre_s * rate_hz_));
  const std::size_t post =
      std::max<std::size_t>(nw / 2, static_cast<std::size_t>(options_.aic_post_s * rate_hz_));
  std::vector<std::size_t> centre;
  for (std::size_t t : peaks) {
    // The click is most likely in the newest half of the window at the flux peak.
    centre.push_back(t * hop + nw / 2 + nw / 4);
    window_lo->push_back(static_cast<long>(centre.back()) - static_cast<long>(pre));
    window_hi->push_back(static_cast<long>(centre.back() + post));
  }
  // Each peak's refinement reads only the signal and `res`'s whitened signal and noise: the
  // peaks are refined on the threads, each into its own slot.
  std::vector<Impact> refined(peaks.size());
  ParallelForGroups(Threads(), peaks.size(), kRefinePart, [&](std::size_t i0, std::size_t i1) {
    for (std::size_t i = i0; i < i1; ++i) refined[i] = Refine(x, res, centre[i], false);
  });
  return refined;
}

Impact OnsetDetector::Refine(const std::vector<float>& x, const OnsetResult& res,
                             std::size_t centre, bool tight) const {
  // AIC pick around the coarse onset `centre`; tight: the coarse onset is already good to a few
  // samples (template match), so the window is narrower.
  const std::vector<float>& w = res.whitened;
  const std::size_t n = w.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t nw = static_cast<std::size_t>(window_);
  const std::size_t pre =
      std::max<std::size_t>(nw, static_cast<std::size_t>(options_.aic_pre_s * rate_hz_));
  const std::size_t post =
      std::max<std::size_t>(nw / 2, static_cast<std::size_t>(options_.aic_post_s * rate_hz_));
  const double noise_var = std::max(res.noise_rms * res.noise_rms, 1e-30);
  // Timing floor: the AIC pick keeps a bias of a fraction of a sample that depends on where the
  // onset falls between samples (measured on rendered clicks, tests/onsets_test.cpp).
  const double floor_s = res.sigma_floor_s;
  double onset = static_cast<double>(centre);
  double sigma = static_cast<double>(hop) / std::sqrt(12.0);
  {
    const std::size_t pr = tight ? std::max<std::size_t>(16, pre / 3) : pre;
    const std::size_t po = tight ? std::max<std::size_t>(8, post / 2) : post;
    const std::size_t b = centre > pr ? centre - pr : 0;
    const AicPick p = PickAic(w, b, std::min(n, centre + po), options_.aic_upsample);
    if (p.valid) {
      onset = p.index;
      sigma = p.sigma;
    }
  }
  Impact imp;
  imp.time_s = onset / rate_hz_;
  imp.sigma_s = std::hypot(sigma / rate_hz_, floor_s);
  const std::size_t i0 =
      std::min(n - 1, static_cast<std::size_t>(std::max(0.0, std::floor(onset))));
  const std::size_t pk_end = std::min(n, i0 + static_cast<std::size_t>(0.003 * rate_hz_) + 1);
  double amp = 0.0;
  for (std::size_t i = i0; i < pk_end; ++i)
    amp = std::max(amp, static_cast<double>(std::fabs(x[i])));
  imp.amplitude = amp;
  // SNR: whitened power just after the onset over the power in the 10 ms before it.
  const std::size_t len_post =
      std::max<std::size_t>(8, static_cast<std::size_t>(0.0005 * rate_hz_));
  double e_post = 0.0;
  std::size_t c_post = 0;
  for (std::size_t i = i0; i < std::min(n, i0 + len_post); ++i, ++c_post)
    e_post += static_cast<double>(w[i]) * w[i];
  const std::size_t pre_end = i0 > 2 ? i0 - 2 : 0;
  const std::size_t pre_len = static_cast<std::size_t>(0.01 * rate_hz_);
  const std::size_t pre_begin = pre_end > pre_len ? pre_end - pre_len : 0;
  double e_pre = 0.0;
  for (std::size_t i = pre_begin; i < pre_end; ++i) e_pre += static_cast<double>(w[i]) * w[i];
  const double p_post = c_post ? e_post / static_cast<double>(c_post) : 0.0;
  const double p_pre =
      pre_end > pre_begin ? e_pre / static_cast<double>(pre_end - pre_begin) : noise_var;
  imp.snr_db = 10.0 * std::log10((p_post + 1e-30) / (std::max(p_pre, 1e-6 * noise_var) + 1e-30));
  return imp;
}

}  // namespace bouncecal
