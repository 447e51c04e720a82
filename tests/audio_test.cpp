// Tests of audio input/output (audio.hpp): round trips of every written format and subtype,
// extreme rates and channel counts, channel selection, clipping reports and every bad input.
#include "bouncecal/acoustic/audio.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {
namespace fs = std::filesystem;

class AudioTest : public ::testing::Test {
 protected:
  std::string Path(const std::string& name) const { return scratch_ / name; }
  testing_util::ScratchDir scratch_{"bc_audio"};
  const fs::path& dir_ = scratch_.path();
};

// Distinct, deterministic content per channel (catches interleaving mistakes).
std::vector<std::vector<float>> TestSignal(int channels, std::size_t frames, double rate_hz) {
  std::vector<std::vector<float>> x(static_cast<std::size_t>(channels));
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(-0.05f, 0.05f);
  for (int c = 0; c < channels; ++c) {
    auto& ch = x[static_cast<std::size_t>(c)];
    ch.resize(frames);
    const double f_hz = std::min(440.0 * (c + 1), 0.2 * rate_hz);
    for (std::size_t i = 0; i < frames; ++i) {
      ch[i] =
          static_cast<float>(0.6 * std::sin(2 * M_PI * f_hz * static_cast<double>(i) / rate_hz)) +
          u(rng);
    }
  }
  return x;
}

ErrorCode CodeOf(const std::string& path, std::string* message = nullptr) {
  try {
    ReadAudio(path);
  } catch (const Error& e) {
    if (message) *message = e.what();
    return e.code();
  }
  return ErrorCode::kOk;
}

struct FormatCase {
  std::string ext;
  std::string subtype;
  std::string format;  // AudioInfo::format expected
  double tolerance;    // max |error| per sample; < 0: lossy, use the relative RMS error bound
};

class RoundTrip : public AudioTest, public ::testing::WithParamInterface<FormatCase> {};

TEST_P(RoundTrip, ValuesSurviveWithinQuantisation) {
  const FormatCase& fc = GetParam();
  const double rate = 44100.0;
  const auto x = TestSignal(2, 22050, rate);
  const std::string path = Path("rt" + fc.ext);
  WriteAudio(path, x, rate, AudioWriteOptions{fc.subtype});
  const Audio a = ReadAudio(path);
  EXPECT_EQ(a.info.format, fc.format);
  EXPECT_EQ(a.info.subtype, fc.subtype);
  EXPECT_EQ(a.info.sample_rate_hz, rate);
  ASSERT_EQ(a.info.channels, 2);
  ASSERT_EQ(a.info.frames, 22050);
  ASSERT_EQ(a.channels.size(), 2u);
  for (std::size_t c = 0; c < 2; ++c) {
    ASSERT_EQ(a.channels[c].size(), x[c].size());
    double max_err = 0, err2 = 0, sig2 = 0;
    for (std::size_t i = 0; i < x[c].size(); ++i) {
      const double e = a.channels[c][i] - x[c][i];
      max_err = std::max(max_err, std::fabs(e));
      err2 += e * e;
      sig2 += double(x[c][i]) * x[c][i];
    }
    if (fc.tolerance >= 0) {
      EXPECT_LE(max_err, fc.tolerance) << "channel " << c;
    } else {
      EXPECT_LT(std::sqrt(err2 / sig2), 0.1) << "lossy channel " << c;
    }
  }
  // Atomic write leaves no temporary file behind.
  int files = 0;
  for (const auto& e : fs::directory_iterator(dir_)) {
    (void)e;
    ++files;
  }
  EXPECT_EQ(files, 1);
}

// libsndfile writes float x as round(x * 32767) and reads n / 32768: up to 1.5 LSB apart.
constexpr double kLsb16 = 1.0 / 32768.0;
constexpr double kLsb24 = 1.0 / 8388608.0;
INSTANTIATE_TEST_SUITE_P(Formats, RoundTrip,
                         ::testing::Values(FormatCase{".wav", "PCM_16", "WAV", 1.5 * kLsb16},
                                           FormatCase{".wav", "PCM_24", "WAV", 1.5 * kLsb24},
                                           FormatCase{".wav", "PCM_32", "WAV", 1e-7},
                                           FormatCase{".wav", "FLOAT", "WAV", 0.0},
                                           FormatCase{".flac", "PCM_16", "FLAC", 1.5 * kLsb16},
                                           FormatCase{".flac", "PCM_24", "FLAC", 1.5 * kLsb24},
                                           FormatCase{".aiff", "PCM_16", "AIFF", 1.5 * kLsb16},
                                           FormatCase{".aif", "PCM_24", "AIFF", 1.5 * kLsb24},
                                           FormatCase{".aiff", "FLOAT", "AIFF", 0.0},
                                           FormatCase{".ogg", "VORBIS", "OGG", -1.0}),
                         [](const auto& param_info) {
                           return param_info.param.ext.substr(1) + "_" + param_info.param.subtype;
                         });

TEST_F(AudioTest, ExtremeRatesAndSixChannels) {
  for (double rate : {8000.0, 384000.0}) {
    const auto x = TestSignal(1, 4000, rate);
    const std::string path = Path("r" + std::to_string(int(rate)) + ".wav");
    WriteAudio(path, x, rate, AudioWriteOptions{"FLOAT"});
    const Audio a = ReadAudio(path);
    EXPECT_EQ(a.info.sample_rate_hz, rate);
    EXPECT_EQ(a.channels[0], x[0]);
    EXPECT_NEAR(a.info.duration_s(), 4000.0 / rate, 1e-12);
  }
  const auto x6 = TestSignal(6, 3000, 48000.0);
  WriteAudio(Path("six.flac"), x6, 48000.0, AudioWriteOptions{"PCM_24"});
  const Audio a6 = ReadAudio(Path("six.flac"));
  ASSERT_EQ(a6.info.channels, 6);
  ASSERT_EQ(a6.clipping.size(), 6u);
  for (std::size_t c = 0; c < 6; ++c) {
    for (std::size_t i = 0; i < x6[c].size(); i += 97) {
      ASSERT_NEAR(a6.channels[c][i], x6[c][i], 1.5 * kLsb24) << "channel " << c << " frame " << i;
    }
  }
}

TEST_F(AudioTest, RatesOutsideTheSupportedRangeAreRejected) {
  const auto x = TestSignal(1, 1000, 4000.0);
  WriteAudio(Path("slow.wav"), x, 4000.0);
  std::string msg;
  EXPECT_EQ(CodeOf(Path("slow.wav"), &msg), ErrorCode::kNotAudio);
  EXPECT_NE(msg.find("sample rate 4000"), std::string::npos) << msg;
}

// Two channels of equal noise; only `click_channel` carries impacts.
Audio ClickAudio(int click_channel) {
  Audio a;
  a.info.path = "mem";
  a.info.sample_rate_hz = 48000;
  a.info.channels = 2;
  std::mt19937 rng(11);
  std::normal_distribution<float> n(0.0f, 0.01f);
  a.channels.assign(2, std::vector<float>(48000));
  for (auto& c : a.channels) {
    for (auto& v : c) v = n(rng);
  }
  for (int k = 0; k < 8; ++k) {
    const std::size_t at = 3000 + static_cast<std::size_t>(k) * 5000;
    for (std::size_t j = 0; j < 200; ++j) {
      a.channels[static_cast<std::size_t>(click_channel)][at + j] +=
          static_cast<float>(0.5 * std::exp(-double(j) / 30.0) * std::sin(double(j) * 1.3));
    }
  }
  a.info.frames = 48000;
  return a;
}

TEST(ChannelSelection, AutoPicksTheChannelWithTheClicks) {
  for (int click : {0, 1}) {
    const Audio a = ClickAudio(click);
    const SelectedSignal s = SelectChannel(a, ParseChannelSelection("auto"));
    EXPECT_EQ(s.channel, click);
    ASSERT_EQ(s.channel_score.size(), 2u);
    EXPECT_GT(s.channel_score[static_cast<std::size_t>(click)],
              s.channel_score[static_cast<std::size_t>(1 - click)] + 10.0);
    EXPECT_EQ(s.samples, a.channels[static_cast<std::size_t>(click)]);
  }
}

TEST(ChannelSelection, IndexAndMix) {
  const Audio a = ClickAudio(1);
  const SelectedSignal s0 = SelectChannel(a, ParseChannelSelection("0"));
  EXPECT_EQ(s0.channel, 0);
  EXPECT_EQ(s0.samples, a.channels[0]);
  const SelectedSignal m = SelectChannel(a, ParseChannelSelection("mix"));
  EXPECT_EQ(m.channel, -1);
  ASSERT_EQ(m.samples.size(), a.channels[0].size());
  for (std::size_t i = 0; i < m.samples.size(); i += 101) {
    EXPECT_NEAR(m.samples[i], 0.5 * (a.channels[0][i] + a.channels[1][i]), 1e-7);
  }
  try {
    SelectChannel(a, ParseChannelSelection("2"));
    FAIL() << "channel 2 of 2 accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kUsage);
  }
  for (const char* bad : {"", "left", "-1", "1.5"}) {
    try {
      ParseChannelSelection(bad);
      FAIL() << "accepted '" << bad << "'";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kUsage);
    }
  }
}

TEST(Clipping, PlateauIsClippingACleanPeakIsNot) {
  std::vector<float> clean(4800), clipped(4800);
  for (std::size_t i = 0; i < clean.size(); ++i) {
    clean[i] = static_cast<float>(0.9 * std::sin(2 * M_PI * 1000.0 * double(i) / 48000.0 + 0.3));
    clipped[i] = std::clamp(clean[i], -0.5f, 0.5f);
  }
  const ClippingReport rc = AnalyzeClipping(clean, 0);
  EXPECT_FALSE(rc.clipped());
  EXPECT_NEAR(rc.peak, 0.9, 1e-3);
  const ClippingReport rx = AnalyzeClipping(clipped, 1);
  EXPECT_TRUE(rx.clipped());
  EXPECT_EQ(rx.channel, 1);
  EXPECT_FLOAT_EQ(static_cast<float>(rx.clip_level), 0.5f);
  // 1 kHz at 48 kHz over 4800 samples: 100 periods, two plateaus each.
  EXPECT_EQ(rx.clipped_runs, 200);
  EXPECT_GT(rx.clipped_samples, 200 * 3);
  // Two equal samples at the maximum are a peak, three are a plateau.
  std::vector<float> two{0.1f, 0.8f, 0.8f, 0.2f}, three{0.1f, 0.8f, 0.8f, 0.8f, 0.2f};
  EXPECT_FALSE(AnalyzeClipping(two, 0).clipped());
  EXPECT_EQ(AnalyzeClipping(three, 0).clipped_samples, 3);
  EXPECT_FALSE(AnalyzeClipping(std::vector<float>(100, 0.0f), 0).clipped());
}

TEST_F(AudioTest, OverFullScaleSaturatesAndIsReportedAsClipped) {
  std::vector<std::vector<float>> x(1, std::vector<float>(4800));
  for (std::size_t i = 0; i < 4800; ++i) {
    x[0][i] = static_cast<float>(1.5 * std::sin(2 * M_PI * 300.0 * double(i) / 48000.0));
  }
  WriteAudio(Path("hot.wav"), x, 48000.0, AudioWriteOptions{"PCM_16"});
  const Audio a = ReadAudio(Path("hot.wav"));
  ASSERT_EQ(a.clipping.size(), 1u);
  EXPECT_TRUE(a.clipping[0].clipped());
  EXPECT_NEAR(a.clipping[0].peak, 1.0, 1e-4);  // saturated, not wrapped around
}

// ---- bad input: each case with its error code, message naming the file ----

TEST_F(AudioTest, MissingFileAndDirectory) {
  std::string msg;
  EXPECT_EQ(CodeOf(Path("nope.wav"), &msg), ErrorCode::kInputMissing);
  EXPECT_EQ(msg.rfind(Path("nope.wav"), 0), 0u) << msg;
  EXPECT_EQ(CodeOf(dir_.string(), &msg), ErrorCode::kInputMissing);
  EXPECT_NE(msg.find("directory"), std::string::npos) << msg;
  EXPECT_EQ(CodeOf("", &msg), ErrorCode::kInputMissing);
}

TEST_F(AudioTest, UnreadableFile) {
  if (::geteuid() == 0) GTEST_SKIP() << "root can read a mode-000 file";
  WriteAudio(Path("locked.wav"), TestSignal(1, 100, 8000.0), 8000.0);
  fs::permissions(Path("locked.wav"), fs::perms::none);
  EXPECT_EQ(CodeOf(Path("locked.wav")), ErrorCode::kInputMissing);
}

TEST_F(AudioTest, TextFileRenamedWav) {
  std::ofstream(Path("notes.wav")) << "these are not samples\n";
  std::string msg;
  EXPECT_EQ(CodeOf(Path("notes.wav"), &msg), ErrorCode::kNotAudio);
  EXPECT_EQ(msg.rfind(Path("notes.wav") + ": ", 0), 0u) << msg;
}

TEST_F(AudioTest, ZeroLengthFile) {
  std::ofstream(Path("empty.wav")).close();
  std::string msg;
  EXPECT_EQ(CodeOf(Path("empty.wav"), &msg), ErrorCode::kNotAudio);
  EXPECT_NE(msg.find("empty"), std::string::npos) << msg;
}

TEST_F(AudioTest, HeaderOnlyWavWithZeroFrames) {
  WriteAudio(Path("zero.wav"), std::vector<std::vector<float>>(1), 48000.0);
  EXPECT_EQ(fs::file_size(Path("zero.wav")), 44u);  // a valid header, no data
  std::string msg;
  EXPECT_EQ(CodeOf(Path("zero.wav"), &msg), ErrorCode::kNotAudio);
  EXPECT_NE(msg.find("no audio frames"), std::string::npos) << msg;
}

void CopyPrefix(const std::string& from, const std::string& to, std::size_t bytes) {
  std::ifstream in(from, std::ios::binary);
  std::vector<char> buf(bytes);
  in.read(buf.data(), static_cast<std::streamsize>(bytes));
  ASSERT_EQ(static_cast<std::size_t>(in.gcount()), bytes);
  std::ofstream(to, std::ios::binary).write(buf.data(), static_cast<std::streamsize>(bytes));
}

TEST_F(AudioTest, TruncatedFiles) {
  const auto x = TestSignal(2, 48000, 48000.0);
  WriteAudio(Path("full.wav"), x, 48000.0);
  WriteAudio(Path("full.flac"), x, 48000.0);
  WriteAudio(Path("full.aiff"), x, 48000.0);
  ASSERT_EQ(CodeOf(Path("full.wav")), ErrorCode::kOk);
  ASSERT_EQ(CodeOf(Path("full.flac")), ErrorCode::kOk);
  ASSERT_EQ(CodeOf(Path("full.aiff")), ErrorCode::kOk);
  struct Cut {
    std::string from, to;
    std::size_t bytes;
  };
  const std::size_t wav = fs::file_size(Path("full.wav"));
  const std::size_t flac = fs::file_size(Path("full.flac"));
  const std::size_t aiff = fs::file_size(Path("full.aiff"));
  for (const Cut& c :
       {Cut{"full.wav", "half.wav", wav / 2}, Cut{"full.wav", "head.wav", 44},
        Cut{"full.wav", "short.wav", wav - 1000}, Cut{"full.flac", "half.flac", flac / 2},
        Cut{"full.aiff", "half.aiff", aiff / 2}}) {
    CopyPrefix(Path(c.from), Path(c.to), c.bytes);
    std::string msg;
    EXPECT_EQ(CodeOf(Path(c.to), &msg), ErrorCode::kNotAudio) << c.to;
    EXPECT_NE(msg.find("truncated"), std::string::npos) << msg;
  }
}

TEST_F(AudioTest, HandMadeFloatWavReads) {
  std::vector<float> x{0.25f, -0.5f, 0.125f, 1.5f, -0.75f, 0.0f};
  testing_util::WriteFloatWav(Path("hand.wav"), x, 2, 22050);
  const Audio a = ReadAudio(Path("hand.wav"));
  EXPECT_EQ(a.info.subtype, "FLOAT");
  ASSERT_EQ(a.info.channels, 2);
  EXPECT_EQ(a.channels[0], (std::vector<float>{0.25f, 0.125f, -0.75f}));
  EXPECT_EQ(a.channels[1], (std::vector<float>{-0.5f, 1.5f, 0.0f}));  // > 1 kept in float files
}

TEST_F(AudioTest, NanAndInfSamples) {
  for (float bad : {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity(),
                    -std::numeric_limits<float>::infinity()}) {
    std::vector<float> x(2000, 0.1f);
    x[2 * 777 + 1] = bad;  // channel 1, frame 777
    testing_util::WriteFloatWav(Path("bad.wav"), x, 2, 48000);
    std::string msg;
    EXPECT_EQ(CodeOf(Path("bad.wav"), &msg), ErrorCode::kBadSamples) << bad;
    EXPECT_NE(msg.find("channel 1 at frame 777"), std::string::npos) << msg;
    EXPECT_EQ(msg.rfind(Path("bad.wav") + ": ", 0), 0u) << msg;
    // The writer refuses them instead of writing garbage.
    std::vector<std::vector<float>> planar{std::vector<float>(10, 0.1f)};
    planar[0][3] = bad;
    try {
      WriteAudio(Path("never.wav"), planar, 48000.0);
      FAIL() << "wrote a non-finite sample";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    }
    EXPECT_FALSE(fs::exists(Path("never.wav")));
  }
}

TEST_F(AudioTest, WriteErrors) {
  const auto x = TestSignal(1, 100, 48000.0);
  auto code = [&](const std::string& path, const std::string& subtype, double rate,
                  const std::vector<std::vector<float>>& ch) {
    try {
      WriteAudio(path, ch, rate, AudioWriteOptions{subtype});
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kOk;
  };
  EXPECT_EQ(code(Path("a.mp4"), "PCM_16", 48000, x), ErrorCode::kOutput);
  EXPECT_EQ(code(Path("a.flac"), "FLOAT", 48000, x), ErrorCode::kOutput);
  EXPECT_EQ(code(Path("a.wav"), "PCM_12", 48000, x), ErrorCode::kOutput);
  EXPECT_EQ(code(Path("nodir/a.wav"), "PCM_16", 48000, x), ErrorCode::kOutput);
  EXPECT_EQ(code(Path("a.wav"), "PCM_16", 48000.5, x), ErrorCode::kBadParameter);
  EXPECT_EQ(code(Path("a.wav"), "PCM_16", 48000, {x[0], std::vector<float>(5)}),
            ErrorCode::kBadParameter);
  EXPECT_TRUE(fs::is_empty(dir_));  // nothing partial left behind
}

// An MP3 goes to FFmpeg, not libsndfile's libmpg123 (which prints its own "Note: Illegal
// Audio-MPEG-Header" / "dequantization failed" lines on a damaged file): a good one decodes, a
// damaged one gives our one message and exit 4, with nothing else on stderr.
TEST_F(AudioTest, Mp3IsDecodedQuietlyByFfmpeg) {
  const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
  const std::string wav = Path("drop.wav"), mp3 = Path("drop.mp3"), bad = Path("bad.mp3");
  WriteAudio(wav, s.recording.channels, s.recording.sample_rate_hz);
  if (std::system("command -v ffmpeg > /dev/null 2>&1") != 0 ||
      std::system(("ffmpeg -nostdin -loglevel error -y -i '" + wav + "' -b:a 192k '" + mp3 + "'")
                      .c_str()) != 0) {
    const char* ci = std::getenv("CI");
    if (ci && std::string(ci) == "true") FAIL() << "ffmpeg is needed to make the mp3 test file";
    GTEST_SKIP() << "no ffmpeg program to make the mp3 test file";
  }
  const Audio a = ReadAudio(mp3);
  EXPECT_EQ(a.info.decoder, "ffmpeg");
  EXPECT_TRUE(a.info.lossy);
  EXPECT_GE(DetectImpacts(a, DetectOptions{}).main().impacts.size(), 20u);
  // Damage: every MPEG frame header after the first kilobyte loses its layer bits.
  std::ifstream in(mp3, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  int damaged = 0;
  for (std::size_t i = 1024; i + 1 < bytes.size(); ++i) {
    const auto b0 = static_cast<unsigned char>(bytes[i]),
               b1 = static_cast<unsigned char>(bytes[i + 1]);
    if (b0 == 0xFF && (b1 & 0xE0) == 0xE0 && (i % 3 == 0)) {
      bytes[i + 1] = static_cast<char>(b1 ^ 0x1E);
      ++damaged;
    }
  }
  ASSERT_GT(damaged, 10);
  std::ofstream(bad, std::ios::binary) << bytes;
  const testing_util::CommandResult r = testing_util::RunCommand(BOUNCECAL_BINARY, "detect " + bad);
  EXPECT_EQ(r.exit_code, 4) << r.err;
  EXPECT_EQ(r.err.find("Note:"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find("libmpg123"), std::string::npos) << r.err;
  EXPECT_EQ(r.err.rfind("bouncecal: " + bad + ": ", 0), 0u) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

// --- Phone formats through FFmpeg ------------------------------------------------------------

// Makes an m4a (AAC) file from a WAV with the ffmpeg program (installed by tools/install-deps.sh
// for the tests). Returns false when ffmpeg is not there (a failure under CI=true).
bool MakeM4a(const std::string& wav, const std::string& m4a) {
  if (std::system("command -v ffmpeg > /dev/null 2>&1") != 0) return false;
  const std::string cmd =
      "ffmpeg -nostdin -loglevel error -y -i '" + wav + "' -c:a aac -b:a 160k '" + m4a + "'";
  return std::system(cmd.c_str()) == 0;
}

TEST_F(AudioTest, M4aAacIsDecodedByFfmpegAndDetected) {
  const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
  const std::string wav = Path("drop.wav"), m4a = Path("drop.m4a");
  WriteAudio(wav, s.recording.channels, s.recording.sample_rate_hz);
  if (!MakeM4a(wav, m4a)) {
    const char* ci = std::getenv("CI");
    if (ci && std::string(ci) == "true") FAIL() << "ffmpeg is needed to make the m4a test file";
    GTEST_SKIP()
        << "no ffmpeg program to make the m4a test file (tools/install-deps.sh installs it)";
  }
  const Audio a = ReadAudio(m4a);
  EXPECT_EQ(a.info.decoder, "ffmpeg");
  EXPECT_EQ(a.info.subtype, "aac");
  EXPECT_TRUE(a.info.lossy);
  EXPECT_EQ(a.info.sample_rate_hz, 44100.0);
  EXPECT_EQ(a.info.channels, 1);
  // AAC primes 1024 samples (ffmpeg's encoder writes them in an edit list): trimmed, so the
  // decoded length is the original's to within one frame of padding at the end.
  EXPECT_EQ(a.info.codec_delay_samples, 1024);
  EXPECT_TRUE(a.info.codec_delay_trimmed);
  EXPECT_NEAR(static_cast<double>(a.info.frames),
              static_cast<double>(s.recording.channels[0].size()), 1024.0);
  // The same impacts as from the WAV: intervals within 20 us (AAC at 160 kb/s; measured 0.6 us
  // median, 4.5 us max), and a coded warning that the audio went through a lossy codec.
  const DetectionResult rw = DetectImpacts(ReadAudio(wav), DetectOptions{});
  const DetectionResult rm = DetectImpacts(a, DetectOptions{});
  EXPECT_TRUE(HasWarning(rm.warnings, "codec_delay"));
  EXPECT_FALSE(HasWarning(rw.warnings, "codec_delay"));
  const auto& iw = rw.main().impacts;
  const auto& im = rm.main().impacts;
  ASSERT_GE(im.size(), iw.size() - 2);
  int compared = 0;
  for (std::size_t k = 0; k + 1 < iw.size(); ++k) {
    for (std::size_t j = 0; j + 1 < im.size(); ++j) {
      if (std::fabs(im[j].time_s - iw[k].time_s) > 1e-3 ||
          std::fabs(im[j + 1].time_s - iw[k + 1].time_s) > 1e-3)
        continue;
      EXPECT_NEAR(im[j + 1].time_s - im[j].time_s, iw[k + 1].time_s - iw[k].time_s, 20e-6) << k;
      ++compared;
    }
  }
  EXPECT_GE(compared, 15);
  // A truncated m4a (its index is at the end) is not audio: exit 4, both readers named.
  std::ifstream in(m4a, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  std::ofstream(Path("cut.m4a"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  std::string msg;
  EXPECT_EQ(CodeOf(Path("cut.m4a"), &msg), ErrorCode::kNotAudio);
  EXPECT_NE(msg.find("libsndfile or FFmpeg"), std::string::npos) << msg;
}

}  // namespace
}  // namespace bouncecal
