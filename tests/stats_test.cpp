// core/stats.hpp: the medians against sorted samples, the deviation and quantile ranks, the
// normal quantile against tables.
#include "bouncecal/core/stats.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

namespace bouncecal {
namespace {

TEST(Stats, MedianIsTheMiddleValueOrTheMeanOfTheTwoMiddleOnes) {
  EXPECT_EQ(Median({3.0, 1.0, 2.0}), 2.0);
  EXPECT_EQ(Median({3.0, 1.0, 2.0, 10.0}), 2.5);
  EXPECT_EQ(Median({-4.0}), -4.0);
  EXPECT_TRUE(std::isnan(Median({})));
}

TEST(Stats, UpperMedianIsTheHalfRankElementOfASortedCopy) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g;
  for (const std::size_t n : {1u, 2u, 7u, 100u, 1001u}) {
    std::vector<double> v(n);
    for (double& x : v) x = g(rng);
    std::vector<double> sorted = v;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(UpperMedian(v), sorted[n / 2]) << n;
  }
  EXPECT_EQ(UpperMedian({3.0, 1.0, 2.0, 10.0}), 3.0);
  EXPECT_TRUE(std::isnan(UpperMedian({})));
}

TEST(Stats, MedianAbsoluteDeviationOfAGaussianSampleGivesItsSigma) {
  EXPECT_EQ(MedianAbsoluteDeviation({1.0, 2.0, 3.0, 4.0, 100.0}, 3.0), 1.0);  // |dev| 2 1 0 1 97
  std::mt19937 rng(9);
  std::normal_distribution<double> g(5.0, 2.0);
  std::vector<double> v(20001);
  for (double& x : v) x = g(rng);
  // 1.4826 MAD estimates sigma with a relative error of ~1.1 / sqrt(n) = 0.8 %.
  EXPECT_NEAR(1.4826 * MedianAbsoluteDeviation(v, UpperMedian(v)), 2.0, 0.06);
}

TEST(Stats, LowerQuantileTakesRankFloorOfPTimesNMinusOne) {
  std::vector<float> v = {5, 1, 4, 2, 3};  // sorted: 1 2 3 4 5
  EXPECT_EQ(LowerQuantile(&v, 0.0), 1.0);
  EXPECT_EQ(LowerQuantile(&v, 0.5), 3.0);
  EXPECT_EQ(LowerQuantile(&v, 0.74), 3.0);  // floor(0.74 * 4) = 2
  EXPECT_EQ(LowerQuantile(&v, 1.0), 5.0);
  std::vector<float> empty;
  EXPECT_EQ(LowerQuantile(&empty, 0.5), 0.0);
}

TEST(Stats, NormalQuantileMatchesTables) {
  EXPECT_NEAR(NormalQuantileTwoSided(0.05), 1.959964, 1e-6);
  EXPECT_NEAR(NormalQuantileTwoSided(0.01), 2.575829, 1e-6);
  EXPECT_NEAR(NormalQuantileTwoSided(1e-4), 3.890592, 1e-6);
  EXPECT_NEAR(std::erfc(NormalQuantileTwoSided(1e-9) / std::sqrt(2.0)), 1e-9, 1e-18);
}

// The thread-safe replacements give, bit for bit, what the standard library gives (so the
// synthesized sounds and the timing sigma did not change when they replaced it), and the tables.
TEST(Stats, LogGammaAndBesselI0AreTheStandardLibrarysValues) {
  for (double x = 0.05; x < 60.0; x *= 1.07) EXPECT_EQ(LogGamma(x), std::lgamma(x)) << x;
  EXPECT_NEAR(LogGamma(0.5), 0.5 * std::log(M_PI), 1e-15);
  EXPECT_EQ(LogGamma(1.0), 0.0);
  for (double x = 0.0; x <= 12.0; x += 0.013)
    EXPECT_EQ(BesselI0(x), std::cyl_bessel_i(0.0, x)) << x;
  EXPECT_NEAR(BesselI0(1.0), 1.2660658777520082, 1e-15);  // A&S table 9.8
  EXPECT_NEAR(BesselI0(3.0), 4.8807925858650249, 1e-14);
}

}  // namespace
}  // namespace bouncecal
