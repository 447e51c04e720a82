// Onset detection: whitening, relative spectral flux on a short-hop STFT, adaptive threshold, peak
// picking, AIC sub-sample refinement. See include/bouncecal/acoustic/onsets.hpp.
#include "bouncecal/acoustic/onsets.hpp"

#include <fftw3.h>

#include <algorithm>
#include <atomic>
#include <cassert>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <memory>
#include <mutex>
#include <new>
#include <numbers>
#include <sstream>

#include "../core/huge_pages.hpp"
#include "avx2_clones.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/parallel.hpp"
#include "power_spectra.hpp"

namespace bouncecal {
namespace {

// Median of v (copied), robust and O(n).
double Median(std::vector<double> v) {
  if (v.empty()) return 0.0;
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

// The median (the (m / 2)-th smallest, 0-based, as std::nth_element selects it) of the m values
// of v[0, n) that are >= 0; 0 if there are none. Doubles >= 0 order as their bit patterns do (as
// unsigned integers; -0 is taken as +0), so a histogram of their top 64 - kMedianKeyShift bits,
// counted in parts on the threads, finds the bucket that holds the rank in one pass, and only
// that bucket's values are selected from. The novelty's ~180 000 denominators of a 1-minute
// recording, two threads: 0.87 ms (median of 25 runs) against 1.15 ms for copying them and
// std::nth_element (1/4 octave per bucket: 1.56 ms, the bucket's selection dominating). The
// counts are integers: how the values are split among the threads does not change them.
constexpr int kMedianKeyShift = 48;  // 16 top bits: 1/16 octave per bucket
constexpr std::size_t kMedianBuckets = std::size_t{1} << (64 - kMedianKeyShift);
double MedianOfNonNegative(const double* v, std::size_t n, int threads, WorkerPool* pool) {
  auto key = [](double x) {
    const double y = x + 0.0;  // -0 -> +0
    std::uint64_t k;
    std::memcpy(&k, &y, sizeof k);
    return k;
  };
  const std::size_t parts = std::clamp<std::size_t>(n / 16384, 1, std::max(1, threads));
  const std::size_t part = (n + parts - 1) / parts;
  std::vector<std::vector<std::uint32_t>> counts(parts);
  ParallelFor(
      threads, parts,
      [&](std::size_t p) {
        std::vector<std::uint32_t>& c = counts[p];
        c.assign(kMedianBuckets, 0);
        for (std::size_t i = p * part; i < std::min(n, (p + 1) * part); ++i)
          if (v[i] >= 0.0) ++c[key(v[i]) >> kMedianKeyShift];
      },
      pool);
  std::vector<std::uint64_t> total(kMedianBuckets, 0);
  std::uint64_t m = 0;
  for (const std::vector<std::uint32_t>& c : counts)
    for (std::size_t b = 0; b < kMedianBuckets; ++b) total[b] += c[b];
  for (std::uint64_t t : total) m += t;
  if (m == 0) return 0.0;
  std::uint64_t rank = m / 2;
  std::size_t bucket = 0;
  while (rank >= total[bucket]) rank -= total[bucket++];
  std::vector<double> in_bucket;
  in_bucket.reserve(total[bucket]);
  for (std::size_t i = 0; i < n; ++i)
    if (v[i] >= 0.0 && key(v[i]) >> kMedianKeyShift == bucket) in_bucket.push_back(v[i] + 0.0);
  const auto mid = in_bucket.begin() + static_cast<std::ptrdiff_t>(rank);
  std::nth_element(in_bucket.begin(), mid, in_bucket.end());
  return *mid;
}

// Robust rms of x from the median absolute value (Gaussian: rms = median|x| / 0.6745),
// on at most ~16k samples spread over x.
double RobustRms(const std::vector<float>& x) {
  if (x.empty()) return 0.0;
  const std::size_t step = std::max<std::size_t>(1, x.size() / 16384);
  std::vector<double> a;
  a.reserve(x.size() / step + 1);
  for (std::size_t i = 0; i < x.size(); i += step) a.push_back(std::fabs(x[i]));
  return Median(std::move(a)) / 0.6745;
}

// FFTW's planner (plan creation and destruction) is not thread-safe; execution of distinct
// plans is. This module-local mutex serialises the planner calls of all OnsetDetectors.
std::mutex& PlannerMutex() {
  static std::mutex m;
  return m;
}

// An array that is written in full before it is read: unlike std::vector it is not zero-filled
// first (the fill of two such float arrays per block and signal, 23 MB each for 2 minutes at
// 48 kHz, was 8 % of detection time).
template <typename T>
struct Buffer {
  std::unique_ptr<T[]> data;
  std::size_t n = 0;
  void Allocate(std::size_t size) {
    data.reset(new T[size]);
    AdviseHugePages(data.get(), size * sizeof(T));
    n = size;
  }
  std::size_t size() const { return n; }
  T operator[](std::size_t i) const { return data[i]; }
  T& operator[](std::size_t i) { return data[i]; }
};
using FloatBuffer = Buffer<float>;

// Blocks of the whitening's autocorrelation and filter per task on a thread (64 x 4096 samples:
// ~90 tasks per 2-minute block at 48 kHz, each long enough to outweigh its scheduling).
constexpr std::size_t kWhitenGroup = 64;

// Input and output arrays of one real FFT of `n` points, allocated like the ones its plan was made
// with (fftw_malloc: the same alignment), so that one plan serves any number of threads at once
// (fftw_execute_dft_r2c/c2r on new arrays is thread-safe).
struct FftArrays {
  double* real = nullptr;
  fftw_complex* spec = nullptr;
  explicit FftArrays(std::size_t n) {
    real = static_cast<double*>(fftw_malloc(sizeof(double) * n));
    spec = static_cast<fftw_complex*>(fftw_malloc(sizeof(fftw_complex) * (n / 2 + 1)));
    if (!real || !spec) {
      fftw_free(real);
      fftw_free(spec);
      throw std::bad_alloc();
    }
  }
  ~FftArrays() {
    fftw_free(real);
    fftw_free(spec);
  }
  FftArrays(const FftArrays&) = delete;
  FftArrays& operator=(const FftArrays&) = delete;
};

// The novelty's frames are computed a chunk at a time (each chunk its own power spectra: memory
// for one chunk per thread, whatever the length): kSpectraChunk frames, fewer where the power
// rows of that many would pass kSpectraChunkBytes (long hops, --hop-ms: 16 MB per thread at
// 5 ms), at least kMinSpectraChunk.
constexpr std::size_t kSpectraChunk = 4096;
constexpr std::size_t kSpectraChunkBytes = std::size_t{2} << 20;
constexpr std::size_t kMinSpectraChunk = 256;
// Overlap-save blocks of the template correlation per task.
constexpr std::size_t kCorrelatePart = 8;
// Running-energy restarts (samples) of the template energy, and how many per task (a multiple
// of 4: RunningEnergy4).
constexpr std::size_t kEnergyRestart = 8192;
constexpr std::size_t kEnergyPart = 4;
// Flux peaks refined (AIC picks) per task.
constexpr std::size_t kRefinePart = 16;
// Threshold blocks (their medians) per task.
constexpr std::size_t kThresholdPart = 64;

// Frames averaged into the novelty's reference spectrum (~3 ms at the default hop).
constexpr std::size_t kRefFrames = 8;

// The template, and its normalised cross-correlation with the whitened signal, computed a chunk
// at a time: the correlation xc[i] = sum_j h[j] w[i + j] and the energy under the template
// ww[i] = sum of w^2 over [i, min(n, i + tl)) of every template start i. Both were whole-block
// float arrays (46 MB for a 2-minute block at 48 kHz, 40 % of the detection's memory, all of it
// first touched per block); a chunk holds kNccChunk starts, and each value is computed the same
// way wherever the chunk starts (xc from the overlap-save block of the whole signal that holds
// it, ww from its kEnergyRestart stretch), so the values are the same to the bit. 65536 starts
// per chunk: the kept chunks take 2 MB; with 262144 they took 8 MB and a 1-minute detection's
// peak memory was 50 against 45 MB, in the same time (31 alternating runs, two threads: 68.4
// against 68.2 ms median).
constexpr std::size_t kNccChunk = 8 * kEnergyRestart;
constexpr std::size_t kNccChunksKept = 4;

// Frames per novelty chunk for power rows of `bins` values (a multiple of the frame batch).
std::size_t SpectraChunkFrames(std::size_t bins) {
  const std::size_t fit = kSpectraChunkBytes / (bins * sizeof(double)) / 8 * 8;
  return std::clamp(fit, kMinSpectraChunk, kSpectraChunk);
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

std::vector<double> LevinsonDurbin(const std::vector<double>& r, int order) {
  assert(static_cast<int>(r.size()) > order && r[0] > 0.0);
  std::vector<double> a(static_cast<std::size_t>(order) + 1, 0.0), prev;
  a[0] = 1.0;
  double err = r[0];
  for (int i = 1; i <= order; ++i) {
    double acc = r[static_cast<std::size_t>(i)];
    for (int j = 1; j < i; ++j)
      acc += a[static_cast<std::size_t>(j)] * r[static_cast<std::size_t>(i - j)];
    const double k = -acc / err;  // reflection coefficient (Makhoul 1975, eq. 38c)
    prev = a;
    for (int j = 1; j < i; ++j)
      a[static_cast<std::size_t>(j)] += k * prev[static_cast<std::size_t>(i - j)];
    a[static_cast<std::size_t>(i)] = k;
    err *= (1.0 - k * k);
    if (!(err > r[0] * 1e-12)) break;  // numerically singular: keep the order reached
  }
  return a;
}

namespace {

// The hot loops of Whiten, compiled for AVX2 and for the baseline x86-64 (avx2_clones.hpp): the
// same float multiplications and additions lane by lane, 8 lanes per instruction instead of 4.

// Eight float lanes (Float8, avx2_clones.hpp), loaded from unaligned memory with memcpy.
#define BOUNCECAL_LOAD8(v, p) std::memcpy(&(v), (p), sizeof(Float8))

// The float partial sums of one lag over [s, e) (i0 = max(s, l)) added up in double: the tail
// products first, then the eight lanes in order.
[[gnu::always_inline]] inline double LagTotal(const float* a, const float* b, std::size_t m8,
                                              std::size_t m, const Float8& acc) {
  double total = 0.0;
  for (std::size_t k = m8; k < m; ++k) total += static_cast<double>(a[k]) * b[k];
  for (int q = 0; q < 8; ++q) total += acc[q];
  return total;
}

// r_l over one block [s, e) of x for l in [0, lags): eight independent float partial sums (a
// block's products are well inside float precision), then summed in double (see Whiten).
// Lags whose products all lie before the block are left as they are. Lags l <= s all start at
// s: kAutocorrLags of them run together, so that their sums' additions overlap and share the
// loads of x[s, e) (one lag alone is a chain of dependent additions): each lag's lanes see the
// same products in the same order, the same sums to the bit.
constexpr std::size_t kAutocorrLags = 8;
BOUNCECAL_AVX2_CLONES
void BlockAutocorrelation(const float* x, std::size_t s, std::size_t e, std::size_t lags,
                          double* out) {
  std::size_t l = 0;
  if (e > s && lags >= kAutocorrLags && lags - 1 <= s) {  // every lag's products start at s
    const std::size_t m = e - s, m8 = m & ~std::size_t{7};
    const float* a = x + s;
    // Groups of kAutocorrLags lags; the last group ends at the last lag (lags it shares with the
    // group before are computed again, the same sums: cheaper than single lags, each a chain).
    for (std::size_t g0 = 0; g0 < lags; g0 += kAutocorrLags) {
      const std::size_t g = std::min(g0, lags - kAutocorrLags);  // the group's first lag
      Float8 acc[kAutocorrLags] = {};
      const float* b = a - g;
      for (std::size_t k = 0; k < m8; k += 8) {
        Float8 va;
        BOUNCECAL_LOAD8(va, a + k);
        for (std::size_t q = 0; q < kAutocorrLags; ++q) {
          Float8 v;
          BOUNCECAL_LOAD8(v, b + k - q);
          acc[q] += va * v;
        }
      }
      for (std::size_t q = 0; q < kAutocorrLags; ++q)
        out[g + q] = LagTotal(a, b - q, m8, m, acc[q]);
    }
    l = lags;
  }
  for (; l < lags; ++l) {
    const std::size_t i0 = std::max(s, l);
    if (i0 >= e) continue;
    const float* __restrict a = x + i0;
    const float* __restrict b = x + i0 - l;
    const std::size_t m = e - i0, m8 = m & ~std::size_t{7};
    float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
    for (std::size_t k = 0; k < m8; k += 8)
      for (std::size_t q = 0; q < 8; ++q) acc[q] += a[k + q] * b[k + q];
    double total = 0.0;
    for (std::size_t k = m8; k < m; ++k) total += static_cast<double>(a[k]) * b[k];
    for (float v : acc) total += v;
    out[l] = total;
  }
}

// o[i] = x[i] + sum_{j >= 1} af[j] x[i - j] for i in [b0, b1) (o holds x there on entry). Where
// every tap lies inside x (i >= taps - 1) eight groups of eight outputs are summed in registers,
// tap by tap in order (the same float additions as one pass per tap over o, to the bit, without
// storing and reloading o per tap); the first taps - 1 samples of x take one pass per tap.
BOUNCECAL_AVX2_CLONES
void PredictionErrorBlock(const float* x, const float* af, std::size_t taps, std::size_t b0,
                          std::size_t b1, float* o) {
  const std::size_t full = std::max(b0, taps > 0 ? taps - 1 : 0);
  const std::size_t edge = std::min(b1, full);
  for (std::size_t j = 1; j < taps; ++j) {
    const float aj = af[j];
    for (std::size_t i = std::max(b0, j); i < edge; ++i) o[i] += aj * x[i - j];
  }
  std::size_t i = std::max(full, b0);
  constexpr std::size_t kGroup = 64;
  for (; i + kGroup <= b1; i += kGroup) {
    Float8 acc[8];
    for (int q = 0; q < 8; ++q) BOUNCECAL_LOAD8(acc[q], o + i + 8 * q);
    for (std::size_t j = 1; j < taps; ++j) {
      const float aj = af[j];
      const Float8 a8 = {aj, aj, aj, aj, aj, aj, aj, aj};
      const float* xs = x + i - j;
      for (int q = 0; q < 8; ++q) {
        Float8 v;
        BOUNCECAL_LOAD8(v, xs + 8 * q);
        acc[q] += a8 * v;
      }
    }
    std::memcpy(o + i, acc, sizeof acc);
  }
  for (; i < b1; ++i) {
    float acc = o[i];
    for (std::size_t j = 1; j < taps; ++j) acc += af[j] * x[i - j];
    o[i] = acc;
  }
}

}  // namespace

std::vector<float> Whiten(const std::vector<float>& x, int order, int threads, WorkerPool* pool) {
  const std::size_t n = x.size();
  if (order <= 0 || n <= static_cast<std::size_t>(order) * 4) return x;
  // Autocorrelation of the whole signal, r[l] = sum_i x[i] x[i - l]. All of it, so that the
  // predictor does not depend on where the file starts: an impact's ringing dominates r, and a
  // fit on the first seconds or on a grid of blocks anchored at sample 0 took impacts in or out
  // with the start (cutting the quiet before a superball's drop moved its impact times by a
  // ringing cycle). Blocks only bound the float partial sums; the lag products cross them.
  // Per block of 4096 samples and lag, eight independent float partial sums (a block's products
  // are well inside float precision), summed in double per block. Through restrict pointers the
  // compiler vectorises the eight sums (each lane keeps its order: the same sums to the bit as
  // the scalar loop, whose aliasing it could not rule out), 4x faster: 40 against 160 ms on
  // 5.76 M samples (2 minutes at 48 kHz). The summation order matters: sixteen sums over
  // 1024-sample blocks, as fast, moved the fragile harsh-cut rubber-ball case of the start
  // invariance test (tests/recordings_test.cpp) from 3 members assigned differently to 8.
  // The blocks' partial sums are independent: they are computed on `threads` threads (groups of
  // kWhitenGroup blocks each) and added into r in block order, the same sums to the bit.
  const std::size_t block = 4096;
  const std::size_t lags = static_cast<std::size_t>(order) + 1;
  const std::size_t nblocks = (n + block - 1) / block;
  std::vector<double> partial(nblocks * lags, 0.0);
  ParallelForGroups(
      threads, nblocks, kWhitenGroup,
      [&](std::size_t b0, std::size_t b1) {
        for (std::size_t bi = b0; bi < b1; ++bi)
          BlockAutocorrelation(x.data(), bi * block, std::min(n, bi * block + block), lags,
                               partial.data() + bi * lags);
      },
      pool);
  std::vector<double> r(lags, 0.0);
  for (std::size_t bi = 0; bi < nblocks; ++bi)
    for (std::size_t l = 0; l < lags; ++l)
      if (std::max(bi * block, l) < std::min(n, bi * block + block)) r[l] += partial[bi * lags + l];
  if (!(r[0] > 0.0)) return x;
  // A little white-noise floor (-60 dB) keeps the predictor stable on pure tones
  // (lag-window / "white noise correction", Makhoul 1975 sec. III-D).
  r[0] *= 1.0 + 1e-6;
  const std::vector<double> a = LevinsonDurbin(r, order);
  // e[i] = x[i] + sum_j a[j] x[i - j], in cache-sized blocks (one pass per tap inside a block);
  // every output block depends on x only, so groups of blocks run on the threads.
  std::vector<float> out;
  ReserveHugePages(&out, n);
  out.assign(x.begin(), x.end());
  std::vector<float> af(a.size());
  for (std::size_t j = 0; j < a.size(); ++j) af[j] = static_cast<float>(a[j]);
  const std::size_t blk = 2048;
  const std::size_t fblocks = (n + blk - 1) / blk;
  ParallelForGroups(
      threads, fblocks, kWhitenGroup,
      [&](std::size_t b0, std::size_t b1) {
        for (std::size_t fb = b0; fb < b1; ++fb)
          PredictionErrorBlock(x.data(), af.data(), af.size(), fb * blk,
                               std::min(n, fb * blk + blk), out.data());
      },
      pool);
  return out;
}

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

namespace {

// The per-sample loops around the FFTs (the novelty's frames, the template correlation's
// overlap-save blocks), compiled for AVX2 and for the baseline x86-64 (avx2_clones.hpp): the
// same conversions, products and sums per element, more elements per instruction.
BOUNCECAL_AVX2_CLONES
void Windowed(const float* __restrict src, const double* __restrict window, std::size_t n,
              double* __restrict out) {
  for (std::size_t i = 0; i < n; ++i) out[i] = src[i] * window[i];
}
BOUNCECAL_AVX2_CLONES
void PowerSpectrum(const fftw_complex* __restrict spec, std::size_t bins, double* __restrict p) {
  for (std::size_t k = 0; k < bins; ++k) p[k] = spec[k][0] * spec[k][0] + spec[k][1] * spec[k][1];
}
BOUNCECAL_AVX2_CLONES
void ToDouble(const float* __restrict x, std::size_t n, double* __restrict out) {
  for (std::size_t i = 0; i < n; ++i) out[i] = x[i];
}
// spec = spec * conj(t), bin by bin (correlation in the frequency domain).
BOUNCECAL_AVX2_CLONES
void MultiplyByConjugate(fftw_complex* __restrict spec, const fftw_complex* __restrict t,
                         std::size_t bins) {
  for (std::size_t k = 0; k < bins; ++k) {
    const double re = spec[k][0] * t[k][0] + spec[k][1] * t[k][1];
    const double im = spec[k][1] * t[k][0] - spec[k][0] * t[k][1];
    spec[k][0] = re;
    spec[k][1] = im;
  }
}
BOUNCECAL_AVX2_CLONES
void ScaledToFloat(const double* __restrict in, std::size_t n, double scale,
                   float* __restrict out) {
  for (std::size_t i = 0; i < n; ++i) out[i] = static_cast<float>(in[i] * scale);
}

}  // namespace

struct OnsetDetector::Fft {
  int n = 0;
  double* in = nullptr;
  fftw_complex* out = nullptr;
  fftw_plan plan = nullptr;
  std::vector<double> window;
  // The novelty's transforms four frames at a time where the size allows (power_spectra.hpp).
  std::unique_ptr<PowerSpectra4> four;
  explicit Fft(int size) : n(size) {
    std::lock_guard<std::mutex> lock(PlannerMutex());
    in = static_cast<double*>(fftw_malloc(sizeof(double) * static_cast<std::size_t>(n)));
    out = static_cast<fftw_complex*>(
        fftw_malloc(sizeof(fftw_complex) * static_cast<std::size_t>(n / 2 + 1)));
    plan = fftw_plan_dft_r2c_1d(n, in, out, FFTW_ESTIMATE);
    window.resize(static_cast<std::size_t>(n));
    for (int i = 0; i < n; ++i)  // periodic Hann
      window[static_cast<std::size_t>(i)] =
          0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * i / static_cast<double>(n));
    if (PowerSpectra4::Supports(n)) four = std::make_unique<PowerSpectra4>(n, window);
  }
  ~Fft() {
    std::lock_guard<std::mutex> lock(PlannerMutex());
    fftw_destroy_plan(plan);
    fftw_free(in);
    fftw_free(out);
  }
  Fft(const Fft&) = delete;
  Fft& operator=(const Fft&) = delete;
};

// Overlap-save FFT correlation of a long signal with a short template (plans made once).
struct OnsetDetector::Correlator {
  int n = 0;  // FFT size
  fftw_plan fwd = nullptr, inv = nullptr;
  explicit Correlator(int size) : n(size) {
    std::lock_guard<std::mutex> lock(PlannerMutex());
    // Planned on arrays of the kind Correlate executes them on (FFTW_ESTIMATE does not touch them).
    FftArrays a(static_cast<std::size_t>(n));
    fwd = fftw_plan_dft_r2c_1d(n, a.real, a.spec, FFTW_ESTIMATE);
    inv = fftw_plan_dft_c2r_1d(n, a.spec, a.real, FFTW_ESTIMATE);
  }
  ~Correlator() {
    std::lock_guard<std::mutex> lock(PlannerMutex());
    fftw_destroy_plan(fwd);
    fftw_destroy_plan(inv);
  }
  Correlator(const Correlator&) = delete;
  Correlator& operator=(const Correlator&) = delete;

  // The spectrum of the template h (zero-padded to the FFT size), which Correlate multiplies.
  void TemplateSpectrum(const std::vector<double>& h, FftArrays* tf) const {
    const std::size_t nn = static_cast<std::size_t>(n);
    assert(h.size() < nn / 2);
    std::fill(tf->real, tf->real + nn, 0.0);
    std::copy(h.begin(), h.end(), tf->real);
    fftw_execute_dft_r2c(fwd, tf->real, tf->spec);
  }

  // The overlap-save blocks CorrelateBlocks computes [lo, hi) from (m = the template's length).
  std::size_t Blocks(std::size_t m, std::size_t lo, std::size_t hi) const {
    const std::size_t step = static_cast<std::size_t>(n) - m + 1;  // valid outputs per block
    return hi <= lo ? 0 : (hi - 1) / step + 1 - lo / step;
  }

  // out[i - lo] = sum_j h[j] x[i + j] for the i in [lo, hi) that blocks [b0, b1) of Blocks(m, lo,
  // hi) give, x zero beyond its end (tspec: the TemplateSpectrum of h, m = h.size()), from the
  // overlap-save blocks of the whole x that hold them: block bi gives [bi step, (bi + 1) step),
  // each the same computation wherever the range starts, so that the blocks are independent.
  // `a`: the FFT arrays to work in.
  void CorrelateBlocks(const std::vector<float>& x, const fftw_complex* tspec, std::size_t m,
                       std::size_t lo, std::size_t hi, std::size_t b0, std::size_t b1, float* out,
                       FftArrays* a) const {
    const std::size_t nn = static_cast<std::size_t>(n), nb = nn / 2 + 1;
    const std::size_t step = nn - m + 1;
    const double scale = 1.0 / static_cast<double>(nn);
    const std::size_t first = lo / step;
    double* buf = a->real;
    fftw_complex* spec = a->spec;
    for (std::size_t bi = first + b0; bi < first + b1; ++bi) {
      const std::size_t b = bi * step;
      const std::size_t len = std::min(nn, x.size() - b);
      ToDouble(x.data() + b, len, buf);
      std::fill(buf + len, buf + nn, 0.0);
      fftw_execute_dft_r2c(fwd, buf, spec);
      MultiplyByConjugate(spec, tspec, nb);  // X * conj(H): correlation
      fftw_execute_dft_c2r(inv, spec, buf);
      const std::size_t i0 = std::max(b, lo), i1 = std::min({b + step, hi, x.size()});
      if (i1 > i0) ScaledToFloat(buf + (i0 - b), i1 - i0, scale, out + (i0 - lo));
    }
  }
};

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

int OnsetDetector::Threads() const {
  return StageThreads(options_.threads, options_.available_threads);
}

int OnsetDetector::HopSamples(const OnsetOptions& options, double rate_hz) {
  const double hop_target = options.hop_s > 0.0 ? options.hop_s * rate_hz : 0.00033 * rate_hz;
  return std::max(1, NearestPowerOfTwo(hop_target));
}

std::size_t OnsetDetector::WorkingBytes(const OnsetOptions& options, double rate_hz,
                                        std::size_t samples) {
  const std::size_t hop = static_cast<std::size_t>(HopSamples(options, rate_hz));
  const std::size_t frames = samples / hop + 1;
  const std::size_t bins = std::max<std::size_t>(16, 4 * hop) / 2 + 1;  // the window's
  // The whitened signal (float); per frame the novelty's num, den and dB values, the novelty
  // and its threshold (double); this thread's power rows of a novelty chunk; the template
  // correlation's kept chunks, xc and ww (float).
  return samples * sizeof(float) + frames * 5 * sizeof(double) +
         (std::min(frames, SpectraChunkFrames(bins)) + 4 + kRefFrames) * bins * sizeof(double) +
         std::min(samples, kNccChunksKept * kNccChunk) * 2 * sizeof(float);
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
  res.whitened = Whiten(x, options_.lpc_order, Threads(), options_.pool);
  res.noise_rms = RobustRms(res.whitened);
  const std::size_t n = res.whitened.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t nw = static_cast<std::size_t>(window_);
  if (n < nw + hop) return res;
  // 1-3. Relative spectral flux, adaptive threshold, peaks.
  res.novelty_db = Novelty(res.whitened);
  res.threshold_db = Threshold(res.novelty_db);
  const std::vector<std::size_t> peaks = Peaks(res.novelty_db, res.threshold_db);
  // 4. Refinement and per-impact measures at each peak's coarse onset.
  const std::size_t pre =
      std::max<std::size_t>(nw, static_cast<std::size_t>(options_.aic_pre_s * rate_hz_));
  const std::size_t post =
      std::max<std::size_t>(nw / 2, static_cast<std::size_t>(options_.aic_post_s * rate_hz_));
  // Each peak's refinement reads only the signal and `res`'s whitened signal and noise: the
  // peaks are refined on the threads, each into its own slot.
  std::vector<long> window_lo, window_hi;  // onset samples the AIC window of each onset spans
  std::vector<std::size_t> centre;
  for (std::size_t t : peaks) {
    // The click is most likely in the newest half of the window at the flux peak.
    centre.push_back(t * hop + nw / 2 + nw / 4);
    window_lo.push_back(static_cast<long>(centre.back()) - static_cast<long>(pre));
    window_hi.push_back(static_cast<long>(centre.back() + post));
  }
  std::vector<Impact> refined(peaks.size());
  ParallelForGroups(
      Threads(), peaks.size(), kRefinePart,
      [&](std::size_t i0, std::size_t i1) {
        for (std::size_t i = i0; i < i1; ++i) refined[i] = Refine(x, res, centre[i], false);
      },
      options_.pool);
  res.onsets = std::move(refined);
  // 5. Template pass.
  TemplatePass(x, window_lo, window_hi, &res);
  return res;
}

namespace {

// The reference of frame t: the kRefFrames frames that end `lag` frames before it,
// [t - lag - kRefFrames + 1, t - lag], those of them that exist (fewer at the recording's start).
struct RefSpan {
  std::size_t first = 0, count = 0;
};
RefSpan RefFramesOf(std::size_t t, std::size_t lag) {
  if (t < lag) return {};
  const std::size_t last = t - lag;
  const std::size_t first = last + 1 >= kRefFrames ? last + 1 - kRefFrames : 0;
  return {first, last + 1 - first};
}

// ref += row and ref -= row, bin by bin.
void AddRow(const double* __restrict row, std::size_t bins, double* __restrict ref) {
  for (std::size_t k = 0; k < bins; ++k) ref[k] += row[k];
}
void SubtractRow(const double* __restrict row, std::size_t bins, double* __restrict ref) {
  for (std::size_t k = 0; k < bins; ++k) ref[k] -= row[k];
}

// kNoveltyBatch consecutive frames t, t+1, ... of the novelty's reference loop at once, in its
// steady state (the reference full: every frame's enters and leaves), the same operations as
// that many passes of the loop: each frame's reference values and its two sums over the bins in
// bin order (the ones NoveltyOne forms), one frame per lane of 4-lane vectors (GCC/Clang vector
// extension), so that the frames' sums overlap (one frame's sum is a chain of dependent
// additions). pw[j]: frame t + j's power row; in_rows / out_rows: the rows entering / leaving the
// reference after frame t + j.
constexpr std::size_t kNoveltyBatch = 8;
BOUNCECAL_AVX2_CLONES
void NoveltyBatch(const double* const* pw, std::size_t bins, double* ref, double inv_ref,
                  const double* const* in_rows, const double* const* out_rows, double* scratch,
                  double* num, double* den) {
  constexpr std::size_t kB = kNoveltyBatch;
  for (std::size_t j = 0; j < kB; ++j) {
    for (std::size_t k = 0; k < bins; ++k) scratch[k * kB + j] = ref[k] * inv_ref;
    for (std::size_t k = 0; k < bins; ++k) ref[k] += in_rows[j][k];
    for (std::size_t k = 0; k < bins; ++k) ref[k] -= out_rows[j][k];
  }
  const Double4 zero = {0.0, 0.0, 0.0, 0.0};
  Double4 up0 = zero, up1 = zero, total0 = zero, total1 = zero;
  for (std::size_t k = 0; k < bins; ++k) {
    const Double4 p0 = {pw[0][k], pw[1][k], pw[2][k], pw[3][k]};
    const Double4 p1 = {pw[4][k], pw[5][k], pw[6][k], pw[7][k]};
    Double4 r0, r1;
    std::memcpy(&r0, scratch + k * kB, sizeof r0);
    std::memcpy(&r1, scratch + k * kB + 4, sizeof r1);
    const Double4 d0 = p0 - r0, d1 = p1 - r1;
    up0 += d0 < zero ? zero : d0;  // std::max(p - r, 0.0)
    up1 += d1 < zero ? zero : d1;
    total0 += r0;
    total1 += r1;
  }
  for (std::size_t j = 0; j < kB; ++j) {
    num[j] = j < 4 ? up0[j] : up1[j - 4];
    den[j] = j < 4 ? total0[j] : total1[j - 4];
  }
}
void NoveltyOne(const double* pw, std::size_t bins, const double* ref, double* num, double* den) {
  double up = 0.0, total = 0.0;
  for (std::size_t k = 0; k < bins; ++k) {
    const double d = pw[k] - ref[k];
    up += d < 0.0 ? 0.0 : d;
    total += ref[k];
  }
  *num = up;
  *den = total;
}

}  // namespace

std::vector<double> OnsetDetector::Novelty(const std::vector<float>& w) const {
  const std::size_t n = w.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t nw = static_cast<std::size_t>(window_);
  const std::size_t frames = (n - nw) / hop + 1;
  const std::size_t bins = nw / 2 + 1;
  // Relative spectral flux against the recent background: the reference spectrum R_t is the
  // mean power of kRefFrames frames that end where frame t begins (no overlap with it, so a
  // click cannot hide in its own reference):
  //   num_t = sum_k max(0, P_t(k) - R_t(k)),  den_t = sum_k R_t(k).
  // The reference is a running sum slid from frame to frame. The frames are cut into chunks of
  // SpectraChunkFrames that start their sums anew, each from its first frame's reference frames, so
  // the chunks are independent: each computes the power rows it needs (its own and the
  // lag + kRefFrames - 1 before) and its frames' sums, on any thread. The cuts do not depend
  // on the thread count, nor then do the values.
  const std::size_t lag = (nw + hop - 1) / hop;  // frames overlapping frame t
  const std::size_t warm = lag + kRefFrames - 1;
  Buffer<double> num, den;  // every frame's written below
  num.Allocate(frames);
  den.Allocate(frames);
  const Fft& f = *fft_;
  const double inv_ref = 1.0 / static_cast<double>(kRefFrames);
  const int threads = Threads();
  const std::size_t chunk = SpectraChunkFrames(bins);
  const std::size_t chunks = (frames + chunk - 1) / chunk;
  // Each thread takes the next chunk until none is left, with its own arrays for them.
  std::atomic<std::size_t> next_chunk{0};
  ParallelFor(
      threads, std::min<std::size_t>(chunks, static_cast<std::size_t>(threads)),
      [&](std::size_t) {
        FftArrays a(nw);
        Buffer<double> power, scratch, ref;  // written before they are read
        power.Allocate((std::min(frames, chunk) + warm) * bins);
        scratch.Allocate(kNoveltyBatch * bins);
        ref.Allocate(bins);
        for (std::size_t ch = next_chunk++; ch < chunks; ch = next_chunk++) {
          const std::size_t c0 = ch * chunk, c1 = std::min(frames, c0 + chunk);
          const std::size_t p0 = c0 >= warm ? c0 - warm : 0;  // first power row of this chunk
          for (std::size_t t = p0; t < c1;) {
            if (f.four) {  // four frames a time; the last ones repeated to fill the lanes
              const float* src[4];
              double* out[4];
              for (std::size_t j = 0; j < 4; ++j) {
                const std::size_t tj = std::min(t + j, c1 - 1);
                src[j] = w.data() + tj * hop;
                out[j] = tj == t + j ? power.data.get() + (tj - p0) * bins : scratch.data.get();
              }
              f.four->Compute(src, out);
              t += 4;
              continue;
            }
            Windowed(w.data() + t * hop, f.window.data(), nw, a.real);
            fftw_execute_dft_r2c(f.plan, a.real, a.spec);
            PowerSpectrum(a.spec, bins, power.data.get() + (t - p0) * bins);
            ++t;
          }
          auto row = [&](std::size_t frame) { return power.data.get() + (frame - p0) * bins; };
          // The reference at the chunk's first frame: its frames summed in frame order (as sliding
          // it from the recording's start would have, in exact arithmetic); then slid frame by
          // frame.
          const RefSpan first = RefFramesOf(c0, lag);
          std::fill(ref.data.get(), ref.data.get() + bins, 0.0);
          for (std::size_t i = 0; i < first.count; ++i)
            AddRow(row(first.first + i), bins, ref.data.get());
          // After frame t, frame t + 1 - lag enters the reference and t + 1 - lag - kRefFrames
          // leaves.
          auto slide = [&](std::size_t t) {
            if (t + 1 < lag) return;
            AddRow(row(t + 1 - lag), bins, ref.data.get());
            if (t + 1 >= lag + kRefFrames)
              SubtractRow(row(t + 1 - lag - kRefFrames), bins, ref.data.get());
          };
          for (std::size_t t = c0; t < c1;) {
            if (t >= lag + kRefFrames && t + kNoveltyBatch <= c1) {  // steady state: a batch
              const double *pw[kNoveltyBatch], *in_rows[kNoveltyBatch], *out_rows[kNoveltyBatch];
              for (std::size_t j = 0; j < kNoveltyBatch; ++j) {
                pw[j] = row(t + j);
                in_rows[j] = row(t + j + 1 - lag);
                out_rows[j] = row(t + j + 1 - lag - kRefFrames);
              }
              NoveltyBatch(pw, bins, ref.data.get(), inv_ref, in_rows, out_rows, scratch.data.get(),
                           num.data.get() + t, den.data.get() + t);
              t += kNoveltyBatch;
              continue;
            }
            for (std::size_t k = 0; k < bins; ++k) scratch[k] = ref[k] * inv_ref;
            NoveltyOne(row(t), bins, scratch.data.get(), &num[t], &den[t]);
            if (t < lag + kRefFrames) den[t] = -1.0;  // -1: reference not yet full
            slide(t);
            ++t;
          }
        }
      },
      options_.pool);
  // Floor of the denominator: the median reference power (the background), so silence and
  // digital zeros do not turn tiny increases into large ratios.
  // (-1 marks a frame whose reference is not full.)
  double floor_power = MedianOfNonNegative(den.data.get(), frames, threads, options_.pool);
  if (!(floor_power > 0.0)) {
    double mx = 0.0;
    for (std::size_t t = 0; t < frames; ++t)
      if (den[t] >= 0.0) mx = std::max(mx, den[t]);
    floor_power = std::max(mx * 1e-6, 1e-30);
  }
  // A click stays above its reference for the ~lag frames that contain it, a noise peak for
  // one: a 3-frame mean of the flux (in dB) separates them better than single frames.
  Buffer<double> raw_db;
  raw_db.Allocate(frames);
  std::vector<double> novelty;
  ReserveHugePages(&novelty, frames);
  novelty.resize(frames, 0.0);
  const std::size_t group = std::max<std::size_t>(kSpectraChunk, frames / (4 * threads) + 1);
  ParallelForGroups(
      threads, frames, group,
      [&](std::size_t t0, std::size_t t1) {
        for (std::size_t t = t0; t < t1; ++t) {
          const double d = den[t] < 0.0 ? floor_power : den[t];
          raw_db[t] = 10.0 * std::log10(1.0 + num[t] / (d + floor_power));
        }
      },
      options_.pool);
  ParallelForGroups(
      threads, frames, group,
      [&](std::size_t t0, std::size_t t1) {
        for (std::size_t t = std::max<std::size_t>(t0, 1); t < std::min(t1, frames - 1); ++t)
          novelty[t] = (raw_db[t - 1] + raw_db[t] + raw_db[t + 1]) / 3.0;
      },
      options_.pool);
  return novelty;
}

void SlidingSample::Set(const std::vector<double>& v, std::size_t lo, std::size_t hi,
                        std::size_t stride) {
  stride = std::max<std::size_t>(1, stride);
  hi = std::max(hi, lo);
  // The first sampled index at or after `from` on the grid lo + k stride.
  auto on_grid = [&](std::size_t from) {
    return from <= lo ? lo : lo + (from - lo + stride - 1) / stride * stride;
  };
  bool slide =
      valid_ && stride == stride_ && lo >= lo_ && hi >= hi_ && lo < hi_ && (lo - lo_) % stride == 0;
  if (slide) {
    // One merge pass: the kept values in order, minus the ones that left, plus the ones that
    // came (both sorted). A value that left must be among the kept ones (NaN is not).
    leaving_.clear();
    for (std::size_t q = lo_; q < lo; q += stride) leaving_.push_back(v[q]);
    coming_.clear();
    for (std::size_t q = on_grid(hi_); q < hi; q += stride) coming_.push_back(v[q]);
    std::sort(leaving_.begin(), leaving_.end());
    std::sort(coming_.begin(), coming_.end());
    merged_.clear();
    std::size_t a = 0, l = 0, c = 0;
    const std::size_t na = sorted_.size(), nl = leaving_.size(), nc = coming_.size();
    while (a < na) {
      const double x = sorted_[a];
      if (l < nl && leaving_[l] == x) {  // one copy leaves
        ++l;
        ++a;
      } else if (l < nl && !(leaving_[l] > x)) {
        break;  // a leaving value not among the kept ones (NaN): select anew
      } else if (c < nc && coming_[c] < x) {
        merged_.push_back(coming_[c++]);
      } else {
        merged_.push_back(x);
        ++a;
      }
    }
    slide = a == na && l == nl;
    if (slide) {
      merged_.insert(merged_.end(), coming_.begin() + static_cast<std::ptrdiff_t>(c),
                     coming_.end());
      sorted_.swap(merged_);
    }
  }
  if (!slide) {
    sorted_.clear();
    for (std::size_t q = lo; q < hi; q += stride) sorted_.push_back(v[q]);
    std::sort(sorted_.begin(), sorted_.end());
  }
  lo_ = lo;
  hi_ = hi;
  stride_ = stride;
  valid_ = true;
}

double SlidingSample::Median() const { return sorted_.empty() ? 0.0 : sorted_[sorted_.size() / 2]; }

double SlidingSample::Mad(double centre) const {
  if (sorted_.empty()) return 0.0;
  // |value - centre| grows away from centre on both sides of the sorted values: merge the two
  // runs (left of the first value >= centre going down, the rest going up) up to the rank.
  const std::size_t n = sorted_.size(), rank = n / 2;
  std::size_t right = static_cast<std::size_t>(
      std::lower_bound(sorted_.begin(), sorted_.end(), centre) - sorted_.begin());
  std::size_t left = right;  // values [0, left) not taken yet, taken from left - 1 down
  double d = 0.0;
  for (std::size_t taken = 0; taken <= rank; ++taken) {
    const bool has_l = left > 0, has_r = right < n;
    const double dl = has_l ? std::fabs(sorted_[left - 1] - centre) : 0.0;
    const double dr = has_r ? std::fabs(sorted_[right] - centre) : 0.0;
    if (has_l && (!has_r || dl <= dr)) {
      d = dl;
      --left;
    } else {
      d = dr;
      ++right;
    }
  }
  return d;
}

// The threshold at frame c: median + max(threshold_mads MAD, min_novelty_db) of the novelty
// over the `win` frames around c (every fourth frame). `window` slides from the previous
// block's frames (SlidingSample: the same median and MAD as selecting from all of them).
double OnsetDetector::BlockThreshold(const std::vector<double>& nov, std::size_t c, std::size_t win,
                                     SlidingSample* window) const {
  const std::size_t frames = nov.size();
  const std::size_t lo = c > win / 2 ? c - win / 2 : 0;
  const std::size_t hi = std::min(frames, lo + win);
  // Every fourth frame of the window (~225 values at the default hop): the median and MAD of
  // the background are as good and a quarter of the work.
  window->Set(nov, lo, hi, 4);
  const double med = window->Median();
  const double mad = 1.4826 * window->Mad(med);
  return med + std::max(options_.threshold_mads * mad, options_.min_novelty_db);
}

std::vector<double> OnsetDetector::Threshold(const std::vector<double>& nov) const {
  // Running median + k * MAD, evaluated on blocks and interpolated.
  const std::size_t frames = nov.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t win = std::max<std::size_t>(
      16, static_cast<std::size_t>(options_.median_window_s * rate_hz_ / static_cast<double>(hop)));
  const std::size_t blk = std::max<std::size_t>(1, win / 8);
  const std::size_t nblk = (frames + blk - 1) / blk;
  std::vector<double> blk_thr(nblk);
  // Each block's median and MAD are independent: groups of kThresholdPart blocks per thread task.
  ParallelForGroups(
      Threads(), nblk, kThresholdPart,
      [&](std::size_t b0, std::size_t b1) {
        SlidingSample window;
        for (std::size_t b = b0; b < b1; ++b)
          blk_thr[b] = BlockThreshold(nov, b * blk + blk / 2, win, &window);
      },
      options_.pool);
  std::vector<double> thr;
  ReserveHugePages(&thr, frames);
  thr.resize(frames);
  ParallelForGroups(
      Threads(), frames, kSpectraChunk,
      [&](std::size_t t0, std::size_t t1) {
        for (std::size_t t = t0; t < t1; ++t) {
          const double pos =
              (static_cast<double>(t) - static_cast<double>(blk) / 2.0) / static_cast<double>(blk);
          const double cl = std::clamp(pos, 0.0, static_cast<double>(nblk - 1));
          const std::size_t b0 = static_cast<std::size_t>(cl);
          const std::size_t b1 = std::min(nblk - 1, b0 + 1);
          const double fr = cl - static_cast<double>(b0);
          thr[t] = blk_thr[b0] * (1.0 - fr) + blk_thr[b1] * fr;
        }
      },
      options_.pool);
  return thr;
}

std::vector<std::size_t> OnsetDetector::Peaks(const std::vector<double>& nov,
                                              const std::vector<double>& thr) const {
  // Local maxima above threshold; within min_gap keep the stronger.
  std::vector<std::size_t> peaks;
  const std::size_t gap =
      static_cast<std::size_t>(options_.min_gap_s * rate_hz_ / static_cast<double>(hop_));
  for (std::size_t t = 1; t + 1 < nov.size(); ++t) {
    if (nov[t] <= thr[t] || nov[t] < nov[t - 1] || nov[t] <= nov[t + 1]) continue;
    if (!peaks.empty() && t - peaks.back() <= gap) {
      if (nov[t] > nov[peaks.back()]) peaks.back() = t;
      continue;
    }
    peaks.push_back(t);
  }
  return peaks;
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

struct OnsetDetector::TemplateMatch {
  double hh = 0.0;
  long ref_start = 0;  // template start sample
  double t_ref = 0.0;  // its onset time (AIC pick of the strongest onset)
  long lead = 0;       // samples from the template start to its onset
  long n = 0;          // template starts (samples of the whitened signal)
};

// NCC values of one stretch of template starts [begin, begin + xc.size()), kept for later.
struct OnsetDetector::NccWindow {
  long begin = 0;
  std::vector<float> xc, ww;
};

namespace {

// The first k in [k0, k1) where xc[k] > 0 and not xc[k]^2 < k2 ww[k] (in double, as the blind
// search asks), k1 if none: eight starts at a time (GCC/Clang vector extension, the same double
// operations per lane), the few that pass looked at one by one.
BOUNCECAL_AVX2_CLONES
std::size_t NextNccCandidate(const float* xc, const float* ww, std::size_t k0, std::size_t k1,
                             double k2) {
  typedef float Float4 __attribute__((vector_size(16)));
  typedef double Double4v __attribute__((vector_size(32)));
  typedef long long Long4 __attribute__((vector_size(32)));
  auto passes = [&](std::size_t k) {
    const double c = xc[k], e = ww[k];
    return (c > 0.0) & !(c * c < k2 * e);
  };
  std::size_t k = k0;
  const Double4v zero = {0.0, 0.0, 0.0, 0.0};
  const Double4v k2v = {k2, k2, k2, k2};
  for (; k + 8 <= k1; k += 8) {
    Long4 any = {0, 0, 0, 0};
    for (std::size_t h = 0; h < 8; h += 4) {
      Float4 cf, ef;
      std::memcpy(&cf, xc + k + h, sizeof cf);
      std::memcpy(&ef, ww + k + h, sizeof ef);
      const Double4v cv = __builtin_convertvector(cf, Double4v);
      const Double4v ev = __builtin_convertvector(ef, Double4v);
      any |= (cv > zero) & ~(cv * cv < k2v * ev);
    }
    if (any[0] | any[1] | any[2] | any[3]) break;
  }
  for (; k < k1; ++k)
    if (passes(k)) return k;
  return k1;
}

// ww[i - base] = sum of w^2 over [i, min(n, i + tl)) for i in [b, e): exact at b, then running.
void RunningEnergy(const std::vector<float>& w, std::size_t tl, std::size_t b, std::size_t e,
                   std::size_t base, float* ww) {
  const std::size_t n = w.size();
  double run = 0.0;
  for (std::size_t j = b; j < std::min(n, b + tl); ++j) run += static_cast<double>(w[j]) * w[j];
  ww[b - base] = static_cast<float>(run);
  const std::size_t e_in = std::min(e, n - std::min(n, tl - 1));  // w[i + tl - 1] exists
  std::size_t i = b + 1;
  for (; i < e_in; ++i) {
    const double in_v = w[i + tl - 1], out_v = w[i - 1];
    run += in_v * in_v - out_v * out_v;
    ww[i - base] = static_cast<float>(std::max(run, 0.0));
  }
  for (; i < e; ++i) {
    const double out_v = w[i - 1];
    run -= out_v * out_v;
    ww[i - base] = static_cast<float>(std::max(run, 0.0));
  }
}

// RunningEnergy on the four whole stretches starting at b, b + kEnergyRestart, ... (all of
// w[i + tl - 1] inside w): the same operations per stretch, interleaved, so that the four
// running sums' additions overlap (one sum alone is a chain of dependent additions).
void RunningEnergy4(const std::vector<float>& w, std::size_t tl, std::size_t b, std::size_t base,
                    float* ww) {
  double run[4];
  for (std::size_t q = 0; q < 4; ++q) {
    const std::size_t bq = b + q * kEnergyRestart;
    run[q] = 0.0;
    for (std::size_t j = bq; j < bq + tl; ++j) run[q] += static_cast<double>(w[j]) * w[j];
    ww[bq - base] = static_cast<float>(run[q]);
  }
  for (std::size_t i = 1; i < kEnergyRestart; ++i)
    for (std::size_t q = 0; q < 4; ++q) {
      const std::size_t at = b + q * kEnergyRestart + i;
      const double in_v = w[at + tl - 1], out_v = w[at - 1];
      run[q] += in_v * in_v - out_v * out_v;
      ww[at - base] = static_cast<float>(std::max(run[q], 0.0));
    }
}

}  // namespace

// The chunks of xc and ww, computed on demand and kept (the kNccChunksKept used last): the
// template pass reads them in time order, so each is computed once.
struct OnsetDetector::NccChunks {
  const Correlator& corr;
  const std::vector<float>& w;
  const std::vector<double>& h;
  double hh;
  int threads;
  WorkerPool* pool;
  FftArrays tf;  // the template's spectrum
  struct Chunk {
    long index = -1;
    unsigned long used = 0;
    FloatBuffer xc, ww;
  };
  Chunk kept[kNccChunksKept];
  unsigned long clock = 0;

  NccChunks(const Correlator& c, const std::vector<float>& whitened, const std::vector<double>& tpl,
            double tpl_energy, int n_threads, WorkerPool* workers)
      : corr(c),
        w(whitened),
        h(tpl),
        hh(tpl_energy),
        threads(n_threads),
        pool(workers),
        tf(static_cast<std::size_t>(c.n)) {
    corr.TemplateSpectrum(h, &tf);
  }

  const Chunk& Get(std::size_t index) {
    Chunk* slot = &kept[0];
    for (Chunk& c : kept) {
      if (c.index == static_cast<long>(index)) {
        c.used = ++clock;
        return c;
      }
      if (c.used < slot->used) slot = &c;
    }
    Compute(index, slot);
    slot->used = ++clock;
    return *slot;
  }

  void Compute(std::size_t index, Chunk* c) {
    const std::size_t n = w.size(), tl = h.size();
    const std::size_t lo = index * kNccChunk, hi = std::min(n, lo + kNccChunk);
    if (c->xc.size() < kNccChunk) {
      c->xc.Allocate(kNccChunk);
      c->ww.Allocate(kNccChunk);
    }
    c->index = static_cast<long>(index);
    // The correlation's blocks and the energy's stretches are independent (the restarts make
    // the stretches so; kNccChunk is a multiple of kEnergyRestart): one set of tasks, groups of
    // kCorrelatePart blocks and of kEnergyPart stretches, on the threads. (The two as separate
    // ParallelFor calls of larger groups: the energy's one group ran alone, and a 1-minute
    // recording's template pass took 12 ms on one thread and on two alike.)
    const std::size_t blocks = corr.Blocks(tl, lo, hi);
    const std::size_t ctasks = (blocks + kCorrelatePart - 1) / kCorrelatePart;
    const std::size_t s0 = lo / kEnergyRestart, s1 = (hi + kEnergyRestart - 1) / kEnergyRestart;
    const std::size_t etasks = (s1 - s0 + kEnergyPart - 1) / kEnergyPart;
    float* xc = c->xc.data.get();
    float* ww = c->ww.data.get();
    ParallelFor(
        threads, ctasks + etasks,
        [&](std::size_t task) {
          if (task < ctasks) {
            FftArrays a(static_cast<std::size_t>(corr.n));
            corr.CorrelateBlocks(w, tf.spec, tl, lo, hi, task * kCorrelatePart,
                                 std::min(blocks, (task + 1) * kCorrelatePart), xc, &a);
            return;
          }
          const std::size_t g = task - ctasks;
          std::size_t b = (s0 + g * kEnergyPart) * kEnergyRestart;
          const std::size_t end = std::min(s1, s0 + (g + 1) * kEnergyPart) * kEnergyRestart;
          for (; b + 4 * kEnergyRestart <= end && b + 4 * kEnergyRestart + tl <= n + 1;
               b += 4 * kEnergyRestart)
            RunningEnergy4(w, tl, b, lo, ww);
          for (; b < end; b += kEnergyRestart)
            RunningEnergy(w, tl, b, std::min(n, b + kEnergyRestart), lo, ww);
        },
        pool);
  }

  double Ncc(std::size_t i) {
    const Chunk& c = Get(i / kNccChunk);
    const std::size_t k = i - static_cast<std::size_t>(c.index) * kNccChunk;
    const double e = c.ww[k];
    return e > 0.0 ? static_cast<double>(c.xc[k]) / std::sqrt(hh * e) : 0.0;
  }

  // xc and ww over [a, b] (inclusive, inside [0, n)), for later.
  void Keep(long a, long b, NccWindow* out) {
    out->begin = a;
    out->xc.resize(static_cast<std::size_t>(b - a + 1));
    out->ww.resize(out->xc.size());
    for (long i = a; i <= b; ++i) {
      const std::size_t u = static_cast<std::size_t>(i);
      const Chunk& c = Get(u / kNccChunk);
      const std::size_t k = u - static_cast<std::size_t>(c.index) * kNccChunk;
      out->xc[static_cast<std::size_t>(i - a)] = c.xc[k];
      out->ww[static_cast<std::size_t>(i - a)] = c.ww[k];
    }
  }
};

bool OnsetDetector::BuildTemplate(OnsetResult* res, TemplateMatch* m) const {
  const std::vector<float>& w = res->whitened;
  const std::size_t n = w.size();
  std::size_t strongest = 0;
  for (std::size_t i = 1; i < res->onsets.size(); ++i)
    if (res->onsets[i].snr_db > res->onsets[strongest].snr_db) strongest = i;
  m->lead = static_cast<long>(0.1e-3 * rate_hz_) + 1;
  const std::size_t tl = static_cast<std::size_t>(template_len_);
  m->ref_start = std::lround(res->onsets[strongest].time_s * rate_hz_) - m->lead;
  if (m->ref_start < 0 || static_cast<std::size_t>(m->ref_start) + tl > n) return false;
  std::vector<double> h(tl);
  for (std::size_t j = 0; j < tl; ++j) {
    h[j] = w[static_cast<std::size_t>(m->ref_start) + j];
    m->hh += h[j] * h[j];
  }
  if (!(m->hh > 0.0)) return false;
  res->template_wave = h;
  res->template_start = m->ref_start;
  res->template_onset_s = res->onsets[strongest].time_s;
  m->t_ref = res->onsets[strongest].time_s;
  m->n = static_cast<long>(n);
  return true;
}

void OnsetDetector::TimeWithTemplate(const TemplateMatch& m, const std::function<double(long)>& ncc,
                                     long lo, long hi, Impact* im) const {
  // The impacts of one ball on one plate have the same waveform up to level, so the
  // cross-correlation lag to the template times them relative to the template's own onset far
  // more consistently than an AIC pick on each: the AIC moves with the level (it finds the first
  // sample that stands out of the background, later for a quiet impact) and jumps to a later
  // rise when the onset is weak or slow. Measured on the corpus (steel on copper, ping-pong on
  // wood): AIC picks scatter by 5-30 us around the truth and a few jump by 30-2000 us; NCC lags
  // scatter by 1-5 us (tools/bench_detect). Every impact with a clear match
  // (NCC >= template_timing_ncc) is therefore timed by the template. t_guess: the AIC pick;
  // [lo, hi]: template starts the AIC window allowed (the pick can land anywhere in it).
  const long n = m.n;
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long s0 = std::lround(im->time_s * rate_hz_) - m.lead;
  // Best NCC within +-maxlag of the guess; a farther one (in the AIC window or 2 maxlag around
  // the guess) only if it is clearly better (ball ringing and echoes also match).
  long best_l = -1, far_l = -1;
  double best_c = -2.0, far_c = -2.0;
  const long from = std::max(1L, std::min(lo, s0 - 2 * maxlag));
  const long to = std::min(n - 2, std::max(hi, s0 + 2 * maxlag));
  for (long l = from; l <= to; ++l) {
    const double c = ncc(l);
    const bool near = std::labs(l - s0) <= maxlag;
    if (near && c > best_c) {
      best_c = c;
      best_l = l;
    }
    if (!near && c > far_c) {
      far_c = c;
      far_l = l;
    }
  }
  if (far_c > best_c + 0.15) {
    best_c = far_c;
    best_l = far_l;
  }
  if (best_c < options_.template_timing_ncc || best_l < 1) return;
  const double cm = ncc(best_l - 1);
  const double cp = ncc(best_l + 1);
  const double curv = cm - 2.0 * best_c + cp;
  const double d = curv < 0.0 ? std::clamp(0.5 * (cm - cp) / curv, -0.5, 0.5) : 0.0;
  im->time_s = m.t_ref + (static_cast<double>(best_l - m.ref_start) + d) / rate_hz_;
  im->score = std::max(im->score, std::min(best_c, 1.0));
  // NCC peak precision ~ sqrt(1 - c^2) / c samples (scaled), plus the floor. (The final timing
  // of sequence members, with its calibrated sigma, is timing.hpp's.)
  const double sig_samples = 0.3 * std::sqrt(std::max(0.0, 1.0 - best_c * best_c)) / best_c;
  im->sigma_s =
      std::hypot(sig_samples / rate_hz_,
                 std::max(options_.sigma_floor_s, options_.sigma_floor_samples / rate_hz_));
}

// Template starts TimeWithTemplate reads for an impact at time_s ([lo, hi]: as it is given):
// [from - 1, to + 1] inside [0, n).
std::pair<long, long> OnsetDetector::TimingStarts(const TemplateMatch& m, long lo, long hi,
                                                  double time_s) const {
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long s0 = std::lround(time_s * rate_hz_) - m.lead;
  const long from = std::max(1L, std::min(lo, s0 - 2 * maxlag));
  const long to = std::min(m.n - 2, std::max(hi, s0 + 2 * maxlag));
  return {std::max(0L, from - 1), std::min(m.n - 1, to + 1)};
}

// A start where the NCC with the template reaches the blind search's threshold (the best of
// its run), and the NCC around it that timing it will read.
struct OnsetDetector::BlindCandidate {
  std::size_t start = 0;
  double ncc = 0.0;
  NccWindow window;
};

void OnsetDetector::BlindScan(const TemplateMatch& m, NccChunks* chunks, std::size_t chunk,
                              std::vector<BlindCandidate>* found) const {
  // Onsets the flux missed (late impacts on top of ringing): starts where the NCC with the
  // template reaches template_threshold; runs closer than min_gap_s keep their best start.
  const std::size_t n = static_cast<std::size_t>(m.n);
  const std::size_t tl = static_cast<std::size_t>(template_len_);
  const std::size_t gap_s = static_cast<std::size_t>(options_.min_gap_s * rate_hz_);
  // The NCC of a template of L samples with white noise has a standard deviation of about
  // 1/sqrt(L): ask for 4 of those at least, so short templates (low rates) stay selective.
  const double ncc_min =
      std::max(options_.template_threshold, 4.0 / std::sqrt(static_cast<double>(tl)));
  const double k2 = ncc_min * ncc_min * m.hh;
  // The starts Refine's tight AIC window and TimeWithTemplate may read around a candidate
  // (TimingStarts of any time the window can give, with a margin); beyond them the chunks answer.
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  const long nw = window_;
  const long pre = std::max(nw, static_cast<long>(options_.aic_pre_s * rate_hz_));
  const long post = std::max(nw / 2, static_cast<long>(options_.aic_post_s * rate_hz_));
  const long before = std::max(16L, pre / 3) + 2 * maxlag + 8;
  const long after = std::max(8L, post / 2) + 2 * maxlag + 8;
  auto keep = [&](BlindCandidate* f) {
    const long i = static_cast<long>(f->start);
    chunks->Keep(std::max(0L, i - before), std::min(m.n - 1, i + after), &f->window);
  };
  const NccChunks::Chunk& c = chunks->Get(chunk);
  const std::size_t base = chunk * kNccChunk;
  const std::size_t i1 = std::min(base + kNccChunk, n > tl ? n - tl : 0);  // i + tl < n
  const float* xc = c.xc.data.get();
  const float* ww = c.ww.data.get();
  for (std::size_t i = std::max<std::size_t>(1, base); i < i1; ++i) {
    // NCC >= ncc_min <=> xc > 0 and xc^2 >= ncc_min^2 hh ww (no sqrt): most starts are not.
    i = base + NextNccCandidate(xc, ww, i - base, i1 - base, k2);
    if (i >= i1) break;
    const double c_i = xc[i - base];
    const double e = ww[i - base];
    const double ncc = e > 0.0 ? c_i / std::sqrt(m.hh * e) : 0.0;
    if (!found->empty() && i - found->back().start <= gap_s) {
      if (ncc > found->back().ncc) {
        found->back().start = i;
        found->back().ncc = ncc;
        keep(&found->back());
      }
      continue;
    }
    found->push_back({i, ncc, {}});
    keep(&found->back());
  }
}

void OnsetDetector::AddBlindCandidates(const std::vector<float>& x, const TemplateMatch& m,
                                       NccChunks* chunks, const std::vector<BlindCandidate>& found,
                                       OnsetResult* res) const {
  // Candidates away from the known onsets (timed by the template already) become onsets.
  std::vector<double> known;
  for (const Impact& im : res->onsets) known.push_back(im.time_s);
  std::sort(known.begin(), known.end());
  const std::size_t before = res->onsets.size();
  const std::size_t lead = static_cast<std::size_t>(m.lead);
  for (const BlindCandidate& f : found) {
    const double t = static_cast<double>(f.start + lead) / rate_hz_;
    auto it = std::lower_bound(known.begin(), known.end(), t);
    const bool near_known = (it != known.end() && *it - t < options_.min_gap_s) ||
                            (it != known.begin() && t - *(it - 1) < options_.min_gap_s);
    if (near_known) continue;
    Impact imp = Refine(x, *res, f.start + lead, true);
    imp.score = std::clamp(f.ncc, 0.0, 1.0);
    const long s0 = static_cast<long>(f.start);
    const NccWindow& v = f.window;
    const double hh = m.hh;
    auto ncc = [&](long l) {
      const long k = l - v.begin;
      if (k < 0 || k >= static_cast<long>(v.xc.size()))
        return chunks->Ncc(static_cast<std::size_t>(l));
      const double e = v.ww[static_cast<std::size_t>(k)];
      return e > 0.0 ? static_cast<double>(v.xc[static_cast<std::size_t>(k)]) / std::sqrt(hh * e)
                     : 0.0;
    };
    TimeWithTemplate(m, ncc, s0, s0, &imp);
    res->onsets.push_back(imp);
  }
  if (res->onsets.size() != before)
    std::sort(res->onsets.begin(), res->onsets.end(),
              [](const Impact& a, const Impact& b) { return a.time_s < b.time_s; });
}

void OnsetDetector::TemplatePass(const std::vector<float>& x, const std::vector<long>& window_lo,
                                 const std::vector<long>& window_hi, OnsetResult* res) const {
  // The impacts of one ball on one plate look alike: the whitened waveform of the strongest
  // onset is the template; its NCC with the whole whitened signal (FFT overlap-save) scores
  // every onset (Impact::score), times the clear matches and finds impacts the flux missed.
  // The NCC is computed chunk by chunk in time order (NccChunks); each onset is scored and
  // timed once the chunk holding the last start it reads is there, each chunk searched blind.
  if (res->onsets.empty()) return;
  TemplateMatch m;
  if (!BuildTemplate(res, &m)) return;
  NccChunks chunks(*corr_, res->whitened, res->template_wave, m.hh, Threads(), options_.pool);
  auto live = [&](long l) { return chunks.Ncc(static_cast<std::size_t>(l)); };
  const long n = m.n;
  const long maxlag = static_cast<long>(0.0003 * rate_hz_) + 1;
  std::vector<Impact>& onsets = res->onsets;
  auto last_start = [&](std::size_t k) {
    const long s0 = std::lround(onsets[k].time_s * rate_hz_) - m.lead;
    return std::max(
        s0 + maxlag,
        TimingStarts(m, window_lo[k] - m.lead, window_hi[k] - m.lead, onsets[k].time_s).second);
  };
  auto score_and_time = [&](std::size_t k) {
    Impact& im = onsets[k];
    const long s0 = std::lround(im.time_s * rate_hz_) - m.lead;
    double best = 0.0;
    for (long l = std::max(0L, s0 - maxlag); l <= s0 + maxlag && l < n; ++l)
      best = std::max(best, live(l));
    im.score = std::clamp(best, 0.0, 1.0);
    TimeWithTemplate(m, live, window_lo[k] - m.lead, window_hi[k] - m.lead, &im);
  };
  const bool blind = options_.template_threshold < 1.0;
  std::vector<BlindCandidate> found;
  std::size_t next = 0;
  const std::size_t nchunks = (static_cast<std::size_t>(n) + kNccChunk - 1) / kNccChunk;
  for (std::size_t c = 0; c < nchunks; ++c) {
    const long chunk_end =
        static_cast<long>(std::min((c + 1) * kNccChunk, static_cast<std::size_t>(n)));
    for (; next < onsets.size() && last_start(next) < chunk_end; ++next) score_and_time(next);
    if (blind) BlindScan(m, &chunks, c, &found);
  }
  for (; next < onsets.size(); ++next) score_and_time(next);
  if (blind) AddBlindCandidates(x, m, &chunks, found, res);
}

bool FindByTemplate(const OnsetResult& r, const std::vector<float>& x, double t_center_s,
                    double half_window_s, double min_ncc, Impact* out, double edge_penalty,
                    double* ncc_spread) {
  const std::vector<double>& h = r.template_wave;
  const std::vector<float>& w = r.whitened;
  if (h.empty() || !(r.rate_hz > 0.0) || w.size() != x.size()) return false;
  const long n = static_cast<long>(w.size()), tl = static_cast<long>(h.size());
  double hh = 0.0;
  for (double v : h) hh += v * v;
  if (!(hh > 0.0)) return false;
  // Template start l <-> onset t_ref + (l - template_start) / rate.
  auto start_of = [&](double t) {
    return r.template_start + std::lround((t - r.template_onset_s) * r.rate_hz);
  };
  const long lo = std::max(1L, start_of(t_center_s - half_window_s));
  const long hi = std::min(n - tl - 2, start_of(t_center_s + half_window_s));
  if (hi < lo) return false;
  auto ncc = [&](long l) {
    double xy = 0.0, yy = 0.0;
    for (long j = 0; j < tl; ++j) {
      const double y = w[static_cast<std::size_t>(l + j)];
      xy += h[static_cast<std::size_t>(j)] * y;
      yy += y * y;
    }
    return yy > 0.0 ? xy / std::sqrt(hh * yy) : 0.0;
  };
  long best_l = -1;
  double best_c = -2.0, best_rank = -1e300;
  const long l_centre = start_of(t_center_s);
  const double inv_half = half_window_s > 0.0 ? 1.0 / (half_window_s * r.rate_hz) : 0.0;
  std::vector<double> all;  // the window's NCCs, for *ncc_spread
  for (long l = lo; l <= hi; ++l) {
    const double c = ncc(l);
    if (ncc_spread) all.push_back(c);
    const double u = static_cast<double>(l - l_centre) * inv_half;
    const double rank = c - edge_penalty * u * u;
    if (rank > best_rank) {
      best_rank = rank;
      best_c = c;
      best_l = l;
    }
  }
  if (ncc_spread) {
    // 1.4826 MAD: the spread of the NCC where there is no impact (a peak's main lobe is a few
    // of the window's positions).
    const auto mid = all.begin() + static_cast<std::ptrdiff_t>(all.size() / 2);
    std::nth_element(all.begin(), mid, all.end());
    const double med = *mid;
    for (double& v : all) v = std::fabs(v - med);
    std::nth_element(all.begin(), mid, all.end());
    *ncc_spread = 1.4826 * *mid;
  }
  if (best_l < 1 || best_c < min_ncc) return false;
  const double cm = ncc(best_l - 1), cp = ncc(best_l + 1);
  const double curv = cm - 2.0 * best_c + cp;
  const double d = curv < 0.0 ? std::clamp(0.5 * (cm - cp) / curv, -0.5, 0.5) : 0.0;
  Impact imp;
  imp.time_s =
      r.template_onset_s + (static_cast<double>(best_l - r.template_start) + d) / r.rate_hz;
  const double sig_samples = 0.3 * std::sqrt(std::max(0.0, 1.0 - best_c * best_c)) / best_c;
  imp.sigma_s = std::hypot(sig_samples / r.rate_hz, r.sigma_floor_s);
  imp.score = std::clamp(best_c, 0.0, 1.0);
  const long i0 = std::clamp(std::lround(imp.time_s * r.rate_hz), 0L, n - 1);
  const long len_post = std::max(8L, static_cast<long>(0.0005 * r.rate_hz));
  const long len_pre = static_cast<long>(0.01 * r.rate_hz);
  double amp = 0.0, e_post = 0.0, e_pre = 0.0;
  long c_post = 0, c_pre = 0;
  for (long i = i0; i < std::min(n, i0 + static_cast<long>(0.003 * r.rate_hz) + 1); ++i)
    amp = std::max(amp, static_cast<double>(std::fabs(x[static_cast<std::size_t>(i)])));
  for (long i = i0; i < std::min(n, i0 + len_post); ++i, ++c_post)
    e_post += static_cast<double>(w[static_cast<std::size_t>(i)]) * w[static_cast<std::size_t>(i)];
  for (long i = std::max(0L, i0 - 2 - len_pre); i < i0 - 2; ++i, ++c_pre)
    e_pre += static_cast<double>(w[static_cast<std::size_t>(i)]) * w[static_cast<std::size_t>(i)];
  imp.amplitude = amp;
  const double floor_var = std::max(r.noise_rms * r.noise_rms, 1e-30);
  const double p_post = c_post ? e_post / static_cast<double>(c_post) : 0.0;
  const double p_pre = c_pre ? e_pre / static_cast<double>(c_pre) : floor_var;
  imp.snr_db = 10.0 * std::log10((p_post + 1e-30) / (std::max(p_pre, 1e-6 * floor_var) + 1e-30));
  *out = imp;
  return true;
}

}  // namespace bouncecal
