// Parameter files (bouncecal.params/1 and /2 JSON): ReadParamFile.
#include <cstddef>
#include <cstdint>

#include "bouncecal/core/error.hpp"
#include "bouncecal/io/param_file.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = bouncecal::fuzz::AsFile(data, size, ".params.json");
  try {
    (void)bouncecal::ReadParamFile(path);
  } catch (const bouncecal::Error&) {
  }
  return 0;
}
