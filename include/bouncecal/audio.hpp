// bouncecal/audio.hpp — reading and writing recordings through libsndfile.
//
// Every format libsndfile reads (WAV 16/24/32-bit int and float, FLAC, OGG/Vorbis, AIFF, ...),
// any sample rate, any channel count. Samples are float in [-1, 1] (float files may exceed it).
//
//   Audio a = ReadAudio("drop.wav");                  // throws Error naming the file
//   std::vector<float> x = SelectChannel(a, ParseChannelSelection("auto"));
//
// Errors (Error codes in error.hpp): kInputMissing (missing, directory, unreadable),
// kNotAudio (not audio, unsupported, truncated, zero frames), kBadSamples (NaN/Inf).
#pragma once

#include <cstdint>
#include <string>
#include <vector>

namespace bouncecal {

struct AudioInfo {
  std::string path;
  double sample_rate_hz = 0.0;
  int channels = 0;
  std::int64_t frames = 0;
  std::string format;   // "WAV", "FLAC", ...
  std::string subtype;  // "PCM_16", "FLOAT", ...
  double duration_s() const { return sample_rate_hz > 0 ? frames / sample_rate_hz : 0.0; }
};

struct ClippingReport {
  int channel = 0;
  std::int64_t clipped_samples = 0;  // samples in runs at the channel's extreme value
  double peak = 0.0;                 // max |x|
  bool clipped() const { return clipped_samples > 0; }
};

struct Audio {
  AudioInfo info;
  std::vector<std::vector<float>> channels;  // channels[c][frame]
  std::vector<ClippingReport> clipping;      // one per channel
};

Audio ReadAudio(const std::string& path);

// Which channel the detector listens to.
struct ChannelSelection {
  enum class Kind { kIndex, kMix, kAuto };
  Kind kind = Kind::kAuto;
  int index = 0;  // 0-based, for kIndex
};
// "0", "1", ... (0-based), "mix", "auto". Throws Error(kUsage) otherwise.
ChannelSelection ParseChannelSelection(const std::string& text);

struct SelectedSignal {
  std::vector<float> samples;
  int channel = -1;               // the channel used; -1 for a mix
  std::vector<double> channel_score;  // impact-to-noise ratio (dB) per channel, for auto
};
// Throws Error(kUsage) for an index past the channel count.
SelectedSignal SelectChannel(const Audio& audio, const ChannelSelection& selection);

struct AudioWriteOptions {
  std::string subtype = "PCM_16";  // PCM_16, PCM_24, PCM_32, FLOAT, VORBIS (format from extension)
};
// Writes channels[c][frame] to path; format from the extension (.wav .flac .ogg .aiff).
// Atomic (atomic_file.hpp semantics, force = true). Throws Error(kOutput).
void WriteAudio(const std::string& path, const std::vector<std::vector<float>>& channels,
                double sample_rate_hz, const AudioWriteOptions& options = {});

}  // namespace bouncecal
