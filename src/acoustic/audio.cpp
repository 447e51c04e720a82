// Reading and writing recordings through libsndfile (see include/bouncecal/acoustic/audio.hpp).
#include "bouncecal/acoustic/audio.hpp"

#include <sndfile.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <regex>
#include <sstream>

#include "audio_bytes.hpp"
#include "avx2_clones.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/stats.hpp"

namespace bouncecal {
namespace fs = std::filesystem;

namespace {

struct SndfileCloser {
  void operator()(SNDFILE* f) const {
    if (f != nullptr) sf_close(f);
  }
};
using SndfilePtr = std::unique_ptr<SNDFILE, SndfileCloser>;

std::string MajorFormatName(int format) {
  switch (format & SF_FORMAT_TYPEMASK) {
    case SF_FORMAT_WAV:
    case SF_FORMAT_WAVEX:
      return "WAV";
    case SF_FORMAT_RF64:
      return "RF64";
    case SF_FORMAT_W64:
      return "W64";
    case SF_FORMAT_AIFF:
      return "AIFF";
    case SF_FORMAT_AU:
      return "AU";
    case SF_FORMAT_RAW:
      return "RAW";
    case SF_FORMAT_FLAC:
      return "FLAC";
    case SF_FORMAT_OGG:
      return "OGG";
    case SF_FORMAT_CAF:
      return "CAF";
    default:
      break;
  }
  SF_FORMAT_INFO info{};
  info.format = format & SF_FORMAT_TYPEMASK;
  if (sf_command(nullptr, SFC_GET_FORMAT_INFO, &info, sizeof(info)) == 0 && info.extension) {
    std::string ext = info.extension;
    std::transform(ext.begin(), ext.end(), ext.begin(),
                   [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
    return ext;
  }
  return "format 0x" + std::to_string(format & SF_FORMAT_TYPEMASK);
}

struct SubtypeEntry {
  const char* name;
  int code;
};
constexpr SubtypeEntry kSubtypes[] = {
    {"PCM_S8", SF_FORMAT_PCM_S8},      {"PCM_U8", SF_FORMAT_PCM_U8},
    {"PCM_16", SF_FORMAT_PCM_16},      {"PCM_24", SF_FORMAT_PCM_24},
    {"PCM_32", SF_FORMAT_PCM_32},      {"FLOAT", SF_FORMAT_FLOAT},
    {"DOUBLE", SF_FORMAT_DOUBLE},      {"ULAW", SF_FORMAT_ULAW},
    {"ALAW", SF_FORMAT_ALAW},          {"IMA_ADPCM", SF_FORMAT_IMA_ADPCM},
    {"MS_ADPCM", SF_FORMAT_MS_ADPCM},  {"GSM610", SF_FORMAT_GSM610},
    {"VORBIS", SF_FORMAT_VORBIS},
#ifdef SF_FORMAT_OPUS
    {"OPUS", SF_FORMAT_OPUS},
#endif
#ifdef SF_FORMAT_MPEG_LAYER_III
    {"MP3", SF_FORMAT_MPEG_LAYER_III},
#endif
};

std::string SubtypeName(int format) {
  const int sub = format & SF_FORMAT_SUBMASK;
  for (const auto& s : kSubtypes) {
    if (s.code == sub) return s.name;
  }
  return "subtype 0x" + std::to_string(sub);
}

// libsndfile shortens the frame count of a WAV/AIFF whose data chunk declares more bytes than
// the file holds; its log then says e.g. "data : 96000 (should be 49956)". A declared size of
// 0 or 0xFFFFFFFF is a streaming placeholder, not a truncation.
bool LogShowsTruncatedData(SNDFILE* f, std::string* detail) {
  std::vector<char> log(16384, '\0');
  sf_command(f, SFC_GET_LOG_INFO, log.data(), static_cast<int>(log.size()));
  std::istringstream in(std::string(log.data()));
  static const std::regex kLine(R"(^\s*(data|SSND|DATA)\s*:\s*(\d+)\s*\(should be (\d+)\))");
  std::string line;
  while (std::getline(in, line)) {
    std::smatch m;
    if (std::regex_search(line, m, kLine)) {
      const long long declared = std::stoll(m[2].str());
      const long long present = std::stoll(m[3].str());
      if (declared > present && declared != 0xFFFFFFFFLL && declared != 0) {
        *detail = "the " + m[1].str() + " chunk declares " + std::to_string(declared) +
                  " bytes but only " + std::to_string(present) + " are present";
        return true;
      }
    }
  }
  return false;
}

int FormatFromExtension(const std::string& path) {
  std::string ext = fs::path(path).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  if (ext == ".wav") return SF_FORMAT_WAV;
  if (ext == ".flac") return SF_FORMAT_FLAC;
  if (ext == ".ogg" || ext == ".oga") return SF_FORMAT_OGG;
  if (ext == ".aiff" || ext == ".aif") return SF_FORMAT_AIFF;
  throw Error(ErrorCode::kOutput, path + ": unknown audio extension '" + ext +
                                      "' (expected .wav .flac .ogg .aiff .aif)");
}

int SubtypeFromName(const std::string& path, const std::string& name) {
  for (const auto& s : kSubtypes) {
    if (name == s.name) return s.code;
  }
  throw Error(ErrorCode::kOutput, path + ": unknown sample subtype '" + name +
                                      "' (expected PCM_16, PCM_24, PCM_32, FLOAT or VORBIS)");
}

}  // namespace

ClippingReport AnalyzeClipping(const std::vector<float>& x, int channel) {
  ClippingReport r;
  r.channel = channel;
  if (x.empty()) return r;
  const auto [mn_it, mx_it] = std::minmax_element(x.begin(), x.end());
  const double mx = *mx_it;
  const double mn = *mn_it;
  r.peak = std::max(std::fabs(mx), std::fabs(mn));
  if (r.peak <= 0.0) return r;
  // A plateau: >= kMinClipRun consecutive samples equal (within a float rounding step) to the
  // channel's most positive or most negative value. A clean peak has at most two such samples.
  const double tol = 1e-6 * r.peak;
  auto count_runs = [&](auto at_extreme) {
    std::int64_t run = 0;
    for (std::size_t i = 0; i <= x.size(); ++i) {
      if (i < x.size() && at_extreme(x[i])) {
        ++run;
        continue;
      }
      if (run >= kMinClipRun) {
        r.clipped_samples += run;
        ++r.clipped_runs;
      }
      run = 0;
    }
  };
  if (mx > 0.0) count_runs([&](float v) { return v >= mx - tol; });
  if (mn < 0.0) count_runs([&](float v) { return v <= mn + tol; });
  if (r.clipped_runs > 0) r.clip_level = r.peak;
  return r;
}

namespace {

// MPEG audio by its first bytes: an ID3v2 tag ("ID3"), or an MPEG audio frame sync (11 set
// bits, then a layer other than the reserved 00).
bool LooksLikeMpegAudio(AudioBytes* bytes) {
  const std::vector<unsigned char> b = bytes->Head(3);
  if (b.size() < 3) return false;
  if (b[0] == 'I' && b[1] == 'D' && b[2] == '3') return true;
  return b[0] == 0xFF && (b[1] & 0xE0) == 0xE0 && (b[1] & 0x06) != 0;
}

}  // namespace

// See avx2_clones.hpp (the reader calls it after its finite check).
BOUNCECAL_AVX2_CLONES
void MinMax(const float* x, std::size_t n, float* lo, float* hi) {
  float mn = x[0], mx = x[0];
  std::size_t i = 0;
  if (n >= 8) {
    Float8 vmin, vmax;
    std::memcpy(&vmin, x, sizeof vmin);
    vmax = vmin;
    for (i = 8; i + 8 <= n; i += 8) {
      Float8 v;
      std::memcpy(&v, x + i, sizeof v);
      vmin = v < vmin ? v : vmin;
      vmax = v > vmax ? v : vmax;
    }
    for (int q = 0; q < 8; ++q) {
      mn = std::min(mn, vmin[q]);
      mx = std::max(mx, vmax[q]);
    }
  }
  for (; i < n; ++i) {
    mn = std::min(mn, x[i]);
    mx = std::max(mx, x[i]);
  }
  *lo = mn;
  *hi = mx;
}

// Clipping of one channel, kept up to date block by block (AnalyzeClipping's rule without
// knowing the channel's extremes in advance): per side, the extreme so far and the runs of
// samples within a float rounding step (1e-6 relative) of it; a new extreme beyond that step
// starts the count again.
struct AudioReader::Tracker {
  struct Side {
    double extreme = 0.0;  // most positive (or, negated, most negative) value so far
    std::int64_t samples = 0, runs = 0, run = 0;
    void Close() {
      if (run >= kMinClipRun) {
        samples += run;
        ++runs;
      }
      run = 0;
    }
    void Add(double v) {  // v: the sample (negated for the negative side)
      const double tol = 1e-6 * std::fabs(extreme);
      if (v > extreme + tol) {
        extreme = v;
        samples = runs = 0;
        run = 1;
      } else if (v >= extreme - tol && extreme > 0.0) {
        extreme = std::max(extreme, v);
        ++run;
      } else {
        Close();
      }
    }
  };
  Side pos, neg;
  bool any = false;
  // The block's samples; blocks with nothing near the extremes only end the current runs.
  void Update(const float* x, std::size_t n) {
    if (n == 0) return;
    float lo = 0.0f, hi = 0.0f;
    MinMax(x, n, &lo, &hi);
    const double mx = hi, mn = lo;
    const bool near_pos = mx >= pos.extreme - 1e-6 * std::fabs(pos.extreme) || !any;
    const bool near_neg = -mn >= neg.extreme - 1e-6 * std::fabs(neg.extreme) || !any;
    any = true;
    if (!near_pos && !near_neg) {
      pos.Close();
      neg.Close();
      return;
    }
    for (std::size_t i = 0; i < n; ++i) {
      if (near_pos) pos.Add(x[i]);
      if (near_neg) neg.Add(-static_cast<double>(x[i]));
    }
    if (!near_pos) pos.Close();
    if (!near_neg) neg.Close();
  }
  ClippingReport Report(int channel) const {
    Side p = pos, q = neg;
    p.Close();
    q.Close();
    ClippingReport r;
    r.channel = channel;
    if (!any) return r;
    r.peak = std::max(std::max(p.extreme, 0.0), std::max(q.extreme, 0.0));
    if (p.extreme > 0.0) {
      r.clipped_samples += p.samples;
      r.clipped_runs += p.runs;
    }
    if (q.extreme > 0.0) {
      r.clipped_samples += q.samples;
      r.clipped_runs += q.runs;
    }
    if (r.clipped_runs > 0) r.clip_level = r.peak;
    return r;
  }
};

// What a reader reads from: libsndfile on the recording's bytes, or audio FFmpeg decoded on
// opening. `data_start` and `frame_bytes` (PCM only, else 0) let the end of a stream of unknown
// length tell a last frame cut short.
struct AudioReader::Source {
  std::unique_ptr<AudioBytes> bytes;
  SndfilePtr file;
  Audio decoded;
  std::vector<float> interleaved;
  std::int64_t data_start = 0;
  std::int64_t frame_bytes = 0;
  bool ended = false;  // an unknown length's end was met
};

namespace {

// The path checks every reader makes first (exit 3 for a missing or unreadable input, 4 for
// an empty file). "-" is standard input; a FIFO or device is read as a stream too.
void CheckInputPath(const std::string& path) {
  std::error_code ec;
  const fs::path p(path);
  if (path.empty()) throw Error(ErrorCode::kInputMissing, "<empty path>: no file given");
  if (path == "-") return;
  if (!fs::exists(p, ec)) throw Error(ErrorCode::kInputMissing, path + ": no such file");
  if (fs::is_directory(p, ec)) throw Error(ErrorCode::kInputMissing, path + ": is a directory");
  // A FIFO or a device: not opened here (opening and closing a FIFO's read end lets its writer
  // start into a pipe without a reader), and its size says nothing.
  if (!fs::is_regular_file(p, ec)) return;
  {
    std::ifstream probe(p, std::ios::binary);
    if (!probe) {
      throw Error(ErrorCode::kInputMissing,
                  path + ": cannot be opened for reading (" + std::strerror(errno) + ")");
    }
  }
  const auto size = fs::file_size(p, ec);
  if (!ec && size == 0) throw Error(ErrorCode::kNotAudio, path + ": empty file (0 bytes)");
}

// A frame count past this is a header's way of saying "until the end": 2^53 frames are 740
// years at the highest rate read (libsndfile reports SF_COUNT_MAX for a FLAC whose STREAMINFO
// total is 0, and about SF_COUNT_MAX / frame size for a headerless length on a stream).
constexpr std::int64_t kMaxDeclaredFrames = std::int64_t{1} << 53;

// Bytes per frame of an uncompressed subtype (0 for a compressed one).
std::int64_t PcmFrameBytes(const SF_INFO& sfinfo) {
  std::int64_t width = 0;
  switch (sfinfo.format & SF_FORMAT_SUBMASK) {
    case SF_FORMAT_PCM_S8:
    case SF_FORMAT_PCM_U8:
    case SF_FORMAT_ULAW:
    case SF_FORMAT_ALAW:
      width = 1;
      break;
    case SF_FORMAT_PCM_16:
      width = 2;
      break;
    case SF_FORMAT_PCM_24:
      width = 3;
      break;
    case SF_FORMAT_PCM_32:
    case SF_FORMAT_FLOAT:
      width = 4;
      break;
    case SF_FORMAT_DOUBLE:
      width = 8;
      break;
    default:
      return 0;
  }
  const int major = sfinfo.format & SF_FORMAT_TYPEMASK;
  const bool framed = major == SF_FORMAT_WAV || major == SF_FORMAT_WAVEX ||
                      major == SF_FORMAT_AIFF || major == SF_FORMAT_AU || major == SF_FORMAT_W64 ||
                      major == SF_FORMAT_RF64 || major == SF_FORMAT_CAF || major == SF_FORMAT_RAW;
  return framed ? width * sfinfo.channels : 0;
}

// The header of an opened libsndfile file: what it says, and its refusals. `frames` is
// kUnknownFrames when the header gives no length (`placeholder`: a WAV data size of 0 or
// 0xFFFFFFFF; or a count no recording reaches).
AudioInfo SndfileInfo(const std::string& path, SNDFILE* f, const SF_INFO& sfinfo,
                      bool placeholder) {
  AudioInfo info;
  info.path = path;
  info.sample_rate_hz = sfinfo.samplerate;
  info.channels = sfinfo.channels;
  info.format = MajorFormatName(sfinfo.format);
  info.subtype = SubtypeName(sfinfo.format);
  info.frames = placeholder || sfinfo.frames >= kMaxDeclaredFrames ? kUnknownFrames : sfinfo.frames;
  std::string detail;
  if (LogShowsTruncatedData(f, &detail)) {
    throw Error(ErrorCode::kNotAudio, path + ": truncated (" + detail + ")");
  }
  if (sfinfo.channels < 1) {
    throw Error(ErrorCode::kNotAudio,
                path + ": unsupported channel count " + std::to_string(sfinfo.channels));
  }
  if (sfinfo.samplerate < kMinSampleRateHz || sfinfo.samplerate > kMaxSampleRateHz) {
    throw Error(ErrorCode::kNotAudio, path + ": unsupported sample rate " +
                                          std::to_string(sfinfo.samplerate) + " Hz (expected " +
                                          std::to_string(kMinSampleRateHz) + " to " +
                                          std::to_string(kMaxSampleRateHz) + " Hz)");
  }
  if (info.frames == 0 || sfinfo.frames <= 0) {
    throw Error(ErrorCode::kNotAudio, path + ": no audio frames (zero-length audio data)");
  }
  return info;
}

// FFmpeg's decoding of what libsndfile cannot read; a stream is spooled to a file for it, and
// its messages name the input, not the spool.
Audio DecodeWithFfmpeg(const std::string& path, AudioBytes* bytes) {
  const std::string from = bytes->Spool();
  if (from == path) return ReadAudioFfmpeg(path);
  try {
    Audio a = ReadAudioFfmpeg(from);
    a.info.path = path;
    return a;
  } catch (const Error& e) {
    std::string why = e.what();
    for (std::size_t at = why.find(from); at != std::string::npos; at = why.find(from, at))
      why.replace(at, from.size(), path);
    throw Error(e.code(), why);
  }
}

}  // namespace

AudioReader::AudioReader(const std::string& path) : source_(std::make_unique<Source>()) {
  CheckInputPath(path);
  source_->bytes = std::make_unique<AudioBytes>(path);
  AudioBytes* bytes = source_->bytes.get();
  if (bytes->stream() && bytes->Head(1).empty())
    throw Error(ErrorCode::kNotAudio, path + ": empty input (0 bytes)");
  bool decoded = false;
  SF_INFO sfinfo{};
  if (LooksLikeMpegAudio(bytes) && FfmpegAvailable()) {
    source_->decoded = DecodeWithFfmpeg(path, bytes);
    decoded = true;
  } else {
    source_->file.reset(sf_open_virtual(AudioBytes::Io(), SFM_READ, &sfinfo, bytes));
    if (!source_->file) {
      const std::string sf_why = sf_strerror(nullptr);
      try {
        source_->decoded = DecodeWithFfmpeg(path, bytes);
      } catch (const Error& e) {
        std::string ff_why = e.what();
        if (ff_why.rfind(path + ": ", 0) == 0) ff_why = ff_why.substr(path.size() + 2);
        throw Error(ErrorCode::kNotAudio, path +
                                              ": not an audio file libsndfile or FFmpeg can read "
                                              "(libsndfile: " +
                                              sf_why + "; FFmpeg: " + ff_why + ")");
      }
      decoded = true;
    }
  }
  if (decoded) {
    info_ = source_->decoded.info;
    info_.frames = source_->decoded.channels.empty()
                       ? 0
                       : static_cast<std::int64_t>(source_->decoded.channels.front().size());
    memory_ = &source_->decoded;
  } else {
    bytes->EndHeader();
    source_->data_start = bytes->position();
    source_->frame_bytes = PcmFrameBytes(sfinfo);
    info_ = SndfileInfo(path, source_->file.get(), sfinfo, bytes->length_placeholder());
  }
  trackers_.resize(static_cast<std::size_t>(std::max(info_.channels, 0)));
}

AudioReader::AudioReader(const Audio& audio) : info_(audio.info), memory_(&audio) {
  info_.channels = static_cast<int>(audio.channels.size());
  info_.frames =
      audio.channels.empty() ? 0 : static_cast<std::int64_t>(audio.channels.front().size());
}

AudioReader::~AudioReader() = default;

std::int64_t AudioReader::Read(std::int64_t frames, std::vector<std::vector<float>>* out) {
  const std::size_t nch = static_cast<std::size_t>(info_.channels);
  out->resize(nch);
  // An unknown length is read in pieces of at most kMaxStreamReadFrames until the data ends.
  constexpr std::int64_t kMaxStreamReadFrames = std::int64_t{1} << 20;
  const bool unknown = info_.frames == kUnknownFrames;
  const std::int64_t want =
      unknown
          ? (source_->ended ? 0 : std::max<std::int64_t>(0, std::min(frames, kMaxStreamReadFrames)))
          : std::max<std::int64_t>(0, std::min(frames, info_.frames - position_));
  if (want == 0) return 0;
  std::vector<std::size_t> first(nch);
  for (std::size_t c = 0; c < nch; ++c) first[c] = (*out)[c].size();
  std::int64_t got = 0;
  if (memory_ != nullptr) {
    for (std::size_t c = 0; c < nch; ++c) {
      const std::vector<float>& src = memory_->channels[c];
      const auto b = src.begin() + static_cast<std::ptrdiff_t>(position_);
      (*out)[c].insert((*out)[c].end(), b, b + static_cast<std::ptrdiff_t>(want));
    }
    got = want;
  } else {
    SNDFILE* f = source_->file.get();
    if (nch == 1) {  // straight into the channel's buffer
      std::vector<float>& o = (*out)[0];
      o.resize(first[0] + static_cast<std::size_t>(want));
      got = std::max<sf_count_t>(0, sf_readf_float(f, o.data() + first[0], want));
      o.resize(first[0] + static_cast<std::size_t>(got));
    } else {
      std::vector<float>& buf = source_->interleaved;
      buf.resize(static_cast<std::size_t>(want) * nch);
      got = std::max<sf_count_t>(0, sf_readf_float(f, buf.data(), want));
      for (std::size_t c = 0; c < nch; ++c) {
        std::vector<float>& o = (*out)[c];
        o.resize(first[c] + static_cast<std::size_t>(got));
        float* dst = o.data() + first[c];
        for (std::int64_t i = 0; i < got; ++i) dst[i] = buf[static_cast<std::size_t>(i) * nch + c];
      }
    }
    if (got < want && unknown) {
      EndOfUnknownLength(position_ + got);
    } else if (got < want) {
      const std::string why = sf_strerror(f);
      throw Error(ErrorCode::kNotAudio,
                  info_.path + ": truncated (header says " + std::to_string(info_.frames) +
                      " frames, only " + std::to_string(position_ + got) + " could be read" +
                      (sf_error(f) != SF_ERR_NO_ERROR ? ": " + why : std::string()) + ")");
    }
  }
  if (!trackers_.empty()) {  // a file (not an Audio handed in): check and track every sample
    constexpr std::size_t kCheckBlock = 4096;
    for (std::size_t c = 0; c < nch; ++c) {
      const float* x = (*out)[c].data() + first[c];
      const std::size_t n = static_cast<std::size_t>(got);
      for (std::size_t b = 0; b < n; b += kCheckBlock) {
        const std::size_t e = std::min(n, b + kCheckBlock);
        bool ok = true;
        for (std::size_t i = b; i < e; ++i) ok &= std::fabs(x[i]) <= kMaxSampleMagnitude;
        if (!ok) {
          for (std::size_t i = b; i < e; ++i)
            if (!(std::fabs(x[i]) <= kMaxSampleMagnitude))
              throw Error(
                  ErrorCode::kBadSamples,
                  BadSampleMessage(info_.path, x[i], c, position_ + static_cast<std::int64_t>(i),
                                   info_.sample_rate_hz));
        }
        trackers_[c].Update(x + b, e - b);
      }
    }
  }
  position_ += got;
  return got;
}

void AudioReader::EndOfUnknownLength(std::int64_t frames) {
  constexpr const char* kStreamHint =
      "check that the writer finished (its end is the recording's end); the frames before the "
      "cut are used as they are";
  source_->ended = true;
  info_.frames = frames;
  const std::string& path = info_.path;
  if (frames == 0)
    throw Error(ErrorCode::kNotAudio, path + ": no audio frames (the stream ends before any)");
  SNDFILE* f = source_->file.get();
  const AudioBytes& bytes = *source_->bytes;
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%.3f", info_.duration_s());
  const std::string read_to =
      "read up to its last whole frame, " + std::to_string(frames) + " frames (" + seconds + " s)";
  if (!bytes.read_error().empty()) {
    warnings_.push_back(
        {"truncated_stream",
         path + ": reading the input failed (" + bytes.read_error() + "); " + read_to, -1,
         kStreamHint});
  } else if (sf_error(f) != SF_ERR_NO_ERROR) {
    warnings_.push_back({"truncated_stream",
                         path + ": the " + info_.format + " stream ends inside a frame (" +
                             sf_strerror(f) + "); " + read_to,
                         -1, kStreamHint});
  } else if (source_->frame_bytes > 0 && bytes.ended()) {
    const std::int64_t rest = bytes.size() - source_->data_start - frames * source_->frame_bytes;
    if (rest > 0 && rest < source_->frame_bytes)
      warnings_.push_back({"truncated_stream",
                           path + ": the stream ends inside a frame (" + std::to_string(rest) +
                               " of its " + std::to_string(source_->frame_bytes) + " bytes); " +
                               read_to,
                           -1, kStreamHint});
  }
}

const std::vector<Warning>& AudioReader::warnings() const {
  return trackers_.empty() && memory_ != nullptr ? memory_->warnings : warnings_;
}

std::int64_t AudioReader::Skip(std::int64_t frames) {
  std::int64_t skipped = 0;
  constexpr std::int64_t kBlock = 65536;
  while (skipped < frames) {
    for (auto& c : scratch_) c.clear();
    const std::int64_t got = Read(std::min(kBlock, frames - skipped), &scratch_);
    if (got == 0) break;
    skipped += got;
  }
  return skipped;
}

std::vector<ClippingReport> AudioReader::clipping() const {
  if (trackers_.empty() && memory_ != nullptr) return memory_->clipping;
  std::vector<ClippingReport> out;
  for (std::size_t c = 0; c < trackers_.size(); ++c)
    out.push_back(trackers_[c].Report(static_cast<int>(c)));
  return out;
}

Audio ReadAudio(const std::string& path) {
  AudioReader reader(path);
  Audio a;
  a.info = reader.info();
  a.channels.assign(static_cast<std::size_t>(a.info.channels), std::vector<float>());
  // (A corrupt header may claim absurd lengths: reserve at most 16 Mi frames up front.)
  // (An unknown length grows as read.)
  for (auto& c : a.channels)
    c.reserve(std::min<std::size_t>(
        static_cast<std::size_t>(std::max<std::int64_t>(a.info.frames, 0)), std::size_t{1} << 24));
  while (reader.Read(std::int64_t{1} << 20, &a.channels) > 0) {
  }
  a.info = reader.info();
  a.clipping = reader.clipping();
  a.warnings = reader.warnings();
  return a;
}

ChannelSelection ParseChannelSelection(const std::string& text) {
  ChannelSelection s;
  if (text == "auto") {
    s.kind = ChannelSelection::Kind::kAuto;
    return s;
  }
  if (text == "mix") {
    s.kind = ChannelSelection::Kind::kMix;
    return s;
  }
  if (!text.empty() && text.size() < 6 &&
      std::all_of(text.begin(), text.end(), [](unsigned char c) { return std::isdigit(c); })) {
    s.kind = ChannelSelection::Kind::kIndex;
    s.index = std::stoi(text);
    return s;
  }
  throw Error(ErrorCode::kUsage,
              "channel '" + text + "': not a channel (expected a 0-based index, mix or auto)");
}

double ImpactToNoiseDb(const std::vector<float>& x) {
  if (x.size() < 3) return 0.0;
  // First difference = a crude high-pass: keeps the broadband attack of an impact and removes
  // hum and low-frequency room noise. Robust peak (99.99th percentile of |d|, so a single
  // glitch does not win) over the median |d| (the noise floor; impacts fill far less than
  // half of any recording).
  std::vector<float> d(x.size() - 1);
  for (std::size_t i = 1; i < x.size(); ++i) d[i - 1] = std::fabs(x[i] - x[i - 1]);
  const double peak = LowerQuantile(&d, 0.9999);
  const double noise = LowerQuantile(&d, 0.5);
  constexpr double kTiny = 1e-10;  // keeps digital silence finite (about 200 dB)
  return 20.0 * std::log10((peak + kTiny) / (noise + kTiny));
}

SelectedSignal SelectChannel(const Audio& audio, const ChannelSelection& selection) {
  SelectedSignal out;
  const int nch = static_cast<int>(audio.channels.size());
  if (nch == 0) throw Error(ErrorCode::kNotAudio, audio.info.path + ": no channels");
  switch (selection.kind) {
    case ChannelSelection::Kind::kIndex:
      if (selection.index < 0 || selection.index >= nch) {
        throw Error(ErrorCode::kUsage, audio.info.path + ": channel " +
                                           std::to_string(selection.index) + " out of range (" +
                                           std::to_string(nch) + " channel" +
                                           (nch == 1 ? "" : "s") + ", 0-based)");
      }
      out.channel = selection.index;
      out.samples = audio.channels[static_cast<std::size_t>(selection.index)];
      return out;
    case ChannelSelection::Kind::kMix: {
      out.channel = -1;
      std::size_t n = audio.channels[0].size();
      for (const auto& c : audio.channels) n = std::min(n, c.size());
      std::vector<double> acc(n, 0.0);
      for (const auto& c : audio.channels) {
        for (std::size_t i = 0; i < n; ++i) acc[i] += c[i];
      }
      out.samples.resize(n);
      for (std::size_t i = 0; i < n; ++i) out.samples[i] = static_cast<float>(acc[i] / nch);
      return out;
    }
    case ChannelSelection::Kind::kAuto: {
      int best = 0;
      for (int c = 0; c < nch; ++c) {
        out.channel_score.push_back(ImpactToNoiseDb(audio.channels[static_cast<std::size_t>(c)]));
        if (out.channel_score.back() > out.channel_score[static_cast<std::size_t>(best)]) best = c;
      }
      out.channel = best;
      out.samples = audio.channels[static_cast<std::size_t>(best)];
      return out;
    }
  }
  return out;
}

void WriteAudio(const std::string& path, const std::vector<std::vector<float>>& channels,
                double sample_rate_hz, const AudioWriteOptions& options) {
  if (channels.empty()) throw Error(ErrorCode::kBadParameter, path + ": no channels to write");
  const std::size_t frames = channels[0].size();
  for (const auto& c : channels) {
    if (c.size() != frames) {
      throw Error(ErrorCode::kBadParameter, path + ": channels have different lengths");
    }
  }
  if (!(sample_rate_hz >= 1.0) || sample_rate_hz > 1e7 ||
      std::fabs(sample_rate_hz - std::round(sample_rate_hz)) > 1e-9) {
    throw Error(ErrorCode::kBadParameter, path + ": sample rate " + std::to_string(sample_rate_hz) +
                                              " Hz is not a positive whole number of hertz");
  }
  for (std::size_t c = 0; c < channels.size(); ++c) {
    for (std::size_t i = 0; i < frames; ++i) {
      if (!std::isfinite(channels[c][i])) {
        throw Error(ErrorCode::kBadParameter, path + ": non-finite sample in channel " +
                                                  std::to_string(c) + " at frame " +
                                                  std::to_string(i) + "; nothing written");
      }
    }
  }
  const int major = FormatFromExtension(path);
  const int sub = SubtypeFromName(path, options.subtype);
  SF_INFO sfinfo{};
  sfinfo.samplerate = static_cast<int>(std::lround(sample_rate_hz));
  sfinfo.channels = static_cast<int>(channels.size());
  sfinfo.format = major | sub;
  if (!sf_format_check(&sfinfo)) {
    throw Error(ErrorCode::kOutput, path + ": libsndfile cannot write subtype " + options.subtype +
                                        " in this format (" + std::to_string(channels.size()) +
                                        " channels, " + std::to_string(sfinfo.samplerate) + " Hz)");
  }
  // The same atomic write as every other output (core/atomic_file.hpp: temporary file in the
  // target's directory, fsync, rename, directory sync, mode kept, removed on SIGINT/SIGTERM).
  // WriteAudio replaces an existing file: callers enforce --force before calling it.
  AtomicFile out(path, WriteOptions{.force = true, .inputs = {}});
  auto fail = [&](const std::string& why) { throw Error(ErrorCode::kOutput, path + ": " + why); };
  {
    // libsndfile writes through the temporary file's descriptor and leaves it open (SF_FALSE):
    // AtomicFile syncs, closes and renames it.
    SndfilePtr f(sf_open_fd(out.fd(), SFM_WRITE, &sfinfo, SF_FALSE));
    if (!f) fail(std::string("cannot create the file: ") + sf_strerror(nullptr));
    // Values beyond full scale saturate instead of wrapping around in integer formats.
    sf_command(f.get(), SFC_SET_CLIPPING, nullptr, SF_TRUE);
    if (sub == SF_FORMAT_VORBIS) {
      double quality = 0.9;
      sf_command(f.get(), SFC_SET_VBR_ENCODING_QUALITY, &quality, sizeof(quality));
    }
    const int nch = sfinfo.channels;
    constexpr std::size_t kBlock = 65536;
    std::vector<float> buf(kBlock * static_cast<std::size_t>(nch));
    for (std::size_t start = 0; start < frames; start += kBlock) {
      const std::size_t n = std::min(kBlock, frames - start);
      for (std::size_t i = 0; i < n; ++i) {
        for (int c = 0; c < nch; ++c) {
          buf[i * static_cast<std::size_t>(nch) + static_cast<std::size_t>(c)] =
              channels[static_cast<std::size_t>(c)][start + i];
        }
      }
      const auto wrote = sf_writef_float(f.get(), buf.data(), static_cast<sf_count_t>(n));
      if (wrote != static_cast<sf_count_t>(n)) {
        fail(std::string("write failed: ") + sf_strerror(f.get()));
      }
    }
    SNDFILE* raw = f.release();
    if (sf_close(raw) != 0) fail("closing the file failed");  // finishes headers/encoders
  }
  out.Commit();
}

std::string BadSampleMessage(const std::string& path, float v, std::size_t channel,
                             std::int64_t frame, double rate_hz) {
  char msg[256];
  if (std::isfinite(v)) {
    std::snprintf(msg, sizeof(msg),
                  ": sample %g in channel %zu at frame %lld (%.6f s) is more than %g times "
                  "full scale (a float file this loud is corrupt or mis-scaled: rescale it "
                  "to +-1)",
                  static_cast<double>(v), channel, static_cast<long long>(frame),
                  static_cast<double>(frame) / rate_hz, kMaxSampleMagnitude);
  } else {
    std::snprintf(msg, sizeof(msg), ": %s sample in channel %zu at frame %lld (%.6f s)",
                  std::isnan(v) ? "NaN" : "infinite", channel, static_cast<long long>(frame),
                  static_cast<double>(frame) / rate_hz);
  }
  return path + msg;
}

}  // namespace bouncecal
