// Number and list formatting shared by the fit wing's reports and messages (internal).
#pragma once

#include <cstdarg>
#include <cstdio>
#include <iomanip>
#include <sstream>
#include <string>
#include <vector>

namespace bouncecal::fit_text {

// v with `prec` significant digits (std::ostream's default float format).
inline std::string Fmt(double v, int prec = 6) {
  std::ostringstream os;
  os << std::setprecision(prec) << v;
  return os.str();
}

// printf into a std::string (messages up to 255 characters); the format attribute lets the
// compiler check every call's arguments against its format.
__attribute__((format(printf, 1, 2))) inline std::string Printf(const char* format, ...) {
  char buf[256];
  va_list args;
  va_start(args, format);
  std::vsnprintf(buf, sizeof buf, format, args);
  va_end(args);
  return buf;
}

inline std::string Join(const std::vector<std::string>& v, const char* sep = ", ") {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) out += (i ? sep : "") + v[i];
  return out;
}

}  // namespace bouncecal::fit_text
