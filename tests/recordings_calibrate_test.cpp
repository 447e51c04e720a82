// Calibration of the real recordings that come with a scene file (../shared/recordings: tennis
// 2.5 m, superball 0.9 m, ping-pong), through the executable as a user runs it:
//   bouncecal calibrate X.wav --scene X.toml --law hertz-viscoelastic --json
// The numbers must be believable: the outcome is converged or poor_fit and the exit code says
// which; chi2/dof of the full model is ~1 (the scatter absorbs what timing cannot explain);
// the scatter lies in what real balls show (docs/physics.md §6); the damping has a finite sigma
// that includes the scatter. Known diagnoses fire: the superball's low bounce at the end of its
// regular sequence is an irregular bounce (and no e > 1 is reported: none is annotated); a
// ping-pong recording analysed as if dropped from 0.2 m has an inconsistent
// drop. Skips when the folder is absent (a user's machine), fails under CI=true.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "test_util.hpp"

namespace bouncecal {
namespace {

using testing_util::RunCommand;

std::string Recording(const std::string& name) {
  return (std::filesystem::path(BOUNCECAL_SHARED_RECORDINGS) / name).string();
}

bool Present(const std::string& name) {
  if (std::filesystem::exists(Recording(name + ".wav"))) return true;
  const char* ci = std::getenv("CI");
  if (ci && std::string(ci) == "true") ADD_FAILURE() << "CI=true but " << name << " is absent";
  return false;
}

bool HasCode(const nlohmann::json& j, const std::string& code) {
  for (const auto& w : j.at("warnings")) {
    if (w.at("code") == code) return true;
  }
  return false;
}

class RealCalibration : public ::testing::TestWithParam<std::string> {};

TEST_P(RealCalibration, NumbersAreBelievable) {
  const std::string name = GetParam();
  if (!Present(name)) GTEST_SKIP() << "no " << Recording(name + ".wav") << " (folder absent)";
  const auto r = RunCommand(BOUNCECAL_BINARY, "calibrate " + Recording(name + ".wav") +
                                                  " --scene " + Recording(name + ".toml") +
                                                  " --law hertz-viscoelastic --json");
  const auto j = nlohmann::json::parse(r.out);
  const auto& fit = j.at("fit");
  const std::string outcome = fit.at("outcome");
  SCOPED_TRACE(name + ": " + outcome + " — " + fit.at("reason").get<std::string>());
  EXPECT_TRUE(outcome == "converged" || outcome == "poor_fit");
  EXPECT_EQ(r.exit_code, fit.at("exit_code").get<int>());
  EXPECT_EQ(r.exit_code, outcome == "converged" ? 0 : 14);
  // Measured chi2/dof 1.00 on all three (docs/benchmarks.md table); sigma_s 0.011-0.025.
  EXPECT_NEAR(fit.at("chi2_dof").get<double>(), 1.0, 0.2);
  const double s = fit.at("scatter_e").get<double>();
  EXPECT_GT(s, 0.002);
  EXPECT_LT(s, 0.05);
  EXPECT_GT(fit.at("scatter_e_sigma").get<double>(), 0.0);
  const auto& a = j.at("law").at("parameters").at("A");
  ASSERT_TRUE(a.at("sigma").is_number());
  EXPECT_LT(a.at("sigma").get<double>(), 0.2 * a.at("value").get<double>());
  // The assumed list names what the scene files leave open.
  bool surface = false;
  for (const auto& x : j.at("assumed")) surface |= x.at("key") == "surface.material";
  EXPECT_TRUE(surface);
}

INSTANTIATE_TEST_SUITE_P(Shared, RealCalibration,
                         ::testing::Values("pisa_fr4nci_tennis_h2.50m",
                                           "pfe_bouncyball_h0.9m_stereo48k", "eeps_pingpong"));

TEST(RealCalibration, KnownDiagnosesFire) {
  if (!Present("pfe_bouncyball_h0.9m_stereo48k") || !Present("eeps_pingpong")) {
    GTEST_SKIP() << "folder absent";
  }
  const std::string ball = "pfe_bouncyball_h0.9m_stereo48k";
  const auto sb =
      RunCommand(BOUNCECAL_BINARY, "calibrate " + Recording(ball + ".wav") + " --scene " +
                                       Recording(ball + ".toml") + " --json");
  const auto jb = nlohmann::json::parse(sb.out);
  // The annotated e_31 = 0.861 (../shared/recordings/pfe_bouncyball_h0.9m_stereo48k.impacts.csv,
  // where the regular sequence ends at ~10.6 s) against 0.92-0.95 around it: measured e = 0.857,
  // 4.4 sigma below the smooth e(v). The e > 1 this test once required came from an impact the
  // old detection mis-tracked; every annotated e is below 0.96 and the detection matches every
  // annotated impact, so no bounce of the annotated span may have e > 1. (Past it, in the
  // irregular events the annotators left unmarked, a tail impact at the noise floor may.)
  EXPECT_TRUE(HasCode(jb, "irregular_bounce")) << jb.at("warnings");
  const auto ab = RunCommand(BOUNCECAL_BINARY, "analyze " + Recording(ball + ".wav") + " --scene " +
                                                   Recording(ball + ".toml") + " --json");
  ASSERT_EQ(ab.exit_code, 0) << ab.err;
  int in_span = 0;
  const auto ja = nlohmann::json::parse(ab.out);
  for (const auto& b : ja.at("bounces")) {
    if (b.at("time_s").get<double>() > 10.5939 || !b.at("e").is_number()) continue;
    ++in_span;
    EXPECT_LE(b.at("e").get<double>(), 1.0) << b;
  }
  EXPECT_GE(in_span, 30);
  // The ping-pong scene gives no drop; stating 0.2 m contradicts the first interval.
  const auto pp =
      RunCommand(BOUNCECAL_BINARY, "analyze " + Recording("eeps_pingpong.wav") + " --scene " +
                                       Recording("eeps_pingpong.toml") + " --height 0.2 --json");
  ASSERT_EQ(pp.exit_code, 0) << pp.err;
  const auto jp = nlohmann::json::parse(pp.out);
  EXPECT_TRUE(HasCode(jp, "drop_height_inconsistent")) << jp.at("warnings");
  EXPECT_FALSE(jp.at("summary").at("drop_consistent").get<bool>());
  // Without drag the ping-pong ball's e would climb as it slows: drag is suggested.
  const auto nd = RunCommand(BOUNCECAL_BINARY, "analyze " + Recording("eeps_pingpong.wav") +
                                                   " --diameter 0.04 --mass 0.0027 --json");
  ASSERT_EQ(nd.exit_code, 0) << nd.err;
  EXPECT_TRUE(HasCode(nlohmann::json::parse(nd.out), "drag_likely_needed"));
}

}  // namespace
}  // namespace bouncecal
