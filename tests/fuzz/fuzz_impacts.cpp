// --impacts files (detect JSON, CSV, Audacity labels, plain lists): ReadImpactsFile.
#include <cstddef>
#include <cstdint>

#include "bouncecal/acoustic/impacts_file.hpp"
#include "bouncecal/core/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = bouncecal::fuzz::AsFile(data, size, ".impacts.csv");
  try {
    (void)bouncecal::ReadImpactsFile(path);
  } catch (const bouncecal::Error&) {
  }
  return 0;
}
