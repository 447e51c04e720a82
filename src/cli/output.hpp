// Output helpers shared by the commands. The JSON objects themselves (and JsonNumber,
// WarningsJson, CsvNumber, CsvField) are the library's schema (bouncecal/io/schema.hpp).
#pragma once

#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bouncecal/core/error.hpp"
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

// Library messages name Options fields ("SceneOverrides::height_m", "WriteOptions::force"); a
// user of the command line reads the flags. FlagText rewrites a message with the flag that
// sets each field named in it ("--height", "use --force to replace it"): one table in
// output.cpp, applied to every error main() prints and to the per-input errors of batch runs.
std::string FlagText(const std::string& message);
// Runs f; an Error it throws comes out with its message in flag names (same code).
template <class F>
auto WithFlagText(F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error& e) {
    throw Error(e.code(), FlagText(e.what()));
  }
}

}  // namespace bouncecal::cli
