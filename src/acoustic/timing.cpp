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
#include "timing_parts.hpp"

namespace bouncecal {

using namespace timing_parts;

namespace {

using timing_parts::kSincHalf;
// The fine grid (steps per sample) on which the interpolated correlation peak is searched before
// a parabolic refinement.
constexpr int kPeakGrid = 32;
// Members (best template matches) whose own AIC picks set the sequence's constant offset.
constexpr std::size_t kAnchorMembers = 9;
// Stride (samples) of the template positions over the noise window (ProjectedNoise).
constexpr long kNoiseStride = 4;
// Template choice: the earliest member whose local SNR is within this of the best. Measured: a
// rubber ball's two loudest members 0.5 dB apart swapped with the weak tail's membership (every
// time moved by 55 us); 3 dB took a clipped phone recording's first impacts as the template and
// overstated every sigma there by 45 % (RMS(err/sigma) 0.69).
constexpr double kTemplateSnrToleranceDb = 1.0;

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

// The noise window before an onset: samples [lo, hi) (noise_window_s, ending noise_guard_s
// before the onset), where the template's window starts there (`at`, lead_s before the onset),
// and the decay of the whitened noise's log power over the window, per sample (`slope`, <= 0).
//
// The noise before an onset is often the ringing of the impacts before it, which decays
// exponentially (a damped mode, the room's reverberation), so its level under the template is
// below the window's (whose middle is ~11 ms earlier). Measured on real impact sounds re-placed at
// exact times (tools/bench_sigma, one cut, 8 seeds): with the window's level, interval pull RMS
// 0.77-0.79 on ping-pong (the noise term dominant on 85 % of the members; the same with the room
// noise 10 dB louder or quieter: the "noise" there is the earlier impacts' ringing), 0.73-1.01 on
// the basketball, 0.71-0.74 on the superball; carried along the decay: 0.92-0.96, 0.95-1.23,
// 0.75-0.79. The decay is the Theil-Sen slope (the median of the pairwise slopes, Sen 1968) of
// the log of the robust power of blocks of the template's length (robust to a block holding an
// earlier impact's attack); 0 with fewer than kMinTrendBlocks blocks. A rise toward the onset is
// not carried: it is the impact's own lead-in (its leading edge within the guard; in the re-placed
// real sounds, the cut's copy of its recording's noise, which the template holds too: the loud
// members' rise shrank from x1.10-1.27 to x1.03-1.11 with the room noise 10 dB louder), not
// noise; carried, it took the rubber ball's pull RMS from 0.70-1.02 to 0.67-0.97. The price: in
// stationary noise the slope's own scatter (x0.86-1.14, p10-p90, on the synth presets) is carried
// on its falling half only, sigma_noise there ~4 % short.
struct NoiseWindow {
  long lo = 0, hi = 0;
  double at = 0.0, slope = 0.0;
  // Amplitude factor carrying noise at sample n to sample n + (at - n) along the trend.
  double Carry(double n) const { return std::exp(0.5 * slope * (at - n)); }
};

// Four blocks: three pairwise slopes' worth of agreement at least (a 20-ms window at 16 kHz and a
// 1.5-ms template holds 13).
constexpr std::size_t kMinTrendBlocks = 4;

NoiseWindow NoiseWindowBefore(const Neighbourhood& nb, double onset, double rate_hz,
                              const TimingOptions& o, long block) {
  NoiseWindow nw;
  const long i0 = static_cast<long>(std::floor(onset)) + 1;  // first sample of the new regime
  const long guard = std::max(2L, std::lround(o.noise_guard_s * rate_hz));
  const long noise_len = std::max(16L, std::lround(o.noise_window_s * rate_hz));
  nw.hi = std::max(nb.begin, i0 - guard);
  nw.lo = std::max(nb.begin, nw.hi - noise_len);
  nw.at = static_cast<double>(i0 - std::max(1L, std::lround(o.lead_s * rate_hz)));
  std::vector<double> t, lp, sq;
  for (long b = nw.lo; b + block <= std::min(nw.hi, nb.end()); b += block) {
    sq.clear();
    for (long i = b; i < b + block; ++i) sq.push_back(std::fabs(static_cast<double>(nb.at(i))));
    const double median_abs = UpperMedian(sq);
    if (!(median_abs > 0.0)) continue;
    t.push_back(static_cast<double>(b) + 0.5 * static_cast<double>(block));
    lp.push_back(2.0 * std::log(median_abs));  // the robust power's log, up to a constant
  }
  if (t.size() < kMinTrendBlocks) return nw;
  std::vector<double> slopes;
  for (std::size_t i = 0; i < t.size(); ++i)
    for (std::size_t j = i + 1; j < t.size(); ++j)
      slopes.push_back((lp[j] - lp[i]) / (t[j] - t[i]));
  nw.slope = std::min(0.0, Median(std::move(slopes)));
  return nw;
}

// Robust rms (1.4826 median |.|) of the noise window's samples, each carried to the middle of
// the template's window (L / 2 after `at`) along the decay: the local noise level under the
// template (the cycle-slip gate's E_n, which must be the same noise as its s_c).
double NoiseRmsAtTemplate(const Neighbourhood& nb, const NoiseWindow& nw, long L) {
  std::vector<double> v;
  for (long i = nw.lo; i < nw.hi; ++i)
    v.push_back(std::fabs(static_cast<double>(nb.at(i))) *
                nw.Carry(static_cast<double>(i) - 0.5 * static_cast<double>(L)));
  return v.empty() ? 0.0 : 1.4826 * UpperMedian(std::move(v));
}

// Robust spread (1.4826 median |.|) of <w[l, l + L), g> over the template starts l of the noise
// window, each carried to the template's own start along the noise's level trend (NoiseWindow):
// the noise term of timing.hpp. 0 when the window is too short.
double ProjectedNoise(const Neighbourhood& nb, const std::vector<double>& g,
                      const NoiseWindow& nw) {
  const long L = static_cast<long>(g.size());
  const long hi = nw.hi - L;
  const long lo = nw.lo;
  auto carry = [&](long l) { return nw.Carry(static_cast<double>(l)); };
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
      for (int t = 0; t < 4; ++t) p.push_back(std::fabs(d[t]) * carry(l + t * kNoiseStride));
      l = l3;
      continue;
    }
    if (l >= nb.begin && l + L <= nb.end()) {
      acc = Dot(g.data(), nb.w.data() + (l - nb.begin), static_cast<std::size_t>(L));
    } else {
      for (long j = 0; j < L; ++j) acc += g[static_cast<std::size_t>(j)] * nb.at(l + j);
    }
    p.push_back(std::fabs(acc) * carry(l));
  }
  if (p.size() < 8) return 0.0;
  const auto mid = p.begin() + static_cast<std::ptrdiff_t>(p.size() / 2);
  std::nth_element(p.begin(), mid, p.end());
  return 1.4826 * *mid;
}

struct LagChoice {
  long lag = 0;
  double ncc = -2.0;
  // The rival peaks: every local maximum of the window outside the chosen peak's main lobe
  // (lag, NCC).
  std::vector<std::pair<long, double>> rivals;
};

// Integer template start: the best NCC within +- near of the expected start s0 (the detection's
// time; a better match farther out is ringing or an echo as often as the impact: on the ping-pong
// recording such picks were 0.7-1.4 ms early), and the rival peaks of that window outside the
// chosen peak's main lobe (those the rule could have chosen instead). Whether the chosen peak is
// on the right ringing cycle is checked afterwards against the member's own AIC pick.
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
    if ((l < a || l > b) && (l == lo || at(l - 1) < at(l)) && (l == hi || at(l + 1) <= at(l)))
      best.rivals.push_back({l, at(l)});
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
                                {"mismatch_gain", mismatch_gain},
                                {"shape_s_per_neper", shape_s_per_neper},
                                {"ambiguity_gain", ambiguity_gain},
                                {"slip_gain", slip_gain},
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

namespace timing_parts {

double NccAt(const Neighbourhood& nb, const std::vector<double>& h, double hh, long l) {
  double xy = 0.0, yy = 0.0;
  for (std::size_t j = 0; j < h.size(); ++j) {
    const double y = nb.at(l + static_cast<long>(j));
    xy += h[j] * y;
    yy += y * y;
  }
  return yy > 0.0 && hh > 0.0 ? xy / std::sqrt(hh * yy) : 0.0;
}

double XcAt(const Neighbourhood& nb, const std::vector<double>& h, long l) {
  double xy = 0.0;
  for (std::size_t j = 0; j < h.size(); ++j) xy += h[j] * nb.at(l + static_cast<long>(j));
  return xy;
}

AicPick AicAround(const Neighbourhood& nb, long anchor, const Geometry& g) {
  const long b = std::max(nb.begin, anchor - g.aic_pre);
  return PickAic(nb.w, static_cast<std::size_t>(b - nb.begin),
                 static_cast<std::size_t>(anchor + g.aic_post - nb.begin));
}

double CorrelationPeak(const Neighbourhood& nb, const std::vector<double>& h, long at,
                       double* peak) {
  std::vector<double> c(static_cast<std::size_t>(2 * kSincHalf + 1));
  for (long q = -kSincHalf; q <= kSincHalf; ++q)
    c[static_cast<std::size_t>(q + kSincHalf)] = XcAt(nb, h, at + q);
  return static_cast<double>(at - kSincHalf) +
         InterpolatedPeak(c, static_cast<std::size_t>(kSincHalf), peak);
}

}  // namespace timing_parts

namespace {

// The band-limited derivative of the whitened signal at sample n: sum over k != 0 of
// x[n - k] (-1)^k / k (the derivative of the sinc interpolant at the samples), Hann-windowed over
// |k| < kSincHalf. Central differences (response sin(w) instead of w) understate a whitened
// click's derivative, whose energy reaches Nyquist, and with it overstated the noise term.
double Derivative(const Neighbourhood& nb, long n) {
  double acc = 0.0;
  for (long k = 1; k < kSincHalf; ++k) {
    const double w = 0.5 + 0.5 * std::cos(std::numbers::pi * static_cast<double>(k) /
                                          static_cast<double>(kSincHalf));
    const double sign = k % 2 == 0 ? 1.0 : -1.0;
    acc += sign * w / static_cast<double>(k) * (nb.at(n - k) - nb.at(n + k));
  }
  return acc;
}

// The band-limited second derivative at sample n: -x[n] pi^2 / 3 + sum over k != 0 of
// x[n - k] 2 (-1)^(k + 1) / k^2, Hann-windowed over |k| < kSincHalf.
double SecondDerivative(const Neighbourhood& nb, long n) {
  double acc = -nb.at(n) * std::numbers::pi * std::numbers::pi / 3.0;
  for (long k = 1; k < kSincHalf; ++k) {
    const double w = 0.5 + 0.5 * std::cos(std::numbers::pi * static_cast<double>(k) /
                                          static_cast<double>(kSincHalf));
    const double sign = k % 2 == 0 ? -1.0 : 1.0;
    acc += sign * 2.0 * w / static_cast<double>(k * k) * (nb.at(n - k) + nb.at(n + k));
  }
  return acc;
}

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
  t.hdd.resize(t.h.size());
  for (long j = 0; j < g.tl; ++j) {
    const std::size_t i = static_cast<std::size_t>(j);
    t.h[i] = tn.at(t.start + j);
    t.hd[i] = Derivative(tn, t.start + j);
    t.hdd[i] = SecondDerivative(tn, t.start + j);
    t.hh += t.h[i] * t.h[i];
    t.dd += t.hd[i] * t.hd[i];
  }
  return t;
}

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
  // Sub-sample lag: the peak of the cross-correlation, band-limited interpolation.
  double xy_peak = 0.0;
  const double lag = CorrelationPeak(nb, t.h, lc.lag, &xy_peak);
  d->by_template = true;
  out->onset = t.t_ref + (lag - static_cast<double>(t.start));
  const NoiseWindow noise = NoiseWindowBefore(nb, out->onset, rate_hz, o, g.tl);
  out->noise_rms_at_template = NoiseRmsAtTemplate(nb, noise, g.tl);
  // Ambiguity: noise moves each lag's NCC by s_c = spread(<n, h>) / (|h| |y|) (measured on the
  // noise window before the onset and carried to the template along its decay, like the noise
  // term); each rival peak j of the search window
  // beats the chosen one with probability p_j = P(N(0, 2 s_c^2 (1 - rho_j)) > c1 - c_j), and then
  // the time is off by its lag difference dl_j. rho_j = <h, h shifted by dl_j> / |h|^2: the noise
  // projected on the template at two lags is correlated as the template is with itself (the
  // whitened noise is white), and a rival peak exists because that correlation is high; taken as
  // independent (rho = 0), the rivals of synth phone-16k's quiet members (3-6 dB) counted 1 sample
  // (65 us) of sigma on 5-13 us errors (interval pull RMS 0.38). As a mixture over the chosen peak
  // and the rivals, weights normalised (1 and the p_j: several rivals cannot all win): sum p_j
  // dl_j^2 / (1 + sum p_j). (The best rival alone understated the soft rubber ball's members at the
  // noise floor, whose correlation has several sidelobes within the NCC noise: interval pull
  // RMS 1.42 over 43 intervals of 8 seeds; every rival, unnormalised, overstated them: 0.48;
  // normalised: 0.71.)
  out->lag = lc.lag;
  {
    double yy = 0.0;
    for (long j = 0; j < g.tl; ++j)
      yy += static_cast<double>(nb.at(lc.lag + j)) * nb.at(lc.lag + j);
    out->yy = yy;
    if (yy > 0.0) d->ncc = std::clamp(std::max(lc.ncc, xy_peak / std::sqrt(t.hh * yy)), -1.0, 1.0);
    out->ncc_noise = std::max(1e-12, ProjectedNoise(nb, t.h, noise) / std::sqrt(t.hh * yy));
  }
  if (!is_template) {
    double var = 0.0, odds = 1.0;  // the chosen peak's weight 1, each rival's p_j
    for (const auto& [rival_lag, rival_ncc] : lc.rivals) {
      const long shift = std::labs(rival_lag - lc.lag);
      double hh_shift = 0.0;
      for (long j = 0; j + shift < g.tl; ++j)
        hh_shift += t.h[static_cast<std::size_t>(j)] * t.h[static_cast<std::size_t>(j + shift)];
      // 1 - rho, floored at 1e-3: a rival that is a copy of the chosen peak (rho -> 1) would
      // otherwise win or lose by an infinitely sharp rule.
      const double decorrelated = std::max(1e-3, 1.0 - hh_shift / t.hh);
      const double p =
          0.5 * std::erfc((d->ncc - rival_ncc) / (2.0 * out->ncc_noise * std::sqrt(decorrelated)));
      const double dl = static_cast<double>(rival_lag - lc.lag);
      var += p * dl * dl;
      odds += p;
    }
    d->sigma_ambiguity = o.ambiguity_gain * std::sqrt(var / odds);
  }
  // Scale of this member relative to the template: the least-squares amplitude <h, y> / |h|^2
  // at the interpolated peak. (Taken at the integer start nearest to the onset, it was off by a
  // sample for half the members, and a whitened click's correlation falls steeply within a
  // sample: ratios of 0.3 for members placed at 0.93 of the template.)
  const double a = is_template ? 1.0 : xy_peak / t.hh;
  d->level_ratio = a;
  // Noise: the lag moves by C'/(-C'') of the correlation C at the true lag: C' = <n, h'> (the
  // spread of the noise's projection on h', measured on the noise before the onset, not assumed
  // white, and carried to the template along the noise's decay: NoiseWindow), -C'' = a |h'|^2 - <n,
  // h''>. To second order in the curvature's relative noise s = spread(<n, h''>) / (a |h'|^2): var
  // = (spread(<n, h'>) / (a |h'|^2))^2 (1 + 3 s^2). The first factor is the Cramer-Rao bound in
  // white noise (Kay 1993, eq. 3.36); the second is what a noisy peak curvature adds at low SNR (s
  // reaches 0.3-0.8 on the quietest members).
  const double scale = std::max(std::fabs(a) * t.dd, 1e-300);
  d->curvature_noise = ProjectedNoise(nb, t.hdd, noise) / scale;
  d->sigma_noise = o.noise_gain * ProjectedNoise(nb, t.hd, noise) / scale *
                   std::sqrt(1.0 + 3.0 * d->curvature_noise * d->curvature_noise);
  // The level-dependent shape drift: reported, not in sigma (timing.hpp).
  d->shape_drift = -o.shape_s_per_neper * rate_hz * std::log(std::max(std::fabs(a), 1e-6));
  out->sigma2 = d->sigma_noise * d->sigma_noise + d->sigma_ambiguity * d->sigma_ambiguity;
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
  const SelfMatch self = tpl.usable() ? MeasureSelfMatch(nb[tk], tpl) : SelfMatch{};
  const double resolution = self.floor_samples;
  res.resolution_samples = resolution;
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
    if (d.by_template && mt.yy > 0.0) {
      d.noise_share = static_cast<double>(g.tl) * m.noise_rms * m.noise_rms / mt.yy;
      d.residual_share = std::max(0.0, 1.0 - d.ncc * d.ncc - d.noise_share - self.residual_share);
      d.sigma_mismatch = o.mismatch_gain * std::sqrt(d.residual_share * mt.yy / tpl.dd) /
                         std::max(std::fabs(d.level_ratio), 1e-6);
    }
    Impact& im = imps[k];
    im.time_s = mt.onset / rate_hz;
    im.sigma_s =
        std::sqrt(mt.sigma2 + d.sigma_mismatch * d.sigma_mismatch + resolution * resolution) /
        rate_hz;
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
  TemplateMemberMismatch(tk, rate_hz, &res, &imps);
  return res;
}

}  // namespace bouncecal
