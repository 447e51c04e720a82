// core/format.hpp: each function against printf's conversion (what it promises), on special
// values and 40 000 random doubles; the shortest form round-trips with the fewest digits.
#include "bouncecal/core/format.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

namespace bouncecal {
namespace {

std::string WithPrintf(const char* format, double v) {
  char buf[512];
  std::snprintf(buf, sizeof buf, format, v);
  return buf;
}

// "%.{p}g" (appended piece by piece: GCC 12's -Wrestrict misreads "literal" + std::string).
std::string GeneralSpec(int p) {
  std::string spec = "%.";
  spec += std::to_string(p);
  spec += 'g';
  return spec;
}

std::vector<double> Samples() {
  std::vector<double> v = {0.0,
                           -0.0,
                           1.0,
                           -1.5,
                           0.1,
                           1e-5,
                           123456.0,
                           1e16,
                           1e17,
                           5e-324,
                           1e-310,
                           2.2250738585072014e-308,
                           std::numeric_limits<double>::max(),
                           std::numeric_limits<double>::quiet_NaN(),
                           std::numeric_limits<double>::infinity(),
                           -std::numeric_limits<double>::infinity()};
  std::mt19937_64 rng(17);
  for (int i = 0; i < 20000; ++i) {
    std::uint64_t bits = rng();
    double x;
    std::memcpy(&x, &bits, sizeof x);
    v.push_back(x);
    v.push_back(
        std::ldexp(static_cast<double>(rng() % 1000000), static_cast<int>(rng() % 80) - 40));
  }
  return v;
}

TEST(Format, FixedAndGeneralArePrintfs) {
  for (double v : Samples()) {
    ASSERT_EQ(FormatFixed(v, 0), WithPrintf("%.0f", v));
    ASSERT_EQ(FormatFixed(v, 4), WithPrintf("%.4f", v));
    ASSERT_EQ(FormatGeneral(v), WithPrintf("%g", v));
    ASSERT_EQ(FormatGeneral(v, 3), WithPrintf("%.3g", v));
    ASSERT_EQ(FormatGeneral(v, 10), WithPrintf("%.10g", v));
    std::string row = "|";
    AppendFixed(&row, v, 3, 12);
    ASSERT_EQ(row.substr(1), WithPrintf("%12.3f", v));
    row.clear();
    AppendGeneral(&row, v, 4, 11);
    ASSERT_EQ(row, WithPrintf("%11.4g", v));
  }
}

TEST(Format, ShortestReadsBackWithTheFewestDigits) {
  EXPECT_EQ(FormatShortest(0.2), "0.2");
  EXPECT_EQ(FormatShortest(123456.0), "123456");
  EXPECT_EQ(FormatShortest(100.0), "1e+02");  // %.1g's layout, where to_chars' shortest is "100"
  EXPECT_EQ(FormatShortest(1e-5), "1e-05");
  EXPECT_EQ(FormatShortest(std::numeric_limits<double>::infinity()), "inf");
  for (double v : Samples()) {
    if (std::isnan(v)) continue;
    const std::string s = FormatShortest(v);
    ASSERT_EQ(std::strtod(s.c_str(), nullptr), v) << s;
    // The least precision p in 1..17 whose %.{p}g reads back (a decimal tie can make the
    // correctly rounded p-digit text miss while a p-digit text exists: then p + 1 digits).
    int p = 1;
    while (p < 17 && std::strtod(WithPrintf(GeneralSpec(p).c_str(), v).c_str(), nullptr) != v) ++p;
    ASSERT_EQ(s, WithPrintf(GeneralSpec(p).c_str(), v));
  }
}

TEST(Format, PrintfHasNoLengthLimit) {
  const std::string long_text(1000, 'x');
  const std::string text = Printf("%s = %.2f", long_text.c_str(), 0.5);
  EXPECT_EQ(text.size(), 1007u);
  EXPECT_EQ(text.substr(995), "xxxxx = 0.50");
  EXPECT_EQ(Printf("%d", 7), "7");
}

}  // namespace
}  // namespace bouncecal
