// List formatting shared by the fit wing's reports and messages (internal); numbers are
// core/format.hpp's.
#pragma once

#include <string>
#include <vector>

#include "bouncecal/core/format.hpp"

namespace bouncecal::fit_text {

inline std::string Join(const std::vector<std::string>& v, const char* sep = ", ") {
  std::string out;
  for (size_t i = 0; i < v.size(); ++i) out += (i ? sep : "") + v[i];
  return out;
}

}  // namespace bouncecal::fit_text
