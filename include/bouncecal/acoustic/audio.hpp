// bouncecal/acoustic/audio.hpp — reading and writing recordings through libsndfile, and reading
// what libsndfile cannot (m4a/AAC and the other formats phones write) through FFmpeg.
//
// Every format libsndfile reads (WAV 16/24/32-bit int and float, FLAC, OGG/Vorbis, AIFF, ...),
// and when libsndfile refuses a file, everything FFmpeg's libavformat/libavcodec decode; any
// sample rate in [8 kHz, 384 kHz], any channel count, decoded at the file's own rate (no
// resampling). Samples are float in [-1, 1] (float files may exceed it). Decoded audio is
// checked like any other (NaN/Inf, clipping).
//
//   Audio a = ReadAudio("drop.wav");                  // throws Error naming the file
//   std::vector<float> x = SelectChannel(a, ParseChannelSelection("auto"));
//
// "-" reads standard input, and a pipe, FIFO or device is read as a stream, once, from start to
// end (formats only FFmpeg decodes are first copied to a temporary file). A header that gives
// no length — FLAC STREAMINFO total 0 (libsndfile: SF_COUNT_MAX frames), a WAV data size of 0
// or 0xFFFFFFFF, what an encoder writing to a pipe leaves — is read to the end of the data:
// AudioInfo::frames is kUnknownFrames until then. Such a stream that ends inside a frame is read
// up to its last whole frame, with a `truncated_stream` warning (Audio::warnings,
// AudioReader::warnings); a declared length the data falls short of stays an error.
//
// Errors (Error codes in error.hpp): kInputMissing (missing, directory, unreadable),
// kNotAudio (not audio, unsupported, truncated, zero frames), kBadSamples (NaN/Inf, or a
// sample beyond 1e6 times full scale).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "bouncecal/core/warning.hpp"

namespace bouncecal {

// AudioInfo::frames of a recording whose header gives no length, until its end is read.
inline constexpr std::int64_t kUnknownFrames = -1;

struct AudioInfo {
  std::string path;
  double sample_rate_hz = 0.0;
  int channels = 0;
  std::int64_t frames = 0;  // kUnknownFrames: not given by the header, not read to the end yet
  std::string format;       // "WAV", "FLAC", ... (FFmpeg: its demuxer name, "mov,mp4,m4a,3gp,...")
  std::string subtype;      // "PCM_16", "FLOAT", ... (FFmpeg: the codec, "aac", "opus", ...)
  std::string decoder = "libsndfile";  // or "ffmpeg"
  bool lossy = false;                  // a lossy codec (FFmpeg path): onsets are smeared
  // Priming samples of the codec (encoder delay): trimmed by the decoder when the container says
  // how many (codec_delay_trimmed), else only reported: times then include the delay, a
  // constant offset that cancels in intervals.
  std::int64_t codec_delay_samples = 0;
  bool codec_delay_trimmed = false;
  double duration_s() const {
    return sample_rate_hz > 0 && frames > 0 ? static_cast<double>(frames) / sample_rate_hz : 0.0;
  }
};

// Sample rates ReadAudio accepts (Hz); others are Error(kNotAudio, "unsupported sample rate").
inline constexpr int kMinSampleRateHz = 8000;
inline constexpr int kMaxSampleRateHz = 384000;
// Largest sample magnitude accepted, in units of full scale (libsndfile reads integer formats
// into [-1, 1] and float formats as stored, nominally [-1, 1]). 1e6 is 120 dB above full scale:
// it admits float files written on the int16 scale (+-32768, a known quirk of some software)
// with a margin of 30, and keeps the single-precision processing finite (Whiten sums x^2 over
// 4096-sample blocks: 4096 * (1e6)^2 = 4e15, far below FLT_MAX = 3.4e38). A float file of
// +-1e30 made every such sum overflow: "no bounce sequence" or an SNR of -nan (issue 14).
inline constexpr double kMaxSampleMagnitude = 1e6;
// "<source>: NaN sample in channel 0 at frame 12 (0.000250 s)" (or too loud: kMaxSampleMagnitude).
std::string BadSampleMessage(const std::string& source, float v, std::size_t channel,
                             std::int64_t frame, double rate_hz);
// A clip is a run of at least this many consecutive samples at the channel's extreme value.
inline constexpr std::int64_t kMinClipRun = 3;

// Clipping (hard clip or brick-wall limiter): runs of >= kMinClipRun consecutive samples equal
// to the channel's most positive or most negative value. A clean peak (one or two samples at
// the maximum) is not clipping.
struct ClippingReport {
  int channel = 0;
  std::int64_t clipped_samples = 0;  // samples in runs at the channel's extreme value
  std::int64_t clipped_runs = 0;     // number of such runs (plateaus)
  double peak = 0.0;                 // max |x|
  double clip_level = 0.0;           // |x| of the plateaus when clipped, else 0
  bool clipped() const { return clipped_samples > 0; }
};
ClippingReport AnalyzeClipping(const std::vector<float>& samples, int channel);

struct Audio {
  AudioInfo info;
  std::vector<std::vector<float>> channels;  // channels[c][frame]
  std::vector<ClippingReport> clipping;      // one per channel
  std::vector<Warning> warnings;             // truncated_stream
};

// A recording read block by block, so that detection of any length needs memory for one block
// only (detect.hpp: DetectImpacts on a reader). Opening does every check ReadAudio does on the
// header (missing file, directory, empty, not audio, truncated data chunk, rate, channels);
// Read checks each sample as it passes (NaN/Inf, beyond 1e6 x full scale: Error(kBadSamples)
// naming channel, frame and time) and keeps each channel's clipping report up to date; the
// end of the data before the header's frame count is Error(kNotAudio, "truncated ..."), raised
// by the Read that meets it. A length the header does not give is read until the data ends, as
// it arrives on a stream (each Read blocks until its frames or the end are there); info().frames
// is then kUnknownFrames until the Read that returns 0, and a stream with no frame at all is
// Error(kNotAudio) there. Formats only FFmpeg decodes (m4a/AAC, MP3, ...) are decoded whole on
// opening (phone recordings: minutes) and then served block by block.
//
//   AudioReader r("drop.flac");
//   std::vector<std::vector<float>> block;            // block[c][frame]
//   while (r.Read(65536, &block) > 0) { ... block.front().size() frames appended ... }
//
// ReadAudio is this reader read to the end. A reader on an Audio already in memory serves its
// samples as they are (no checks: ReadAudio made them) with its clipping reports.
class AudioReader {
 public:
  explicit AudioReader(const std::string& path);
  explicit AudioReader(const Audio& audio);  // `audio` must outlive the reader
  ~AudioReader();
  AudioReader(const AudioReader&) = delete;
  AudioReader& operator=(const AudioReader&) = delete;

  const AudioInfo& info() const { return info_; }
  std::int64_t position() const { return position_; }  // frames read so far
  // Appends up to `frames` frames to (*out)[c] (out gets one vector per channel); returns how
  // many were read, 0 at the end of the data.
  std::int64_t Read(std::int64_t frames, std::vector<std::vector<float>>* out);
  // Reads (and checks) `frames` frames without keeping them; returns how many there were.
  std::int64_t Skip(std::int64_t frames);
  // Clipping of the frames read so far (every frame once Read returned 0), one per channel.
  std::vector<ClippingReport> clipping() const;
  // What the reading found (truncated_stream), complete once Read returned 0.
  const std::vector<Warning>& warnings() const;

 private:
  struct Source;
  struct Tracker;
  // The data of an unknown length ended after `frames` frames: the length, and its warnings.
  void EndOfUnknownLength(std::int64_t frames);
  std::int64_t ReadChecked(std::int64_t frames, std::vector<std::vector<float>>* out);
  AudioInfo info_;
  std::int64_t position_ = 0;
  std::unique_ptr<Source> source_;
  std::vector<Tracker> trackers_;
  const Audio* memory_ = nullptr;  // the in-memory recording served, if any
  std::vector<std::vector<float>> scratch_;
  std::vector<Warning> warnings_;
};

// libsndfile first, FFmpeg when libsndfile cannot open the file. MPEG audio (MP3: an ID3 tag or
// an MPEG frame sync at the start) goes to FFmpeg first: libsndfile 1.2 decodes it with
// libmpg123 opened without MPG123_QUIET, which prints its own lines on stderr for a damaged
// file; FFmpeg is quiet and its errors become ours. Without the FFmpeg module, libsndfile.
Audio ReadAudio(const std::string& path);
// FFmpeg only (the fallback above). Throws Error(kNotAudio) naming the file.
Audio ReadAudioFfmpeg(const std::string& path);
// Whether the FFmpeg module (libbouncecal_ffmpeg.so) loads here.
bool FfmpegAvailable();

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
  int channel = -1;                   // the channel used; -1 for a mix
  std::vector<double> channel_score;  // impact-to-noise ratio (dB) per channel, for auto
};
// Impact-to-noise ratio of one channel (dB), the score behind "auto": on the first difference
// d of the signal (a high-pass that keeps click attacks, drops hum), 20 log10 of the 99.99th
// percentile of |d| over the median |d|.
double ImpactToNoiseDb(const std::vector<float>& samples);
// Throws Error(kUsage) for an index past the channel count.
SelectedSignal SelectChannel(const Audio& audio, const ChannelSelection& selection);

struct AudioWriteOptions {
  std::string subtype = "PCM_16";  // PCM_16, PCM_24, PCM_32, FLOAT, VORBIS (format from extension)
};
// Writes channels[c][frame] to path; format from the extension (.wav .flac .ogg/.oga .aiff .aif).
// Atomic (atomic_file.hpp semantics, force = true: callers enforce --force themselves).
// Values beyond full scale saturate in integer subtypes. Throws Error(kOutput) for an unknown
// extension/subtype or a failed write, Error(kBadParameter) for ragged channels, NaN/Inf
// samples or a non-integer sample rate.
void WriteAudio(const std::string& path, const std::vector<std::vector<float>>& channels,
                double sample_rate_hz, const AudioWriteOptions& options = {});

}  // namespace bouncecal
