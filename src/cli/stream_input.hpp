// A recording read as it arrives on a pipe (`bouncecal listen -`): a WAV stream (RIFF or RF64
// header, then PCM until the end of the stream; arecord -t wav writes one) or raw PCM in a
// format the flags give. Blocking reads of whatever is there, so that a live stream is processed
// as it comes.
//
// Why not AudioReader (acoustic/audio.hpp), which reads standard input since issue 30: it
// takes no raw PCM (`--rate`, `--format`), its reads wait until a whole block has arrived, and a
// stream libsndfile cannot parse goes to FFmpeg whole (spooled to its end). Live, this reader
// returns whatever frames are there.
//
//   StreamInput in(STDIN_FILENO, "stdin", RawFormat{});
//   std::vector<float> x;                       // interleaved frames
//   while (in.Read(2400, &x) > 0) { ... }
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace bouncecal::cli {

// Raw PCM (no header): encoding s16le, s24le, s32le, f32le or u8; rate 0 = not given.
struct RawFormat {
  std::string encoding = "s16le";
  double rate_hz = 0.0;
  int channels = 1;
};

class StreamInput {
 public:
  // Reads the WAV header if the stream starts with one; otherwise `raw` says what the bytes are
  // (Error(kUsage) when its rate is not given). Error(kNotAudio) for a WAV header that is not
  // PCM or float, or is cut short.
  StreamInput(int fd, const std::string& name, const RawFormat& raw);

  double rate_hz() const { return rate_hz_; }
  int channels() const { return channels_; }
  const std::string& description() const { return description_; }  // "WAV, 16-bit PCM"
  // Appends up to `frames` frames (interleaved) as they arrive: blocks until at least one whole
  // frame came, or the end. Returns the frames appended; 0 at the end of the stream (or when a
  // signal interrupted the read: interrupted() then).
  std::size_t Read(std::size_t frames, std::vector<float>* interleaved);
  bool interrupted() const { return interrupted_; }

 private:
  // Reads into pending_ until it holds `want` bytes (whole) or at least a frame, or the end.
  std::size_t Fill(std::size_t want, bool whole);
  void ReadHeader(const RawFormat& raw);
  int fd_;
  std::string name_;
  double rate_hz_ = 0.0;
  int channels_ = 1;
  std::string encoding_;
  int bytes_per_sample_ = 2;
  std::string description_;
  std::string pending_;          // bytes read and not yet returned
  std::int64_t data_left_ = -1;  // bytes of the data chunk left (-1: to the end)
  bool in_data_ = false;         // past the header
  bool eof_ = false;
  bool interrupted_ = false;
};

}  // namespace bouncecal::cli
