// bouncecal/core/format.hpp — numbers as text, for messages, tables and files.
//
// Each function gives exactly what printf gives for the same conversion in the C locale:
// std::to_chars with a precision is defined that way ([charconv.to.chars]), without printf's
// locale or format parsing. FormatShortest is the round-trip form: the fewest significant
// digits that read back as the same double, laid out as %g lays them out.
//
//   FormatFixed(0.12345, 3)    // "0.123"        printf("%.3f")
//   FormatGeneral(1234567.0)   // "1.23457e+06"  printf("%g")
//   FormatGeneral(0.5, 10)     // "0.5"          printf("%.10g"), std::ostream at precision 10
//   FormatShortest(0.1)        // "0.1"          reads back as 0.1
//
// Common mistake: std::to_chars without a precision is also "shortest", but it picks fixed or
// scientific by length (1e+05 for 100000), not as %g does: use FormatShortest.
#pragma once

#include <string>

namespace bouncecal {

// The shortest %g text that reads back (strtod) as v: "%.{p}g" with the least p in 1..17
// that round-trips.
std::string FormatShortest(double v);

// printf("%.{significant_digits}g", v); also what std::ostream prints at that precision.
std::string FormatGeneral(double v, int significant_digits = 6);

// printf("%.{decimals}f", v).
std::string FormatFixed(double v, int decimals);

// The same, appended right-aligned in `width` characters: printf's "%*.*f" and "%*.*g".
void AppendFixed(std::string* out, double v, int decimals, int width = 0);
void AppendGeneral(std::string* out, double v, int significant_digits, int width = 0);

// printf into a std::string, for messages of any length; the format attribute lets the compiler
// check every call's arguments against its format.
__attribute__((format(printf, 1, 2))) std::string Printf(const char* format, ...);

}  // namespace bouncecal
