// The FFTs of onset detection (internal to the library, src/): FFTW plans made once per
// OnsetDetector and executed on arrays of each thread's own, the short-time spectra of the
// novelty (OnsetDetector::Fft) and the overlap-save correlation of the template search
// (OnsetDetector::Correlator), and the per-sample loops around them.
#pragma once

#include <fftw3.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <memory>
#include <mutex>
#include <new>
#include <numbers>
#include <vector>

#include "bouncecal/acoustic/onsets.hpp"

namespace bouncecal {

// FFTW's planner (plan creation and destruction) is not thread-safe; execution of distinct
// plans is. This mutex serialises the planner calls of all OnsetDetectors.
std::mutex& PlannerMutex();

// An array that is written in full before it is read: unlike std::vector it is not zero-filled
// first (the fill of two such float arrays per block and signal, 23 MB each for 2 minutes at
// 48 kHz, was 8 % of detection time).
template <typename T>
struct Buffer {
  std::unique_ptr<T[]> data;
  std::size_t n = 0;
  void Allocate(std::size_t size) {
    data.reset(new T[size]);
    n = size;
  }
  std::size_t size() const { return n; }
  T operator[](std::size_t i) const { return data[i]; }
  T& operator[](std::size_t i) { return data[i]; }
};
using FloatBuffer = Buffer<float>;

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

// The per-sample loops around the FFTs (the novelty's frames, the template correlation's
// overlap-save blocks), compiled for AVX2 and for the baseline x86-64 (avx2_clones.hpp): the
// same conversions, products and sums per element, more elements per instruction.
namespace spectra {
void Windowed(const float* __restrict src, const double* __restrict window, std::size_t n,
              double* __restrict out);
void PowerSpectrum(const fftw_complex* __restrict spec, std::size_t bins, double* __restrict p);
void ToDouble(const float* __restrict x, std::size_t n, double* __restrict out);
// spec = spec * conj(t), bin by bin (correlation in the frequency domain).
void MultiplyByConjugate(fftw_complex* __restrict spec, const fftw_complex* __restrict t,
                         std::size_t bins);
void ScaledToFloat(const double* __restrict in, std::size_t n, double scale, float* __restrict out);
}  // namespace spectra

struct OnsetDetector::Fft {
  int n = 0;
  double* in = nullptr;
  fftw_complex* out = nullptr;
  fftw_plan plan = nullptr;
  std::vector<double> window;
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
      spectra::ToDouble(x.data() + b, len, buf);
      std::fill(buf + len, buf + nn, 0.0);
      fftw_execute_dft_r2c(fwd, buf, spec);
      spectra::MultiplyByConjugate(spec, tspec, nb);  // X * conj(H): correlation
      fftw_execute_dft_c2r(inv, spec, buf);
      const std::size_t i0 = std::max(b, lo), i1 = std::min({b + step, hi, x.size()});
      if (i1 > i0) spectra::ScaledToFloat(buf + (i0 - b), i1 - i0, scale, out + (i0 - lo));
    }
  }
};

}  // namespace bouncecal
