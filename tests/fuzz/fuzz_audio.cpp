// Audio files of any format libsndfile reads, and what it cannot through our FFmpeg module
// (libbouncecal_ffmpeg.so, loaded from the build directory on first use and instrumented like
// the library: its first finding was ours, a stream changing format mid-way), then the whole
// detector on what decodes.
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
