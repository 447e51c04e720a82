// The relative spectral flux of the whitened signal on a short-hop STFT (the onset detector's
// novelty). See include/bouncecal/acoustic/onsets.hpp.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <vector>

#include "avx2_clones.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/parallel.hpp"
#include "onset_constants.hpp"
#include "spectra.hpp"

namespace bouncecal {
namespace {

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
double MedianOfNonNegative(const double* v, std::size_t n, int threads) {
  auto key = [](double x) {
    const double y = x + 0.0;  // -0 -> +0
    std::uint64_t k;
    std::memcpy(&k, &y, sizeof k);
    return k;
  };
  const std::size_t parts = std::clamp<std::size_t>(n / 16384, 1, std::max(1, threads));
  const std::size_t part = (n + parts - 1) / parts;
  std::vector<std::vector<std::uint32_t>> counts(parts);
  ParallelFor(threads, parts, [&](std::size_t p) {
    std::vector<std::uint32_t>& c = counts[p];
    c.assign(kMedianBuckets, 0);
    for (std::size_t i = p * part; i < std::min(n, (p + 1) * part); ++i)
      if (v[i] >= 0.0) ++c[key(v[i]) >> kMedianKeyShift];
  });
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

// The novelty's frames are computed a chunk at a time (each chunk its own power spectra: memory
// for one chunk per thread, whatever the length): kSpectraChunk frames, fewer where the power
// rows of that many would pass kSpectraChunkBytes (long hops, --hop-ms: 16 MB per thread at
// 5 ms), at least kMinSpectraChunk.
constexpr std::size_t kSpectraChunkBytes = std::size_t{2} << 20;
constexpr std::size_t kMinSpectraChunk = 256;

// Frames averaged into the novelty's reference spectrum (~3 ms at the default hop).
constexpr std::size_t kRefFrames = 8;

// Frames per novelty chunk for power rows of `bins` values (a multiple of the frame batch).
std::size_t SpectraChunkFrames(std::size_t bins) {
  const std::size_t fit = kSpectraChunkBytes / (bins * sizeof(double)) / 8 * 8;
  return std::clamp(fit, kMinSpectraChunk, kSpectraChunk);
}

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
      threads, std::min<std::size_t>(chunks, static_cast<std::size_t>(threads)), [&](std::size_t) {
        FftArrays a(nw);
        Buffer<double> power, scratch, ref;  // written before they are read
        power.Allocate((std::min(frames, chunk) + warm) * bins);
        scratch.Allocate(kNoveltyBatch * bins);
        ref.Allocate(bins);
        for (std::size_t ch = next_chunk++; ch < chunks; ch = next_chunk++) {
          const std::size_t c0 = ch * chunk, c1 = std::min(frames, c0 + chunk);
          const std::size_t p0 = c0 >= warm ? c0 - warm : 0;  // first power row of this chunk
          for (std::size_t t = p0; t < c1; ++t) {
            spectra::Windowed(w.data() + t * hop, f.window.data(), nw, a.real);
            fftw_execute_dft_r2c(f.plan, a.real, a.spec);
            spectra::PowerSpectrum(a.spec, bins, power.data.get() + (t - p0) * bins);
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
      });
  // Floor of the denominator: the median reference power (the background), so silence and
  // digital zeros do not turn tiny increases into large ratios.
  // (-1 marks a frame whose reference is not full.)
  double floor_power = MedianOfNonNegative(den.data.get(), frames, threads);
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
  std::vector<double> novelty(frames, 0.0);
  const std::size_t group = std::max<std::size_t>(kSpectraChunk, frames / (4 * threads) + 1);
  ParallelForGroups(threads, frames, group, [&](std::size_t t0, std::size_t t1) {
    for (std::size_t t = t0; t < t1; ++t) {
      const double d = den[t] < 0.0 ? floor_power : den[t];
      raw_db[t] = 10.0 * std::log10(1.0 + num[t] / (d + floor_power));
    }
  });
  ParallelForGroups(threads, frames, group, [&](std::size_t t0, std::size_t t1) {
    for (std::size_t t = std::max<std::size_t>(t0, 1); t < std::min(t1, frames - 1); ++t)
      novelty[t] = (raw_db[t - 1] + raw_db[t] + raw_db[t + 1]) / 3.0;
  });
  return novelty;
}

}  // namespace bouncecal
