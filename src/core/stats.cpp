// Robust location and spread, normal quantiles. See include/bouncecal/core/stats.hpp.
#include "bouncecal/core/stats.hpp"

namespace bouncecal {

double Median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

double UpperMedian(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), mid, v.end());
  return *mid;
}

double MedianAbsoluteDeviation(const std::vector<double>& v, double centre) {
  std::vector<double> dev;
  dev.reserve(v.size());
  for (double x : v) dev.push_back(std::fabs(x - centre));
  return UpperMedian(std::move(dev));
}

double NormalQuantileTwoSided(double alpha) {
  // Bisection on erfc: P(|Z| > z) = erfc(z / sqrt 2).
  double a = 0.0, b = 40.0;
  for (int i = 0; i < 200; ++i) {
    const double c = 0.5 * (a + b);
    (std::erfc(c / std::sqrt(2.0)) > alpha ? a : b) = c;
  }
  return 0.5 * (a + b);
}

}  // namespace bouncecal
