// End-to-end tests of the bouncecal executable (BOUNCECAL_BINARY): bad inputs to `detect` and
// `analyze` give the documented exit code, exactly one line on stderr naming the input, nothing
// on stdout, and never a crash; `analyze` on a synthesized recording honours its JSON/CSV
// contract.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/synth/synth.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {
namespace fs = std::filesystem;

struct RunResult {
  int exit_code = -1;
  bool signaled = false;
  std::string out, err;
};

std::string Quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += (c == '\'') ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

std::string ReadAll(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

class CliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = fs::path(::testing::TempDir()) / ("bouncecal_cli_test_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
    MakeInputs();
  }
  static void TearDownTestSuite() {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  static std::string P(const std::string& name) { return (dir_ / name).string(); }

  static RunResult Run(const std::string& args) {
    const fs::path out = dir_ / "stdout.txt", err = dir_ / "stderr.txt";
    const std::string cmd = Quote(BOUNCECAL_BINARY) + " " + args + " > " + Quote(out.string()) +
                            " 2> " + Quote(err.string()) + " < /dev/null";
    const int status = std::system(cmd.c_str());
    RunResult r;
    if (WIFEXITED(status)) {
      r.exit_code = WEXITSTATUS(status);
    } else {
      r.signaled = true;
    }
    r.out = ReadAll(out);
    r.err = ReadAll(err);
    return r;
  }

  static void MakeInputs() {
    fs::create_directories(dir_ / "a_directory");
    std::ofstream(P("text.wav")) << "this is not audio, just a text file\nwith two lines\n";
    std::ofstream(P("empty.wav")).close();
    const int rate = 48000;
    // Silence.
    WriteAudio(P("silence.wav"), {std::vector<float>(2 * rate, 0.0f)}, rate);
    // Noise only.
    std::mt19937 rng(7);
    std::normal_distribution<float> normal(0.0f, 0.05f);
    std::vector<float> noise(3 * rate);
    for (float& v : noise) v = normal(rng);
    WriteAudio(P("noise.wav"), {noise}, rate);
    // NaN samples in a float WAV (written byte by byte: WriteAudio refuses NaN).
    std::vector<float> nan_samples = noise;
    nan_samples[rate] = std::nanf("");
    testing_util::WriteFloatWav(P("nan.wav"), nan_samples, 1, rate);
    // A truncated WAV: a valid file cut in the middle of its data chunk.
    WriteAudio(P("full.wav"), {noise}, rate);
    {
      const std::string bytes = ReadAll(P("full.wav"));
      std::ofstream(P("truncated.wav"), std::ios::binary).write(bytes.data(), 3000);
    }
    // A single impact: one rendered click (synth library) in quiet noise.
    TruthImpact one;
    one.time_s = 0.5;
    one.v_in_m_s = 2.0;
    one.v_out_m_s = 1.8;
    one.contact_s = 40e-6;
    RenderOptions ro;
    ro.sample_rate_hz = rate;
    ro.tail_s = 2.0;
    const Recording single = RenderRecording(std::vector<TruthImpact>{one}, ro);
    WriteAudio(P("single.wav"), single.channels, single.sample_rate_hz);
    // A real bouncing-ball recording from the renderer.
    SynthSpec spec = SynthPreset("steel-copper");
    spec.render.seed = 3;
    const SynthResult good = Synthesize(spec);
    WriteAudio(P("good.wav"), good.recording.channels, good.recording.sample_rate_hz);
    // Scene files.
    std::ofstream(P("bad.toml")) << "[ball]\ndiameter_m = 0.01\nmass_kg = -3\n";
    std::ofstream(P("syntax.toml")) << "[ball\ndiameter_m = 0.01\n";
    std::ofstream(P("good.toml")) << "[drop]\nheight_m = 0.2\n[effects]\ndrag = \"quadratic\"\n";
  }

  // Exit code, one line on stderr naming `names`, nothing on stdout, no crash.
  static void ExpectFailure(const std::string& args, int code, const std::string& names) {
    SCOPED_TRACE(args);
    const RunResult r = Run(args);
    EXPECT_FALSE(r.signaled) << "crashed";
    EXPECT_LT(r.exit_code, 128);
    EXPECT_EQ(r.exit_code, code) << r.err;
    EXPECT_EQ(r.out, "") << "stdout must stay empty on failure";
    ASSERT_FALSE(r.err.empty());
    EXPECT_EQ(r.err.back(), '\n');
    EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
    EXPECT_NE(r.err.find(names), std::string::npos) << r.err << " should name " << names;
  }

  static fs::path dir_;
};

fs::path CliTest::dir_;

TEST_F(CliTest, BadInputsGiveTheirExitCodes) {
  // Table of (input, exit code) from error.hpp, for both subcommands and with/without --json.
  struct Case {
    std::string file;
    int code;
  };
  const std::vector<Case> cases = {
      {P("does-not-exist.wav"), 3}, {P("a_directory"), 3}, {P("text.wav"), 4},
      {P("truncated.wav"), 4},      {P("empty.wav"), 4},   {P("nan.wav"), 5},
      {P("silence.wav"), 6},        {P("noise.wav"), 7},   {P("single.wav"), 7},
  };
  for (const char* cmd : {"detect", "analyze"}) {
    for (const Case& c : cases) {
      ExpectFailure(std::string(cmd) + " " + Quote(c.file) + " --json", c.code,
                    fs::path(c.file).filename().string());
    }
  }
  // Human-readable mode fails the same way.
  ExpectFailure("analyze " + Quote(P("silence.wav")), 6, "silence.wav");
  ExpectFailure("detect " + Quote(P("text.wav")) + " --csv", 4, "text.wav");
}

TEST_F(CliTest, BadSceneFilesAndFlags) {
  const std::string good = Quote(P("good.wav"));
  ExpectFailure("analyze " + good + " --json --scene " + Quote(P("bad.toml")), 8, "bad.toml:3");
  ExpectFailure("analyze " + good + " --json --scene " + Quote(P("syntax.toml")), 8,
                "syntax.toml:1");
  ExpectFailure("analyze " + good + " --json --scene " + Quote(P("missing.toml")), 3,
                "missing.toml");
  ExpectFailure("analyze " + good + " --json --height -1", 9, "--height");
  ExpectFailure("analyze " + good + " --json --height nan", 9, "--height");
  ExpectFailure("analyze " + good + " --json --drag cubic", 9, "cubic");
  ExpectFailure("analyze " + good + " --json --mass 0.004 --density 7800", 9, "--mass");
  ExpectFailure("analyze " + good + " --json --material unobtainium", 9, "unobtainium");
  ExpectFailure("analyze " + good + " --json --contact-time -1", 9, "--contact-time");
  ExpectFailure("analyze " + good + " --json --channel 5", 2, "good.wav");
  // CLI11's own conversion errors use exit code 2 (kUsage); no crash, nothing on stdout.
  const RunResult r = Run("analyze " + good + " --json --height abc");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_EQ(r.out, "");
  EXPECT_NE(r.err.find("--height"), std::string::npos);
}

TEST_F(CliTest, AnalyzeJsonContract) {
  const RunResult r = Run("analyze " + Quote(P("good.wav")) + " --height 0.2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.out.find("nan"), std::string::npos) << "NaN must be null in JSON";
  const nlohmann::json j = nlohmann::json::parse(r.out);
  for (const char* key : {"file", "sample_rate_hz", "scene", "bounces", "summary", "warnings"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["file"], P("good.wav"));
  EXPECT_EQ(j["sample_rate_hz"], 48000.0);
  EXPECT_EQ(j["schema"], "bouncecal.analysis/1");
  for (const char* key : {"drag", "buoyancy", "contact_duration", "surface_compliance"}) {
    EXPECT_TRUE(j["scene"]["effects"].contains(key)) << key;
  }
  EXPECT_EQ(j["scene"]["effects"]["drag"], "none");
  ASSERT_GE(j["bounces"].size(), 3u);
  for (const auto& b : j["bounces"]) {
    for (const char* key :
         {"index", "time_s", "time_sigma_s", "interval_s", "v_in_m_s", "v_in_sigma_m_s",
          "v_out_m_s", "v_out_sigma_m_s", "e", "e_sigma", "eta", "eta_sigma", "contact_s"}) {
      EXPECT_TRUE(b.contains(key)) << key;
    }
  }
  // The steel-copper preset bounces with e around 0.9: the physics came through.
  const auto& b1 = j["bounces"][1];
  ASSERT_TRUE(b1["e"].is_number());
  EXPECT_GT(b1["e"].get<double>(), 0.5);
  EXPECT_LT(b1["e"].get<double>(), 1.0);
  EXPECT_NEAR(b1["eta"].get<double>(), 1 - std::pow(b1["e"].get<double>(), 2), 1e-12);
  EXPECT_TRUE(j["bounces"].back()["e"].is_null());  // the last impact has no rebound
  for (const char* key : {"mean_eta_first3", "mean_eta_first3_sigma", "first_e", "n_bounces"}) {
    EXPECT_TRUE(j["summary"].contains(key)) << key;
  }
  EXPECT_EQ(j["summary"]["n_bounces"], j["bounces"].size());
  EXPECT_TRUE(j["summary"]["first_e"].is_number());  // --height given
  // Without a drop height the first e is unknown (null), not computed from the default 0.2 m.
  const RunResult nd = Run("analyze " + Quote(P("good.wav")) + " --json");
  ASSERT_EQ(nd.exit_code, 0) << nd.err;
  const nlohmann::json k = nlohmann::json::parse(nd.out);
  EXPECT_TRUE(k["summary"]["first_e"].is_null());
  EXPECT_TRUE(k["bounces"][0]["e"].is_null());
  // A scene file turns drag on.
  const RunResult sc =
      Run("analyze " + Quote(P("good.wav")) + " --json --scene " + Quote(P("good.toml")));
  ASSERT_EQ(sc.exit_code, 0) << sc.err;
  EXPECT_EQ(nlohmann::json::parse(sc.out)["scene"]["effects"]["drag"], "quadratic");
}

TEST_F(CliTest, SceneFlagsReachTheAnalysis) {
  const std::string good = Quote(P("good.wav"));
  RunResult r = Run("analyze " + good +
                    " --json --material glass --diameter 0.02 --buoyancy --drag linear --g 9.81");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json s = nlohmann::json::parse(r.out)["scene"];
  const nlohmann::json summary = nlohmann::json::parse(r.out)["summary"];
  EXPECT_EQ(s["effects"]["drag"], "linear");
  EXPECT_EQ(s["effects"]["buoyancy"], true);
  EXPECT_EQ(s["ball"]["material"], "glass");
  EXPECT_EQ(s["ball"]["density_kg_m3"], 2500.0);
  EXPECT_EQ(s["ball"]["diameter_m"], 0.02);
  EXPECT_NEAR(summary["effective_gravity_m_s2"].get<double>(), 9.81 * (1 - 1.2 / 2500), 1e-12);
  EXPECT_TRUE(summary["terminal_speed_m_s"].is_number());
  // --mass replaces the file's density; flags override the scene file.
  r = Run("analyze " + good + " --json --scene " + Quote(P("good.toml")) +
          " --mass 0.01 --impact-speed 1.5");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  s = nlohmann::json::parse(r.out)["scene"];
  EXPECT_EQ(s["ball"]["mass_kg"], 0.01);
  EXPECT_EQ(s["effects"]["drag"], "quadratic");  // from the file
  EXPECT_TRUE(s["drop"]["height_m"].is_null());
  EXPECT_EQ(s["drop"]["impact_speed_m_s"], 1.5);
  // A fixed contact time turns the contact-duration effect on and is reported per bounce.
  r = Run("analyze " + good + " --json --contact-time 0.0001");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["scene"]["effects"]["contact_duration"], true);
  EXPECT_EQ(j["bounces"][0]["contact_s"], 0.0001);
}

TEST_F(CliTest, LawFlagsAreChecked) {
  // --law/--set/--expression (scene_flags.cpp) as simulate uses them.
  ExpectFailure("simulate --json --law linear-dashpot --set k=abc", 9, "k=abc");
  ExpectFailure("simulate --json --law linear-dashpot --set =3", 9, "=3");
  ExpectFailure("simulate --json --law linear-dashpot --set k", 9, "--set k");
  ExpectFailure("simulate --json --law linear-dashpot --set k=1e999", 9, "k=1e999");
  ExpectFailure("simulate --json --law linear-dashpot --set k=nan", 9, "k=nan");
  ExpectFailure("simulate --json --law linear-dashpot --expression 'k*d'", 9, "--expression");
  ExpectFailure("simulate --json --scene " + Quote(P("bad.toml")), 8, "bad.toml:3");
}

TEST_F(CliTest, AnalyzeCsvAndTable) {
  const RunResult js = Run("analyze " + Quote(P("good.wav")) + " --height 0.2 --json");
  ASSERT_EQ(js.exit_code, 0) << js.err;
  const size_t n = nlohmann::json::parse(js.out)["bounces"].size();
  const RunResult csv = Run("analyze " + Quote(P("good.wav")) + " --height 0.2 --csv");
  ASSERT_EQ(csv.exit_code, 0) << csv.err;
  std::istringstream lines(csv.out);
  std::string header;
  std::getline(lines, header);
  EXPECT_EQ(header,
            "sequence,index,time_s,time_sigma_s,interval_s,v_in_m_s,v_in_sigma_m_s,v_out_m_s,"
            "v_out_sigma_m_s,e,e_sigma,e_timing_sigma,eta,eta_sigma,contact_s,irregular");
  size_t rows = 0;
  for (std::string line; std::getline(lines, line);) {
    ++rows;
    EXPECT_EQ(std::count(line.begin(), line.end(), ','), 15) << line;
  }
  EXPECT_EQ(rows, n);
  const RunResult table = Run("analyze " + Quote(P("good.wav")) + " --height 0.2");
  ASSERT_EQ(table.exit_code, 0) << table.err;
  EXPECT_NE(table.out.find("summary:"), std::string::npos);
  EXPECT_NE(table.out.find("mean eta of the first three"), std::string::npos);
  EXPECT_NE(table.out.find("drag none"), std::string::npos);
  // --json and --csv together is a usage error.
  const RunResult both = Run("analyze " + Quote(P("good.wav")) + " --json --csv");
  EXPECT_EQ(both.exit_code, 2);
  EXPECT_EQ(both.out, "");
}

// The simulate table is written without printf (cmd_simulate.cpp: integer digits where that is
// provably printf's rounding, to_chars otherwise): every row must be what
// "%5zu %14.9f %11.6f %11.6f %9.6f %11.4f %12.5f %11.4g %6d" prints of the same impact, read
// back from --json (shortest round-trip numbers: the same doubles). Hunt-Crossley's 10 000
// contacts run e towards 1 and v_in towards 1e-4 m/s, so the fields cross many magnitudes and
// rounding ties.
TEST_F(CliTest, SimulateTableIsWhatPrintfPrints) {
  const RunResult js = Run("simulate --law hunt-crossley --json");
  ASSERT_EQ(js.exit_code, 0) << js.err;
  const nlohmann::json impacts = nlohmann::json::parse(js.out)["impacts"];
  const RunResult table = Run("simulate --law hunt-crossley");
  ASSERT_EQ(table.exit_code, 0) << table.err;
  std::istringstream lines(table.out);
  std::string line;
  while (std::getline(lines, line) && line.find("time_s") == std::string::npos) {
  }
  ASSERT_GT(impacts.size(), 1000u);
  size_t rows = 0, mismatches = 0;
  for (size_t k = 0; k < impacts.size() && std::getline(lines, line); ++k, ++rows) {
    const nlohmann::json& i = impacts[k];
    const double v_in = i["v_in_m_s"].get<double>(), v_out = i["v_out_m_s"].get<double>();
    char expected[256];
    std::snprintf(expected, sizeof expected,
                  "%5zu %14.9f %11.6f %11.6f %9.6f %11.4f %12.5f %11.4g %6d", k,
                  i["time_s"].get<double>(), v_in, v_out, v_in > 0.0 ? v_out / v_in : 0.0,
                  i["contact_s"].get<double>() * 1e6, i["peak_overlap_m"].get<double>() * 1e6,
                  i["peak_force_n"].get<double>(), i["steps"].get<int>());
    if (line != expected && ++mismatches <= 5) ADD_FAILURE() << line << "\n" << expected;
  }
  EXPECT_EQ(rows, impacts.size());
  EXPECT_EQ(mismatches, 0u);
}
}  // namespace
}  // namespace bouncecal
