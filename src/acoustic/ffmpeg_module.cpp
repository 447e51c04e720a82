// ReadAudioFfmpeg: loads libbouncecal_ffmpeg.so (src/acoustic/ffmpeg_audio.cpp) the first time a
// recording needs FFmpeg, and calls its decoder. The module is looked for, in this order:
//   1. the file named by the environment variable BOUNCECAL_FFMPEG_MODULE (installs, tests);
//   2. next to the binary or shared object this library is linked into (build/bouncecal, the
//      test programs, the Python module);
//   3. the build directory this library was compiled for (BOUNCECAL_MODULE_DIR).
// Loading happens once per process (std::call_once); the handle is never closed. A missing
// module is an Error(kNotAudio) that names the file and says where the module was looked for.
#include <dlfcn.h>

#include <cstddef>
#include <filesystem>
#include <mutex>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

using DecodeFn = int (*)(const char* path, Audio* out, int* exit_code, char* message,
                         std::size_t message_size);

constexpr const char* kModuleName = "libbouncecal_ffmpeg.so";
constexpr const char* kEntryPoint = "bouncecal_ffmpeg_decode_v1";

struct Module {
  DecodeFn decode = nullptr;
  std::string why;  // when decode is null: where it was looked for and what failed
};

std::vector<std::string> Candidates() {
  std::vector<std::string> out;
  if (const char* env = std::getenv("BOUNCECAL_FFMPEG_MODULE"); env != nullptr && *env != '\0') {
    out.push_back(env);
  }
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&ReadAudioFfmpeg), &info) != 0 && info.dli_fname != nullptr) {
    std::error_code ec;
    const std::filesystem::path self = std::filesystem::canonical(info.dli_fname, ec);
    if (!ec) out.push_back((self.parent_path() / kModuleName).string());
  }
  out.push_back((std::filesystem::path(BOUNCECAL_MODULE_DIR) / kModuleName).string());
  return out;
}

Module Load() {
  Module m;
  for (const std::string& path : Candidates()) {
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* e = dlerror();
      m.why += (m.why.empty() ? "" : "; ") + (e != nullptr ? std::string(e) : path);
      continue;
    }
    m.decode = reinterpret_cast<DecodeFn>(dlsym(handle, kEntryPoint));
    if (m.decode != nullptr) return m;
    m.why += (m.why.empty() ? "" : "; ") + path + ": no " + kEntryPoint;
    dlclose(handle);
  }
  return m;
}

const Module& TheModule() {
  static std::once_flag once;
  static Module module;
  std::call_once(once, [] { module = Load(); });
  return module;
}

}  // namespace

bool FfmpegAvailable() { return TheModule().decode != nullptr; }

Audio ReadAudioFfmpeg(const std::string& path) {
  const Module& m = TheModule();
  if (m.decode == nullptr) {
    throw Error(ErrorCode::kNotAudio, path + ": FFmpeg decoding is unavailable (" + kModuleName +
                                          " not loaded: " + m.why + ")");
  }
  Audio out;
  int exit_code = static_cast<int>(ErrorCode::kInternal);
  char message[1024] = {0};
  if (m.decode(path.c_str(), &out, &exit_code, message, sizeof message) != 0) {
    throw Error(static_cast<ErrorCode>(exit_code), message);
  }
  return out;
}

}  // namespace bouncecal
