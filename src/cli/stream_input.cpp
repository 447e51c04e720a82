// A recording read as it arrives on a pipe (stream_input.hpp). WAV: Microsoft's RIFF/WAVE
// (fmt chunk: format tag 1 PCM, 3 IEEE float, 0xFFFE WAVE_FORMAT_EXTENSIBLE with its sub-format's
// first two bytes the tag), and EBU Tech 3306 RF64 (sizes of 0xFFFFFFFF: read to the end).
#include "stream_input.hpp"

#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstring>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal::cli {
namespace {

std::uint32_t Le32(const char* p) {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  return u[0] | (u[1] << 8) | (u[2] << 16) | (static_cast<std::uint32_t>(u[3]) << 24);
}
std::uint16_t Le16(const char* p) {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  return static_cast<std::uint16_t>(u[0] | (u[1] << 8));
}

int BytesOf(const std::string& encoding) {
  if (encoding == "u8") return 1;
  if (encoding == "s16le") return 2;
  if (encoding == "s24le") return 3;
  if (encoding == "s32le" || encoding == "f32le") return 4;
  return 0;
}

float Sample(const char* p, const std::string& encoding) {
  const auto* u = reinterpret_cast<const unsigned char*>(p);
  if (encoding == "s16le") return static_cast<float>(static_cast<std::int16_t>(Le16(p))) / 32768.0f;
  if (encoding == "s24le") {
    std::int32_t v = u[0] | (u[1] << 8) | (u[2] << 16);
    if (v & 0x800000) v -= 0x1000000;
    return static_cast<float>(v) / 8388608.0f;
  }
  if (encoding == "s32le")
    return static_cast<float>(static_cast<double>(static_cast<std::int32_t>(Le32(p))) /
                              2147483648.0);
  if (encoding == "f32le") {
    float f = 0.0f;
    const std::uint32_t bits = Le32(p);
    std::memcpy(&f, &bits, 4);
    return f;
  }
  return (static_cast<float>(u[0]) - 128.0f) / 128.0f;  // u8
}

}  // namespace

StreamInput::StreamInput(int fd, const std::string& name, const RawFormat& raw)
    : fd_(fd), name_(name) {
  ReadHeader(raw);
  if (!(rate_hz_ >= kMinSampleRateHz && rate_hz_ <= kMaxSampleRateHz))
    throw Error(ErrorCode::kNotAudio, name_ + ": sample rate " + std::to_string(rate_hz_) +
                                          " Hz (expected " + std::to_string(kMinSampleRateHz) +
                                          " to " + std::to_string(kMaxSampleRateHz) + ")");
  if (channels_ < 1 || channels_ > 64)
    throw Error(ErrorCode::kNotAudio, name_ + ": " + std::to_string(channels_) + " channels");
}

std::size_t StreamInput::Fill(std::size_t want, bool whole) {
  char buf[65536];
  while (pending_.size() < want && !eof_) {
    std::size_t ask = std::min(sizeof buf, want - pending_.size());
    if (data_left_ >= 0) ask = std::min<std::size_t>(ask, static_cast<std::size_t>(data_left_));
    if (ask == 0) {
      eof_ = in_data_;  // the data chunk's end is the recording's; a header chunk's is not
      break;
    }
    const ssize_t n = ::read(fd_, buf, ask);
    if (n < 0 && errno == EINTR) {
      interrupted_ = true;
      break;
    }
    if (n < 0)
      throw Error(ErrorCode::kInputMissing, name_ + ": read failed: " + std::strerror(errno));
    if (n == 0) {
      eof_ = true;
      break;
    }
    pending_.append(buf, static_cast<std::size_t>(n));
    if (data_left_ >= 0) data_left_ -= n;
    // A live stream: return once a whole frame came, rather than wait for all `want` bytes.
    if (!whole && pending_.size() >= static_cast<std::size_t>(bytes_per_sample_ * channels_)) break;
  }
  return pending_.size();
}

void StreamInput::ReadHeader(const RawFormat& raw) {
  data_left_ = 12;
  Fill(12, true);
  const bool riff = pending_.size() >= 12 &&
                    (pending_.compare(0, 4, "RIFF") == 0 || pending_.compare(0, 4, "RF64") == 0);
  if (!riff || pending_.compare(8, 4, "WAVE") != 0) {
    data_left_ = -1;
    in_data_ = true;
    if (raw.rate_hz <= 0.0)
      throw Error(ErrorCode::kUsage, name_ +
                                         ": not a WAV stream (no RIFF/WAVE header): raw PCM "
                                         "needs --rate (and --format, --channels)");
    encoding_ = raw.encoding;
    bytes_per_sample_ = BytesOf(encoding_);
    if (bytes_per_sample_ == 0)
      throw Error(ErrorCode::kUsage, "--format " + encoding_ +
                                         ": expected s16le, s24le, s32le, "
                                         "f32le or u8");
    rate_hz_ = raw.rate_hz;
    channels_ = raw.channels;
    description_ = "raw " + encoding_;
    return;
  }
  pending_.clear();
  bool have_format = false;
  for (int chunks = 0; chunks < 64; ++chunks) {
    data_left_ = 8;
    if (Fill(8, true) < 8) throw Error(ErrorCode::kNotAudio, name_ + ": WAV header cut short");
    const std::string id = pending_.substr(0, 4);
    const std::uint32_t size = Le32(pending_.data() + 4);
    pending_.clear();
    if (id == "data") {
      if (!have_format)
        throw Error(ErrorCode::kNotAudio, name_ + ": WAV data before its fmt chunk");
      // A stream's writer does not know the length: 0, 0xFFFFFFFF (RF64) or near 2^31 (arecord).
      data_left_ = size == 0 || size >= 0x7fff0000u ? -1 : static_cast<std::int64_t>(size);
      in_data_ = true;
      return;
    }
    if (size > (1u << 20))
      throw Error(ErrorCode::kNotAudio, name_ + ": WAV chunk '" + id + "' too large");
    data_left_ = size + (size & 1u);
    Fill(static_cast<std::size_t>(data_left_), true);
    if (pending_.size() < size) throw Error(ErrorCode::kNotAudio, name_ + ": WAV header cut short");
    if (id == "fmt " && size >= 16) {
      std::uint16_t tag = Le16(pending_.data());
      channels_ = Le16(pending_.data() + 2);
      rate_hz_ = Le32(pending_.data() + 4);
      const int bits = Le16(pending_.data() + 14);
      if (tag == 0xFFFE && size >= 26) tag = Le16(pending_.data() + 24);
      if (tag == 1 && (bits == 8 || bits == 16 || bits == 24 || bits == 32))
        encoding_ = bits == 8 ? "u8" : "s" + std::to_string(bits) + "le";
      else if (tag == 3 && bits == 32)
        encoding_ = "f32le";
      else
        throw Error(ErrorCode::kNotAudio, name_ + ": WAV format tag " + std::to_string(tag) +
                                              " with " + std::to_string(bits) +
                                              " bits (expected PCM or float)");
      bytes_per_sample_ = bits / 8;
      description_ = "WAV, " + std::to_string(bits) + "-bit " + (tag == 3 ? "float" : "PCM");
      have_format = true;
    }
    pending_.clear();
  }
  throw Error(ErrorCode::kNotAudio, name_ + ": no data chunk in the WAV header");
}

std::size_t StreamInput::Read(std::size_t frames, std::vector<float>* out) {
  interrupted_ = false;
  const std::size_t frame_bytes = static_cast<std::size_t>(bytes_per_sample_ * channels_);
  if (pending_.size() < frame_bytes) Fill(frames * frame_bytes, false);
  const std::size_t n = std::min(frames, pending_.size() / frame_bytes);
  const std::size_t values = n * static_cast<std::size_t>(channels_);
  out->reserve(out->size() + values);
  for (std::size_t i = 0; i < values; ++i)
    out->push_back(
        Sample(pending_.data() + i * static_cast<std::size_t>(bytes_per_sample_), encoding_));
  pending_.erase(0, n * frame_bytes);
  return n;
}

}  // namespace bouncecal::cli
