// Output helpers shared by the commands. The JSON objects themselves (and JsonNumber,
// WarningsJson, CsvNumber, CsvField) are the library's schema (bouncecal/io/schema.hpp).
#pragma once

#include <vector>

#include "bouncecal/core/warning.hpp"
#include "bouncecal/io/schema.hpp"

namespace bouncecal::cli {

// "bouncecal: warning [code]: message" on stderr, one line each.
void PrintWarnings(const std::vector<Warning>& warnings);

}  // namespace bouncecal::cli
