// The bytes of a recording as libsndfile reads them (SF_VIRTUAL_IO): a regular file read at
// offsets, or a stream read once from its start to its end — standard input ("-"), a pipe, a
// FIFO, a character device. Internal to the acoustic wing (audio.cpp's AudioReader).
//
// A stream cannot seek, and libsndfile parses a header with seeks: back to where the audio
// starts, forward over chunks, and (the source being seekable for it) forward over the audio
// itself to the chunks a file may keep after it. A stream keeps every byte it reads until the
// header is parsed (EndHeader), so that seeks back land in kept bytes; while the header is
// parsed, a forward jump of more than kMaxHeaderJumpBytes reads as the end of the input (it
// is a jump over the audio, which the reader comes back for) instead of reading the audio
// away. After EndHeader it reads on, keeping nothing it has passed.
//
// A WAV (RIFF/WAVE) whose data chunk declares 0 bytes (a writer that never learnt the length
// and wrote no placeholder) is served with 0xFFFFFFFF there, the placeholder libsndfile reads
// to the end of the data; length_placeholder() says that the header gives no length.
//
//   AudioBytes bytes("-");
//   SNDFILE* f = sf_open_virtual(AudioBytes::Io(), SFM_READ, &info, &bytes);
//   bytes.EndHeader();
#pragma once

#include <sndfile.h>

#include <cstdint>
#include <string>
#include <vector>

namespace bouncecal {

class AudioBytes {
 public:
  // "-" is standard input. Throws Error(kInputMissing) when the path cannot be opened.
  explicit AudioBytes(const std::string& path);
  ~AudioBytes();
  AudioBytes(const AudioBytes&) = delete;
  AudioBytes& operator=(const AudioBytes&) = delete;

  // The callbacks; their user data is the AudioBytes.
  static SF_VIRTUAL_IO* Io();

  bool stream() const { return stream_; }
  // The first `n` bytes (fewer when the input is shorter), read without moving position().
  std::vector<unsigned char> Head(std::size_t n);
  // Whether a WAV's data chunk declares 0 or 0xFFFFFFFF bytes: no length.
  bool length_placeholder() const { return length_placeholder_; }
  // The header is parsed: a stream stops keeping bytes and treats jumps as reads again.
  void EndHeader() { in_header_ = false; }
  std::int64_t position() const { return position_; }
  // The bytes of the input: the file's size, or what a stream read before its end (its size
  // once ended() is true).
  std::int64_t size() const { return stream_ ? consumed_ : file_size_; }
  // A stream met its end (a file always has one).
  bool ended() const { return !stream_ || ended_; }
  // Why a stream's read failed ("" if none did).
  const std::string& read_error() const { return read_error_; }
  // The whole input as a regular file: a file's own path; a stream's kept bytes and the rest
  // of it written to a temporary file (removed with this object), for FFmpeg, which decodes
  // from a path. A stream can be spooled only while it keeps all it read (before EndHeader);
  // throws Error(kInputMissing) when the temporary file cannot be written.
  std::string Spool();

  // SF_VIRTUAL_IO's operations.
  std::int64_t Length() const;
  std::int64_t Seek(std::int64_t offset, int whence);
  std::int64_t Read(void* out, std::int64_t bytes);

 private:
  // Reads from the descriptor until `bytes` are read or the input ends; keeps them while the
  // header is parsed. Returns how many were read.
  std::int64_t ReadStream(unsigned char* out, std::int64_t bytes);
  // A stream's bytes up to `offset` read (kept while the header is parsed); false at its end.
  bool FillTo(std::int64_t offset);
  void FindWavLength();

  std::string path_;
  int fd_ = -1;
  bool owns_fd_ = false;
  bool stream_ = false;
  std::int64_t file_size_ = 0;
  std::int64_t position_ = 0;
  // Stream: bytes read from the descriptor, the kept ones (kept_[0] is byte kept_start_).
  std::int64_t consumed_ = 0;
  std::vector<unsigned char> kept_;
  std::int64_t kept_start_ = 0;
  bool in_header_ = true;
  bool ended_ = false;
  std::string read_error_;
  // The WAV data chunk's size field served as 0xFFFFFFFF (its offset), -1 for none.
  std::int64_t patch_at_ = -1;
  bool length_placeholder_ = false;
  std::string spooled_;  // the temporary file Spool wrote, removed in the destructor
};

}  // namespace bouncecal
