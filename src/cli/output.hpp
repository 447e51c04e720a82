// Output helpers shared by the commands. The JSON objects themselves (and JsonNumber,
// WarningsJson, CsvNumber, CsvField) are the library's schema (bouncecal/io/schema.hpp).
#pragma once

#include <vector>

#include <CLI/CLI.hpp>

#include "bouncecal/core/warning.hpp"
#include "bouncecal/io/schema.hpp"

namespace bouncecal::cli {

// An option naming a file or directory the command writes (-o, --click-track, --report, ...).
// An empty value (`-o ''`) would read as "not given" and write nothing with exit 0: it is
// refused while parsing with exit 11 (ErrorCode::kOutput) and a message naming the option.
CLI::Option* AddOutputOption(CLI::App* sub, const std::string& names, std::string* path,
                             const std::string& help);

// Default worker threads for --jobs: the machine's cores, at least 1 and at most 8. Outputs do
// not depend on the thread count (tested: --law all and --batch are byte-identical).
int DefaultJobs();

// "bouncecal: warning [code]: message" on stderr, one line each.
void PrintWarnings(const std::vector<Warning>& warnings);

}  // namespace bouncecal::cli
