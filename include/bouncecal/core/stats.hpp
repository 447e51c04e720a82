// bouncecal/core/stats.hpp — robust location and spread of a sample, normal quantiles, and two
// special functions safe to call from several threads.
//
//   Median({3, 1, 2, 10})        // 2.5: the mean of the two middle values
//   UpperMedian({3, 1, 2, 10})   // 3: the (n / 2)-th smallest, what std::nth_element selects
//   1.4826 * MedianAbsoluteDeviation(x, UpperMedian(x))  // a Gaussian's sigma, robustly
//
// Median is the textbook median; UpperMedian is one element of the sample, selected in O(n),
// for large samples and where a value of the sample is wanted. NaN for an empty sample.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <vector>

namespace bouncecal {

// The middle value of v, or the mean of the two middle values for an even count.
double Median(std::vector<double> v);

// The (v.size() / 2)-th smallest value of v (0-based).
double UpperMedian(std::vector<double> v);

// The UpperMedian of |v[i] - centre|.
double MedianAbsoluteDeviation(const std::vector<double>& v, double centre);

// The value of rank floor(p (n - 1)) (0-based) of v, p in [0, 1]; v is reordered. 0 when empty.
template <typename T>
double LowerQuantile(std::vector<T>* v, double p) {
  if (v->empty()) return 0.0;
  const auto k = static_cast<std::size_t>(std::min<double>(
      static_cast<double>(v->size() - 1), std::floor(p * static_cast<double>(v->size() - 1))));
  std::nth_element(v->begin(), v->begin() + static_cast<std::ptrdiff_t>(k), v->end());
  return static_cast<double>((*v)[k]);
}

// z with P(|Z| > z) = alpha for a standard normal Z (two-sided), alpha in (0, 1].
double NormalQuantileTwoSided(double alpha);

// Thread-safe special functions. std::lgamma writes the process-wide `signgam`, and
// std::cyl_bessel_i's series branch calls it: a data race when detection runs on several threads.
// log|Gamma(x)|, the value std::lgamma gives, without touching signgam.
double LogGamma(double x);
// The modified Bessel function I0(x), x >= 0, the value std::cyl_bessel_i(0, x) gives.
double BesselI0(double x);

}  // namespace bouncecal
