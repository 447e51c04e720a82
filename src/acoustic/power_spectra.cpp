// The power spectra of four windowed frames at a time. See power_spectra.hpp.
#include "power_spectra.hpp"

#include <cmath>
#include <cstring>
#include <numbers>
#include <stdexcept>
#include <string>
#include <utility>

#include "avx2_clones.hpp"

namespace bouncecal {

namespace {

typedef float Float4 __attribute__((vector_size(16)));
typedef int Int4 __attribute__((vector_size(16)));
typedef long long Long4 __attribute__((vector_size(32)));

// Lanes i, j, k, l of the concatenation of a and b (Clang's and GCC's spellings).
#if defined(__clang__)
#define BOUNCECAL_SHUFFLE4_F(a, b, i, j, k, l) __builtin_shufflevector(a, b, i, j, k, l)
#define BOUNCECAL_SHUFFLE4_D(a, b, i, j, k, l) __builtin_shufflevector(a, b, i, j, k, l)
#else
#define BOUNCECAL_SHUFFLE4_F(a, b, i, j, k, l) __builtin_shuffle(a, b, Int4{i, j, k, l})
#define BOUNCECAL_SHUFFLE4_D(a, b, i, j, k, l) __builtin_shuffle(a, b, Long4{i, j, k, l})
#endif

// Rows r[j] (4 values of frame j) to columns c[q] (value q of the 4 frames), by shuffles.
inline void TransposeFloats(const Float4 r[4], Float4 c[4]) {
  const Float4 t0 = BOUNCECAL_SHUFFLE4_F(r[0], r[1], 0, 4, 1, 5);
  const Float4 t1 = BOUNCECAL_SHUFFLE4_F(r[2], r[3], 0, 4, 1, 5);
  const Float4 t2 = BOUNCECAL_SHUFFLE4_F(r[0], r[1], 2, 6, 3, 7);
  const Float4 t3 = BOUNCECAL_SHUFFLE4_F(r[2], r[3], 2, 6, 3, 7);
  c[0] = BOUNCECAL_SHUFFLE4_F(t0, t1, 0, 1, 4, 5);
  c[1] = BOUNCECAL_SHUFFLE4_F(t0, t1, 2, 3, 6, 7);
  c[2] = BOUNCECAL_SHUFFLE4_F(t2, t3, 0, 1, 4, 5);
  c[3] = BOUNCECAL_SHUFFLE4_F(t2, t3, 2, 3, 6, 7);
}
inline void TransposeDoubles(const Double4 r[4], Double4 c[4]) {
  const Double4 t0 = BOUNCECAL_SHUFFLE4_D(r[0], r[1], 0, 4, 2, 6);
  const Double4 t1 = BOUNCECAL_SHUFFLE4_D(r[0], r[1], 1, 5, 3, 7);
  const Double4 t2 = BOUNCECAL_SHUFFLE4_D(r[2], r[3], 0, 4, 2, 6);
  const Double4 t3 = BOUNCECAL_SHUFFLE4_D(r[2], r[3], 1, 5, 3, 7);
  c[0] = BOUNCECAL_SHUFFLE4_D(t0, t2, 0, 1, 4, 5);
  c[1] = BOUNCECAL_SHUFFLE4_D(t1, t3, 0, 1, 4, 5);
  c[2] = BOUNCECAL_SHUFFLE4_D(t0, t2, 2, 3, 6, 7);
  c[3] = BOUNCECAL_SHUFFLE4_D(t1, t3, 2, 3, 6, 7);
}

struct Tables {
  const double* window;
  const int* rev;
  const double *cs, *sn, *split_cos, *split_sin;
};

// The transform of PowerSpectra4::Compute for M = n/2 complex points, lane j of every vector
// frame j. Lane by lane the same IEEE operations in the same order whichever copy runs
// (avx2_clones.hpp: no FMA) and whichever frames share the call (shuffles only move values), so
// a frame's values do not depend on the frames beside it.
template <int M>
__attribute__((always_inline)) inline void Spectra4Of(const float* const src[4], const Tables& tb,
                                                      double* const out[4]) {
  Double4 re[M], im[M];
// The real frame packed as z_i = x_2i + i x_2i+1, stored in bit-reversed order; four samples
// of the four frames at a time, turned from rows into lanes.
#pragma GCC unroll 128
  for (int i0 = 0; i0 < 2 * M; i0 += 4) {
    Float4 rows[4], cols[4];
#pragma GCC unroll 128
    for (int j = 0; j < 4; ++j) std::memcpy(&rows[j], src[j] + i0, sizeof(Float4));
    TransposeFloats(rows, cols);
#pragma GCC unroll 128
    for (int q = 0; q < 4; q += 2) {
      const int r = tb.rev[(i0 + q) / 2];
      re[r] = __builtin_convertvector(cols[q], Double4) * tb.window[i0 + q];
      im[r] = __builtin_convertvector(cols[q + 1], Double4) * tb.window[i0 + q + 1];
    }
  }
// Radix-2 decimation in time; the first butterfly of each group has the twiddle 1.
#pragma GCC unroll 128
  for (int len = 2; len <= M; len *= 2) {
    const int half = len / 2, step = M / len;
#pragma GCC unroll 128
    for (int i = 0; i < M; i += len) {
      {
        const Double4 ar = re[i], ai = im[i], br = re[i + half], bi = im[i + half];
        re[i] = ar + br;
        im[i] = ai + bi;
        re[i + half] = ar - br;
        im[i + half] = ai - bi;
      }
#pragma GCC unroll 128
      for (int j = 1; j < half; ++j) {
        const double c = tb.cs[j * step], s = tb.sn[j * step];
        const Double4 br = re[i + j + half], bi = im[i + j + half];
        const Double4 tr = br * c - bi * s;
        const Double4 ti = br * s + bi * c;
        const Double4 ar = re[i + j], ai = im[i + j];
        re[i + j] = ar + tr;
        im[i + j] = ai + ti;
        re[i + j + half] = ar - tr;
        im[i + j + half] = ai - ti;
      }
    }
  }
  // Split: X_k = E_k + e^(-2 pi i k / n) O_k with E_k = (Z_k + conj Z_(M-k)) / 2 and
  // O_k = (Z_k - conj Z_(M-k)) / 2i; X_0 and X_M are real.
  Double4 power[M + 4];
  {
    const Double4 x0 = re[0] + im[0], xm = re[0] - im[0];
    power[0] = x0 * x0;
    power[M] = xm * xm;
  }
#pragma GCC unroll 128
  for (int k = 1; k < M; ++k) {
    const Double4 a = re[k], b = im[k], c = re[M - k], d = im[M - k];
    const Double4 er = (a + c) * 0.5, ei = (b - d) * 0.5;
    const Double4 orr = (b + d) * 0.5, oi = (c - a) * 0.5;
    const double wc = tb.split_cos[k], ws = tb.split_sin[k];
    const Double4 xr = er + (orr * wc + oi * ws);
    const Double4 xi = ei + (oi * wc - orr * ws);
    power[k] = xr * xr + xi * xi;
  }
// Lanes back to rows: four bins of the four frames at a time, then bin M.
#pragma GCC unroll 128
  for (int k = 0; k < M; k += 4) {
    Double4 rows[4];
    TransposeDoubles(power + k, rows);
    for (int j = 0; j < 4; ++j) std::memcpy(out[j] + k, &rows[j], sizeof(Double4));
  }
  for (int j = 0; j < 4; ++j) out[j][M] = power[M][j];
}

#define BOUNCECAL_SPECTRA4(M)                                                            \
  BOUNCECAL_AVX2_CLONES                                                                  \
  void Spectra4_##M(const float* const src[4], const Tables& tb, double* const out[4]) { \
    Spectra4Of<M>(src, tb, out);                                                         \
  }
BOUNCECAL_SPECTRA4(4)
BOUNCECAL_SPECTRA4(8)
BOUNCECAL_SPECTRA4(16)
BOUNCECAL_SPECTRA4(32)
BOUNCECAL_SPECTRA4(64)
BOUNCECAL_SPECTRA4(128)
#undef BOUNCECAL_SPECTRA4

}  // namespace

bool PowerSpectra4::Supports(int n) {
  return n >= kMinPoints && n <= kMaxPoints && (n & (n - 1)) == 0;
}

PowerSpectra4::PowerSpectra4(int n, std::vector<double> window)
    : n_(n), window_(std::move(window)) {
  if (!Supports(n) || window_.size() != static_cast<std::size_t>(n))
    throw std::invalid_argument("PowerSpectra4: " + std::to_string(n) +
                                " points (a power of two from 8 to 256, with as many weights)");
  const int m = n / 2;
  for (int j = 0; j < m / 2; ++j) {
    const double a = 2.0 * std::numbers::pi * j / m;
    cos_.push_back(std::cos(a));
    sin_.push_back(-std::sin(a));
  }
  for (int k = 0; k <= m; ++k) {
    const double a = 2.0 * std::numbers::pi * k / n;
    split_cos_.push_back(std::cos(a));
    split_sin_.push_back(std::sin(a));
  }
  int bits = 0;
  while ((1 << bits) < m) ++bits;
  for (int i = 0; i < m; ++i) {
    int r = 0;
    for (int b = 0; b < bits; ++b)
      if (i & (1 << b)) r |= 1 << (bits - 1 - b);
    bit_reversed_.push_back(r);
  }
}

void PowerSpectra4::Compute(const float* const src[4], double* const out[4]) const {
  const Tables tb{window_.data(), bit_reversed_.data(), cos_.data(),
                  sin_.data(),    split_cos_.data(),    split_sin_.data()};
  switch (n_) {
    case 8:
      return Spectra4_4(src, tb, out);
    case 16:
      return Spectra4_8(src, tb, out);
    case 32:
      return Spectra4_16(src, tb, out);
    case 64:
      return Spectra4_32(src, tb, out);
    case 128:
      return Spectra4_64(src, tb, out);
    default:
      return Spectra4_128(src, tb, out);
  }
}

}  // namespace bouncecal
