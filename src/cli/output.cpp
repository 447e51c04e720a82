#include "output.hpp"

#include <cmath>
#include <cstdio>

namespace bouncecal::cli {

nlohmann::json JsonNumber(double v) {
  return std::isfinite(v) ? nlohmann::json(v) : nlohmann::json();
}

nlohmann::json JsonNumber(const std::optional<double>& v) {
  return v ? JsonNumber(*v) : nlohmann::json();
}

nlohmann::json WarningsJson(const std::vector<Warning>& warnings) {
  nlohmann::json out = nlohmann::json::array();
  for (const Warning& w : warnings) {
    out.push_back({{"code", w.code},
                   {"message", w.message},
                   {"impact", w.impact >= 0 ? nlohmann::json(w.impact) : nlohmann::json()}});
  }
  return out;
}

void PrintWarnings(const std::vector<Warning>& warnings) {
  for (const Warning& w : warnings)
    std::fprintf(stderr, "bouncecal: warning [%s]: %s\n", w.code.c_str(), w.message.c_str());
}

}  // namespace bouncecal::cli
