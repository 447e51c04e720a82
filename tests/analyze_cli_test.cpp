// `bouncecal analyze` through the executable: what is assumed is listed, a scene without [drop]
// means the drop is unknown, the seed paper's line only for a steel ball on copper, the scatter
// and both sigmas per bounce, and the warnings a user's usual mistakes raise (units_suspect,
// drop_height_inconsistent, drag_likely_needed), each with its code in the JSON and a stderr
// line in the human output.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "test_util.hpp"

namespace bouncecal {
namespace {

using testing_util::RunCommand;
using testing_util::ScratchDir;

const std::string kData = std::string(BOUNCECAL_SOURCE_DIR) + "/data/";
const std::string kRecording = kData + "default_steel_copper.flac";
const std::string kScene = kData + "default_steel_copper.toml";

testing_util::CommandResult Analyze(const std::string& args) {
  return RunCommand(BOUNCECAL_BINARY, "analyze " + kRecording + " " + args);
}

std::vector<std::string> Codes(const nlohmann::json& j) {
  std::vector<std::string> out;
  for (const auto& w : j.at("warnings")) out.push_back(w.at("code"));
  return out;
}

bool Contains(const std::vector<std::string>& v, const std::string& s) {
  return std::find(v.begin(), v.end(), s) != v.end();
}

TEST(AnalyzeCli, TheBundledSceneListsItsAssumptionsAndTheScatter) {
  const auto r = Analyze("--scene " + kScene + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  std::vector<std::string> assumed;
  for (const auto& a : j.at("assumed")) assumed.push_back(a.at("key"));
  // Not in the scene file: g, buoyancy, the height's sigma. Given there: drag, the ball.
  for (const char* k : {"environment.g_m_s2", "effects.buoyancy", "drop.height_sigma_m"}) {
    EXPECT_TRUE(Contains(assumed, k)) << k;
  }
  for (const char* k : {"effects.drag", "ball.diameter_m", "drop.height_m"}) {
    EXPECT_FALSE(Contains(assumed, k)) << k;
  }
  // Nothing about the analysis: the only warnings are the detector's notes on tail impacts it
  // removed (at SNR ~0 dB their timing sigma is too large to keep).
  for (const auto& w : j.at("warnings"))
    EXPECT_TRUE(w.at("code") == "sigma_removed" || w.at("code") == "low_snr_removed") << w;
  // A synthetic recording without scatter: scatter 0 (or far below the timing sigma).
  EXPECT_LT(j.at("summary").at("scatter_e").get<double>(), 1e-5);
  EXPECT_TRUE(j.at("summary").at("drop_consistent").get<bool>());
  for (const auto& b : j.at("bounces")) {
    if (b.at("e").is_null()) continue;
    EXPECT_GE(b.at("e_sigma").get<double>(), b.at("e_timing_sigma").get<double>());
    EXPECT_FALSE(b.at("irregular").get<bool>());
  }
  const auto human = Analyze("--scene " + kScene);
  ASSERT_EQ(human.exit_code, 0);
  EXPECT_NE(human.out.find("assumed (not given): environment.g_m_s2 = 9.8"), std::string::npos);
  EXPECT_NE(human.out.find("scatter of e from bounce to bounce: "), std::string::npos) << human.out;
  EXPECT_NE(human.out.find("(seed 002: 0.58 for a steel ball on copper)"), std::string::npos);
}

TEST(AnalyzeCli, ASceneWithoutDropMeansTheDropIsUnknown) {
  ScratchDir dir;
  { std::ofstream(dir / "nodrop.toml") << "[ball]\ndiameter_m = 0.01\nmaterial = \"steel\"\n"; }
  const auto r = Analyze("--scene " + dir / "nodrop.toml" + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_TRUE(j.at("scene").at("drop").at("height_m").is_null());
  EXPECT_TRUE(j.at("summary").at("first_e").is_null());
  EXPECT_TRUE(j.at("bounces")[0].at("e").is_null());
  const auto human = Analyze("--scene " + dir / "nodrop.toml");
  EXPECT_NE(human.out.find("drop unknown"), std::string::npos) << human.out;
}

TEST(AnalyzeCli, TheSeedPaperLineOnlyForASteelBallOnCopper) {
  const auto glass = Analyze("--height 0.2 --diameter 0.01 --material glass");
  ASSERT_EQ(glass.exit_code, 0) << glass.err;
  EXPECT_NE(glass.out.find("mean eta of the first three"), std::string::npos);
  EXPECT_EQ(glass.out.find("seed 002: 0.58"), std::string::npos) << glass.out;
  // A ball of unstated material on an unstated surface: the built-in steel and copper are
  // defaults, not the user's experiment, so no comparison with the seed paper either.
  const auto unstated = Analyze("--height 0.2 --diameter 0.05 --mass 0.05");
  ASSERT_EQ(unstated.exit_code, 0) << unstated.err;
  EXPECT_NE(unstated.out.find("mean eta of the first three"), std::string::npos);
  EXPECT_EQ(unstated.out.find("seed 002: 0.58"), std::string::npos) << unstated.out;
}

TEST(AnalyzeCli, UnitSlipsAndAWrongHeightAreFlagged) {
  // 10 (mm) as a diameter, 20 (cm) as a height.
  const auto r = Analyze("--scene " + kScene + " --diameter 10 --height 20 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  const auto codes = Codes(j);
  EXPECT_TRUE(Contains(codes, "units_suspect")) << j.at("warnings");
  EXPECT_TRUE(Contains(codes, "drop_height_inconsistent")) << j.at("warnings");
  EXPECT_FALSE(j.at("summary").at("drop_consistent").get<bool>());
  bool mm = false, cm = false;
  for (const auto& w : j.at("warnings")) {
    const std::string m = w.at("message");
    mm |= m.find("ball.diameter_m = 10 m") != std::string::npos &&
          m.find("millimetres (0.01 m)") != std::string::npos;
    cm |= w.at("code") == "drop_height_inconsistent" && m.find("centimetres") != std::string::npos;
  }
  EXPECT_TRUE(mm) << j.at("warnings");
  EXPECT_TRUE(cm) << j.at("warnings");
  // The human form: one stderr line per warning, with its code.
  const auto human = Analyze("--scene " + kScene + " --height 0.3");
  EXPECT_NE(human.err.find("bouncecal: warning [drop_height_inconsistent]: impact 0: "),
            std::string::npos)
      << human.err;
}

TEST(AnalyzeCli, DragIsSuggestedOnlyWhenTheUserDidNotChooseIt) {
  // The bundled recording has no drag, but a real 1 cm steel ball from 0.2 m would feel ~1e-3
  // in e, far above these timing sigmas: without a stated drag model, analyze says so.
  const auto r = Analyze("--height 0.2 --diameter 0.01 --material steel --contact-duration --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  ASSERT_TRUE(Contains(Codes(j), "drag_likely_needed")) << j.at("warnings");
  for (const auto& w : j.at("warnings")) {
    if (w.at("code") != "drag_likely_needed") continue;
    EXPECT_NE(w.at("message").get<std::string>().find("effects.drag"), std::string::npos);
  }
  EXPECT_GT(j.at("summary").at("drag_effect_e").get<double>(), 1e-4);
  const auto chosen = Analyze(
      "--height 0.2 --diameter 0.01 --material steel --contact-duration "
      "--drag none --json");
  ASSERT_EQ(chosen.exit_code, 0);
  EXPECT_FALSE(Contains(Codes(nlohmann::json::parse(chosen.out)), "drag_likely_needed"));
}

}  // namespace
}  // namespace bouncecal
