// Audio files of any format libsndfile reads (FFmpeg is a module loaded on first use and is left
// out here: libFuzzer runs in one process and FFmpeg's decoders are fuzzed upstream), then the
// whole detector on what decodes.
#include <cstddef>
#include <cstdint>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "fuzz_util.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  const auto path = bouncecal::fuzz::AsFile(data, size, ".wav");
  try {
    const bouncecal::Audio audio = bouncecal::ReadAudio(path);
    if (audio.info.frames > 0 && audio.info.frames < 2'000'000) {
      (void)bouncecal::DetectImpacts(audio, bouncecal::DetectOptions{});
    }
  } catch (const bouncecal::Error&) {
  }
  return 0;
}
