// Output helpers shared by the commands: JSON numbers (null when not finite), coded warnings in
// their one JSON form and their one human form.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bouncecal/core/warning.hpp"

namespace bouncecal::cli {

// A finite number, or null (JSON has no NaN/Inf; unknown values are null, never "nan").
nlohmann::json JsonNumber(double v);
nlohmann::json JsonNumber(const std::optional<double>& v);

// [{"code", "message", "impact": int|null}, ...]
nlohmann::json WarningsJson(const std::vector<Warning>& warnings);

// An option naming a file or directory the command writes (-o, --click-track, --report, ...).
// An empty value (`-o ''`) would read as "not given" and write nothing with exit 0: it is
// refused while parsing with exit 11 (ErrorCode::kOutput) and a message naming the option.
CLI::Option* AddOutputOption(CLI::App* sub, const std::string& names, std::string* path,
                             const std::string& help);

// "bouncecal: warning [code]: message" on stderr, one line each.
void PrintWarnings(const std::vector<Warning>& warnings);

}  // namespace bouncecal::cli
