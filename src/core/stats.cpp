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

double LogGamma(double x) {
  int sign = 0;
  return ::lgamma_r(x, &sign);
}

double BesselI0(double x) {
  // libstdc++'s own split: its power series (A&S 9.6.10) where x^2 < 10, where it takes 1 for the
  // prefactor exp(0 log(x/2) - lgamma(1)); Temme's method (no lgamma) beyond.
  if (!(x * x < 10.0)) return std::cyl_bessel_i(0.0, x);
  if (x == 0.0) return 1.0;
  const double xx4 = 0.25 * x * x;
  double sum = 1.0, term = 1.0;
  for (unsigned i = 1; i < 200; ++i) {
    term *= xx4 / (static_cast<double>(i) * static_cast<double>(i));
    sum += term;
    if (std::fabs(term / sum) < std::numeric_limits<double>::epsilon()) break;
  }
  return sum;
}

}  // namespace bouncecal
