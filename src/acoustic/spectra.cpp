// The FFTs of onset detection. See spectra.hpp.
#include "spectra.hpp"

#include "avx2_clones.hpp"

namespace bouncecal {

std::mutex& PlannerMutex() {
  static std::mutex m;
  return m;
}

namespace spectra {

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

}  // namespace spectra
}  // namespace bouncecal
