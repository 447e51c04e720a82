#include "output.hpp"

#include <cstdio>

namespace bouncecal::cli {

void PrintWarnings(const std::vector<Warning>& warnings) {
  for (const Warning& w : warnings)
    std::fprintf(stderr, "bouncecal: warning [%s]: %s\n", w.code.c_str(), w.message.c_str());
}

}  // namespace bouncecal::cli
