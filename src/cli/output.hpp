// Output helpers shared by the commands: JSON numbers (null when not finite), coded warnings in
// their one JSON form and their one human form.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/core/warning.hpp"

namespace bouncecal::cli {

// A finite number, or null (JSON has no NaN/Inf; unknown values are null, never "nan").
nlohmann::json JsonNumber(double v);
nlohmann::json JsonNumber(const std::optional<double>& v);

// [{"code", "message", "impact": int|null}, ...]
nlohmann::json WarningsJson(const std::vector<Warning>& warnings);

// "bouncecal: warning [code]: message" on stderr, one line each.
void PrintWarnings(const std::vector<Warning>& warnings);

}  // namespace bouncecal::cli
