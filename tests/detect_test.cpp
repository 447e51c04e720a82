// The detect pipeline (channel selection + onsets + tracking) and `bouncecal detect`.
#include "bouncecal/acoustic/detect.hpp"

#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

namespace fs = std::filesystem;

Audio InMemory(std::vector<std::vector<float>> ch, double rate, const std::string& name) {
  Audio a;
  a.info.path = name;
  a.info.sample_rate_hz = rate;
  a.info.channels = static_cast<int>(ch.size());
  a.info.frames = static_cast<std::int64_t>(ch[0].size());
  for (std::size_t c = 0; c < ch.size(); ++c) {
    ClippingReport r;
    r.channel = static_cast<int>(c);
    for (float v : ch[c]) r.peak = std::max(r.peak, static_cast<double>(std::fabs(v)));
    a.clipping.push_back(r);
  }
  a.channels = std::move(ch);
  return a;
}

ErrorCode CodeOf(const Audio& a) {
  try {
    DetectImpacts(a, DetectOptions{});
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(a.info.path), std::string::npos) << e.what();
    return e.code();
  }
  return ErrorCode::kOk;
}

TEST(Detect, RenderedDropIsFoundWithExactTimes) {
  SynthSpec spec = SynthPreset("steel-copper");
  const SynthResult s = Synthesize(spec);
  const Audio a = InMemory(s.recording.channels, s.recording.sample_rate_hz, "steel.wav");
  const DetectionResult r = DetectImpacts(a, DetectOptions{});
  ASSERT_GE(r.main_sequence, 0);
  const auto& truth = s.recording.drops[0];
  // The first 20 impacts (all loud, far apart): every one found to within 20 us.
  const auto& imps = r.main().impacts;
  ASSERT_GE(imps.size(), 20u);
  std::vector<double> err;  // signed error of the nearest detected impact
  for (std::size_t k = 0; k < 20; ++k) {
    double best = 1.0;
    for (const Impact& i : imps)
      if (std::fabs(i.time_s - truth[k].onset_s) < std::fabs(best))
        best = i.time_s - truth[k].onset_s;
    EXPECT_LT(std::fabs(best), 20e-6) << "impact " << k;
    err.push_back(best);
  }
  // Sub-sample timing: the sequence's constant offset (the median error) and the RMS error about
  // it. Times on the integer sample grid alone would scatter by 1/sqrt(12) of a sample (6.0 us at
  // this preset's 48 kHz); an onset convention off by a sample would move the offset by 21 us.
  // Measured: offset -1.36 us (bound 3 us), RMS 1.72 us (bound 2.5 us; the errors drift from
  // -4.5 us on the loud first impacts to +2 us by the 20th).
  std::vector<double> sorted = err;
  std::sort(sorted.begin(), sorted.end());
  const double offset = 0.5 * (sorted[9] + sorted[10]);
  double ss = 0.0;
  for (double e : err) ss += (e - offset) * (e - offset);
  const double rms = std::sqrt(ss / static_cast<double>(err.size()));
  std::printf("[ measured ] steel-copper: offset %.2f us, RMS error about it %.2f us (%g Hz)\n",
              offset * 1e6, rms * 1e6, s.recording.sample_rate_hz);
  EXPECT_LT(std::fabs(offset), 3e-6);
  EXPECT_LT(rms, 2.5e-6);
  for (const Impact& i : imps) {
    EXPECT_GT(i.sigma_s, 0.0);
    EXPECT_GE(i.score, 0.0);
    EXPECT_LE(i.score, 1.0);
  }
}

TEST(Detect, RefinementOffChangesTimingNotDetection) {
  // Refinement off reports each impact at the centre of its STFT hop: the same impacts (one
  // per refined impact, within half a hop of it), with sigma = hop / sqrt(12).
  const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
  const Audio a = InMemory(s.recording.channels, s.recording.sample_rate_hz, "pp.wav");
  const DetectionResult fine = DetectImpacts(a, DetectOptions{});
  DetectOptions o;
  o.refine = false;
  const DetectionResult coarse = DetectImpacts(a, o);
  ASSERT_EQ(coarse.sequences.size(), fine.sequences.size());
  const double hop_s = 16.0 / s.recording.sample_rate_hz;  // auto hop at 48 kHz: 16 samples
  double worst = 0.0;
  for (std::size_t q = 0; q < fine.sequences.size(); ++q) {
    const auto& f = fine.sequences[q].impacts;
    const auto& c = coarse.sequences[q].impacts;
    ASSERT_EQ(c.size(), f.size()) << "sequence " << q;
    for (std::size_t k = 0; k < f.size(); ++k) {
      EXPECT_LE(std::fabs(c[k].time_s - f[k].time_s), 0.5 * hop_s + 1e-9) << "impact " << k;
      EXPECT_NEAR(c[k].sigma_s, hop_s / std::sqrt(12.0), 1e-9);
      worst = std::max(worst, std::fabs(c[k].time_s - f[k].time_s));
    }
  }
  EXPECT_GT(worst, 0.25 * hop_s);  // the times did move to the hop grid
}

TEST(Detect, TwoDropsAreTwoSequences) {
  const SynthResult s = Synthesize(SynthPreset("two-drops"));
  const Audio a = InMemory(s.recording.channels, s.recording.sample_rate_hz, "two.wav");
  const DetectionResult r = DetectImpacts(a, DetectOptions{});
  ASSERT_GE(r.sequences.size(), 2u);
  // Each drop's first impact starts a sequence (channel delay <= 0.25 ms).
  for (const auto& drop : s.recording.drops) {
    bool starts = false;
    for (const Sequence& q : r.sequences)
      starts = starts || std::fabs(q.impacts.front().time_s - drop.front().onset_s) < 1e-3;
    EXPECT_TRUE(starts) << "drop at " << drop.front().onset_s;
  }
}

TEST(Detect, SilenceIsKSilence) {
  EXPECT_EQ(CodeOf(InMemory({std::vector<float>(48000, 0.0f)}, 48000, "silent.wav")),
            ErrorCode::kSilence);
  // One 16-bit step of dither is still silence.
  std::vector<float> x(48000);
  for (std::size_t i = 0; i < x.size(); ++i) x[i] = (i % 2 ? 1.0f : -1.0f) / 32768.0f;
  EXPECT_EQ(CodeOf(InMemory({x}, 48000, "dither.wav")), ErrorCode::kSilence);
}

TEST(Detect, NoiseWithoutBouncesIsKNoBounces) {
  std::mt19937 rng(9);
  std::normal_distribution<float> g(0.0f, 0.05f);
  std::vector<float> x(5 * 48000);
  for (float& v : x) v = g(rng);
  EXPECT_EQ(CodeOf(InMemory({x}, 48000, "noise.wav")), ErrorCode::kNoBounces);
}

TEST(Detect, SingleImpactIsKNoBounces) {
  RenderOptions ro;
  ro.snr_db = 60.0;
  TruthImpact t;
  t.time_s = 0.5;
  t.v_in_m_s = 1.0;
  t.v_out_m_s = 0.9;
  t.contact_s = 5e-5;
  const Recording rec = RenderRecording(std::vector<TruthImpact>{t}, ro);
  EXPECT_EQ(CodeOf(InMemory(rec.channels, rec.sample_rate_hz, "single.wav")),
            ErrorCode::kNoBounces);
}

TEST(Detect, OptionsValidation) {
  DetectOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why));
  o.min_sequence_impacts = 1;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("min_sequence_impacts"), std::string::npos);
  o = DetectOptions{};
  o.hop_s = -1;
  EXPECT_FALSE(o.IsValid(&why));
  const Audio a = InMemory({std::vector<float>(4800, 0.1f)}, 48000, "x.wav");
  EXPECT_THROW(DetectImpacts(a, o), Error);
}

// --- CLI ----------------------------------------------------------------------------------

struct CliRun {
  int code = -1;
  std::string out;
};

CliRun Cli(const std::string& args) {
  CliRun r;
  const std::string cmd = std::string(BOUNCECAL_BINARY) + " " + args + " 2>/dev/null";
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen(cmd.c_str(), "r"), pclose);
  char buf[4096];
  std::size_t n;
  while ((n = std::fread(buf, 1, sizeof buf, p.get())) > 0) r.out.append(buf, n);
  const int st = pclose(p.release());
  r.code = WIFEXITED(st) ? WEXITSTATUS(st) : -1;
  return r;
}

// The impacts of the first chosen sequence of a `detect --json` object (bouncecal.detect/2 lists
// each impact once, in its sequence).
const nlohmann::json& ChosenImpacts(const nlohmann::json& d) {
  return d.at("sequences").at(d.at("chosen_sequences").at(0).get<std::size_t>()).at("impacts");
}

class DetectCli : public ::testing::Test {
 protected:
  testing_util::ScratchDir scratch_{"bc_detect_cli"};
  const fs::path& dir_ = scratch_.path();
};

TEST_F(DetectCli, JsonCsvAndTable) {
  const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
  const std::string wav = (dir_ / "pp.wav").string();
  WriteAudio(wav, s.recording.channels, s.recording.sample_rate_hz);
  const CliRun j = Cli("detect " + wav + " --json");
  ASSERT_EQ(j.code, 0);
  const nlohmann::json doc = nlohmann::json::parse(j.out);
  EXPECT_EQ(doc["sample_rate_hz"].get<double>(), 44100.0);
  EXPECT_EQ(doc["channels"].get<int>(), 1);
  // Each impact once, in its sequence (bouncecal.detect/2): no top-level copy.
  EXPECT_FALSE(doc.contains("impacts"));
  const nlohmann::json& main = doc["sequences"][doc["chosen_sequences"][0].get<int>()]["impacts"];
  ASSERT_TRUE(main.is_array());
  ASSERT_GE(main.size(), 10u);
  for (const char* key : {"time_s", "time_sigma_s", "amplitude", "snr_db", "score"})
    EXPECT_TRUE(main[0].contains(key)) << key;
  ASSERT_GE(doc["sequences"].size(), 1u);
  EXPECT_TRUE(doc["sequences"][0].contains("end_reason"));
  EXPECT_TRUE(doc["sequences"][0].contains("missed_after"));
  EXPECT_NEAR(main[0]["time_s"].get<double>(), s.recording.drops[0][0].onset_s, 1e-4);

  const CliRun c = Cli("detect " + wav + " --csv");
  ASSERT_EQ(c.code, 0);
  EXPECT_EQ(c.out.rfind("sequence,index,time_s,time_sigma_s", 0), 0u);
  std::size_t rows = 0;
  for (char ch : c.out) rows += ch == '\n';
  std::size_t total = 0;
  for (const auto& q : doc["sequences"]) total += q["impacts"].size();
  EXPECT_EQ(rows, total + 1);

  const CliRun t = Cli("detect " + wav);
  ASSERT_EQ(t.code, 0);
  EXPECT_NE(t.out.find("sequence 0"), std::string::npos);
}

TEST_F(DetectCli, BadInputExitCodes) {
  EXPECT_EQ(Cli("detect " + (dir_ / "missing.wav").string()).code,
            static_cast<int>(ErrorCode::kInputMissing));
  const std::string silent = (dir_ / "silent.wav").string();
  WriteAudio(silent, {std::vector<float>(44100, 0.0f)}, 44100);
  const CliRun r = Cli("detect " + silent + " --json");
  EXPECT_EQ(r.code, static_cast<int>(ErrorCode::kSilence));
  EXPECT_TRUE(r.out.empty());  // nothing on stdout on failure
  EXPECT_EQ(Cli("detect " + silent + " --channel 5").code, static_cast<int>(ErrorCode::kUsage));
  EXPECT_EQ(Cli("detect " + silent + " --hop-ms -1").code, static_cast<int>(ErrorCode::kUsage));
}

// --- Channel choice by sequence quality, windows, sequence choice, several files, click track

using testing_util::RunCommand;
using testing_util::ScratchDir;

TEST(Detect, AutoChoosesTheChannelWithTheBetterSequenceAndSaysSo) {
  // Channel 0 hears the drop; channel 1 only noise and two loud knocks (a level statistic would
  // like channel 1: its peaks are higher).
  const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
  std::vector<float> other(s.recording.channels[0].size());
  std::mt19937 rng(4);
  std::normal_distribution<float> g(0.0f, 0.003f);
  for (float& v : other) v = g(rng);
  for (double t : {0.3, 1.9})
    for (int n = 0; n < 200; ++n)
      other[static_cast<std::size_t>(t * 44100) + static_cast<std::size_t>(n)] +=
          0.9f * std::exp(-static_cast<float>(n) / 40.0f) * (n % 2 ? 1.0f : -1.0f);
  const Audio a =
      InMemory({s.recording.channels[0], other}, s.recording.sample_rate_hz, "two_mics.wav");
  const DetectionResult r = DetectImpacts(a, DetectOptions{});
  EXPECT_NE(r.channel, 1);
  ASSERT_EQ(r.channel_scores.size(), 3u);  // channel 0, channel 1, the mix
  EXPECT_EQ(r.channel_scores[1].channel, 1);
  EXPECT_EQ(r.channel_scores[1].impacts, 0);
  EXPECT_FALSE(r.channel_scores[1].failure.empty());
  EXPECT_GT(r.channel_scores[0].score, 10.0);
  EXPECT_TRUE(HasWarning(r.warnings, "channel_choice"));
}

class DetectCliMore : public ::testing::Test {
 protected:
  void SetUp() override {
    const SynthResult s = Synthesize(SynthPreset("two-drops"));
    two_ = dir_ / "two.wav";
    WriteAudio(two_, s.recording.channels, s.recording.sample_rate_hz);
    first_drop_s_ = s.recording.drops[0][0].onset_s;
    second_drop_s_ = s.recording.drops[1][0].onset_s;
  }
  ScratchDir dir_{"detect_cli_more"};
  std::string two_;
  double first_drop_s_ = 0.0, second_drop_s_ = 0.0;
};

TEST_F(DetectCliMore, WindowAndSequenceChoice) {
  // The window keeps file times and only the drop inside it.
  auto r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --start " +
                                            std::to_string(second_drop_s_ - 0.2) + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j["sequences"].size(), 1u);
  EXPECT_NEAR(ChosenImpacts(j)[0]["time_s"].get<double>(), second_drop_s_, 1e-3);
  EXPECT_NEAR(j["window"]["start_s"].get<double>(), second_drop_s_ - 0.2, 1e-4);
  // A window with no impact: exit 7, the window in the message.
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --start 0.1 --end 0.5");
  EXPECT_EQ(r.exit_code, 7);
  EXPECT_NE(r.err.find("[0.1, 0.5) s"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
  // --sequence 1 / all / out of range.
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --sequence 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["chosen_sequences"], nlohmann::json::array({1}));
  EXPECT_NEAR(ChosenImpacts(j)[0]["time_s"].get<double>(), second_drop_s_, 1e-3);
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --sequence 7");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("sequence 7 requested"), std::string::npos) << r.err;
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --sequence first");
  EXPECT_EQ(r.exit_code, 2);
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --end 0.5 --start 1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--end"), std::string::npos) << r.err;
  // analyze --sequence all: each drop analysed separately (a JSON array of two).
  r = RunCommand(BOUNCECAL_BINARY, "analyze " + two_ + " --sequence all --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  j = nlohmann::json::parse(r.out);
  ASSERT_TRUE(j.is_array());
  ASSERT_EQ(j.size(), 2u);
  EXPECT_NEAR(j[1]["bounces"][0]["time_s"].get<double>(), second_drop_s_, 1e-3);
}

TEST_F(DetectCliMore, SeveralRecordingsPerCall) {
  const std::string bad = dir_ / "bad.wav";
  std::ofstream(bad) << "not audio";
  auto r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " " + two_ + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(r.out);
  ASSERT_TRUE(j.is_array());
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[0]["sequences"], j[1]["sequences"]);
  // One bad file among them: the others are printed, exit 12, its error in the array.
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " " + bad + " --json");
  EXPECT_EQ(r.exit_code, 12);
  j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j.size(), 2u);
  EXPECT_EQ(j[1]["error"]["code"], "not_audio");
  EXPECT_EQ(j[1]["error"]["exit_code"], 4);
  EXPECT_NE(r.err.find(bad), std::string::npos);
  // Alone, the bad file keeps its own code and prints nothing on stdout.
  r = RunCommand(BOUNCECAL_BINARY, "detect " + bad + " --json");
  EXPECT_EQ(r.exit_code, 4);
  EXPECT_TRUE(r.out.empty());
  // Text and CSV: one block / rows with a file column per recording.
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " " + two_ + " --csv");
  ASSERT_EQ(r.exit_code, 0);
  EXPECT_EQ(r.out.rfind("file,sequence,index,time_s", 0), 0u) << r.out.substr(0, 80);
  r = RunCommand(BOUNCECAL_BINARY, "analyze " + two_ + " " + two_);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::size_t blocks = 0;
  for (std::size_t p = r.out.find(two_ + ":"); p != std::string::npos;
       p = r.out.find(two_ + ":", p + 1))
    ++blocks;
  EXPECT_EQ(blocks, 2u);
}

TEST_F(DetectCliMore, ClickTrack) {
  const std::string out = dir_ / "clicks.wav";
  auto r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --click-track " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const Audio in = ReadAudio(two_), clicks = ReadAudio(out);
  ASSERT_EQ(clicks.info.channels, in.info.channels);
  ASSERT_EQ(clicks.info.frames, in.info.frames);
  // At every impact the click track departs from the (half-gain) recording by the click; 50 ms
  // before the first impact it is the half-gain recording.
  const double rate = in.info.sample_rate_hz;
  for (const auto& imp : ChosenImpacts(j)) {
    const std::size_t k = static_cast<std::size_t>(imp["time_s"].get<double>() * rate);
    double dev = 0.0;
    for (std::size_t i = k; i < k + 40; ++i)
      dev = std::max(dev, std::fabs(clicks.channels[0][i] - 0.5 * in.channels[0][i]));
    EXPECT_GT(dev, 0.2) << imp["time_s"];
  }
  const std::size_t q = static_cast<std::size_t>((first_drop_s_ - 0.05) * rate);
  EXPECT_NEAR(clicks.channels[0][q], 0.5 * in.channels[0][q], 1e-4);
  // It exists now: without --force, exit 11 and the file is untouched; never over an input.
  const auto before = std::filesystem::last_write_time(out);
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --click-track " + out);
  EXPECT_EQ(r.exit_code, 11);
  EXPECT_EQ(std::filesystem::last_write_time(out), before);
  EXPECT_EQ(RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --click-track " + out + " --force")
                .exit_code,
            0);
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " --click-track " + two_ + " --force");
  EXPECT_EQ(r.exit_code, 11);
  EXPECT_NE(r.err.find("input"), std::string::npos) << r.err;
  EXPECT_EQ(ReadAudio(two_).channels, in.channels);
  r = RunCommand(BOUNCECAL_BINARY, "detect " + two_ + " " + two_ + " --click-track " + out);
  EXPECT_EQ(r.exit_code, 2);
}

}  // namespace
}  // namespace bouncecal
