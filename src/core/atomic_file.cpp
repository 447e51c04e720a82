#include "bouncecal/core/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <random>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace fs = std::filesystem;
namespace {

// Temporary files of writes in progress, for the signal handler. This is process-wide state by
// nature (signal dispositions are): a fixed table the handler can read without allocating.
constexpr int kSlots = 64;
constexpr std::size_t kPathMax = 4096;
struct Slot {
  std::atomic<int> used{0};
  char path[kPathMax];
};
std::array<Slot, kSlots>& Slots() {
  static std::array<Slot, kSlots> slots;
  return slots;
}

int RegisterTemp(const std::string& path) {
  if (path.size() + 1 > kPathMax) return -1;
  for (int i = 0; i < kSlots; ++i) {
    Slot& s = Slots()[static_cast<std::size_t>(i)];
    int expected = 0;
    if (s.used.compare_exchange_strong(expected, 2)) {  // 2: being filled
      std::memcpy(s.path, path.c_str(), path.size() + 1);
      s.used.store(1, std::memory_order_release);
      return i;
    }
  }
  return -1;  // more than kSlots writes at once: this one is not cleaned up on a signal
}

void UnregisterTemp(int slot) {
  if (slot >= 0) Slots()[static_cast<std::size_t>(slot)].used.store(0, std::memory_order_release);
}

void CleanupAndReraise(int sig) {
  for (Slot& s : Slots())
    if (s.used.load(std::memory_order_acquire) == 1) ::unlink(s.path);  // async-signal-safe
  std::signal(sig, SIG_DFL);
  std::raise(sig);
}

std::string Errno() { return std::strerror(errno); }

// The path a write to `path` ends up at: symbolic links followed (also a dangling one).
fs::path ResolveTarget(const std::string& path) {
  fs::path p(path);
  for (int hops = 0; hops < 40; ++hops) {
    std::error_code ec;
    if (!fs::is_symlink(fs::symlink_status(p, ec))) return p;
    const fs::path link = fs::read_symlink(p, ec);
    if (ec) return p;
    p = link.is_absolute() ? link : p.parent_path() / link;
  }
  throw Error(ErrorCode::kOutput, path + ": too many levels of symbolic links");
}

fs::path DirectoryOf(const fs::path& p) {
  fs::path dir = p.parent_path();
  return dir.empty() ? fs::path(".") : dir;
}

void SyncDirectory(const fs::path& dir) {
  const int d = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (d < 0) return;  // best effort: some file systems do not allow opening directories
  ::fsync(d);
  ::close(d);
}

}  // namespace

void CheckOutputPath(const std::string& path, const WriteOptions& options) {
  if (path.empty()) throw Error(ErrorCode::kOutput, "output path is empty");
  const fs::path target = ResolveTarget(path);
  std::error_code ec;
  const fs::path dir = DirectoryOf(target);
  if (!fs::is_directory(dir, ec)) {
    throw Error(ErrorCode::kOutput, path + ": directory '" + dir.string() + "' does not exist");
  }
  if (fs::is_directory(target, ec)) throw Error(ErrorCode::kOutput, path + ": is a directory");
  if (!fs::exists(target, ec)) return;
  for (const auto& in : options.inputs) {
    std::error_code ec2;
    if (fs::exists(in, ec2) && fs::equivalent(target, in, ec2)) {
      throw Error(ErrorCode::kOutput, path + ": is an input file; refusing to overwrite it");
    }
  }
  if (!options.force) {
    throw Error(ErrorCode::kOutput,
                path + ": exists and WriteOptions::force is false (set it to replace the file)");
  }
}

AtomicFile::AtomicFile(const std::string& path, const WriteOptions& options) : path_(path) {
  CheckOutputPath(path, options);
  const fs::path target = ResolveTarget(path);
  target_ = target.string();
  const fs::path dir = DirectoryOf(target);
  std::random_device rd;
  for (int attempt = 0; attempt < 16 && fd_ < 0; ++attempt) {
    char name[32];
    std::snprintf(name, sizeof name, ".bc-%08x.tmp", static_cast<unsigned>(rd()));
    temp_ = (dir / name).string();
    fd_ = ::open(temp_.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd_ < 0 && errno != EEXIST) break;
  }
  if (fd_ < 0) {
    throw Error(ErrorCode::kOutput,
                path + ": cannot create a file in '" + dir.string() + "': " + Errno());
  }
  slot_ = RegisterTemp(temp_);
}

AtomicFile::AtomicFile(AtomicFile&& o) noexcept
    : path_(std::move(o.path_)),
      target_(std::move(o.target_)),
      temp_(std::move(o.temp_)),
      fd_(o.fd_),
      committed_(o.committed_),
      slot_(o.slot_) {
  o.fd_ = -1;
  o.committed_ = true;
  o.slot_ = -1;
}

AtomicFile::~AtomicFile() {
  if (fd_ >= 0) ::close(fd_);
  if (!committed_ && !temp_.empty()) ::unlink(temp_.c_str());
  UnregisterTemp(slot_);
}

void AtomicFile::Write(std::string_view data) {
  if (fd_ < 0) throw Error(ErrorCode::kOutput, path_ + ": write after commit");
  const char* p = data.data();
  std::size_t left = data.size();
  while (left > 0) {
    const ssize_t n = ::write(fd_, p, left);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) throw Error(ErrorCode::kOutput, path_ + ": write failed: " + Errno());
    p += n;
    left -= static_cast<std::size_t>(n);
  }
}

void AtomicFile::Commit() {
  if (fd_ < 0) throw Error(ErrorCode::kOutput, path_ + ": already committed");
  struct stat st {};
  if (::stat(target_.c_str(), &st) == 0 && S_ISREG(st.st_mode)) {
    ::fchmod(fd_, st.st_mode & 07777);  // keep the replaced file's permissions
  }
  if (::fsync(fd_) != 0) throw Error(ErrorCode::kOutput, path_ + ": cannot sync: " + Errno());
  const int closed = ::close(fd_);
  fd_ = -1;
  if (closed != 0) throw Error(ErrorCode::kOutput, path_ + ": cannot close: " + Errno());
  if (::rename(temp_.c_str(), target_.c_str()) != 0) {
    throw Error(ErrorCode::kOutput, path_ + ": cannot rename the temporary file: " + Errno());
  }
  committed_ = true;
  UnregisterTemp(slot_);
  slot_ = -1;
  SyncDirectory(DirectoryOf(fs::path(target_)));
}

void WriteFileAtomically(const std::string& path, const std::string& contents,
                         const WriteOptions& options) {
  AtomicFile out(path, options);
  out.Write(contents);
  out.Commit();
}

void InstallTempFileCleanupOnSignals() {
  Slots();  // constructed before any handler can run
  struct sigaction sa {};
  sa.sa_handler = CleanupAndReraise;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = 0;
  ::sigaction(SIGINT, &sa, nullptr);
  ::sigaction(SIGTERM, &sa, nullptr);
}

}  // namespace bouncecal
