// Impact times from a file (impacts_file.hpp) and `--impacts` on the command line: every format,
// every bad input with its file, line and exit code, and the round trip from `detect --json`
// with one impact removed.
#include "bouncecal/acoustic/impacts_file.hpp"

#include <gtest/gtest.h>

#include <algorithm>

#include <cmath>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

using testing_util::RunCommand;
using testing_util::ScratchDir;

std::string Write(const ScratchDir& d, const std::string& name, const std::string& text) {
  const std::string p = d / name;
  std::ofstream(p) << text;
  return p;
}

std::vector<double> Times(const Sequence& s) {
  std::vector<double> t;
  for (const Impact& i : s.impacts) t.push_back(i.time_s);
  return t;
}

TEST(ImpactsFile, EveryFormat) {
  ScratchDir d("impacts");
  // detect --csv output: sequences, sigma given.
  ImpactsFile f = ReadImpactsFile(Write(d, "a.csv",
                                        "sequence,index,time_s,sigma_s,amplitude\n"
                                        "0,0,1.0,5e-6,0.5\n0,1,1.4,6e-6,0.4\n0,2,1.76,7e-6,0.3\n"
                                        "1,0,5.0,5e-6,0.5\n1,1,5.3,5e-6,0.5\n1,2,5.57,5e-6,0.5\n"));
  EXPECT_EQ(f.format, "csv");
  ASSERT_EQ(f.sequences.size(), 2u);
  EXPECT_EQ(Times(f.sequences[0]), (std::vector<double>{1.0, 1.4, 1.76}));
  EXPECT_DOUBLE_EQ(f.sequences[0].impacts[1].sigma_s, 6e-6);
  // The shared annotation files: k,t_impact_s,confidence,...; no sigma: the default.
  f = ReadImpactsFile(Write(d, "b.csv", "k,t_impact_s,confidence\n0,0.1,H\n1,0.5,H\n2,0.86,M\n"));
  ASSERT_EQ(f.sequences.size(), 1u);
  EXPECT_DOUBLE_EQ(f.sequences[0].impacts[2].time_s, 0.86);
  EXPECT_DOUBLE_EQ(f.sequences[0].impacts[2].sigma_s, ImpactsFileOptions{}.default_sigma_s);
  // phyphox: "Time (s)" with semicolons.
  f = ReadImpactsFile(Write(d, "c.csv", "\"Time (s)\";\"Level\"\n0.2;1\n0.6;1\n0.96;1\n"));
  EXPECT_EQ(Times(f.sequences[0]), (std::vector<double>{0.2, 0.6, 0.96}));
  // Audacity labels.
  f = ReadImpactsFile(
      Write(d, "labels.txt", "0.200000\t0.200000\timpact\n0.6\t0.6\t\n0.96\t0.97\tx\n"));
  EXPECT_EQ(f.format, "audacity-labels");
  EXPECT_EQ(Times(f.sequences[0]), (std::vector<double>{0.2, 0.6, 0.96}));
  // aubioonset output: one time per line.
  f = ReadImpactsFile(Write(d, "onsets.txt", "# aubio\n0.2\n0.6\n0.96\n1.28\n"));
  EXPECT_EQ(f.format, "list");
  EXPECT_EQ(f.sequences[0].impacts.size(), 4u);
  // detect --json.
  f = ReadImpactsFile(Write(d, "d.json",
                            R"({"sequences": [{"impacts": [{"time_s": 1.0, "sigma_s": 4e-6},
                               {"time_s": 1.5, "sigma_s": 4e-6}, {"time_s": 1.9, "sigma_s": 4e-6}]}]})"));
  EXPECT_EQ(f.format, "detect-json");
  EXPECT_DOUBLE_EQ(f.sequences[0].impacts[0].sigma_s, 4e-6);
}

TEST(ImpactsFile, ADeletedImpactIsFlaggedAsAGap) {
  ScratchDir d("impacts");
  // 1.0, 1.4, 1.76, [2.084 deleted], 2.3756: the interval 1.76 -> 2.3756 is two flights.
  const ImpactsFile f = ReadImpactsFile(Write(d, "gap.txt", "1.0\n1.4\n1.76\n2.3756\n2.6380\n"));
  EXPECT_EQ(f.sequences[0].missed_after, (std::vector<int>{2}));
}

// Bad input: Error(kBadScene) = exit 8 naming the file and the line (or JSON element).
void ExpectBad(const std::string& path, const std::string& where, const std::string& what,
               const ImpactsFileOptions& o = {}) {
  try {
    ReadImpactsFile(path, o);
    ADD_FAILURE() << path << ": no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadScene) << e.what();
    EXPECT_NE(std::string(e.what()).find(path + ":" + where), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(ImpactsFile, BadInputNamesFileAndLine) {
  ScratchDir d("impacts");
  ExpectBad(Write(d, "unsorted.csv", "time_s\n1.0\n1.5\n1.3\n"), "4", "must be sorted");
  ExpectBad(Write(d, "dup.csv", "time_s\n1.0\n1.5\n1.5\n"), "4", "duplicate");
  ExpectBad(Write(d, "neg.csv", "time_s\n-0.1\n1.5\n1.8\n"), "2", "negative");
  ExpectBad(Write(d, "nan.csv", "time_s\n0.1\nabc\n1.8\n"), "3", "not a number");
  ExpectBad(Write(d, "late.txt", "1\n2\n30\n"), "3", "beyond the recording",
            ImpactsFileOptions{.duration_s = 12.8});
  ExpectBad(Write(d, "nocol.csv", "a,b\n1,2\n"), "1", "no time column");
  ExpectBad(Write(d, "short.txt", "1\n2\n"), "", "needs 3");
  ExpectBad(Write(d, "bad.json", R"({"sequences": [{"impacts": [{"time_s": "x"}]}]})"),
            "sequences[0].impacts[0]", "not a number");
  ExpectBad(Write(d, "broken.json", "{\"sequences\": ["), "byte", "not valid JSON");
  // Found by tools/run-fuzz.sh (tests/fuzz/regressions/fuzz_impacts/): a number beyond a
  // double's range escaped as nlohmann's out_of_range, an "internal error" with exit 1.
  ExpectBad(Write(d, "huge.json", "[1e542.5\t\"\"\"\"\"\"\"\"\"\"1v"), "",
            "beyond the range of a double");
  try {
    ReadImpactsFile(d / "missing.csv");
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInputMissing);
  }
}

// --- the CLI -------------------------------------------------------------------------------

class ImpactsCli : public ::testing::Test {
 protected:
  void SetUp() override {
    const SynthResult s = Synthesize(SynthPreset("pingpong-wood"));
    wav_ = dir_ / "pp.wav";
    WriteAudio(wav_, s.recording.channels, s.recording.sample_rate_hz);
  }
  ScratchDir dir_{"impacts_cli"};
  std::string wav_;
};

TEST_F(ImpactsCli, RoundTripFromDetectJsonWithOneImpactRemoved) {
  const auto det = RunCommand(BOUNCECAL_BINARY, "detect " + wav_ + " --json");
  ASSERT_EQ(det.exit_code, 0) << det.err;
  nlohmann::json doc = nlohmann::json::parse(det.out);
  const std::size_t n = doc["sequences"][0]["impacts"].size();
  ASSERT_GE(n, 10u);
  // Unchanged, the file gives the same analysis as detection.
  const std::string same = dir_ / "same.json";
  std::ofstream(same) << doc.dump();
  const auto a0 = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --height 0.3 --json");
  const auto a1 = RunCommand(BOUNCECAL_BINARY,
                             "analyze " + wav_ + " --impacts " + same + " --height 0.3 --json");
  ASSERT_EQ(a0.exit_code, 0) << a0.err;
  ASSERT_EQ(a1.exit_code, 0) << a1.err;
  const auto j0 = nlohmann::json::parse(a0.out), j1 = nlohmann::json::parse(a1.out);
  EXPECT_EQ(j1["source"], "impacts_file");
  ASSERT_EQ(j0["bounces"].size(), j1["bounces"].size());
  for (std::size_t k = 0; k + 1 < j0["bounces"].size(); ++k) {
    if (j0["bounces"][k]["e"].is_number()) {
      EXPECT_NEAR(j0["bounces"][k]["e"].get<double>(), j1["bounces"][k]["e"].get<double>(), 1e-12);
    }
  }
  // Impact 5 deleted by hand: one bounce fewer, the gap flagged, e around it not given (the
  // detection's own flags further on move down by one).
  std::vector<int> flags{4};
  for (const auto& k : doc["sequences"][0]["missed_after"])
    flags.push_back(k.get<int>() > 4 ? k.get<int>() - 1 : k.get<int>());
  std::sort(flags.begin(), flags.end());
  doc["sequences"][0]["impacts"].erase(5);
  const std::string cut = dir_ / "cut.json";
  std::ofstream(cut) << doc.dump();
  const auto a2 = RunCommand(BOUNCECAL_BINARY,
                             "analyze " + wav_ + " --impacts " + cut + " --height 0.3 --json");
  ASSERT_EQ(a2.exit_code, 0) << a2.err;
  const auto j2 = nlohmann::json::parse(a2.out);
  EXPECT_EQ(j2["bounces"].size(), j0["bounces"].size() - 1);
  EXPECT_EQ(j2["sequence"]["missed_after"], nlohmann::json(flags));
  bool warned = false;
  for (const auto& w : j2["warnings"]) warned = warned || w["code"] == "missed_impact";
  EXPECT_TRUE(warned) << a2.out;
  // The bounces after the gap keep their e.
  EXPECT_NEAR(j2["bounces"][8]["e"].get<double>(), j0["bounces"][9]["e"].get<double>(), 1e-12);
  // An impact added by hand half-way between impacts 3 and 4: one bounce more, and the e of the
  // bounces around it is what the added time makes it.
  nlohmann::json added = nlohmann::json::parse(det.out);
  auto& imps = added["sequences"][0]["impacts"];
  nlohmann::json extra = imps[3];
  const double t3 = imps[3]["time_s"].get<double>(), t4 = imps[4]["time_s"].get<double>();
  extra["time_s"] = 0.5 * (t3 + t4);
  imps.insert(imps.begin() + 4, extra);
  const std::string more = dir_ / "more.json";
  std::ofstream(more) << added.dump();
  const auto a3 = RunCommand(BOUNCECAL_BINARY,
                             "analyze " + wav_ + " --impacts " + more + " --height 0.3 --json");
  ASSERT_EQ(a3.exit_code, 0) << a3.err;
  const auto j3 = nlohmann::json::parse(a3.out);
  ASSERT_EQ(j3["bounces"].size(), j0["bounces"].size() + 1);
  EXPECT_DOUBLE_EQ(j3["bounces"][4]["time_s"].get<double>(), 0.5 * (t3 + t4));
  const double t2 = imps[2]["time_s"].get<double>();
  EXPECT_NEAR(j3["bounces"][3]["e"].get<double>(), (0.5 * (t4 - t3)) / (t3 - t2), 0.05);
}

// The JSON of `detect --json` lists each impact once (bouncecal.detect/2); a bouncecal.detect/1
// file carries a second copy at the top level, which must agree with the sequence it copies.
TEST_F(ImpactsCli, OldDetectJsonWithTwoDisagreeingCopiesIsRefused) {
  const auto det = RunCommand(BOUNCECAL_BINARY, "detect " + wav_ + " --json");
  ASSERT_EQ(det.exit_code, 0) << det.err;
  nlohmann::json v1 = nlohmann::json::parse(det.out);
  ASSERT_EQ(v1["schema"], "bouncecal.detect/2");
  ASSERT_FALSE(v1.contains("impacts"));
  v1["schema"] = "bouncecal.detect/1";
  v1["impacts"] = v1["sequences"][0]["impacts"];
  const std::string agree = dir_ / "v1.json";
  std::ofstream(agree) << v1.dump();
  auto r = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --impacts " + agree + " --json");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  // Impact 5 deleted from the top-level copy only: the edit would do nothing; refused.
  nlohmann::json edited = v1;
  edited["impacts"].erase(5);
  const std::string bad = dir_ / "v1_edited.json";
  std::ofstream(bad) << edited.dump();
  r = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --impacts " + bad + " --json");
  EXPECT_EQ(r.exit_code, 8) << r.err;
  EXPECT_TRUE(r.out.empty());
  EXPECT_NE(r.err.find(bad + ":impacts[5]"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("sequences[0].impacts"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("bouncecal.detect/2"), std::string::npos) << r.err;
  // Deleted from both copies: read (one bounce fewer than the whole file).
  edited["sequences"][0]["impacts"].erase(5);
  std::ofstream(bad) << edited.dump();
  r = RunCommand(BOUNCECAL_BINARY, "detect " + wav_ + " --impacts " + bad + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["sequences"][0]["impacts"].size(), v1["sequences"][0]["impacts"].size() - 1);
  // A version this bouncecal does not know.
  nlohmann::json v9 = nlohmann::json::parse(det.out);
  v9["schema"] = "bouncecal.detect/9";
  const std::string future = dir_ / "v9.json";
  std::ofstream(future) << v9.dump();
  r = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --impacts " + future + " --json");
  EXPECT_EQ(r.exit_code, 8) << r.err;
  EXPECT_NE(r.err.find("bouncecal.detect/9"), std::string::npos) << r.err;
}

TEST_F(ImpactsCli, BadImpactsFileExitCodes) {
  const std::string late = dir_ / "late.txt";
  std::ofstream(late) << "1\n2\n2.5\n900\n";
  auto r = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --impacts " + late);
  EXPECT_EQ(r.exit_code, 8);
  EXPECT_NE(r.err.find(late + ":4: time 900"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("beyond the recording"), std::string::npos) << r.err;
  EXPECT_TRUE(r.out.empty());
  r = RunCommand(BOUNCECAL_BINARY,
                 "analyze " + wav_ + " " + wav_ + " --impacts " + late);  // 1 for 2 recordings
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("one per recording"), std::string::npos) << r.err;
  r = RunCommand(BOUNCECAL_BINARY, "analyze " + wav_ + " --impacts " + (dir_ / "none.csv"));
  EXPECT_EQ(r.exit_code, 3);
}

}  // namespace
}  // namespace bouncecal
