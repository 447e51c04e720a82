// The bytes of a recording for libsndfile: a file read at offsets, or a stream read once (see
// audio_bytes.hpp).
#include "audio_bytes.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <filesystem>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

// A forward jump longer than this while a stream's header is parsed is a jump over the audio
// (libsndfile skipping the data chunk to look for chunks after it): metadata chunks before the
// audio (fmt, LIST, bext, iXML, cover art) are far smaller, and the bytes a stream keeps for
// seeks back are bounded by it.
constexpr std::int64_t kMaxHeaderJumpBytes = std::int64_t{16} << 20;

std::uint32_t Le32(const unsigned char* p) {
  return static_cast<std::uint32_t>(p[0]) | static_cast<std::uint32_t>(p[1]) << 8 |
         static_cast<std::uint32_t>(p[2]) << 16 | static_cast<std::uint32_t>(p[3]) << 24;
}

sf_count_t IoLength(void* user) { return static_cast<const AudioBytes*>(user)->Length(); }
sf_count_t IoSeek(sf_count_t offset, int whence, void* user) {
  return static_cast<AudioBytes*>(user)->Seek(offset, whence);
}
sf_count_t IoRead(void* out, sf_count_t bytes, void* user) {
  return static_cast<AudioBytes*>(user)->Read(out, bytes);
}
sf_count_t IoWrite(const void*, sf_count_t, void*) { return 0; }
sf_count_t IoTell(void* user) { return static_cast<const AudioBytes*>(user)->position(); }

}  // namespace

AudioBytes::AudioBytes(const std::string& path) : path_(path) {
  if (path == "-") {
    fd_ = STDIN_FILENO;
  } else {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) {
      throw Error(ErrorCode::kInputMissing,
                  path + ": cannot be opened for reading (" + std::strerror(errno) + ")");
    }
    owns_fd_ = true;
  }
  struct stat st {};
  stream_ = ::fstat(fd_, &st) != 0 || !S_ISREG(st.st_mode);
  if (!stream_) file_size_ = static_cast<std::int64_t>(st.st_size);
  FindWavLength();
}

AudioBytes::~AudioBytes() {
  if (owns_fd_) ::close(fd_);
  if (!spooled_.empty()) {
    std::error_code ec;
    std::filesystem::remove(spooled_, ec);
  }
}

SF_VIRTUAL_IO* AudioBytes::Io() {
  static SF_VIRTUAL_IO io{IoLength, IoSeek, IoRead, IoWrite, IoTell};
  return &io;
}

std::vector<unsigned char> AudioBytes::Head(std::size_t n) {
  std::vector<unsigned char> out(n);
  const std::int64_t at = position_;
  position_ = 0;
  out.resize(static_cast<std::size_t>(Read(out.data(), static_cast<std::int64_t>(n))));
  position_ = at;
  return out;
}

// A WAV's chunks up to its data chunk: the data chunk's size field, when 0 (served as
// 0xFFFFFFFF) or 0xFFFFFFFF, says the writer did not know the length.
void AudioBytes::FindWavLength() {
  const std::vector<unsigned char> riff = Head(12);
  if (riff.size() < 12 || std::memcmp(riff.data(), "RIFF", 4) != 0 ||
      std::memcmp(riff.data() + 8, "WAVE", 4) != 0)
    return;
  std::int64_t at = 12;
  while (at < kMaxHeaderJumpBytes) {
    const std::int64_t back = position_;
    position_ = at;
    unsigned char chunk[8];
    const std::int64_t got = Read(chunk, 8);
    position_ = back;
    if (got < 8) return;
    const std::uint32_t size = Le32(chunk + 4);
    if (std::memcmp(chunk, "data", 4) == 0) {
      length_placeholder_ = size == 0 || size == 0xFFFFFFFFu;
      if (size == 0) patch_at_ = at + 4;
      return;
    }
    at += 8 + static_cast<std::int64_t>(size) + (size & 1);
  }
}

std::int64_t AudioBytes::Length() const {
  // A stream's length is unknown until its end: the largest, as libsndfile sets for a pipe.
  if (!stream_) return file_size_;
  return ended_ ? consumed_ : SF_COUNT_MAX;
}

std::int64_t AudioBytes::Seek(std::int64_t offset, int whence) {
  std::int64_t to = offset;
  if (whence == SEEK_CUR) {
    to = position_ + offset;
  } else if (whence == SEEK_END) {
    if (stream_ && !ended_) return -1;
    to = size() + offset;
  }
  if (to < 0 || (stream_ && to < kept_start_)) return -1;  // a stream's dropped bytes
  position_ = to;
  return position_;
}

std::int64_t AudioBytes::ReadStream(unsigned char* out, std::int64_t bytes) {
  std::int64_t got = 0;
  while (got < bytes && !ended_) {
    const ssize_t n = ::read(fd_, out + got, static_cast<std::size_t>(bytes - got));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      if (n < 0) read_error_ = std::strerror(errno);
      ended_ = true;
      break;
    }
    got += n;
  }
  if (in_header_) kept_.insert(kept_.end(), out, out + got);
  consumed_ += got;
  return got;
}

bool AudioBytes::FillTo(std::int64_t offset) {
  unsigned char skip[65536];
  while (consumed_ < offset && !ended_)
    ReadStream(skip, std::min<std::int64_t>(sizeof skip, offset - consumed_));
  return consumed_ >= offset;
}

std::int64_t AudioBytes::Read(void* out, std::int64_t bytes) {
  auto* dst = static_cast<unsigned char*>(out);
  std::int64_t got = 0;
  const std::int64_t from = position_;
  if (!stream_) {
    while (got < bytes) {
      const ssize_t n =
          ::pread(fd_, dst + got, static_cast<std::size_t>(bytes - got), position_ + got);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      got += n;
    }
  } else {
    // Bytes no longer needed for a seek back are dropped once the header is parsed.
    if (!in_header_ && !kept_.empty() && position_ >= consumed_) {
      kept_.clear();
      kept_start_ = consumed_;
    }
    while (got < bytes) {
      const std::int64_t at = position_ + got;
      if (at < consumed_) {  // kept bytes
        const std::int64_t n = std::min(bytes - got, consumed_ - at);
        std::memcpy(dst + got, kept_.data() + (at - kept_start_), static_cast<std::size_t>(n));
        got += n;
      } else if (at > consumed_) {  // a jump forward
        if (in_header_ && at - consumed_ > kMaxHeaderJumpBytes) break;
        if (!FillTo(at)) break;
      } else {
        const std::int64_t n = ReadStream(dst + got, bytes - got);
        got += n;
        if (n == 0) break;
      }
    }
  }
  position_ += got;
  if (patch_at_ >= 0) {  // the data chunk's size 0 served as 0xFFFFFFFF
    for (std::int64_t i = std::max(from, patch_at_); i < std::min(from + got, patch_at_ + 4); ++i)
      dst[i - from] = 0xFF;
  }
  return got;
}

std::string AudioBytes::Spool() {
  if (!stream_) return path_;
  if (!spooled_.empty()) return spooled_;
  if (kept_start_ != 0)
    throw Error(ErrorCode::kInternal, path_ + ": a stream spooled after its header");
  std::string name = (std::filesystem::temp_directory_path() / "bouncecal-stream-XXXXXX").string();
  const int fd = ::mkstemp(name.data());
  if (fd < 0) {
    throw Error(
        ErrorCode::kInputMissing,
        path_ + ": cannot spool the stream to a temporary file (" + std::strerror(errno) + ")");
  }
  spooled_ = name;
  bool ok = true;
  auto put = [&](const unsigned char* p, std::size_t n) {
    while (ok && n > 0) {
      const ssize_t w = ::write(fd, p, n);
      if (w < 0 && errno == EINTR) continue;
      if (w <= 0) {
        ok = false;
        break;
      }
      p += w;
      n -= static_cast<std::size_t>(w);
    }
  };
  put(kept_.data(), kept_.size());
  kept_.clear();
  kept_start_ = consumed_;
  in_header_ = false;
  unsigned char buf[65536];
  while (ok) {
    const std::int64_t n = ReadStream(buf, sizeof buf);
    if (n == 0) break;
    put(buf, static_cast<std::size_t>(n));
  }
  const int closed = ::close(fd);
  if (!ok || closed != 0) {
    throw Error(ErrorCode::kInputMissing,
                path_ + ": cannot spool the stream to " + name + " (" + std::strerror(errno) + ")");
  }
  return spooled_;
}

}  // namespace bouncecal
