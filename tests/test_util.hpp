// Helpers shared by the test suites: a private scratch directory per test process (ctest runs
// the tests of one binary as parallel processes, so fixed names in the system temp directory
// race), and running the bouncecal executable with its output captured.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

namespace bouncecal::testing_util {

// A 32-bit float WAV written byte by byte (WAVE_FORMAT_IEEE_FLOAT), so that samples the writer
// refuses (NaN, Inf) can be put into a file. `interleaved`: frame after frame, every channel.
inline void WriteFloatWav(const std::string& path, const std::vector<float>& interleaved,
                          int channels, int rate) {
  auto u32 = [](std::ofstream& o, std::uint32_t v) { o.write(reinterpret_cast<char*>(&v), 4); };
  auto u16 = [](std::ofstream& o, std::uint16_t v) { o.write(reinterpret_cast<char*>(&v), 2); };
  const auto data_bytes = static_cast<std::uint32_t>(interleaved.size() * 4);
  std::ofstream o(path, std::ios::binary);
  o.write("RIFF", 4);
  u32(o, 36 + data_bytes);
  o.write("WAVEfmt ", 8);
  u32(o, 16);
  u16(o, 3);  // IEEE float
  u16(o, static_cast<std::uint16_t>(channels));
  u32(o, static_cast<std::uint32_t>(rate));
  u32(o, static_cast<std::uint32_t>(rate * channels * 4));
  u16(o, static_cast<std::uint16_t>(channels * 4));
  u16(o, 32);
  o.write("data", 4);
  u32(o, data_bytes);
  o.write(reinterpret_cast<const char*>(interleaved.data()), data_bytes);
}

// A directory that exists for the lifetime of the object and is removed with it; unique per
// process and per object.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag = "bc") {
    static std::atomic<int> counter{0};
    path_ = std::filesystem::temp_directory_path() /
            (tag + "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++));
    std::filesystem::create_directories(path_);
  }
  ~ScratchDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  std::string operator/(const std::string& name) const { return (path_ / name).string(); }
  const std::filesystem::path& path() const { return path_; }

 private:
  std::filesystem::path path_;
};

inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

struct CommandResult {
  int exit_code = -1;
  std::string out, err;
};

// Runs `binary args` through the shell (args are passed as written: quote paths yourself).
inline CommandResult RunCommand(const std::string& binary, const std::string& args) {
  ScratchDir dir("bc_run");
  const std::string out = dir / "out.txt", err = dir / "err.txt";
  const std::string cmd = binary + " " + args + " >" + out + " 2>" + err;
  const int status = std::system(cmd.c_str());
  CommandResult r;
  r.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  r.out = Slurp(out);
  r.err = Slurp(err);
  return r;
}

}  // namespace bouncecal::testing_util
