// io/given_scene.hpp and acoustic/drop_input.hpp: the stages the command line and the Python
// bindings share. Their messages name the Options fields (never a command-line flag); the
// precedence rules (an override that changes which quantity is authoritative resets the other)
// and the record of what the user gave are checked against hand-built scenes.
#include "bouncecal/io/given_scene.hpp"

#include <gtest/gtest.h>

#include <fstream>
#include <string>

#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/core/error.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

// The Error a call throws (code and message); fails the test when it throws none.
template <class F>
Error Thrown(F&& f) {
  try {
    f();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()).find("--"), std::string::npos) << "names a flag: " << e.what();
    return e;
  }
  ADD_FAILURE() << "no Error thrown";
  return Error(ErrorCode::kInternal, "");
}

TEST(GivenScene, OverridesResetTheQuantityTheyReplace) {
  testing_util::ScratchDir dir("bc_given");
  const std::string file = dir / "s.toml";
  std::ofstream(file) << "[ball]\ndiameter_m = 0.02\ndensity_kg_m3 = 2000.0\n"
                         "[drop]\nheight_m = 0.5\nheight_sigma_m = 0.01\n";
  SceneOverrides o;
  o.scene_file = file;
  o.mass_kg = 0.01;
  o.impact_speed_m_s = 2.0;
  const GivenScene gs = ResolveGivenScene(o);
  EXPECT_EQ(gs.scene.ball.diameter_m, 0.02);  // from the file
  EXPECT_EQ(gs.scene.ball.mass_kg, 0.01);
  EXPECT_FALSE(gs.scene.ball.density_kg_m3.has_value());
  EXPECT_EQ(gs.scene.drop.impact_speed_m_s, 2.0);
  EXPECT_FALSE(gs.scene.drop.height_m.has_value());
  EXPECT_FALSE(gs.scene.drop.height_sigma_m.has_value());  // belonged to the file's height
  EXPECT_TRUE(gs.Given("ball.diameter_m") && gs.Given("ball.mass_kg"));
  EXPECT_TRUE(gs.drop_given && gs.ball_given);
  EXPECT_FALSE(gs.Given("environment.g_m_s2"));
  // g was not given: assumed, with the value used; the ball was given: not assumed.
  const std::vector<Assumed> assumed = AssumedValues(gs, /*for_calibration=*/true);
  bool g = false;
  for (const Assumed& a : assumed) {
    g = g || (a.key == "environment.g_m_s2" && a.value == "9.8");
    EXPECT_NE(a.key, "ball.diameter_m");
  }
  EXPECT_TRUE(g);
  EXPECT_NE(AssumedText(assumed).find("assumed (not given): environment.g_m_s2 = 9.8"),
            std::string::npos);

  SceneOverrides m;
  m.material = "glass";
  m.law = "hertz-tsuji";
  m.law_sets = {"e = 0.9"};
  const Scene s = ResolveScene(m);
  EXPECT_EQ(s.ball.density_kg_m3, 2500.0);  // the material's density
  EXPECT_EQ(s.law.parameters.at("e"), 0.9);
}

TEST(GivenScene, MessagesNameTheFieldTheValueAndTheRule) {
  SceneOverrides o;
  o.height_m = -1.0;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  Error e = Thrown([&] { ResolveScene(o); });
  EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  EXPECT_STREQ(e.what(), "SceneOverrides::height_m: must be finite and > 0 (got -1)");
  EXPECT_EQ(why, e.what());

  o = {};
  o.mass_kg = 0.1;
  o.density_kg_m3 = 0.5;
  EXPECT_STREQ(Thrown([&] { ResolveScene(o); }).what(),
               "SceneOverrides::mass_kg 0.1 and SceneOverrides::density_kg_m3 0.5: give one of "
               "them");
  o = {};
  o.law_sets = {"gamma"};
  EXPECT_STREQ(Thrown([&] { ResolveScene(o); }).what(),
               "SceneOverrides::law_sets gamma: expected NAME=VALUE");
  o = {};
  o.drag = "Quadratic";
  EXPECT_STREQ(Thrown([&] { ResolveScene(o); }).what(),
               "SceneOverrides::drag Quadratic: expected none, linear or quadratic");
  o = {};
  o.expression = "k*d";
  o.law = "walton-braun";
  e = Thrown([&] { ResolveScene(o); });
  EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  EXPECT_NE(std::string(e.what()).find("SceneOverrides::expression: only with SceneOverrides::law"),
            std::string::npos)
      << e.what();
  o = {};
  o.height_sigma_m = 0.01;  // no height of the user's to belong to
  EXPECT_NE(std::string(Thrown([&] { ResolveScene(o); }).what())
                .find("give SceneOverrides::height_m, or a scene file"),
            std::string::npos);
  // A scene invalid after the overrides: kBadScene naming the override that set the key.
  o = {};
  o.impact_speed_m_s = 1e200;  // the kinetic energy overflows
  e = Thrown([&] { ResolveScene(o); });
  EXPECT_EQ(e.code(), ErrorCode::kBadScene);
  const std::string what = e.what();
  EXPECT_EQ(what.rfind("scene from overrides: drop.impact_speed_m_s", 0), 0u) << what;
  EXPECT_NE(what.find("(set by SceneOverrides::impact_speed_m_s)"), std::string::npos) << what;
}

TEST(DropInput, PairsRecordingsWithImpactFilesOrSaysWhichFieldIsWrong) {
  DropInputOptions o;
  o.impacts_files = {"a.csv"};
  const auto pairs = PairInputs({"a.wav"}, o);
  ASSERT_EQ(pairs.size(), 1u);
  EXPECT_EQ(pairs[0], std::make_pair(std::string("a.wav"), std::string("a.csv")));
  const Error e = Thrown([&] { PairInputs({"a.wav", "b.wav"}, o); });
  EXPECT_EQ(e.code(), ErrorCode::kUsage);
  EXPECT_NE(std::string(e.what()).find("DropInputOptions::impacts_files given 1 time(s) for 2"),
            std::string::npos)
      << e.what();
  o.detect.start_s = -1.0;
  const Error bad = Thrown([&] { LoadRecording("", nullptr, "a.csv", o); });
  EXPECT_EQ(bad.code(), ErrorCode::kBadParameter);
  EXPECT_NE(std::string(bad.what()).find("DetectOptions::start_s"), std::string::npos);
}

TEST(DropInput, TimesFromAFileKeepTheWindowAndTheChosenSequences) {
  testing_util::ScratchDir dir("bc_dropin");
  const std::string file = dir / "t.txt";
  std::ofstream(file) << "1.0\n1.5\n1.9\n2.2\n2.4\n";
  DropInputOptions o;
  o.impacts_files = {file};
  std::vector<RecordingDrop> drops = LoadDrops({}, o);
  ASSERT_EQ(drops.size(), 1u);
  EXPECT_EQ(drops[0].name, file);
  EXPECT_EQ(drops[0].sequence.impacts.size(), 5u);
  o.detect.start_s = 1.2;  // the window applies to times from a file too
  drops = LoadDrops({}, o);
  ASSERT_EQ(drops.size(), 1u);
  EXPECT_EQ(drops[0].sequence.impacts.size(), 4u);
  EXPECT_EQ(drops[0].sequence.impacts.front().time_s, 1.5);
  o.detect.start_s = 2.0;  // two impacts left: no sequence
  EXPECT_EQ(Thrown([&] { LoadDrops({}, o); }).code(), ErrorCode::kNoBounces);
}

}  // namespace
}  // namespace bouncecal
