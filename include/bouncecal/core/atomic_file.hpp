// bouncecal/core/atomic_file.hpp — write an output file all at once or not at all.
//
// Output files are written to a temporary file in the same directory and renamed over the
// target, so a crash or an error never leaves a partial file. Inputs are never overwritten.
//
//   WriteFileAtomically("params.json", text, {.force = opts.force, .inputs = input_paths});
#pragma once

#include <string>
#include <vector>

namespace bouncecal {

struct WriteOptions {
  bool force = false;               // replace an existing file
  std::vector<std::string> inputs;  // paths that must never be overwritten
};

// Throws Error(kOutput) naming the path: directory missing, target exists without force,
// target is one of the inputs (same file, even through another path), or writing failed.
void WriteFileAtomically(const std::string& path, const std::string& contents,
                         const WriteOptions& options = {});
// Checks the same conditions without writing (run it before expensive work).
void CheckOutputPath(const std::string& path, const WriteOptions& options = {});

}  // namespace bouncecal
