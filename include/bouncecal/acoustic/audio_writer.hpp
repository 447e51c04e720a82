// bouncecal/acoustic/audio_writer.hpp — a recording written as it arrives (a live take), block
// by block, through libsndfile: memory for one block, whatever the length.
//
//   AudioWriter take("take.flac", 48000.0, 1, {.subtype = "PCM_24"});
//   take.Write(samples, n);            // interleaved frames, as often as needed
//   take.Commit();                     // finishes the file; it appears at its path
//
// The file is written through an AtomicFile (core/atomic_file.hpp): a writer destroyed without
// Commit leaves nothing at the path (and SIGINT/SIGTERM remove the temporary file when the
// program installed InstallTempFileCleanupOnSignals). Formats: .wav and .flac (lossless; FLAC
// keeps 16 or 24 bits: PCM_24 holds a 16-bit source exactly and a float source to -144 dB).
// Samples beyond full scale saturate. Throws Error(kOutput) naming the path for an unusable
// path, an unknown extension or subtype, or a failed write; Error(kBadParameter) for a rate that
// is not a whole number of hertz or a channel count outside [1, 64].
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/atomic_file.hpp"

namespace bouncecal {

class AudioWriter {
 public:
  // options.subtype: PCM_16, PCM_24 (WAV and FLAC) or FLOAT (WAV only). `write` as CheckOutputPath.
  AudioWriter(const std::string& path, double rate_hz, int channels,
              const AudioWriteOptions& options = {}, const WriteOptions& write = {});
  ~AudioWriter();
  AudioWriter(const AudioWriter&) = delete;
  AudioWriter& operator=(const AudioWriter&) = delete;

  // Appends `frames` interleaved frames (frames x channels values).
  void Write(const float* interleaved, std::size_t frames);
  std::int64_t frames() const { return frames_; }
  // Finishes the file (headers, encoder) and renames it into place. Nothing may follow.
  void Commit();

 private:
  struct Sndfile;
  std::string path_;
  int channels_ = 1;
  std::int64_t frames_ = 0;
  AtomicFile out_;
  std::unique_ptr<Sndfile> file_;
};

}  // namespace bouncecal
