// bouncecal/core/atomic_file.hpp — write an output file all at once or not at all.
//
// Output files are written to a temporary file in the target's directory, flushed to disk
// (fsync), and renamed over the target; the directory is synced after the rename. A crash, a
// kill or an error therefore never leaves a partial file, and an existing file is replaced only
// by a complete one. Inputs are never overwritten.
//
//   WriteFileAtomically("params.json", text, {.force = opts.force, .inputs = input_paths});
//
//   AtomicFile out("x.wav", {.force = true});   // for writers that need a descriptor or path
//   sf_open_fd(out.fd(), ...); ...; out.Commit();   // not committed: the temporary file is removed
//
// Conventions (documented in docs/reliability.md, "Writes"):
// - A symbolic link as the target is followed: the file it points to is replaced and the link
//   stays a link (a dangling link is written through to the path it names).
// - Replacing a file keeps its permission bits (a 0600 file stays 0600); a new file gets
//   0666 minus the umask.
// - Temporary names are short (".bc-XXXXXXXX.tmp"), so any legal target name works.
// - A SIGINT/SIGTERM during a write removes the temporary file when the program installed
//   InstallTempFileCleanupOnSignals() (the CLI does): finished outputs stay complete, the
//   interrupted one is never created.
#pragma once

#include <string>
#include <string_view>
#include <vector>

namespace bouncecal {

struct WriteOptions {
  bool force = false;               // replace an existing file
  std::vector<std::string> inputs;  // paths that must never be overwritten
};

// Throws Error(kOutput) naming the path: empty path, directory missing, target is a directory,
// target exists without force, target is one of the inputs (same file, even through another
// path or a link).
void CheckOutputPath(const std::string& path, const WriteOptions& options = {});

// One atomic write in progress. Move-only; not thread-safe (one writer per object).
class AtomicFile {
 public:
  // CheckOutputPath, then creates the temporary file. Throws Error(kOutput).
  AtomicFile(const std::string& path, const WriteOptions& options = {});
  ~AtomicFile();  // not committed: closes and removes the temporary file
  AtomicFile(AtomicFile&& other) noexcept;
  AtomicFile& operator=(AtomicFile&&) = delete;
  AtomicFile(const AtomicFile&) = delete;
  AtomicFile& operator=(const AtomicFile&) = delete;

  int fd() const { return fd_; }                              // open for writing
  const std::string& temp_path() const { return temp_; }      // the temporary file
  const std::string& target_path() const { return target_; }  // where Commit() puts it
  void Write(std::string_view data);                          // all of it, or Error(kOutput)
  // fsync, close, rename over the target (keeping a replaced file's mode), fsync the directory.
  void Commit();

 private:
  std::string path_;    // as given (for messages)
  std::string target_;  // symlinks resolved
  std::string temp_;
  int fd_ = -1;
  bool committed_ = false;
  int slot_ = -1;  // signal-cleanup registration
};

// Writes `contents` to `path` through an AtomicFile.
void WriteFileAtomically(const std::string& path, const std::string& contents,
                         const WriteOptions& options = {});

// Installs SIGINT/SIGTERM handlers that remove the temporary files of writes in progress and
// then end the process with the signal's default action (exit status 128 + signal). For
// programs (the CLI); a library caller that handles signals itself need not call it.
void InstallTempFileCleanupOnSignals();

}  // namespace bouncecal
