// Tests of the novelty's four-frame power spectra (src/acoustic/power_spectra.hpp) against
// FFTW's real transform: the same spectrum to rounding, each frame's values independent of the
// frames that share its call, and the sizes it refuses.
#include "acoustic/power_spectra.hpp"

#include <fftw3.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace bouncecal {
namespace {

std::vector<double> Hann(int n) {
  std::vector<double> w(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i)
    w[static_cast<std::size_t>(i)] = 0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * i / n);
  return w;
}

// |X(k)|^2, k in [0, n/2], of x * window by FFTW (the reference the detector used before).
std::vector<double> FftwPower(const float* x, const std::vector<double>& window) {
  const int n = static_cast<int>(window.size());
  double* in = fftw_alloc_real(static_cast<std::size_t>(n));
  fftw_complex* out = fftw_alloc_complex(static_cast<std::size_t>(n / 2 + 1));
  fftw_plan plan = fftw_plan_dft_r2c_1d(n, in, out, FFTW_ESTIMATE);
  for (int i = 0; i < n; ++i) in[i] = x[i] * window[static_cast<std::size_t>(i)];
  fftw_execute(plan);
  std::vector<double> p(static_cast<std::size_t>(n / 2 + 1));
  for (int k = 0; k <= n / 2; ++k)
    p[static_cast<std::size_t>(k)] = out[k][0] * out[k][0] + out[k][1] * out[k][1];
  fftw_destroy_plan(plan);
  fftw_free(in);
  fftw_free(out);
  return p;
}

class PowerSpectraSize : public ::testing::TestWithParam<int> {};

TEST_P(PowerSpectraSize, EqualsFftwToRounding) {
  const int n = GetParam();
  const std::size_t bins = static_cast<std::size_t>(n / 2 + 1);
  std::mt19937 rng(n);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  // Four frames: noise, a click (one sample), a pure tone on bin 3, and silence.
  std::vector<std::vector<float>> frames(4, std::vector<float>(static_cast<std::size_t>(n), 0.0f));
  for (float& v : frames[0]) v = noise(rng);
  frames[1][static_cast<std::size_t>(n / 3)] = 0.7f;
  for (int i = 0; i < n; ++i)
    frames[2][static_cast<std::size_t>(i)] =
        static_cast<float>(std::sin(2.0 * std::numbers::pi * 3.0 * i / n));
  const std::vector<double> window = Hann(n);
  const PowerSpectra4 ps(n, window);
  std::vector<std::vector<double>> got(4, std::vector<double>(bins, -1.0));
  const float* src[4] = {frames[0].data(), frames[1].data(), frames[2].data(), frames[3].data()};
  double* out[4] = {got[0].data(), got[1].data(), got[2].data(), got[3].data()};
  ps.Compute(src, out);
  for (int j = 0; j < 4; ++j) {
    const std::vector<double> want = FftwPower(frames[static_cast<std::size_t>(j)].data(), window);
    const double peak = *std::max_element(want.begin(), want.end());
    for (std::size_t k = 0; k < bins; ++k)
      EXPECT_NEAR(got[static_cast<std::size_t>(j)][k], want[k], 1e-13 * std::max(peak, 1e-300))
          << "frame " << j << " bin " << k << " of " << n << " points";
  }
  // The tone's power peaks in bin 3, and outside the Hann window's main lobes (of bin 3 and of
  // its image n - 3) only the sine's float rounding is left.
  const auto peak = std::max_element(got[2].begin(), got[2].end());
  EXPECT_EQ(peak - got[2].begin(), 3);
  for (std::size_t k = 0; k < bins; ++k) {
    const long d = static_cast<long>(k);
    if (std::labs(d - 3) >= 2 && std::labs(d - (n - 3)) >= 2) {
      EXPECT_LT(got[2][k], 1e-12 * *peak) << "bin " << k;
    }
  }
  for (double p : got[3]) EXPECT_EQ(p, 0.0);
}

TEST_P(PowerSpectraSize, AFramesValuesDoNotDependOnItsLaneOrNeighbours) {
  const int n = GetParam();
  const std::size_t bins = static_cast<std::size_t>(n / 2 + 1);
  std::mt19937 rng(7 * n);
  std::uniform_real_distribution<float> u(-1.0f, 1.0f);
  std::vector<float> x(static_cast<std::size_t>(8 * n));
  for (float& v : x) v = u(rng);
  const PowerSpectra4 ps(n, Hann(n));
  const float* frame = x.data();  // the frame under test
  std::vector<double> first;
  for (int lane = 0; lane < 4; ++lane) {
    const float* src[4];
    for (int j = 0; j < 4; ++j)
      src[j] = j == lane ? frame : x.data() + static_cast<std::size_t>((j + 1 + lane) * n);
    std::vector<std::vector<double>> got(4, std::vector<double>(bins));
    double* out[4] = {got[0].data(), got[1].data(), got[2].data(), got[3].data()};
    ps.Compute(src, out);
    if (lane == 0) {
      first = got[0];
      continue;
    }
    EXPECT_EQ(0, std::memcmp(first.data(), got[static_cast<std::size_t>(lane)].data(),
                             bins * sizeof(double)))
        << "lane " << lane;
  }
}

INSTANTIATE_TEST_SUITE_P(Sizes, PowerSpectraSize, ::testing::Values(8, 16, 32, 64, 128, 256),
                         [](const ::testing::TestParamInfo<int>& i) {
                           std::string name = "n";
                           name += std::to_string(i.param);
                           return name;
                         });

TEST(PowerSpectra4, RefusesSizesItCannotTransform) {
  EXPECT_FALSE(PowerSpectra4::Supports(4));
  EXPECT_FALSE(PowerSpectra4::Supports(48));
  EXPECT_FALSE(PowerSpectra4::Supports(512));
  EXPECT_TRUE(PowerSpectra4::Supports(64));
  EXPECT_THROW(PowerSpectra4(48, std::vector<double>(48, 1.0)), std::invalid_argument);
  EXPECT_THROW(PowerSpectra4(64, std::vector<double>(63, 1.0)), std::invalid_argument);
}

}  // namespace
}  // namespace bouncecal
