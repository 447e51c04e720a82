#include "bouncecal/core/atomic_file.hpp"

#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace fs = std::filesystem;

void CheckOutputPath(const std::string& path, const WriteOptions& options) {
  if (path.empty()) throw Error(ErrorCode::kOutput, "output path is empty");
  const fs::path target(path);
  std::error_code ec;
  fs::path dir = target.parent_path();
  if (dir.empty()) dir = ".";
  if (!fs::is_directory(dir, ec)) {
    throw Error(ErrorCode::kOutput, path + ": directory '" + dir.string() + "' does not exist");
  }
  if (fs::is_directory(target, ec)) {
    throw Error(ErrorCode::kOutput, path + ": is a directory");
  }
  const bool exists = fs::exists(target, ec);
  if (exists) {
    for (const auto& in : options.inputs) {
      std::error_code ec2;
      if (fs::exists(in, ec2) && fs::equivalent(target, in, ec2)) {
        throw Error(ErrorCode::kOutput, path + ": is an input file; refusing to overwrite it");
      }
    }
    if (!options.force) {
      throw Error(ErrorCode::kOutput, path + ": exists; use --force to replace it");
    }
  }
}

void WriteFileAtomically(const std::string& path, const std::string& contents,
                         const WriteOptions& options) {
  CheckOutputPath(path, options);
  const fs::path target(path);
  fs::path dir = target.parent_path();
  if (dir.empty()) dir = ".";
  std::random_device rd;
  // Built by appending (GCC 12 reports a false -Wrestrict for "." + std::string&&).
  std::string tmp_name = ".";
  tmp_name += target.filename().string();
  tmp_name += ".tmp";
  tmp_name += std::to_string(::getpid());
  tmp_name += '-';
  tmp_name += std::to_string(rd());
  const fs::path tmp = dir / tmp_name;
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) {
      throw Error(ErrorCode::kOutput, path + ": cannot create a file in '" + dir.string() +
                                          "': " + std::strerror(errno));
    }
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.flush();
    if (!out) {
      std::error_code ec;
      fs::remove(tmp, ec);
      throw Error(ErrorCode::kOutput, path + ": write failed");
    }
  }
  std::error_code ec;
  fs::rename(tmp, target, ec);
  if (ec) {
    std::error_code ec2;
    fs::remove(tmp, ec2);
    throw Error(ErrorCode::kOutput, path + ": cannot rename temporary file: " + ec.message());
  }
}

}  // namespace bouncecal
