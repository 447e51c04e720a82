#include "output.hpp"

#include <algorithm>
#include <cstdio>
#include <thread>

#include "bouncecal/core/error.hpp"

namespace bouncecal::cli {

CLI::Option* AddOutputOption(CLI::App* sub, const std::string& names, std::string* path,
                             const std::string& help) {
  const std::string shown = names.substr(names.rfind(',') + 1);  // "--output" of "-o,--output"
  return sub->add_option(names, *path, help)->each([shown](const std::string& value) {
    if (value.empty()) {
      throw Error(ErrorCode::kOutput, shown + ": the output path is empty (give a file name)");
    }
  });
}

void PrintWarnings(const std::vector<Warning>& warnings) {
  for (const Warning& w : warnings)
    std::fprintf(stderr, "bouncecal: warning [%s]: %s\n", w.code.c_str(), w.message.c_str());
}

int DefaultJobs() {
  const unsigned n = std::thread::hardware_concurrency();
  return static_cast<int>(std::clamp(n == 0 ? 1u : n, 1u, 8u));
}

}  // namespace bouncecal::cli
