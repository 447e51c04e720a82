// bouncecal/core/fractional_delay.hpp — band-limited interpolation of sampled sound at any time
// (realsound's placement and alignment, the guided search's cancellation): a Kaiser-windowed sinc,
// kHalfTaps taps on each side. With beta 8 its ripple is within 0.01 dB up
// to 0.8 x Nyquist; above, the sound is attenuated (zero phase: no delay at any frequency).
// Used to place a real impact sound at a sub-sample time and to align two sounds.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <vector>

#include "bouncecal/core/stats.hpp"

namespace bouncecal::fractional_delay {

inline constexpr int kHalfTaps = 32;
inline constexpr double kKaiserBeta = 8.0;

// The kernel at offset u (samples): sinc(u) times the Kaiser window over |u| < half.
inline double Kernel(double u, int half = kHalfTaps) {
  const double a = std::fabs(u);
  if (a >= half) return 0.0;
  const double sinc = a < 1e-12 ? 1.0 : std::sin(std::numbers::pi * u) / (std::numbers::pi * u);
  const double r = u / half;
  static const double i0_beta = BesselI0(kKaiserBeta);
  return sinc * BesselI0(kKaiserBeta * std::sqrt(1.0 - r * r)) / i0_beta;
}

// The 2 kHalfTaps + 1 weights w[d + kHalfTaps] = Kernel(d - f), d in [-kHalfTaps, kHalfTaps],
// of a delay by the fraction f in [0, 1): y[n] = sum_d w[d] x[n - d] delays x by f samples.
inline std::vector<double> Weights(double f) {
  std::vector<double> w(2 * kHalfTaps + 1);
  for (int d = -kHalfTaps; d <= kHalfTaps; ++d)
    w[static_cast<std::size_t>(d + kHalfTaps)] = Kernel(static_cast<double>(d) - f);
  return w;
}

// out[j] = x(start + j), j in [0, count): band-limited values at positions that share one
// fraction (one set of weights), 0 outside x.
template <typename T>
std::vector<double> Resample(const std::vector<T>& x, double start, std::size_t count) {
  const double whole = std::floor(start);
  const double f = start - whole;
  std::vector<double> w(2 * kHalfTaps + 1);
  for (int d = -kHalfTaps; d <= kHalfTaps; ++d)
    w[static_cast<std::size_t>(d + kHalfTaps)] = Kernel(f + static_cast<double>(d));
  const auto base = static_cast<std::int64_t>(whole);
  const auto n_x = static_cast<std::int64_t>(x.size());
  std::vector<double> out(count, 0.0);
  for (std::size_t j = 0; j < count; ++j) {
    double s = 0.0;
    // x(base + f + j) = sum_d x[base + j - d] Kernel(f + d)
    for (int d = -kHalfTaps; d <= kHalfTaps; ++d) {
      const std::int64_t m = base + static_cast<std::int64_t>(j) - d;
      if (m < 0 || m >= n_x) continue;
      s += static_cast<double>(x[static_cast<std::size_t>(m)]) *
           w[static_cast<std::size_t>(d + kHalfTaps)];
    }
    out[j] = s;
  }
  return out;
}

// Adds gain * x, delayed so that x's sample `index` lands at the real output position `at`, to
// out (band-limited: every output sample the kernel reaches). Returns max |added|.
template <typename T>
double AddDelayed(const std::vector<T>& x, double index, double at, double gain,
                  std::vector<double>* out) {
  const double shift = at - index;  // output position of x[0]
  const double whole = std::floor(shift);
  const double f = shift - whole;
  const std::vector<double> w = Weights(f);
  const auto s0 = static_cast<std::int64_t>(whole);
  const auto n_out = static_cast<std::int64_t>(out->size());
  // y[s0 + m + d] += gain * x[m] * w(d - f): the sample x[m] sits at s0 + m + f.
  std::vector<double> y(x.size() + 2 * kHalfTaps + 1, 0.0);
  for (std::size_t m = 0; m < x.size(); ++m) {
    const double v = gain * static_cast<double>(x[m]);
    if (v == 0.0) continue;
    double* row = &y[m];  // y index m + d + kHalfTaps
    for (int j = 0; j <= 2 * kHalfTaps; ++j) row[j] += v * w[static_cast<std::size_t>(j)];
  }
  double peak = 0.0;
  for (std::size_t i = 0; i < y.size(); ++i) {
    const std::int64_t n = s0 + static_cast<std::int64_t>(i) - kHalfTaps;
    peak = std::max(peak, std::fabs(y[i]));
    if (n >= 0 && n < n_out) (*out)[static_cast<std::size_t>(n)] += y[i];
  }
  return peak;
}

}  // namespace bouncecal::fractional_delay
