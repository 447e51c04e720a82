// `bouncecal calibrate` end to end through the real executable on the bundled default
// recording: human output, --json (the parameter-file object), -o with its refusals and
// --force, --batch with a failing file (failed row, stderr line, exit kSomeFailed), bad input.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <array>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <random>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

namespace {
namespace fs = std::filesystem;

struct CliRun {
  int code = -1;
  std::string out, err;
};

CliRun Exec(const std::string& args) {
  std::random_device rd;
  const fs::path err_path = fs::temp_directory_path() / ("bc_cli_err_" + std::to_string(rd()));
  const std::string cmd = std::string(BOUNCECAL_BINARY) + " " + args + " 2>" + err_path.string();
  CliRun r;
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return r;
  std::array<char, 4096> buf{};
  size_t n = 0;
  while ((n = fread(buf.data(), 1, buf.size(), p)) > 0) r.out.append(buf.data(), n);
  const int status = pclose(p);
  r.code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  std::ifstream e(err_path);
  std::stringstream ss;
  ss << e.rdbuf();
  r.err = ss.str();
  fs::remove(err_path);
  return r;
}

const std::string kData = std::string(BOUNCECAL_SOURCE_DIR) + "/data/";
const std::string kRecording = kData + "default_steel_copper.flac";
const std::string kScene = kData + "default_steel_copper.toml";

class TempDir {
 public:
  TempDir() {
    std::random_device rd;
    path_ = fs::temp_directory_path() / ("bc_cli_" + std::to_string(rd()));
    fs::create_directories(path_);
  }
  ~TempDir() { fs::remove_all(path_); }
  std::string operator/(const std::string& n) const { return (path_ / n).string(); }

 private:
  fs::path path_;
};

int Lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

TEST(CalibrateCli, HumanReportOnTheDefaultRecording) {
  const CliRun r = Exec("calibrate " + kRecording + " --scene " + kScene);
  ASSERT_EQ(r.code, 0) << r.err;
  for (const char* want :
       {"law hertz-viscoelastic", "A ", "N/m^1.5", "chi2/dof", "determined by the sound", "e(v)"}) {
    EXPECT_NE(r.out.find(want), std::string::npos) << want << "\n" << r.out;
  }
  EXPECT_TRUE(r.err.empty()) << r.err;  // stderr is not a terminal: no progress line
}

TEST(CalibrateCli, JsonIsTheParameterFileObjectAndOutputRules) {
  TempDir dir;
  const std::string out = dir / "params.json";
  const CliRun r = Exec("calibrate " + kRecording + " --scene " + kScene + " --json -o " + out);
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("schema"), "bouncecal.params/1");
  EXPECT_EQ(j.at("law"), "hertz-viscoelastic");  // the law of the scene file
  EXPECT_TRUE(j.at("parameters").at("A").at("value").is_number());
  EXPECT_EQ(j.at("provenance").at("inputs")[0].at("sha256").get<std::string>().size(), 64u);
  // The file holds the same object.
  std::ifstream in(out);
  const auto f = nlohmann::json::parse(in);
  EXPECT_EQ(f, j);
  // Exists: refused (exit 11, one line), untouched; --force replaces it.
  const CliRun again = Exec("calibrate " + kRecording + " -o " + out);
  EXPECT_EQ(again.code, 11);
  EXPECT_EQ(Lines(again.err), 1) << again.err;
  EXPECT_TRUE(again.out.empty());
  const CliRun forced = Exec("calibrate " + kRecording + " --scene " + kScene + " -o " + out +
                             " --force --law linear-dashpot");
  EXPECT_EQ(forced.code, 0) << forced.err;
  std::ifstream in2(out);
  EXPECT_EQ(nlohmann::json::parse(in2).at("law"), "linear-dashpot");
  // Never over an input, missing directory: exit 11 before any work, nothing written.
  const CliRun over = Exec("calibrate " + kRecording + " -o " + kRecording + " --force");
  EXPECT_EQ(over.code, 11);
  EXPECT_NE(over.err.find("input"), std::string::npos);
  const CliRun nodir = Exec("calibrate " + kRecording + " -o " + dir / "none/params.json");
  EXPECT_EQ(nodir.code, 11);
  EXPECT_FALSE(fs::exists(dir / "none"));
}

TEST(CalibrateCli, BatchReportsFailuresPerFileAndExitsSomeFailed) {
  TempDir dir;
  { std::ofstream(dir / "junk.wav") << "not audio"; }
  const CliRun r = Exec("calibrate --batch --csv --jobs 2 " + kRecording + " " + dir / "junk.wav" +
                        " " + kRecording);
  EXPECT_EQ(r.code, 12) << r.err;
  ASSERT_EQ(Lines(r.out), 4) << r.out;  // header + one row per file, in input order
  std::istringstream rows(r.out);
  std::string header, a, b, c;
  std::getline(rows, header);
  std::getline(rows, a);
  std::getline(rows, b);
  std::getline(rows, c);
  EXPECT_EQ(header.rfind("file,status,error,law,outcome", 0), 0u) << header;
  EXPECT_NE(a.find(",ok,"), std::string::npos) << a;
  EXPECT_NE(b.find("junk.wav,not_audio,"), std::string::npos) << b;
  EXPECT_NE(c.find(",ok,"), std::string::npos) << c;
  EXPECT_NE(r.err.find("junk.wav"), std::string::npos);
  EXPECT_NE(r.err.find("1 of 3 recordings failed"), std::string::npos) << r.err;
  // JSON lines.
  const CliRun j = Exec("calibrate --batch --json " + kRecording + " " + dir / "junk.wav");
  EXPECT_EQ(j.code, 12);
  std::istringstream jl(j.out);
  std::string l1, l2;
  std::getline(jl, l1);
  std::getline(jl, l2);
  EXPECT_EQ(nlohmann::json::parse(l1).at("status"), "ok");
  EXPECT_EQ(nlohmann::json::parse(l2).at("status"), "not_audio");
}

TEST(CalibrateCli, BadInputGivesOneLineAndTheRightCode) {
  const CliRun law = Exec("calibrate " + kRecording + " --law no-such-law");
  EXPECT_EQ(law.code, 9);
  EXPECT_EQ(Lines(law.err), 1) << law.err;
  EXPECT_TRUE(law.out.empty());
  const CliRun missing = Exec("calibrate /nonexistent/drop.wav");
  EXPECT_EQ(missing.code, 3);
  EXPECT_EQ(Lines(missing.err), 1) << missing.err;
  const CliRun strategy = Exec("calibrate " + kRecording + " --strategy guess");
  EXPECT_EQ(strategy.code, 2);
  const CliRun free = Exec("calibrate " + kRecording + " --free stiffness");
  EXPECT_EQ(free.code, 9);
  EXPECT_NE(free.err.find("stiffness"), std::string::npos);
  const CliRun conflict = Exec("calibrate " + kRecording + " --mass 0.004 --density 7800");
  EXPECT_NE(conflict.code, 0);
  EXPECT_EQ(Lines(conflict.err), 1) << conflict.err;
}

TEST(CalibrateCli, RepeatableOptionsDoNotSwallowTheRecording) {
  const CliRun r = Exec("calibrate --free k " + kRecording + " --scene " + kScene + " --json");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j.at("parameters").at("k").at("fixed"), false);
  EXPECT_EQ(j.at("provenance").at("options").at("free_parameters"), nlohmann::json::array({"k"}));
}

TEST(CalibrateCli, LawComparisonRanksLaws) {
  const CliRun r = Exec("calibrate --law all --csv " + kRecording + " --scene " + kScene);
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.out.rfind("rank,law,outcome", 0), 0u);
  EXPECT_NE(r.out.find("walton-braun"), std::string::npos);
  EXPECT_NE(r.out.find("hertz-viscoelastic"), std::string::npos);
  EXPECT_EQ(r.out.find("expression"), std::string::npos);  // needs the user's expression
}

}  // namespace
