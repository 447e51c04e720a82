// Helpers shared by the test suites: a private scratch directory per test process (ctest runs
// the tests of one binary as parallel processes, so fixed names in the system temp directory
// race), and running the bouncecal executable with its output captured.
#pragma once

#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

namespace bouncecal::testing_util {

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
