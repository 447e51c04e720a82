// `bouncecal listen`: a stream on standard input, each impact printed as soon as it is final and
// the whole take's analysis at the end. The stream is the bundled recording as 16-bit PCM,
// written into a pipe in real time (a paced pipe, as `arecord ... | bouncecal listen -` gives),
// as a WAV stream and as raw PCM.
#include <gtest/gtest.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstring>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "json_schema.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

using Clock = std::chrono::steady_clock;
using testing_util::RunCommand;
using testing_util::ScratchDir;

const std::string kFlac = std::string(BOUNCECAL_SOURCE_DIR) + "/data/default_steel_copper.flac";

std::vector<std::int16_t> Pcm16(double seconds) {
  const Audio a = ReadAudio(kFlac);
  const auto n = std::min(a.channels[0].size(), static_cast<std::size_t>(seconds * 48000));
  std::vector<std::int16_t> out(n);
  for (std::size_t i = 0; i < n; ++i)
    out[i] = static_cast<std::int16_t>(
        std::lround(std::clamp(a.channels[0][i] * 32768.0f, -32768.0f, 32767.0f)));
  return out;
}

// A WAV header of a stream whose length is not known (sizes 0xFFFFFFFF, as a pipe's writer
// leaves them).
std::string StreamHeader(int rate) {
  std::string h;
  auto u32 = [&](std::uint32_t v) { h.append(reinterpret_cast<const char*>(&v), 4); };
  auto u16 = [&](std::uint16_t v) { h.append(reinterpret_cast<const char*>(&v), 2); };
  h += "RIFF";
  u32(0xffffffffu);
  h += "WAVEfmt ";
  u32(16);
  u16(1);
  u16(1);
  u32(static_cast<std::uint32_t>(rate));
  u32(static_cast<std::uint32_t>(rate * 2));
  u16(2);
  u16(16);
  h += "data";
  u32(0xffffffffu);
  return h;
}

struct Line {
  std::string text;
  double at_s = 0;  // since the stream started
};

struct Listened {
  std::vector<Line> lines;
  double stream_end_s = 0;  // when the writer closed the pipe
  int status = -1;
};

// Runs `listen` with `args`, writing `header` then `pcm` into its stdin in blocks of 50 ms,
// paced at `speed` times real time (0: as fast as the pipe takes); `interrupt`: SIGINT after
// writing, without closing the pipe.
Listened Listen(const std::string& args, const std::string& header,
                const std::vector<std::int16_t>& pcm, double speed, bool interrupt = false) {
  int in[2], out[2];
  EXPECT_EQ(::pipe(in), 0);
  EXPECT_EQ(::pipe(out), 0);
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::dup2(in[0], 0);
    ::dup2(out[1], 1);
    ::close(in[1]);
    ::close(out[0]);
    const int null = ::open("/dev/null", O_WRONLY);
    ::dup2(null, 2);
    ::execl("/bin/sh", "sh", "-c",
            (std::string("exec ") + BOUNCECAL_BINARY + " listen " + args).c_str(),
            static_cast<char*>(nullptr));
    ::_exit(127);
  }
  ::close(in[0]);
  ::close(out[1]);
  Listened r;
  const auto start = Clock::now();
  auto since = [&] { return std::chrono::duration<double>(Clock::now() - start).count(); };
  std::thread writer([&] {
    (void)!::write(in[1], header.data(), header.size());
    const std::size_t block = 2400;
    for (std::size_t at = 0; at < pcm.size(); at += block) {
      const std::size_t n = std::min(block, pcm.size() - at);
      (void)!::write(in[1], pcm.data() + at, n * 2);
      if (speed > 0) {
        const double due = static_cast<double>(at + n) / 48000.0 / speed;
        std::this_thread::sleep_until(start + std::chrono::duration<double>(due));
      }
    }
    r.stream_end_s = since();
    if (interrupt) {
      std::this_thread::sleep_for(std::chrono::milliseconds(300));
      ::kill(pid, SIGINT);
    } else {
      ::close(in[1]);
    }
  });
  std::string pending;
  char buf[65536];
  for (;;) {
    const ssize_t n = ::read(out[0], buf, sizeof buf);
    if (n <= 0) break;
    pending.append(buf, static_cast<std::size_t>(n));
    for (std::size_t nl; (nl = pending.find('\n')) != std::string::npos;) {
      r.lines.push_back({pending.substr(0, nl), since()});
      pending.erase(0, nl + 1);
    }
  }
  writer.join();
  if (interrupt) ::close(in[1]);
  ::close(out[0]);
  ::waitpid(pid, &r.status, 0);
  return r;
}

int ExitCode(int status) { return WIFEXITED(status) ? WEXITSTATUS(status) : -1; }

TEST(Listen, PacedPipePrintsImpactsBeforeTheStreamEnds) {
  // The first 6 s in real time: the drop starts at 1.5 s, ~30 impacts.
  const Listened r = Listen("- --json", StreamHeader(48000), Pcm16(6.0), 1.0);
  ASSERT_EQ(ExitCode(r.status), 0);
  ASSERT_FALSE(r.lines.empty());
  // Impacts a second or more before the end of the stream: printed while it ran (the second
  // leaves room for a machine busy with other tests).
  int early = 0, early_printed = 0, impacts = 0;
  double worst_delay = 0;
  std::string arrivals;
  const testing_util::SchemaSet schemas(std::string(BOUNCECAL_SOURCE_DIR) + "/docs/schema");
  for (const Line& l : r.lines) {
    const nlohmann::json m = nlohmann::json::parse(l.text);
    EXPECT_TRUE(schemas.Validate(m, "live.schema.json").empty()) << l.text.substr(0, 300);
    if (m["type"] != "impact") continue;
    ++impacts;
    const double t = m["impact"]["time_s"].get<double>();
    arrivals += std::to_string(t) + " at " + std::to_string(l.at_s) + "\n";
    if (t > r.stream_end_s - 1.0) continue;
    ++early;
    early_printed += l.at_s < r.stream_end_s ? 1 : 0;
    if (m["impact"]["index"].get<int>() >= 2)
      worst_delay = std::max(worst_delay, l.at_s - m["impact"]["time_s"].get<double>());
  }
  EXPECT_GE(impacts, 25);
  EXPECT_GE(early, 15);  // 16 impacts from 1.5 s to 5 s
  EXPECT_EQ(early_printed, early) << "impacts printed while the stream ran (it ended at "
                                  << r.stream_end_s << " s):\n"
                                  << arrivals;
  RecordProperty("worst_delay_ms", static_cast<int>(1e3 * worst_delay));
  const nlohmann::json last = nlohmann::json::parse(r.lines.back().text);
  ASSERT_EQ(last["type"], "analysis");
  ASSERT_TRUE(last["analysis"].is_object()) << last.dump();
  EXPECT_GE(last["analysis"]["bounces"].size(), 25u);
  EXPECT_EQ(last["analysis"]["file"], "stdin");
}

TEST(Listen, RawPcmWithARateAndTheTakeKept) {
  ScratchDir dir("bc_listen");
  const std::vector<std::int16_t> pcm = Pcm16(100.0);
  const std::string take = dir / "take.flac";
  const Listened r = Listen("- --rate 48000 --format s16le --json --take " + take, "", pcm, 0.0);
  ASSERT_EQ(ExitCode(r.status), 0);
  const nlohmann::json last = nlohmann::json::parse(r.lines.back().text);
  ASSERT_TRUE(last["analysis"].is_object()) << last.dump();
  EXPECT_EQ(last["analysis"]["bounces"].size(), 74u);
  // The take is the stream: analyze on it prints the same analysis.
  const auto cli = RunCommand(BOUNCECAL_BINARY, "analyze " + take + " --json");
  ASSERT_EQ(cli.exit_code, 0) << cli.err;
  EXPECT_EQ(nlohmann::json::parse(cli.out), last["analysis"]);
  EXPECT_EQ(last["take"]["frames"], static_cast<std::int64_t>(pcm.size()));
}

TEST(Listen, CtrlCEndsTheStreamAndPrintsTheAnalysis) {
  const Listened r = Listen("-", StreamHeader(48000), Pcm16(100.0), 0.0, /*interrupt=*/true);
  EXPECT_EQ(ExitCode(r.status), 0);
  std::string all;
  for (const Line& l : r.lines) all += l.text + "\n";
  EXPECT_NE(all.find("impact  sequence 0  #65"), std::string::npos) << all.substr(0, 500);
  EXPECT_NE(all.find("analysis of the whole take"), std::string::npos) << all.substr(0, 500);
}

TEST(Listen, BadStreamsAreRefused) {
  ScratchDir dir("bc_listen");
  const std::string raw = dir / "raw.pcm";
  { std::ofstream(raw, std::ios::binary) << std::string(48000, '\x01'); }
  const auto no_rate =
      RunCommand("/bin/sh", "-c '" + std::string(BOUNCECAL_BINARY) + " listen - < " + raw + "'");
  EXPECT_EQ(no_rate.exit_code, 2) << no_rate.err;
  EXPECT_NE(no_rate.err.find("--rate"), std::string::npos) << no_rate.err;
  const std::string bad = dir / "bad.wav";
  {
    std::ofstream(bad, std::ios::binary)
        << std::string("RIFF\xff\xff\xff\xffWAVEfmt \x10\0\0\0\x07\0", 22);
  }
  const auto cut =
      RunCommand("/bin/sh", "-c '" + std::string(BOUNCECAL_BINARY) + " listen - < " + bad + "'");
  EXPECT_EQ(cut.exit_code, 4) << cut.err;
  EXPECT_NE(cut.err.find("stdin"), std::string::npos) << cut.err;
}

}  // namespace
}  // namespace bouncecal
