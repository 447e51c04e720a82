// Numbers as text. See include/bouncecal/core/format.hpp.
#include "bouncecal/core/format.hpp"

#include <algorithm>
#include <charconv>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <string_view>
#include <system_error>

namespace bouncecal {
namespace {

// Large enough for any double in fixed notation with up to 17 decimals (DBL_MAX has 309
// integer digits).
constexpr int kBuffer = 352;

void Append(std::string* out, double v, std::chars_format format, int precision, int width) {
  char buf[kBuffer];
  const std::to_chars_result r = std::to_chars(buf, buf + sizeof buf, v, format, precision);
  std::string_view text;
  std::string wide;
  if (r.ec == std::errc()) {
    text = std::string_view(buf, static_cast<std::size_t>(r.ptr - buf));
  } else {  // more decimals than the buffer holds: printf's own conversion
    const char* spec = format == std::chars_format::fixed ? "%.*f" : "%.*g";
    wide.resize(static_cast<std::size_t>(std::snprintf(nullptr, 0, spec, precision, v)) + 1);
    wide.resize(
        static_cast<std::size_t>(std::snprintf(wide.data(), wide.size(), spec, precision, v)));
    text = wide;
  }
  if (text.size() < static_cast<std::size_t>(width))
    out->append(static_cast<std::size_t>(width) - text.size(), ' ');
  out->append(text);
}

// strtod, not std::from_chars: libstdc++'s from_chars refuses subnormal results.
bool ReadsBackAs(char* first, char* last, double v) {
  *last = '\0';
  return std::strtod(first, nullptr) == v;
}

}  // namespace

std::string FormatShortest(double v) {
  // std::to_chars's shortest form has the least significant digits that round-trip; %g with
  // that precision is its correctly rounded value, which reads back too except near a decimal
  // tie (then one digit more does, as printf's own search would find).
  char buf[64];
  const std::to_chars_result shortest =
      std::to_chars(buf, buf + sizeof buf, v, std::chars_format::scientific);
  int digits = 0;
  for (const char* p = buf; p < shortest.ptr && *p != 'e'; ++p) digits += *p >= '0' && *p <= '9';
  for (int p = std::max(digits, 1); p <= 17; ++p) {
    const std::to_chars_result r =
        std::to_chars(buf, buf + sizeof buf, v, std::chars_format::general, p);
    if (ReadsBackAs(buf, r.ptr, v)) return std::string(buf, r.ptr);
  }
  return FormatGeneral(v, 17);
}

std::string FormatGeneral(double v, int significant_digits) {
  std::string out;
  Append(&out, v, std::chars_format::general, significant_digits, 0);
  return out;
}

std::string FormatFixed(double v, int decimals) {
  std::string out;
  Append(&out, v, std::chars_format::fixed, decimals, 0);
  return out;
}

void AppendFixed(std::string* out, double v, int decimals, int width) {
  Append(out, v, std::chars_format::fixed, decimals, width);
}

void AppendGeneral(std::string* out, double v, int significant_digits, int width) {
  Append(out, v, std::chars_format::general, significant_digits, width);
}

std::string Printf(const char* format, ...) {
  va_list args;
  va_start(args, format);
  va_list again;
  va_copy(again, args);
  const int n = std::vsnprintf(nullptr, 0, format, args);
  va_end(args);
  std::string out(static_cast<std::size_t>(n > 0 ? n : 0) + 1, '\0');
  std::vsnprintf(out.data(), out.size(), format, again);
  va_end(again);
  out.resize(static_cast<std::size_t>(n > 0 ? n : 0));
  return out;
}

}  // namespace bouncecal
