// Atomic writes: all or nothing, never an input, modes kept, links followed, no temp left.
#include "bouncecal/core/atomic_file.hpp"

#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <csignal>
#include <filesystem>
#include <string>

#include "bouncecal/core/error.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

namespace fs = std::filesystem;
using testing_util::ScratchDir;
using testing_util::Slurp;

int Entries(const ScratchDir& d) {
  return static_cast<int>(std::distance(fs::directory_iterator(d.path()), {}));
}

ErrorCode CodeOfWrite(const std::string& path, const WriteOptions& o, std::string* msg = nullptr) {
  try {
    WriteFileAtomically(path, "x", o);
  } catch (const Error& e) {
    if (msg) *msg = e.what();
    return e.code();
  }
  return ErrorCode::kOk;
}

TEST(AtomicFile, WritesTheContentsAndLeavesNoTemporaryFile) {
  ScratchDir d("bc_atomic");
  WriteFileAtomically(d / "a.json", "{\"a\": 1}\n");
  EXPECT_EQ(Slurp(d / "a.json"), "{\"a\": 1}\n");
  EXPECT_EQ(Entries(d), 1);
}

TEST(AtomicFile, RefusesAnExistingFileWithoutForceAndAnInputEvenWithForce) {
  ScratchDir d("bc_atomic");
  WriteFileAtomically(d / "a.txt", "old");
  std::string msg;
  EXPECT_EQ(CodeOfWrite(d / "a.txt", {}, &msg), ErrorCode::kOutput);
  EXPECT_NE(msg.find(d / "a.txt"), std::string::npos) << msg;
  EXPECT_NE(msg.find("exists"), std::string::npos) << msg;
  EXPECT_EQ(Slurp(d / "a.txt"), "old");
  // The same file through another path is still the input.
  const std::string other = (d.path() / "." / "a.txt").string();
  EXPECT_EQ(CodeOfWrite(d / "a.txt", {.force = true, .inputs = {other}}, &msg), ErrorCode::kOutput);
  EXPECT_NE(msg.find("input"), std::string::npos) << msg;
  EXPECT_EQ(Slurp(d / "a.txt"), "old");
  EXPECT_EQ(CodeOfWrite(d / "a.txt", {.force = true, .inputs = {}}), ErrorCode::kOk);
  EXPECT_EQ(Slurp(d / "a.txt"), "x");
  EXPECT_EQ(Entries(d), 1);
}

TEST(AtomicFile, BadPathsAreOutputErrorsNamingThePath) {
  ScratchDir d("bc_atomic");
  std::string msg;
  EXPECT_EQ(CodeOfWrite("", {}, &msg), ErrorCode::kOutput);
  EXPECT_NE(msg.find("empty"), std::string::npos) << msg;
  EXPECT_EQ(CodeOfWrite(d / "no-such-dir/a.txt", {}, &msg), ErrorCode::kOutput);
  EXPECT_NE(msg.find("does not exist"), std::string::npos) << msg;
  EXPECT_EQ(CodeOfWrite(d.path().string(), {.force = true, .inputs = {}}, &msg),
            ErrorCode::kOutput);
  EXPECT_NE(msg.find("is a directory"), std::string::npos) << msg;
  EXPECT_EQ(Entries(d), 0);
}

TEST(AtomicFile, ReplacingKeepsTheFilesPermissionBits) {
  ScratchDir d("bc_atomic");
  WriteFileAtomically(d / "secret.json", "old");
  ASSERT_EQ(::chmod((d / "secret.json").c_str(), 0600), 0);
  WriteFileAtomically(d / "secret.json", "new", {.force = true, .inputs = {}});
  struct stat st {};
  ASSERT_EQ(::stat((d / "secret.json").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 07777, 0600u);
  EXPECT_EQ(Slurp(d / "secret.json"), "new");
}

TEST(AtomicFile, SymbolicLinksAreFollowedAndStayLinks) {
  ScratchDir d("bc_atomic");
  fs::create_directories(d.path() / "real");
  WriteFileAtomically(d / "real/out.json", "old");
  fs::create_symlink("real/out.json", d.path() / "link.json");
  WriteFileAtomically(d / "link.json", "new", {.force = true, .inputs = {}});
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(d.path() / "link.json")));
  EXPECT_EQ(Slurp(d / "real/out.json"), "new");
  // A dangling link is written through to the file it names.
  fs::create_symlink("real/fresh.json", d.path() / "dangling.json");
  WriteFileAtomically(d / "dangling.json", "fresh");
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(d.path() / "dangling.json")));
  EXPECT_EQ(Slurp(d / "real/fresh.json"), "fresh");
}

TEST(AtomicFile, ALegalLongNameWorks) {
  ScratchDir d("bc_atomic");
  const std::string name(254, 'n');  // NAME_MAX is 255: the temporary name must not be longer
  WriteFileAtomically(d / name, "long");
  EXPECT_EQ(Slurp(d / name), "long");
  EXPECT_EQ(Entries(d), 1);
}

TEST(AtomicFile, AnUncommittedWriteLeavesNothing) {
  ScratchDir d("bc_atomic");
  WriteFileAtomically(d / "keep.txt", "kept");
  {
    AtomicFile f(d / "keep.txt", {.force = true, .inputs = {}});
    f.Write("half of it");
    EXPECT_TRUE(fs::exists(f.temp_path()));
    EXPECT_LE(fs::path(f.temp_path()).filename().string().size(), 20u);
  }  // an error before Commit() ends here
  EXPECT_EQ(Slurp(d / "keep.txt"), "kept");
  EXPECT_EQ(Entries(d), 1);
}

TEST(AtomicFile, ASignalDuringAWriteRemovesTheTemporaryFile) {
  ScratchDir d("bc_atomic");
  WriteFileAtomically(d / "done.txt", "finished before the signal");
  const std::string target = d / "pending.txt";
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    InstallTempFileCleanupOnSignals();
    AtomicFile f(target);
    f.Write("never committed");
    ::raise(SIGTERM);
    ::_exit(0);  // not reached: the default action of SIGTERM ends the process
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(status));
  EXPECT_EQ(WTERMSIG(status), SIGTERM);
  EXPECT_FALSE(fs::exists(target));
  EXPECT_EQ(Slurp(d / "done.txt"), "finished before the signal");
  EXPECT_EQ(Entries(d), 1) << "a temporary file was left behind";
}

}  // namespace
}  // namespace bouncecal
