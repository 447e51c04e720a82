// Whitening: a linear predictor fitted to the whole signal (Levinson-Durbin on its
// autocorrelation) and its prediction error. See include/bouncecal/acoustic/onsets.hpp.
#include <algorithm>
#include <cassert>
#include <cstring>
#include <vector>

#include "avx2_clones.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/parallel.hpp"

namespace bouncecal {
namespace {

// Blocks of the whitening's autocorrelation and filter per task on a thread (64 x 4096 samples:
// ~90 tasks per 2-minute block at 48 kHz, each long enough to outweigh its scheduling).
constexpr std::size_t kWhitenGroup = 64;

}  // namespace

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

std::vector<float> Whiten(const std::vector<float>& x, int order, int threads) {
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
  ParallelForGroups(threads, nblocks, kWhitenGroup, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t bi = b0; bi < b1; ++bi)
      BlockAutocorrelation(x.data(), bi * block, std::min(n, bi * block + block), lags,
                           partial.data() + bi * lags);
  });
  std::vector<double> r(lags, 0.0);
  for (std::size_t bi = 0; bi < nblocks; ++bi)
    for (std::size_t l = 0; l < lags; ++l)
      if (std::max(bi * block, l) < std::min(n, bi * block + block)) r[l] += partial[bi * lags + l];
  if (!(r[0] > 0.0)) return x;
  // A little white-noise floor (-60 dB) keeps the predictor stable on pure tones
  // (lag-window / "white noise correction", Makhoul 1975 sec. III-D).
  r[0] *= 1.0 + 1e-6;
  return PredictionError(x, LevinsonDurbin(r, order), threads);
}

std::vector<float> PredictionError(const std::vector<float>& x, const std::vector<double>& a,
                                   int threads) {
  const std::size_t n = x.size();
  // e[i] = x[i] + sum_j a[j] x[i - j], in cache-sized blocks (one pass per tap inside a block);
  // every output block depends on x only, so groups of blocks run on the threads.
  std::vector<float> out(x);
  std::vector<float> af(a.size());
  for (std::size_t j = 0; j < a.size(); ++j) af[j] = static_cast<float>(a[j]);
  const std::size_t blk = 2048;
  const std::size_t fblocks = (n + blk - 1) / blk;
  ParallelForGroups(threads, fblocks, kWhitenGroup, [&](std::size_t b0, std::size_t b1) {
    for (std::size_t fb = b0; fb < b1; ++fb)
      PredictionErrorBlock(x.data(), af.data(), af.size(), fb * blk, std::min(n, fb * blk + blk),
                           out.data());
  });
  return out;
}

}  // namespace bouncecal
