// Recordings whose header gives no length, and standard input (audio.hpp): what an encoder
// writing to a pipe leaves (ffmpeg to stdout: FLAC STREAMINFO total 0, WAV data size
// 0xFFFFFFFF; a WAV data size of 0) is read to its end; `-` reads standard input in detect,
// analyze and calibrate; a stream cut inside a frame is read to its last whole frame with a
// truncated_stream warning; a stream with no audio is exit 4; a FIFO is read block by block as
// its bytes arrive.
#include <fcntl.h>
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

namespace fs = std::filesystem;
using testing_util::CommandResult;
using testing_util::RunCommand;
using testing_util::ScratchDir;
using testing_util::Slurp;

const std::string kBin = BOUNCECAL_BINARY;

// The bundled steel ball's recording, as a WAV (what every stream below is made from).
struct Source {
  ScratchDir dir{"bc_stream"};
  SynthResult synth = Synthesize(SynthPreset("steel-copper"));
  std::string wav = dir / "drop.wav";
  std::size_t frames = 0;
  Source() {
    WriteAudio(wav, synth.recording.channels, synth.recording.sample_rate_hz);
    frames = synth.recording.channels.front().size();
  }
};

// Runs a shell command (ffmpeg writing to a pipe); false when ffmpeg is not installed (a
// failure under CI=true: tools/install-deps.sh installs it).
bool Shell(const std::string& command) {
  if (std::system("command -v ffmpeg > /dev/null 2>&1") != 0) {
    const char* ci = std::getenv("CI");
    if (ci && std::string(ci) == "true") ADD_FAILURE() << "ffmpeg is needed for the stream files";
    return false;
  }
  return std::system(command.c_str()) == 0;
}

// ffmpeg encoding `wav` to standard output as `format`, through a pipe into `out`: the
// encoder cannot seek back to write the length.
bool PipeWritten(const std::string& wav, const std::string& format, const std::string& out) {
  return Shell("ffmpeg -nostdin -loglevel error -i '" + wav + "' -f " + format + " - | cat > '" +
               out + "'");
}

std::string Bytes(const std::string& path) { return Slurp(path); }
void Write(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary) << bytes;
}

std::uint32_t Le32(const std::string& b, std::size_t at) {
  std::uint32_t v = 0;
  std::memcpy(&v, b.data() + at, 4);
  return v;
}

// The offset of a RIFF/WAVE file's data chunk header.
std::size_t DataChunk(const std::string& b) {
  std::size_t at = 12;
  while (at + 8 <= b.size() && b.compare(at, 4, "data") != 0) at += 8 + Le32(b, at + 4);
  return at;
}

std::vector<double> MainTimes(const DetectionResult& r) {
  std::vector<double> t;
  for (const Impact& i : r.main().impacts) t.push_back(i.time_s);
  return t;
}

TEST(AudioStream, PipeWrittenFlacIsReadToItsEnd) {
  Source src;
  const std::string flac = src.dir / "pipe.flac";
  if (!PipeWritten(src.wav, "flac", flac)) GTEST_SKIP() << "no ffmpeg";
  // The STREAMINFO total (bytes 18-21 hold its low 32 bits) is 0: no length.
  const std::string b = Bytes(flac);
  ASSERT_GT(b.size(), 26u);
  EXPECT_EQ(b.substr(0, 4), "fLaC");
  EXPECT_EQ(Le32(b, 22), 0u);
  {
    AudioReader r(flac);
    EXPECT_EQ(r.info().frames, kUnknownFrames);
    std::vector<std::vector<float>> block;
    std::int64_t n = 0;
    while (const std::int64_t got = r.Read(4096, &block)) n += got;
    EXPECT_EQ(n, static_cast<std::int64_t>(src.frames));
    EXPECT_EQ(r.info().frames, n);  // known once read
    EXPECT_TRUE(r.warnings().empty());
  }
  const Audio a = ReadAudio(flac);
  EXPECT_EQ(a.info.frames, static_cast<std::int64_t>(src.frames));
  const Audio w = ReadAudio(src.wav);
  ASSERT_EQ(a.channels.size(), w.channels.size());
  EXPECT_EQ(a.channels[0], w.channels[0]);  // FLAC is lossless: the same 16-bit samples
  // Detection block by block on the unknown length finds what it finds in the file.
  const DetectionResult from_pipe = DetectImpactsInFile(flac, DetectOptions{});
  EXPECT_EQ(MainTimes(from_pipe), MainTimes(DetectImpactsInFile(src.wav, DetectOptions{})));
  EXPECT_EQ(from_pipe.audio.frames, static_cast<std::int64_t>(src.frames));
  EXPECT_DOUBLE_EQ(from_pipe.end_s, static_cast<double>(src.frames) / a.info.sample_rate_hz);
}

TEST(AudioStream, WavWithoutALengthIsReadToItsEnd) {
  Source src;
  const std::string piped = src.dir / "pipe.wav";
  if (!PipeWritten(src.wav, "wav", piped)) GTEST_SKIP() << "no ffmpeg";
  const std::string b = Bytes(piped);
  EXPECT_EQ(Le32(b, DataChunk(b) + 4), 0xFFFFFFFFu);  // ffmpeg's placeholder
  // A writer that left the data size at 0 (and the RIFF size too).
  std::string zero = b;
  const std::size_t data = DataChunk(zero);
  std::memset(zero.data() + data + 4, 0, 4);
  std::memset(zero.data() + 4, 0, 4);
  Write(src.dir / "zero.wav", zero);
  for (const std::string& f : {piped, src.dir / "zero.wav"}) {
    SCOPED_TRACE(f);
    AudioReader r(f);
    EXPECT_EQ(r.info().frames, kUnknownFrames);
    const Audio a = ReadAudio(f);
    EXPECT_EQ(a.info.frames, static_cast<std::int64_t>(src.frames));
    EXPECT_EQ(a.channels[0], ReadAudio(src.wav).channels[0]);
    EXPECT_TRUE(a.warnings.empty());
  }
}

// Cut inside a frame: the whole frames before the cut, and a warning that names the input.
TEST(AudioStream, AStreamCutInsideAFrameIsReadToItsLastWholeFrame) {
  Source src;
  const std::string piped = src.dir / "pipe.wav", flac = src.dir / "pipe.flac";
  if (!PipeWritten(src.wav, "wav", piped) || !PipeWritten(src.wav, "flac", flac))
    GTEST_SKIP() << "no ffmpeg";
  const std::string b = Bytes(piped);
  const std::size_t start = DataChunk(b) + 8;
  const std::size_t whole = src.frames / 2;
  // 16-bit mono: one byte of frame `whole` is there.
  const std::string cut = src.dir / "cut.wav";
  Write(cut, b.substr(0, start + 2 * whole + 1));
  const Audio a = ReadAudio(cut);
  EXPECT_EQ(a.info.frames, static_cast<std::int64_t>(whole));
  ASSERT_EQ(a.warnings.size(), 1u);
  EXPECT_EQ(a.warnings[0].code, "truncated_stream");
  EXPECT_NE(a.warnings[0].message.find(cut), std::string::npos) << a.warnings[0].message;
  EXPECT_NE(a.warnings[0].message.find(std::to_string(whole) + " frames"), std::string::npos)
      << a.warnings[0].message;
  // Cut on a frame boundary: complete, no warning.
  Write(src.dir / "even.wav", b.substr(0, start + 2 * whole));
  EXPECT_TRUE(ReadAudio(src.dir / "even.wav").warnings.empty());
  // A FLAC stream cut inside a FLAC frame: its whole frames, and the warning.
  const std::string fb = Bytes(flac);
  Write(src.dir / "cut.flac", fb.substr(0, fb.size() / 2 + 3));
  const Audio f = ReadAudio(src.dir / "cut.flac");
  EXPECT_GT(f.info.frames, 0);
  EXPECT_LT(f.info.frames, static_cast<std::int64_t>(src.frames));
  EXPECT_TRUE(HasWarning(f.warnings, "truncated_stream"));
  // Detection carries the reader's warning.
  EXPECT_TRUE(HasWarning(DetectImpactsInFile(cut, DetectOptions{}).warnings, "truncated_stream"));
  // A declared length the data falls short of stays an error (exit 4), as for any file.
  std::string declared = b;
  const std::uint32_t bytes = static_cast<std::uint32_t>(2 * src.frames);
  std::memcpy(declared.data() + DataChunk(declared) + 4, &bytes, 4);
  Write(src.dir / "declared.wav", declared.substr(0, start + 2 * whole + 1));
  try {
    ReadAudio(src.dir / "declared.wav");
    ADD_FAILURE() << "a file shorter than its header says was read";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kNotAudio);
    EXPECT_NE(std::string(e.what()).find("truncated"), std::string::npos) << e.what();
  }
}

TEST(AudioStream, StandardInputForDetectAnalyzeAndCalibrate) {
  Source src;
  const std::string flac = src.dir / "pipe.flac";
  if (!PipeWritten(src.wav, "flac", flac)) GTEST_SKIP() << "no ffmpeg";
  const CommandResult file = RunCommand(kBin, "detect '" + src.wav + "' --json");
  ASSERT_EQ(file.exit_code, 0) << file.err;
  const auto jf = nlohmann::json::parse(file.out);
  // A pipe into `detect -` (the FLAC written to a pipe, read from one), and a redirected file.
  for (const std::string& feed : {"cat '" + flac + "' | " + kBin, kBin + " < '" + src.wav + "'"}) {
    SCOPED_TRACE(feed);
    const CommandResult r = RunCommand(feed, "detect - --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    const auto j = nlohmann::json::parse(r.out);
    EXPECT_EQ(j.at("file"), "-");
    EXPECT_EQ(j.at("sequences").at(0).at("impacts"), jf.at("sequences").at(0).at("impacts"));
    EXPECT_EQ(j.at("duration_s"), jf.at("duration_s"));
  }
  const std::string scene = " --scene '" + src.dir / "scene.toml" + "'";
  Write(src.dir / "scene.toml",
        Slurp(std::string(BOUNCECAL_SOURCE_DIR) + "/data/scenes/steel-copper.toml"));
  const CommandResult an =
      RunCommand("cat '" + flac + "' | " + kBin, "analyze -" + scene + " --json");
  ASSERT_EQ(an.exit_code, 0) << an.err;
  const CommandResult an_file = RunCommand(kBin, "analyze '" + src.wav + "'" + scene + " --json");
  EXPECT_EQ(nlohmann::json::parse(an.out).at("bounces"),
            nlohmann::json::parse(an_file.out).at("bounces"));
  const CommandResult cal =
      RunCommand("cat '" + flac + "' | " + kBin, "calibrate -" + scene + " --json --quiet");
  const CommandResult cal_file =
      RunCommand(kBin, "calibrate '" + src.wav + "'" + scene + " --json --quiet");
  ASSERT_EQ(cal.exit_code, cal_file.exit_code) << cal.err;
  const auto jc = nlohmann::json::parse(cal.out), jcf = nlohmann::json::parse(cal_file.out);
  EXPECT_EQ(jc.at("law").at("parameters"), jcf.at("law").at("parameters"));
  EXPECT_EQ(jc.at("provenance").at("inputs").at(0).at("file"), "-");
  // Standard input is read once: naming it twice is a usage error, before any reading.
  const CommandResult twice = RunCommand(kBin + " < '" + src.wav + "'", "detect - -");
  EXPECT_EQ(twice.exit_code, 2) << twice.err;
  EXPECT_NE(twice.err.find("standard input"), std::string::npos) << twice.err;
}

TEST(AudioStream, CutOrEmptyStandardInput) {
  Source src;
  const std::string piped = src.dir / "pipe.wav";
  if (!PipeWritten(src.wav, "wav", piped)) GTEST_SKIP() << "no ffmpeg";
  const std::string b = Bytes(piped);
  const std::size_t start = DataChunk(b) + 8;
  Write(src.dir / "cut.wav", b.substr(0, start + 2 * (src.frames - 100) + 1));
  const CommandResult cut =
      RunCommand(kBin + " < '" + src.dir / "cut.wav" + "'", "detect - --json");
  ASSERT_EQ(cut.exit_code, 0) << cut.err;
  EXPECT_NE(cut.err.find("warning [truncated_stream]"), std::string::npos) << cut.err;
  bool warned = false;
  const auto j = nlohmann::json::parse(cut.out);
  for (const auto& w : j.at("warnings")) warned |= w.at("code") == "truncated_stream";
  EXPECT_TRUE(warned);
  // No audio at all: nothing, a header and no frame, a header and half a frame.
  Write(src.dir / "empty", "");
  Write(src.dir / "header.wav", b.substr(0, start));
  Write(src.dir / "half.wav", b.substr(0, start + 1));
  for (const char* f : {"empty", "header.wav", "half.wav"}) {
    const CommandResult r = RunCommand(kBin + " < '" + (src.dir / f) + "'", "detect -");
    EXPECT_EQ(r.exit_code, 4) << f << ": " << r.err;
    EXPECT_EQ(r.err.rfind("bouncecal: -: ", 0), 0u) << r.err;
    EXPECT_TRUE(r.out.empty()) << r.out;
  }
}

// What libsndfile cannot read from a stream goes to FFmpeg (through a temporary copy).
TEST(AudioStream, FfmpegFormatsFromStandardInput) {
  Source src;
  const std::string m4a = src.dir / "drop.m4a";
  if (!Shell("ffmpeg -nostdin -loglevel error -i '" + src.wav + "' -c:a aac -b:a 160k '" + m4a +
             "'"))
    GTEST_SKIP() << "no ffmpeg";
  const CommandResult file = RunCommand(kBin, "detect '" + m4a + "' --json");
  const CommandResult in = RunCommand("cat '" + m4a + "' | " + kBin, "detect - --json");
  ASSERT_EQ(in.exit_code, 0) << in.err;
  ASSERT_EQ(file.exit_code, 0) << file.err;
  const auto j = nlohmann::json::parse(in.out), jf = nlohmann::json::parse(file.out);
  EXPECT_EQ(j.at("audio").at("decoder"), "ffmpeg");
  EXPECT_EQ(j.at("sequences").at(0).at("impacts"), jf.at("sequences").at(0).at("impacts"));
  // Garbage on standard input: both readers' reasons, naming the input, exit 4.
  Write(src.dir / "text", std::string(4096, 'x'));
  const CommandResult bad = RunCommand(kBin + " < '" + src.dir / "text" + "'", "detect -");
  EXPECT_EQ(bad.exit_code, 4) << bad.err;
  EXPECT_EQ(bad.err.rfind("bouncecal: -: not an audio file", 0), 0u) << bad.err;
  EXPECT_EQ(bad.err.find("bouncecal-stream"), std::string::npos) << bad.err;  // not the spool
}

// A FIFO is read as its bytes arrive: the first blocks come back while the writer still
// writes (what a streaming listener needs), and the whole recording arrives.
TEST(AudioStream, AFifoIsReadBlockByBlockAsItsBytesArrive) {
  Source src;
  const std::string piped = src.dir / "pipe.wav";
  if (!PipeWritten(src.wav, "wav", piped)) GTEST_SKIP() << "no ffmpeg";
  const std::string b = Bytes(piped);
  const std::string fifo = src.dir / "fifo";
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  std::atomic<bool> writer_done{false};
  std::thread writer([&] {
    const int fd = ::open(fifo.c_str(), O_WRONLY);
    if (fd < 0) return;
    const std::size_t piece = 8192;
    for (std::size_t at = 0; at < b.size(); at += piece) {
      const std::size_t n = std::min(piece, b.size() - at);
      if (::write(fd, b.data() + at, n) != static_cast<ssize_t>(n)) break;
      if (at > b.size() / 2) std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    writer_done = true;
    ::close(fd);
  });
  std::int64_t total = 0;
  bool early = false;
  {
    AudioReader r(fifo);
    EXPECT_EQ(r.info().frames, kUnknownFrames);
    std::vector<std::vector<float>> block;
    while (const std::int64_t got = r.Read(4096, &block)) {
      total += got;
      if (total <= static_cast<std::int64_t>(src.frames / 4) && !writer_done) early = true;
    }
  }
  writer.join();
  EXPECT_TRUE(early) << "no block came back before the writer finished";
  EXPECT_EQ(total, static_cast<std::int64_t>(src.frames));
}

}  // namespace
}  // namespace bouncecal
