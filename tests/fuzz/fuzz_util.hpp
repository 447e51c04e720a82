// Shared by the libFuzzer targets (tests/fuzz/*.cpp; tools/run-fuzz.sh builds and runs them).
// The contract every target checks: any input either works or ends in bouncecal::Error (the
// documented message and exit code). Any other exception, a crash, a hang or a sanitizer report
// is a finding.
#pragma once

#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <string>

namespace bouncecal::fuzz {

// The input as a file (most readers take a path): one file per process, rewritten per input.
inline std::string AsFile(const std::uint8_t* data, std::size_t size, const char* suffix) {
  const std::string path =
      std::string("/tmp/bouncecal_fuzz_") + std::to_string(::getpid()) + suffix;
  std::FILE* f = std::fopen(path.c_str(), "wb");
  if (f == nullptr) return path;
  if (size > 0) std::fwrite(data, 1, size, f);
  std::fclose(f);
  return path;
}

}  // namespace bouncecal::fuzz
