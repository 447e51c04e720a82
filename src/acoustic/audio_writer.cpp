// A recording written as it arrives (see include/bouncecal/acoustic/audio_writer.hpp).
#include "bouncecal/acoustic/audio_writer.hpp"

#include <sndfile.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <filesystem>

#include "bouncecal/core/error.hpp"

namespace bouncecal {

struct AudioWriter::Sndfile {
  SNDFILE* f = nullptr;
  ~Sndfile() {
    if (f != nullptr) sf_close(f);
  }
};

namespace {

int Container(const std::string& path) {
  std::string ext = std::filesystem::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".wav") return SF_FORMAT_WAV;
  if (ext == ".flac") return SF_FORMAT_FLAC;
  throw Error(ErrorCode::kOutput,
              path + ": a streamed recording is written as .wav or .flac, not '" + ext + "'");
}

int Subtype(const std::string& path, const std::string& name) {
  if (name == "PCM_16") return SF_FORMAT_PCM_16;
  if (name == "PCM_24") return SF_FORMAT_PCM_24;
  if (name == "FLOAT") return SF_FORMAT_FLOAT;
  throw Error(ErrorCode::kOutput,
              path + ": unknown sample subtype '" + name + "' (expected PCM_16, PCM_24 or FLOAT)");
}

}  // namespace

AudioWriter::AudioWriter(const std::string& path, double rate_hz, int channels,
                         const AudioWriteOptions& options, const WriteOptions& write)
    : path_(path), channels_(channels), out_(path, write), file_(std::make_unique<Sndfile>()) {
  if (!(rate_hz >= 1.0 && rate_hz <= 1e7) || rate_hz != std::round(rate_hz))
    throw Error(ErrorCode::kBadParameter, path + ": sample rate " + std::to_string(rate_hz) +
                                              " Hz is not a positive whole number of hertz");
  if (channels < 1 || channels > 64)
    throw Error(ErrorCode::kBadParameter,
                path + ": " + std::to_string(channels) + " channels (expected 1 to 64)");
  SF_INFO info{};
  info.samplerate = static_cast<int>(rate_hz);
  info.channels = channels;
  info.format = Container(path) | Subtype(path, options.subtype);
  if (!sf_format_check(&info))
    throw Error(ErrorCode::kOutput, path + ": libsndfile cannot write " + options.subtype +
                                        " in this format at " + std::to_string(info.samplerate) +
                                        " Hz");
  // libsndfile writes through the temporary file's descriptor and leaves it open (SF_FALSE):
  // the AtomicFile syncs, closes and renames it.
  file_->f = sf_open_fd(out_.fd(), SFM_WRITE, &info, SF_FALSE);
  if (file_->f == nullptr)
    throw Error(ErrorCode::kOutput,
                path + ": cannot create the file: " + std::string(sf_strerror(nullptr)));
  sf_command(file_->f, SFC_SET_CLIPPING, nullptr, SF_TRUE);
}

AudioWriter::~AudioWriter() = default;

void AudioWriter::Write(const float* interleaved, std::size_t frames) {
  if (file_->f == nullptr) throw Error(ErrorCode::kOutput, path_ + ": written after Commit");
  const auto wrote = sf_writef_float(file_->f, interleaved, static_cast<sf_count_t>(frames));
  if (wrote != static_cast<sf_count_t>(frames))
    throw Error(ErrorCode::kOutput, path_ + ": write failed: " + sf_strerror(file_->f));
  frames_ += static_cast<std::int64_t>(frames);
}

void AudioWriter::Commit() {
  if (file_->f == nullptr) throw Error(ErrorCode::kOutput, path_ + ": committed twice");
  SNDFILE* f = file_->f;
  file_->f = nullptr;
  if (sf_close(f) != 0) throw Error(ErrorCode::kOutput, path_ + ": closing the file failed");
  out_.Commit();
}

}  // namespace bouncecal
