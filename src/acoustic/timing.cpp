// Final, local timing of a sequence's impacts. See include/bouncecal/acoustic/timing.hpp.
#include "bouncecal/acoustic/timing.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <numbers>
#include <optional>

#include "avx2_clones.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/parallel.hpp"
#include "bouncecal/core/stats.hpp"

namespace bouncecal {
namespace {

// Half width (samples) of the windowed-sinc interpolation kernel, and the fine grid (steps per
// sample) on which the interpolated correlation peak is searched before a parabolic refinement.
constexpr long kSincHalf = 8;
constexpr int kPeakGrid = 32;
// Members (best template matches) whose own AIC picks set the sequence's constant offset.
constexpr std::size_t kAnchorMembers = 9;
// Stride (samples) of the template positions over the noise window (ProjectedNoise).
constexpr long kNoiseStride = 4;
// Cycle-slip model (SlipModel): fewer template-timed members than this and the AIC scatter is
// not measured; the AIC scatter's floor (samples: the parabolic AIC pick's resolution); EM
// iterations (the fit settles in ~10 on the recordings and the corpus).
constexpr std::size_t kMinSlipMembers = 3;
// Template choice: the earliest member whose local SNR is within this of the best. Measured: a
// rubber ball's two loudest members 0.5 dB apart swapped with the weak tail's membership (every
// time moved by 55 us); 3 dB took a clipped phone recording's first impacts as the template and
// overstated every sigma there by 45 % (RMS(err/sigma) 0.69).
constexpr double kTemplateSnrToleranceDb = 1.0;
constexpr double kMinAicSigma = 0.5;
constexpr int kSlipEmIterations = 50;

double WindowedSinc(double d) {
  if (std::fabs(d) >= static_cast<double>(kSincHalf)) return 0.0;
  const double s =
      std::fabs(d) < 1e-12 ? 1.0 : std::sin(std::numbers::pi * d) / (std::numbers::pi * d);
  return s * (0.5 + 0.5 * std::cos(std::numbers::pi * d / static_cast<double>(kSincHalf)));
}

// WindowedSinc at every multiple of 1/kPeakGrid in (-kSincHalf, kSincHalf), computed once with
// the same formula: InterpolatedPeak's fine-grid points t (an integer plus j / kPeakGrid) and
// sample indices m give arguments d = t - m that are such multiples exactly, so looking them up
// gives the same values to the bit as evaluating the sin and cos there (which were ~9 % of a
// `calibrate` of the bundled recording). Immutable after its thread-safe initialisation.
constexpr double kSincGridMaxT = 1 << 20;  // |t| below it: t * kPeakGrid is exact
class SincGrid {
 public:
  static const SincGrid& Get() {
    static const SincGrid grid;
    return grid;
  }
  // d must be a multiple of 1 / kPeakGrid.
  double At(double d) const {
    const long k = std::lround(d * kPeakGrid);
    if (k <= -kSpan || k >= kSpan) return 0.0;
    return values_[static_cast<std::size_t>(k + kSpan)];
  }

 private:
  static constexpr long kSpan = kSincHalf * kPeakGrid;
  SincGrid() : values_(static_cast<std::size_t>(2 * kSpan + 1)) {
    for (long k = -kSpan; k <= kSpan; ++k)
      values_[static_cast<std::size_t>(k + kSpan)] =
          WindowedSinc(static_cast<double>(k) / kPeakGrid);
  }
  std::vector<double> values_;
};

// sum_k a[k] b[k] in double, with four independent partial sums: the compiler may not reorder
// a floating-point sum itself, and a single running sum is one dependent add per product.
template <typename A, typename B>
[[gnu::always_inline]] inline double DotBody(const A* a, const B* b, std::size_t n) {
  double s0 = 0.0, s1 = 0.0, s2 = 0.0, s3 = 0.0;
  std::size_t k = 0;
  for (; k + 4 <= n; k += 4) {
    s0 += static_cast<double>(a[k]) * static_cast<double>(b[k]);
    s1 += static_cast<double>(a[k + 1]) * static_cast<double>(b[k + 1]);
    s2 += static_cast<double>(a[k + 2]) * static_cast<double>(b[k + 2]);
    s3 += static_cast<double>(a[k + 3]) * static_cast<double>(b[k + 3]);
  }
  for (; k < n; ++k) s0 += static_cast<double>(a[k]) * static_cast<double>(b[k]);
  return (s0 + s1) + (s2 + s3);
}

// Dot compiled for AVX2 and for the baseline x86-64 (avx2_clones.hpp): the same products in the
// same four partial sums (one 4-lane register instead of two 2-lane ones).
BOUNCECAL_AVX2_CLONES double Dot(const float* a, const float* b, std::size_t n) {
  return DotBody(a, b, n);
}
BOUNCECAL_AVX2_CLONES double Dot(const double* a, const float* b, std::size_t n) {
  return DotBody(a, b, n);
}

// Four independent Dot products at once, out[t] = Dot(a[t], b[t], n[t]) to the bit: each keeps
// its own four partial sums (one 4-lane register) fed in the same order, and its tail and final
// additions are Dot's; running four side by side overlaps their additions (one Dot alone is a
// chain of dependent ones). Four-lane vectors of the GCC/Clang vector extension (lane-wise IEEE
// operations, one AVX2 register or two SSE2 ones: Double4, avx2_clones.hpp).
[[gnu::always_inline]] inline void Dot4Body(const double* const* a, const double* const* b,
                                            const std::size_t* n, double* out) {
  std::size_t common = std::min(std::min(n[0], n[1]), std::min(n[2], n[3]));
  common &= ~std::size_t{3};
  Double4 s[4] = {};
  for (std::size_t k = 0; k < common; k += 4)
    for (int t = 0; t < 4; ++t) {
      Double4 va, vb;
      std::memcpy(&va, a[t] + k, sizeof va);
      std::memcpy(&vb, b[t] + k, sizeof vb);
      s[t] += va * vb;
    }
  for (int t = 0; t < 4; ++t) {
    double s0 = s[t][0], s1 = s[t][1], s2 = s[t][2], s3 = s[t][3];
    const double* at = a[t];
    const double* bt = b[t];
    std::size_t k = common;
    for (; k + 4 <= n[t]; k += 4) {
      s0 += at[k] * bt[k];
      s1 += at[k + 1] * bt[k + 1];
      s2 += at[k + 2] * bt[k + 2];
      s3 += at[k + 3] * bt[k + 3];
    }
    for (; k < n[t]; ++k) s0 += at[k] * bt[k];
    out[t] = (s0 + s1) + (s2 + s3);
  }
}
// Samples converted to double once (exactly) where many products reuse them: the conversion
// was a third of the instructions of each product.
BOUNCECAL_AVX2_CLONES void Dot4(const double* const* a, const double* const* b,
                                const std::size_t* n, double* out) {
  Dot4Body(a, b, n, out);
}

// The (n / 2)-th smallest (0-based) of |p[0, n)|, the value std::nth_element selects. The bit
// patterns of floats >= 0 order as the floats do (NaN above all, as unsigned integers), so a
// histogram of their top bits (sign, exponent, 3 mantissa bits) finds the bucket holding the
// rank in one pass, and only that bucket's few values are selected from: Measure's noise floor
// takes ~1000 values per call, twice per member and timing round.
constexpr int kSelectShift = 20;
constexpr std::size_t kSelectBuckets = std::size_t{1} << (32 - kSelectShift);
float MedianAbs(const float* p, std::size_t n) {
  std::vector<std::uint32_t> keys(n);
  for (std::size_t i = 0; i < n; ++i) {
    const float a = std::fabs(p[i]);
    std::memcpy(&keys[i], &a, sizeof a);
  }
  std::size_t rank = n / 2;
  std::vector<std::uint32_t> count(kSelectBuckets, 0);
  for (std::uint32_t k : keys) ++count[k >> kSelectShift];
  std::uint32_t bucket = 0;
  while (rank >= count[bucket]) rank -= count[bucket++];
  std::size_t m = 0;
  for (std::uint32_t k : keys)
    if (k >> kSelectShift == bucket) keys[m++] = k;
  keys.resize(m);
  const auto at = keys.begin() + static_cast<std::ptrdiff_t>(rank);
  std::nth_element(keys.begin(), at, keys.end());
  float v;
  std::memcpy(&v, &*at, sizeof v);
  return v;
}

// Robust rms (Gaussian: 1.4826 * median |x|) of p[0, n).
double RobustRms(const float* p, std::size_t n) {
  if (n == 0) return 0.0;
  return 1.4826 * static_cast<double>(MedianAbs(p, n));
}

// The whitened neighbourhood of one member: w[i] is the whitened sample begin + i.
struct Neighbourhood {
  long begin = 0;
  std::vector<float> w;
  long end() const { return begin + static_cast<long>(w.size()); }
  float at(long n) const {
    return n >= begin && n < end() ? w[static_cast<std::size_t>(n - begin)] : 0.0f;
  }
};

// Per-member measures at an onset (fractional sample index): local noise floor of the whitened
// signal, SNR, raw peak level.
struct LocalMeasures {
  double noise_rms = 0.0;
  double snr_db = 0.0;
  double amplitude = 0.0;
};

LocalMeasures Measure(const Neighbourhood& nb, const std::vector<float>& x, double onset,
                      double rate_hz, const TimingOptions& o) {
  LocalMeasures m;
  const long i0 = static_cast<long>(std::floor(onset)) + 1;  // first sample of the new regime
  const long guard = std::max(2L, std::lround(o.noise_guard_s * rate_hz));
  const long noise_len = std::max(16L, std::lround(o.noise_window_s * rate_hz));
  const long n_hi = std::max(nb.begin, i0 - guard);
  const long n_lo = std::max(nb.begin, n_hi - noise_len);
  if (n_hi > n_lo)
    m.noise_rms = RobustRms(nb.w.data() + (n_lo - nb.begin), static_cast<std::size_t>(n_hi - n_lo));
  const long sig_len = std::max(8L, std::lround(o.signal_window_s * rate_hz));
  double e = 0.0;
  long c = 0;
  for (long i = std::max(i0, nb.begin); i < std::min(nb.end(), i0 + sig_len); ++i, ++c)
    e += static_cast<double>(nb.at(i)) * nb.at(i);
  const double sig = c > 0 ? std::sqrt(e / static_cast<double>(c)) : 0.0;
  // Digital silence has no noise floor: keep the ratio finite (at most 120 dB).
  const double floor = std::max(m.noise_rms, 1e-6 * sig);
  m.snr_db = sig > 0.0 ? 20.0 * std::log10(sig / floor) : -120.0;
  const long lvl_len = std::max(1L, std::lround(o.level_window_s * rate_hz));
  const long xs = static_cast<long>(x.size());
  for (long i = std::clamp(i0 - 1, 0L, xs); i < std::min(xs, i0 + lvl_len); ++i)
    m.amplitude =
        std::max(m.amplitude, static_cast<double>(std::fabs(x[static_cast<std::size_t>(i)])));
  return m;
}

// Robust spread (1.4826 median |.|) of <w[l, l + L), g> over the template starts l of the noise
// window before `onset` (timing.hpp: the noise term). 0 when the window is too short.
double ProjectedNoise(const Neighbourhood& nb, const std::vector<double>& g, double onset,
                      double rate_hz, const TimingOptions& o) {
  const long L = static_cast<long>(g.size());
  const long i0 = static_cast<long>(std::floor(onset)) + 1;
  const long guard = std::max(2L, std::lround(o.noise_guard_s * rate_hz));
  const long noise_len = std::max(16L, std::lround(o.noise_window_s * rate_hz));
  const long hi = std::max(nb.begin, i0 - guard) - L;
  const long lo = std::max(nb.begin, i0 - guard - noise_len);
  std::vector<double> p;
  const std::vector<double> wd(nb.w.begin(), nb.w.end());  // exact: see Dot4
  // Every kNoiseStride-th position: the spread is as well estimated (hundreds of positions in a
  // 20 ms window) at a quarter of the work.
  for (long l = lo; l <= hi; l += kNoiseStride) {
    double acc = 0.0;
    const long l3 = l + 3 * kNoiseStride;  // four positions inside nb at once (Dot4)
    if (l >= nb.begin && l3 <= hi && l3 + L <= nb.end()) {
      const double* a[4] = {g.data(), g.data(), g.data(), g.data()};
      const double* b[4];
      const std::size_t len[4] = {static_cast<std::size_t>(L), static_cast<std::size_t>(L),
                                  static_cast<std::size_t>(L), static_cast<std::size_t>(L)};
      for (int t = 0; t < 4; ++t) b[t] = wd.data() + (l + t * kNoiseStride - nb.begin);
      double d[4];
      Dot4(a, b, len, d);
      for (int t = 0; t < 4; ++t) p.push_back(std::fabs(d[t]));
      l = l3;
      continue;
    }
    if (l >= nb.begin && l + L <= nb.end()) {
      acc = Dot(g.data(), nb.w.data() + (l - nb.begin), static_cast<std::size_t>(L));
    } else {
      for (long j = 0; j < L; ++j) acc += g[static_cast<std::size_t>(j)] * nb.at(l + j);
    }
    p.push_back(std::fabs(acc));
  }
  if (p.size() < 8) return 0.0;
  return 1.4826 * UpperMedian(std::move(p));
}

// Normalised cross-correlation of the template h (energy hh) with nb at template start l.
double NccAt(const Neighbourhood& nb, const std::vector<double>& h, double hh, long l) {
  double xy = 0.0, yy = 0.0;
  for (std::size_t j = 0; j < h.size(); ++j) {
    const double y = nb.at(l + static_cast<long>(j));
    xy += h[j] * y;
    yy += y * y;
  }
  return yy > 0.0 && hh > 0.0 ? xy / std::sqrt(hh * yy) : 0.0;
}

struct LagChoice {
  long lag = 0;
  double ncc = -2.0;
  long rival_lag = 0;       // the best lag of the window outside the chosen peak's main lobe
  double rival_ncc = -2.0;  // its NCC (-2: none)
};

// Integer template start: the best NCC within +- near of the expected start s0 (the detection's
// time; a better match farther out is ringing or an echo as often as the impact: on the ping-pong
// recording such picks were 0.7-1.4 ms early), and the best rival in that window outside the
// chosen peak's main lobe (the one the rule could have chosen instead). Whether the chosen peak
// is on the right ringing cycle is checked afterwards against the member's own AIC pick.
LagChoice BestLag(const Neighbourhood& nb, const std::vector<double>& h, double hh, long s0,
                  long near) {
  const long lo = s0 - near, hi = s0 + near;
  std::vector<double> c(static_cast<std::size_t>(hi - lo + 1));
  for (long l = lo; l <= hi; ++l) c[static_cast<std::size_t>(l - lo)] = NccAt(nb, h, hh, l);
  auto at = [&](long l) { return c[static_cast<std::size_t>(l - lo)]; };
  LagChoice best;
  best.lag = s0;
  for (long l = lo; l <= hi; ++l)
    if (at(l) > best.ncc) {
      best.ncc = at(l);
      best.lag = l;
    }
  // Main lobe: walk down from the peak to the first local minimum on each side.
  long a = best.lag, b = best.lag;
  while (a > lo && at(a - 1) < at(a)) --a;
  while (b < hi && at(b + 1) < at(b)) ++b;
  for (long l = lo; l <= hi; ++l)
    if ((l < a || l > b) && at(l) > best.rival_ncc) {
      best.rival_ncc = at(l);
      best.rival_lag = l;
    }
  return best;
}

}  // namespace

bool TimingOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (lpc_order < 0 || lpc_order > 256)
    return fail("TimingOptions::lpc_order = " + std::to_string(lpc_order) + ": must be 0..256");
  for (const auto& [name, v] : {std::pair<const char*, double>{"fit_before_s", fit_before_s},
                                {"fit_after_s", fit_after_s},
                                {"lead_s", lead_s},
                                {"noise_guard_s", noise_guard_s},
                                {"resolution_samples", resolution_samples},
                                {"resolution_s", resolution_s},
                                {"shape_s_per_neper", shape_s_per_neper},
                                {"ambiguity_gain", ambiguity_gain},
                                {"noise_gain", noise_gain}})
    if (!(v >= 0.0) || !std::isfinite(v))
      return fail(std::string("TimingOptions::") + name + " = " + std::to_string(v) +
                  ": must be a finite number >= 0");
  for (const auto& [name, v] : {std::pair<const char*, double>{"template_s", template_s},
                                {"search_s", search_s},
                                {"aic_pre_s", aic_pre_s},
                                {"aic_post_s", aic_post_s},
                                {"noise_window_s", noise_window_s},
                                {"signal_window_s", signal_window_s},
                                {"level_window_s", level_window_s},
                                {"aic_sigma_gain", aic_sigma_gain},
                                {"slip_prior", slip_prior}})
    if (!(v > 0.0) || !std::isfinite(v) || v > 1.0)
      return fail(std::string("TimingOptions::") + name + " = " + std::to_string(v) +
                  ": must be in (0, 1]");
  if (threads < 0 || threads > 256)
    return fail("TimingOptions::threads = " + std::to_string(threads) + ": must be 0..256");
  if (!(min_template_ncc > 0.0) || min_template_ncc > 1.0)
    return fail("TimingOptions::min_template_ncc = " + std::to_string(min_template_ncc) +
                ": must be in (0, 1]");
  return true;
}

std::vector<double> NeighbourhoodPredictor(const std::vector<float>& x,
                                           const std::vector<long>& anchors, int order, long before,
                                           long after) {
  if (order <= 0) return {1.0};
  const long n = static_cast<long>(x.size());
  std::vector<double> r(static_cast<std::size_t>(order) + 1, 0.0), rw(r.size());
  long used = 0;
  for (long a : anchors) {
    const long lo = std::max(0L, a - before), hi = std::min(n, a + after);
    if (hi - lo <= 4L * order) continue;
    int lag = 0;
    const std::vector<double> xd(x.begin() + lo, x.begin() + hi);  // exact: see Dot4
    for (; lag + 3 <= order; lag += 4) {                           // four lags at once (Dot4)
      const double* pa[4];
      const double* pb[4] = {xd.data(), xd.data(), xd.data(), xd.data()};
      std::size_t len[4];
      for (int t = 0; t < 4; ++t) {
        pa[t] = xd.data() + lag + t;
        len[t] = static_cast<std::size_t>(hi - lo - lag - t);
      }
      Dot4(pa, pb, len, rw.data() + lag);
    }
    for (; lag <= order; ++lag)
      rw[static_cast<std::size_t>(lag)] =
          Dot(x.data() + lo + lag, x.data() + lo, static_cast<std::size_t>(hi - lo - lag));
    if (!(rw[0] > 0.0)) continue;
    // Each neighbourhood counts once, whatever its level.
    for (std::size_t k = 0; k < r.size(); ++k) r[k] += rw[k] / rw[0];
    used += hi - lo;
  }
  if (!(r[0] > 0.0)) return {1.0};
  // White-noise correction (-60 dB) keeps the predictor stable on pure tones (Makhoul 1975,
  // Proc. IEEE 63(4), sec. III-D).
  r[0] *= 1.0 + 1e-6;
  (void)used;
  return LevinsonDurbin(r, order);
}

std::vector<float> WhitenSegment(const std::vector<float>& x, const std::vector<double>& a,
                                 long begin, long end) {
  std::vector<float> out(static_cast<std::size_t>(std::max(0L, end - begin)), 0.0f);
  const long n = static_cast<long>(x.size());
  // Taps reversed, so that the inner product runs forward over x (Dot).
  const std::vector<double> rev(a.rbegin(), a.rend());
  const long taps = static_cast<long>(a.size());
  const std::size_t nt = static_cast<std::size_t>(taps);
  // The samples the filter reads, converted to double once (exact: see Dot4).
  const long xd_begin = std::clamp(begin - taps + 1, 0L, n);
  const std::vector<double> xd(x.begin() + xd_begin, x.begin() + std::clamp(end, xd_begin, n));
  for (long i = begin; i < end; ++i) {
    if (i - taps + 1 >= 0 && i + 3 < std::min(n, end)) {  // four outputs at once (Dot4)
      const double* ar[4] = {rev.data(), rev.data(), rev.data(), rev.data()};
      const double* b[4];
      const std::size_t len[4] = {nt, nt, nt, nt};
      for (long t = 0; t < 4; ++t) b[t] = xd.data() + (i + t - taps + 1 - xd_begin);
      double d[4];
      Dot4(ar, b, len, d);
      for (long t = 0; t < 4; ++t)
        out[static_cast<std::size_t>(i + t - begin)] = static_cast<float>(d[t]);
      i += 3;
      continue;
    }
    if (i - taps + 1 >= 0 && i < n) {  // all of the taps inside x
      out[static_cast<std::size_t>(i - begin)] = static_cast<float>(
          Dot(rev.data(), x.data() + (i - taps + 1), static_cast<std::size_t>(taps)));
      continue;
    }
    double acc = 0.0;
    for (std::size_t j = 0; j < a.size(); ++j) {
      const long m = i - static_cast<long>(j);
      if (m >= 0 && m < n) acc += a[j] * x[static_cast<std::size_t>(m)];
    }
    out[static_cast<std::size_t>(i - begin)] = static_cast<float>(acc);
  }
  return out;
}

double InterpolatedPeak(const std::vector<double>& c, std::size_t at, double* peak) {
  const long size = static_cast<long>(c.size());
  const SincGrid& grid = SincGrid::Get();
  auto f = [&](double t) {
    double acc = 0.0;
    const long m0 = static_cast<long>(std::floor(t));
    const double steps = t * kPeakGrid;  // exact for the grid points (multiples of 1/kPeakGrid)
    const bool on_grid = steps == std::floor(steps) && std::fabs(t) < kSincGridMaxT;
    for (long m = std::max(0L, m0 - kSincHalf + 1); m <= std::min(size - 1, m0 + kSincHalf); ++m) {
      const double d = t - static_cast<double>(m);
      acc += c[static_cast<std::size_t>(m)] * (on_grid ? grid.At(d) : WindowedSinc(d));
    }
    return acc;
  };
  const double centre = static_cast<double>(at);
  double best_t = centre, best_v = f(centre);
  for (int j = -kPeakGrid; j <= kPeakGrid; ++j) {
    const double t = centre + static_cast<double>(j) / kPeakGrid;
    const double v = f(t);
    if (v > best_v) {
      best_v = v;
      best_t = t;
    }
  }
  // Parabola through the fine-grid neighbours.
  const double step = 1.0 / kPeakGrid;
  const double vm = f(best_t - step), vp = f(best_t + step);
  const double curv = vm - 2.0 * best_v + vp;
  if (curv < 0.0) {
    const double d = std::clamp(0.5 * (vm - vp) / curv, -0.5, 0.5);
    best_t += d * step;
    best_v = f(best_t);
  }
  *peak = best_v;
  return best_t;
}

namespace {

// Sizes (samples) the stages use, from the options and the rate.
struct Geometry {
  long tl, lead, near, aic_pre, aic_post, before, after;
  Geometry(const TimingOptions& o, double rate_hz) {
    auto samples = [&](double s) { return std::max(1L, std::lround(s * rate_hz)); };
    tl = std::max(8L, samples(o.template_s));
    lead = samples(o.lead_s);
    near = samples(o.search_s);
    aic_pre = std::max(16L, samples(o.aic_pre_s));
    aic_post = std::max(8L, samples(o.aic_post_s));
    before = std::max({near + lead, aic_pre, samples(o.noise_window_s + o.noise_guard_s)}) +
             2 * kSincHalf + 2;
    after = std::max({near + tl, aic_post, samples(o.level_window_s)}) + 2 * kSincHalf;
  }
};

// AIC pick in the window [anchor - aic_pre, anchor + aic_post) of one neighbourhood.
AicPick AicAround(const Neighbourhood& nb, long anchor, const Geometry& g) {
  const long b = std::max(nb.begin, anchor - g.aic_pre);
  return PickAic(nb.w, static_cast<std::size_t>(b - nb.begin),
                 static_cast<std::size_t>(anchor + g.aic_post - nb.begin));
}

// The template: the whitened waveform of one member from `lead` before its AIC onset, and its
// derivative (central differences).
struct Template {
  std::size_t member = 0;
  double t_ref = 0.0;  // onset sample (fractional) of the template impact
  long start = 0;      // sample where the template starts
  long anchor = 0;     // the template member's detection time (sample)
  std::vector<double> h, hd;
  double hh = 0.0, dd = 0.0;
  bool usable() const { return hh > 0.0 && dd > 0.0; }
};

Template MakeTemplate(const std::vector<Neighbourhood>& nb, const std::vector<long>& anchors,
                      std::size_t member, const Geometry& g) {
  Template t;
  t.member = member;
  const Neighbourhood& tn = nb[member];
  t.t_ref = static_cast<double>(anchors[member]) - 0.5;
  const AicPick p = AicAround(tn, anchors[member], g);
  if (p.valid) t.t_ref = p.index + static_cast<double>(tn.begin);
  t.start = std::lround(t.t_ref) - g.lead;
  t.anchor = anchors[member];
  t.h.resize(static_cast<std::size_t>(g.tl));
  t.hd.resize(t.h.size());
  for (long j = 0; j < g.tl; ++j) {
    const std::size_t i = static_cast<std::size_t>(j);
    t.h[i] = tn.at(t.start + j);
    t.hd[i] = 0.5 * (tn.at(t.start + j + 1) - tn.at(t.start + j - 1));
    t.hh += t.h[i] * t.h[i];
    t.dd += t.hd[i] * t.hd[i];
  }
  return t;
}

// One member timed: onset (fractional sample), variance (samples^2) and the model's parts.
struct MemberTime {
  double onset = 0.0;
  double sigma2 = 0.0;
  long lag = 0;            // chosen integer template start (template-timed members)
  double ncc_noise = 0.0;  // s_c: the NCC's spread under the local noise
  double yy = 0.0;         // the member's energy over the template at the chosen lag
};

// Template timing of member k (TimingOptions, the sigma model); false when it does not match
// (NCC below min_template_ncc).
bool TimeByTemplate(const Neighbourhood& nb, long anchor, bool is_template, const Template& t,
                    const Geometry& g, double rate_hz, const TimingOptions& o, MemberTime* out,
                    TimingDetail* d) {
  // Expected template start: where the template sits relative to its own detection time, moved
  // to this member's detection time (the detection's convention for the onset need not be the
  // template's AIC pick: their difference is the same for every member).
  const long s0 = t.start + (anchor - t.anchor);
  const LagChoice lc = BestLag(nb, t.h, t.hh, s0, g.near);
  d->ncc = lc.ncc;
  if (!is_template && lc.ncc < o.min_template_ncc) return false;
  // Sub-sample lag: band-limited interpolation of the NCC around the integer peak.
  std::vector<double> c(static_cast<std::size_t>(2 * kSincHalf + 1));
  for (long q = -kSincHalf; q <= kSincHalf; ++q)
    c[static_cast<std::size_t>(q + kSincHalf)] = NccAt(nb, t.h, t.hh, lc.lag + q);
  double peak = lc.ncc;
  const double frac = InterpolatedPeak(c, static_cast<std::size_t>(kSincHalf), &peak) -
                      static_cast<double>(kSincHalf);
  d->ncc = std::clamp(std::max(peak, lc.ncc), -1.0, 1.0);
  d->by_template = true;
  out->onset = is_template ? t.t_ref : t.t_ref + (static_cast<double>(lc.lag - t.start) + frac);
  // Ambiguity: noise moves each lag's NCC by s_c = spread(<n, h>) / (|h| |y|) (measured on the
  // noise window before the onset, like the noise term); a rival peak of the search window wins
  // with probability p = P(N(0, 2 s_c^2) > c1 - c2), and then the time is off by the lag
  // difference.
  out->lag = lc.lag;
  {
    double yy = 0.0;
    for (long j = 0; j < g.tl; ++j)
      yy += static_cast<double>(nb.at(lc.lag + j)) * nb.at(lc.lag + j);
    out->yy = yy;
    out->ncc_noise =
        std::max(1e-12, ProjectedNoise(nb, t.h, out->onset, rate_hz, o) / std::sqrt(t.hh * yy));
  }
  if (!is_template && lc.rival_ncc > -2.0) {
    const double p = 0.5 * std::erfc((d->ncc - lc.rival_ncc) / (2.0 * out->ncc_noise));
    d->sigma_ambiguity =
        o.ambiguity_gain * std::sqrt(p) * static_cast<double>(std::labs(lc.rival_lag - lc.lag));
  }
  // Scale of this member relative to the template (its fitted amplitude).
  double xy = 0.0;
  const long l0 = std::lround(out->onset) - g.lead;
  for (long j = 0; j < g.tl; ++j) xy += t.h[static_cast<std::size_t>(j)] * nb.at(l0 + j);
  const double a = xy / t.hh;
  d->level_ratio = a;
  // Noise: the spread of the noise's projection on h' before the onset (not assumed white):
  // the delay estimate moves by <n, h'> / (a |h'|^2).
  d->sigma_noise = o.noise_gain * ProjectedNoise(nb, t.hd, out->onset, rate_hz, o) /
                   std::max(std::fabs(a) * t.dd, 1e-300);
  d->sigma_shape =
      o.shape_s_per_neper * rate_hz * std::fabs(std::log(std::max(std::fabs(a), 1e-6)));
  out->sigma2 = d->sigma_noise * d->sigma_noise + d->sigma_ambiguity * d->sigma_ambiguity +
                d->sigma_shape * d->sigma_shape;
  return true;
}

// A member that does not match the template: timed by its own AIC pick. Its sigma is set by
// the cycle-slip stage (SlipModel) from the spread of the sequence's AIC picks; this provisional
// one, the window's width / sqrt(12) (the pick can land anywhere in it), stays when the sequence
// has too few template-timed members to measure that spread.
MemberTime TimeByAic(double own_aic, long anchor, const Geometry& g, const TimingOptions& o,
                     TimingDetail* d) {
  MemberTime m;
  m.onset = std::isfinite(own_aic) ? own_aic : static_cast<double>(anchor) - 0.5;
  d->sigma_noise = o.aic_sigma_gain * static_cast<double>(g.aic_pre + g.aic_post) / std::sqrt(12.0);
  m.sigma2 = d->sigma_noise * d->sigma_noise;
  return m;
}

// The sequence's agreement between template and AIC timing: r_k = (own AIC pick) - (final time)
// of the template-timed members is a Gaussian N(mu, sigma_aic^2) (the AIC picks' own scatter)
// when the template lag is on the right cycle, and anywhere in the AIC window (uniform, width
// `width`) when one of the two slipped by a ringing period. Fitted by EM (Dempster, Laird &
// Rubin 1977) to the members' r_k; `prior` is the share of slipped members.
struct SlipFit {
  double mu = 0.0, sigma_aic = 0.0, prior = 0.0, width = 1.0;
  bool valid = false;
  // Posterior probability that the member with residual r slipped.
  double Posterior(double r) const {
    const double z = (r - mu) / sigma_aic;
    const double gauss = std::exp(-0.5 * z * z) / (std::sqrt(2.0 * std::numbers::pi) * sigma_aic);
    const double uniform = prior / width;
    return uniform / (uniform + (1.0 - prior) * gauss);
  }
};

SlipFit FitSlips(std::vector<double> r, double width, const TimingOptions& o) {
  SlipFit f;
  f.width = width;
  if (r.size() < kMinSlipMembers) return f;
  const double n = static_cast<double>(r.size());
  f.mu = UpperMedian(r);
  f.sigma_aic = std::max(kMinAicSigma, 1.4826 * MedianAbsoluteDeviation(r, f.mu));
  f.prior = o.slip_prior;
  // The prior share stays within [1/(2n), 1/2]: at least half a member may have slipped (none
  // seen is not proof of none), and the Gaussian is the majority by definition.
  const double lo = 0.5 / n;
  for (int it = 0; it < kSlipEmIterations; ++it) {
    double sp = 0.0, sw = 0.0, swr = 0.0, swrr = 0.0;
    for (double x : r) {
      const double p = f.Posterior(x);
      sp += p;
      sw += 1.0 - p;
      swr += (1.0 - p) * x;
    }
    if (!(sw > 0.0)) break;
    f.mu = swr / sw;
    for (double x : r) swrr += (1.0 - f.Posterior(x)) * (x - f.mu) * (x - f.mu);
    f.sigma_aic = std::max(kMinAicSigma, std::sqrt(swrr / sw));
    f.prior = std::clamp(sp / n, lo, 0.5);
  }
  f.valid = true;
  return f;
}

// Cycle-slip stage. Measured: on the superball recording (pfe_bouncyball, 48 kHz) 8 of 33
// annotated impacts were timed 0.60-0.68 ms early by the template (one ringing period; the
// annotation is +-0.2 ms) and their own AIC picks sat 25-34 samples later than the template's,
// where the annotation is; on the ping-pong recording the template and AIC picks agree within
// the AIC's scatter (sigma_aic ~ 9 samples) for all but the last, noise-level members, and the
// annotations agree with the template within their +-0.2 ms. A rival correlation peak a ringing
// period away (the former ambiguity term) said nothing about this: on ping-pong it was higher
// than the chosen one on half the members, all timed right, and on the synthetic corpus the
// term overstated the error 4-8x (RMS(err/sigma) 0.13-0.28 on the members it touched).
// The AIC alone cannot say which of the two slipped: on the bundled steel recording (exact truth)
// the template is right to 12 us on every impact while the AIC picks of 13 of the 52 members,
// at 21-34 dB SNR, jump 6-70 samples on the ringing of earlier impacts. So a slip also needs the
// template to match about as well where the AIC pick puts the onset (the superball's slipped
// members: NCC 0.64 there against 0.27 at the chosen lag; steel: 0.9 at the chosen lag).
// Template-timed members: variance + q P(slip | r) (r - mu)^2, q the probability that the NCC
// at the AIC's lag beats the chosen one under the NCC noise (as the ambiguity term). AIC-timed
// members: the AIC scatter, the pick's posterior spread and, with the prior share of slips, the
// window's uniform variance.
// The sequence's shape mismatch W: the share of a member's energy (over the template, at its
// chosen lag) that the template does not explain and the noise does not either,
// max(0, 1 - ncc^2 - E_n / |y|^2) with E_n = L noise_rms^2 the local whitened noise's expected
// energy over the L template samples; the median over the template-timed members (not the
// template itself), since the mismatch belongs to the ball and surface, not to one impact.
// Measured: bundled steel recording (synthetic, exact truth) W = 0.02 (NCC 0.99 on the loud
// members); superball W = 0.8, ping-pong W = 0.8 (NCC 0.25-0.45 at 30-40 dB SNR).
double ShapeMismatch(const std::vector<MemberTime>& mts, const std::vector<TimingDetail>& detail,
                     std::size_t tk, long tl) {
  std::vector<double> w;
  for (std::size_t k = 0; k < mts.size(); ++k) {
    const TimingDetail& d = detail[k];
    if (k == tk || !d.by_template || !(mts[k].yy > 0.0)) continue;
    const double noise_share = static_cast<double>(tl) * d.noise_rms * d.noise_rms / mts[k].yy;
    w.push_back(std::max(0.0, 1.0 - d.ncc * d.ncc - noise_share));
  }
  if (w.empty()) return 0.0;
  return UpperMedian(std::move(w));
}

void SlipModel(const std::vector<double>& own_aic, const std::vector<double>& own_spread,
               const std::vector<MemberTime>& mts, const std::vector<Neighbourhood>& nb,
               const Template& tpl, const Geometry& g, const TimingOptions& o, double rate_hz,
               std::size_t tk, std::vector<Impact>* imps, TimingResult* res) {
  const std::size_t n = imps->size();
  std::vector<double> r;
  for (std::size_t k = 0; k < n; ++k)
    if (res->detail[k].by_template && k != tk && std::isfinite(own_aic[k]))
      r.push_back(own_aic[k] - (*imps)[k].time_s * rate_hz);
  const double width = static_cast<double>(g.aic_pre + g.aic_post);
  const SlipFit f = FitSlips(r, width, o);
  if (!f.valid) return;
  res->aic_sigma_samples = f.sigma_aic;
  res->slip_prior = f.prior;
  const double shape_share = ShapeMismatch(mts, res->detail, tk, g.tl);
  res->shape_mismatch = shape_share;
  for (std::size_t k = 0; k < n; ++k) {
    TimingDetail& d = res->detail[k];
    Impact& im = (*imps)[k];
    const double var = im.sigma_s * im.sigma_s * rate_hz * rate_hz;
    if (d.by_template) {
      if (k == tk || !std::isfinite(own_aic[k])) continue;
      const double dr = own_aic[k] - im.time_s * rate_hz - f.mu;
      d.aic_residual = dr;
      // The template must match about as well where the AIC pick puts the onset (best NCC
      // within the AIC scatter of it): the NCC noise s_c decides, as for the ambiguity term.
      const long at = mts[k].lag + std::lround(dr);
      const long w = std::max(2L, std::lround(f.sigma_aic));
      double c_alt = -2.0;
      for (long l = at - w; l <= at + w; ++l)
        c_alt = std::max(c_alt, NccAt(nb[k], tpl.h, tpl.hh, l));
      // The NCC at each lag moves by the noise (s_c) and by the shape residual, an energy
      // W |y|^2 that projects on the template as the local noise's energy E_n does (s_c):
      // s_shape = s_c sqrt(W |y|^2 / E_n), added in quadrature.
      const double e_noise = static_cast<double>(g.tl) * d.noise_rms * d.noise_rms;
      const double s_shape =
          e_noise > 0.0 ? mts[k].ncc_noise * std::sqrt(shape_share * mts[k].yy / e_noise) : 0.0;
      const double s_ncc = std::hypot(mts[k].ncc_noise, s_shape);
      const double q = 0.5 * std::erfc((d.ncc - c_alt) / (2.0 * s_ncc));
      d.ncc_at_aic = c_alt;
      d.slip_q = q;
      d.slip_posterior = f.Posterior(dr + f.mu);
      d.sigma_slip = o.slip_gain * std::sqrt(q * d.slip_posterior) * std::fabs(dr);
      im.sigma_s = std::sqrt(var + d.sigma_slip * d.sigma_slip) / rate_hz;
    } else {
      d.sigma_noise = std::hypot(f.sigma_aic, own_spread[k]);
      d.sigma_slip = std::sqrt(f.prior * width * width / 12.0);
      im.sigma_s = std::sqrt(d.sigma_noise * d.sigma_noise + d.sigma_slip * d.sigma_slip +
                             d.sigma_resolution * d.sigma_resolution) /
                   rate_hz;
    }
  }
}

}  // namespace

TimingResult TimeSequence(const std::vector<float>& x, double rate_hz, Sequence* seq,
                          const TimingOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (!(rate_hz > 0.0) || !std::isfinite(rate_hz))
    throw Error(ErrorCode::kBadParameter,
                "TimeSequence: sample rate " + std::to_string(rate_hz) + " Hz must be > 0");
  TimingResult res;
  std::vector<Impact>& imps = seq->impacts;
  const std::size_t n = imps.size();
  if (n == 0 || x.empty()) return res;
  const Geometry g(o, rate_hz);

  // 1. Predictor from the members' neighbourhoods.
  std::vector<long> anchors(n);
  for (std::size_t k = 0; k < n; ++k) anchors[k] = std::lround(imps[k].time_s * rate_hz);
  res.predictor =
      NeighbourhoodPredictor(x, anchors, o.lpc_order, std::lround(o.fit_before_s * rate_hz),
                             std::lround(o.fit_after_s * rate_hz));
  // 2. Local whitening around each member.
  // Stages 2, 3 and 5-6 treat each member on its own (every member writes its own slots), so
  // the members are shared among TimingOptions::threads.
  const int threads = ResolveThreads(o.threads);
  auto each = [&](std::size_t count, const std::function<void(std::size_t)>& task) {
    ParallelFor(threads, count, task);
  };
  std::vector<Neighbourhood> nb(n);
  each(n, [&](std::size_t k) {
    nb[k].begin = anchors[k] - g.before;
    nb[k].w = WhitenSegment(x, res.predictor, anchors[k] - g.before, anchors[k] + g.after);
  });
  // 3-4. Template: the earliest member whose local SNR at its detected time is within
  // kTemplateSnrToleranceDb of the best. Not the best itself: members' SNRs lie within
  // a fraction of a dB of each other and move with the predictor, hence with which weak members the
  // sequence has (a different template moved every time of a rubber ball by 55 us); the earliest
  // within the tolerance stays the same member unless the SNRs move by that much.
  std::vector<double> snr(n);
  each(n, [&](std::size_t k) {
    snr[k] = Measure(nb[k], x, static_cast<double>(anchors[k]) - 0.5, rate_hz, o).snr_db;
  });
  double best_snr = -1e300;
  for (std::size_t k = 0; k < n; ++k) best_snr = std::max(best_snr, snr[k]);
  std::size_t tk = 0;
  while (tk + 1 < n && !(snr[tk] >= best_snr - kTemplateSnrToleranceDb)) ++tk;
  res.template_member = static_cast<int>(tk);
  const Template tpl = MakeTemplate(nb, anchors, tk, g);
  // 5-6. Each member: template lag (or AIC), then the sigma model and the local measures.
  res.detail.resize(n);
  const double resolution = std::hypot(o.resolution_samples, o.resolution_s * rate_hz);
  std::vector<double> own_aic(n, NAN), own_spread(n, 0.0);
  std::vector<MemberTime> mts(n);
  each(n, [&](std::size_t k) {
    TimingDetail& d = res.detail[k];
    const AicPick own = AicAround(nb[k], anchors[k], g);
    if (own.valid) {
      own_aic[k] = own.index + static_cast<double>(nb[k].begin);
      own_spread[k] = own.spread;
    }
    MemberTime mt;
    if (!tpl.usable() || !TimeByTemplate(nb[k], anchors[k], k == tk, tpl, g, rate_hz, o, &mt, &d))
      mt = TimeByAic(own_aic[k], anchors[k], g, o, &d);
    mts[k] = mt;
    d.sigma_resolution = resolution;
    const LocalMeasures m = Measure(nb[k], x, mt.onset, rate_hz, o);
    d.noise_rms = m.noise_rms;
    Impact& im = imps[k];
    im.time_s = mt.onset / rate_hz;
    im.sigma_s = std::sqrt(mt.sigma2 + resolution * resolution) / rate_hz;
    im.snr_db = m.snr_db;
    im.amplitude = m.amplitude;
    im.score = std::clamp(d.ncc, 0.0, 1.0);
  });
  // Anchor: the template's own AIC pick fixes the sequence's constant offset, but which member
  // is the template can change with the audio around the sequence (SNRs within a fraction of a
  // dB). The median over the members of (own AIC pick - template time) does not: shift every
  // time by it, so the offset is a property of the whole sequence.
  // Only the loudest template-timed members take part (kAnchorMembers of them): the weak tail,
  // which comes and goes with the audio around the sequence, does not move it, and the choice
  // does not depend on the template (ranking by NCC with it did: a template that changed with
  // the start of the file changed the members, and the offset moved by 3-4 samples).
  std::vector<std::pair<double, std::size_t>> by_level;
  for (std::size_t k = 0; k < n; ++k)
    if (res.detail[k].by_template) by_level.push_back({-imps[k].amplitude, k});
  std::sort(by_level.begin(), by_level.end());
  if (by_level.size() > kAnchorMembers) by_level.resize(kAnchorMembers);
  // Their AIC picks are made in a whitening fitted on their own neighbourhoods: the sequence's
  // predictor also fits the weak members' (noise-dominated) neighbourhoods, and with them the
  // picks, hence the offset, moved by 2-3 samples when a few weak members came or went.
  std::vector<long> loud_anchors;
  for (const auto& [neg_level, k] : by_level) loud_anchors.push_back(anchors[k]);
  const std::vector<double> loud_predictor =
      NeighbourhoodPredictor(x, loud_anchors, o.lpc_order, std::lround(o.fit_before_s * rate_hz),
                             std::lround(o.fit_after_s * rate_hz));
  std::vector<std::optional<double>> loud_shift(by_level.size());
  each(by_level.size(), [&](std::size_t i) {
    const std::size_t k = by_level[i].second;
    Neighbourhood loud;
    loud.begin = nb[k].begin;
    loud.w = WhitenSegment(x, loud_predictor, nb[k].begin,
                           nb[k].begin + static_cast<long>(nb[k].w.size()));
    const AicPick p = AicAround(loud, std::lround(imps[k].time_s * rate_hz), g);
    if (p.valid)
      loud_shift[i] = p.index + static_cast<double>(loud.begin) - imps[k].time_s * rate_hz;
  });
  std::vector<double> shifts;
  for (const std::optional<double>& s : loud_shift)
    if (s) shifts.push_back(*s);
  if (!shifts.empty()) {
    // Trimmed mean (the middle half): on a soft ball the picks spread over ~20 samples with
    // gaps, and the median jumped by 5 samples when one pick moved; the mean of the middle half
    // moves by a fraction of that, and still ignores a few wild picks.
    std::sort(shifts.begin(), shifts.end());
    const std::size_t trim = shifts.size() / 4;
    double sum = 0.0;
    for (std::size_t i = trim; i < shifts.size() - trim; ++i) sum += shifts[i];
    const double shift = sum / static_cast<double>(shifts.size() - 2 * trim);
    for (std::size_t k = 0; k < n; ++k)
      if (res.detail[k].by_template) imps[k].time_s += shift / rate_hz;
  }
  SlipModel(own_aic, own_spread, mts, nb, tpl, g, o, rate_hz, tk, &imps, &res);
  // The template's lag to itself is exact, but its shape differs from the others' as theirs
  // differs from it (the median of the others' sigma without ambiguity: the template's own lag is
  // never ambiguous), and the sequence's offset rests on the others' lags, whose median is
  // uncertain by about 1.25 sigma / sqrt(n) (the median's standard error).
  std::vector<double> shape, full;
  for (std::size_t k = 0; k < n; ++k) {
    const TimingDetail& d = res.detail[k];
    if (k == tk || !d.by_template) continue;
    // Without the slip term: the template's own lag cannot slip.
    shape.push_back(std::sqrt(d.sigma_noise * d.sigma_noise + d.sigma_shape * d.sigma_shape +
                              d.sigma_resolution * d.sigma_resolution) /
                    rate_hz);
    full.push_back(imps[k].sigma_s);
  }
  if (!shape.empty()) {
    const double m_full = 1.25 * UpperMedian(full) / std::sqrt(static_cast<double>(full.size()));
    imps[tk].sigma_s = std::max(imps[tk].sigma_s, std::hypot(UpperMedian(shape), m_full));
  }
  return res;
}

}  // namespace bouncecal
