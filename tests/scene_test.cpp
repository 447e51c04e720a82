// Tests for scenes (scene.hpp): the TOML format, presets, validation with line numbers, and the
// round trip SceneToToml -> ParseScene.
#include "bouncecal/physics/scene.hpp"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>

#include <gtest/gtest.h>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

// Parses text that must fail; returns the error after checking the code.
Error ParseError(const std::string& text, ErrorCode code = ErrorCode::kBadScene) {
  try {
    ParseScene(text, "s.toml");
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    return e;
  }
  ADD_FAILURE() << "accepted:\n" << text;
  return Error(ErrorCode::kOk, "");
}

void ExpectMessage(const std::string& text, const std::string& prefix, const std::string& has) {
  const Error e = ParseError(text);
  const std::string msg = e.what();
  EXPECT_EQ(msg.rfind(prefix, 0), 0u) << "message: " << msg << "\nexpected prefix: " << prefix;
  EXPECT_NE(msg.find(has), std::string::npos) << "message: " << msg << "\nexpected: " << has;
  EXPECT_EQ(msg.find('\n'), std::string::npos) << "multi-line message: " << msg;
}

TEST(SceneTest, DefaultsAreTheSeedExperimentAndValid) {
  const Scene s;
  std::string err;
  EXPECT_TRUE(s.IsValid(&err)) << err;
  EXPECT_DOUBLE_EQ(s.ball.diameter_m, 0.01);
  EXPECT_DOUBLE_EQ(s.ball.Density(), 7800.0);
  EXPECT_NEAR(s.ball.Mass(), 7800.0 * M_PI / 6 * 1e-6, 1e-18);
  EXPECT_DOUBLE_EQ(*s.drop.height_m, 0.2);
  EXPECT_DOUBLE_EQ(s.EffectiveGravity(), 9.8);
  EXPECT_EQ(s.effects.drag, DragModel::kNone);
  // An empty file is the default scene.
  Scene parsed = ParseScene("", "");
  EXPECT_EQ(parsed, s);
}

TEST(SceneTest, ParsesEveryKey) {
  const std::string text = R"(# comment
[ball]
diameter_m = 0.04
mass_kg = 0.0027
material = "pingpong"
youngs_modulus_pa = 3e9
poisson_ratio = 0.3

[surface]
kind = "spring-mass"
material = "wood"
youngs_modulus_pa = 1.0e10
poisson_ratio = 0.25
mass_kg = 2
stiffness_n_m = 1e6
damping_n_s_m = 3.5

[environment]
g_m_s2 = 9.81
air_density_kg_m3 = 1.18
air_viscosity_pa_s = 1.8e-5
drag_coefficient = 0.5

[drop]
impact_speed_m_s = 3
first_impact_time_s = 0.25

[effects]
drag = "quadratic"
buoyancy = true
contact_duration = true
surface_compliance = true

[law]
name = "hertz-tsuji"
[law.parameters]
k = 1e9
e = 0.8

[limits]
horizon_s = 10
max_impacts = 50
rest_speed_m_s = 0.001
)";
  const Scene s = ParseScene(text, "x.toml");
  std::string err;
  EXPECT_TRUE(s.IsValid(&err)) << err;
  EXPECT_EQ(s.source, "x.toml");
  EXPECT_DOUBLE_EQ(s.ball.diameter_m, 0.04);
  EXPECT_EQ(s.ball.mass_kg, 0.0027);
  EXPECT_FALSE(s.ball.density_kg_m3.has_value());  // mass given: density derived
  EXPECT_NEAR(s.ball.Density(), 0.0027 / (M_PI / 6 * 0.04 * 0.04 * 0.04), 1e-9);
  EXPECT_EQ(s.ball.material, "pingpong");
  EXPECT_DOUBLE_EQ(s.ball.ResolvedYoungsModulusPa(), 3e9);
  EXPECT_EQ(s.surface.kind, Surface::Kind::kSpringMass);
  EXPECT_DOUBLE_EQ(s.surface.mass_kg, 2.0);  // integer accepted as a number
  EXPECT_DOUBLE_EQ(s.surface.damping_n_s_m, 3.5);
  EXPECT_DOUBLE_EQ(s.environment.g_m_s2, 9.81);
  EXPECT_DOUBLE_EQ(s.environment.drag_coefficient, 0.5);
  EXPECT_FALSE(s.drop.height_m.has_value());  // impact speed given: default height dropped
  EXPECT_EQ(s.drop.impact_speed_m_s, 3.0);
  EXPECT_DOUBLE_EQ(s.drop.first_impact_time_s, 0.25);
  EXPECT_EQ(s.effects.drag, DragModel::kQuadratic);
  EXPECT_TRUE(s.effects.buoyancy && s.effects.contact_duration && s.effects.surface_compliance);
  EXPECT_EQ(s.law.name, "hertz-tsuji");
  EXPECT_EQ(s.law.parameters.at("k"), 1e9);
  EXPECT_EQ(s.law.parameters.at("e"), 0.8);
  EXPECT_EQ(s.limits.max_impacts, 50);
  EXPECT_DOUBLE_EQ(s.limits.rest_speed_m_s, 0.001);
  EXPECT_NEAR(s.EffectiveGravity(), 9.81 * (1 - 1.18 / s.ball.Density()), 1e-12);
}

TEST(SceneTest, RoundTripsThroughToml) {
  std::vector<Scene> scenes(4);
  scenes[1].ball.diameter_m = 0.0123456789012345;
  scenes[1].ball.mass_kg = 1.0 / 3.0;
  scenes[1].ball.density_kg_m3.reset();
  scenes[1].ball.material = "glass";
  scenes[1].ball.poisson_ratio = 0.21;
  scenes[1].drop.height_m.reset();
  scenes[1].drop.impact_speed_m_s = 2.0;
  scenes[1].effects.drag = DragModel::kLinear;
  scenes[1].law.name = "expression";
  scenes[1].law.expression = "k*d^1.5 + c*\"v\"\\n";
  scenes[1].law.parameters = {{"k", 1e10}, {"c", 0.1}, {"odd name", 2}};
  scenes[2].surface.kind = Surface::Kind::kSpringMass;
  scenes[2].surface.mass_kg = 0.7;
  scenes[2].surface.stiffness_n_m = 3e5;
  scenes[2].surface.youngs_modulus_pa = 1e9;
  scenes[2].effects.surface_compliance = true;
  scenes[2].effects.buoyancy = true;
  scenes[2].environment.g_m_s2 = 9.80665;
  scenes[2].limits.max_impacts = 7;
  scenes[2].limits.horizon_s = 1e-3;
  scenes[2].drop.first_impact_time_s = -0.1;
  scenes[3].law.name = "walton-braun";
  scenes[3].law.parameters = {{"gamma", 0.1 + 0.2}, {"k", 1e7}};
  for (Scene& s : scenes) {
    s.source = "rt.toml";
    std::string err;
    ASSERT_TRUE(s.IsValid(&err)) << err;
    const std::string text = SceneToToml(s);
    const Scene back = ParseScene(text, "rt.toml");
    EXPECT_EQ(back, s) << text;
    EXPECT_EQ(SceneToToml(back), text);
  }
}

TEST(SceneTest, MaterialPresets) {
  const Scene glass = ParseScene("[ball]\nmaterial = \"glass\"\n", "");
  EXPECT_DOUBLE_EQ(glass.ball.Density(), FindMaterial("glass")->density_kg_m3);
  EXPECT_DOUBLE_EQ(glass.ball.ResolvedYoungsModulusPa(), FindMaterial("glass")->youngs_modulus_pa);
  EXPECT_DOUBLE_EQ(glass.ball.ResolvedPoissonRatio(), FindMaterial("glass")->poisson_ratio);
  // Explicit values win over the preset, whatever the key order.
  const Scene dense = ParseScene("[ball]\ndensity_kg_m3 = 2600\nmaterial = \"glass\"\n", "");
  EXPECT_DOUBLE_EQ(dense.ball.Density(), 2600.0);
  const Scene heavy = ParseScene("[ball]\nmaterial = \"rubber\"\nmass_kg = 0.01\n", "");
  EXPECT_EQ(heavy.ball.mass_kg, 0.01);
  EXPECT_FALSE(heavy.ball.density_kg_m3.has_value());
  EXPECT_DOUBLE_EQ(heavy.ball.ResolvedYoungsModulusPa(), FindMaterial("rubber")->youngs_modulus_pa);
  const Scene stiff = ParseScene("[ball]\nmaterial = \"rubber\"\nyoungs_modulus_pa = 7e6\n", "");
  EXPECT_DOUBLE_EQ(stiff.ball.ResolvedYoungsModulusPa(), 7e6);
  // Surface material.
  const Scene wood = ParseScene("[surface]\nmaterial = \"wood\"\n", "");
  EXPECT_DOUBLE_EQ(wood.surface.ResolvedYoungsModulusPa(), FindMaterial("wood")->youngs_modulus_pa);
  // Every preset is physical; the names the brief asks for exist.
  for (const char* name : {"steel", "copper", "glass", "rubber", "wood", "celluloid", "pingpong",
                           "tennis", "aluminum"}) {
    const MaterialPreset* p = FindMaterial(name);
    ASSERT_NE(p, nullptr) << name;
    EXPECT_GT(p->density_kg_m3, 0);
    EXPECT_GT(p->youngs_modulus_pa, 0);
    EXPECT_GT(p->poisson_ratio, -1);
    EXPECT_LE(p->poisson_ratio, 0.5);
  }
  EXPECT_EQ(FindMaterial("unobtainium"), nullptr);
  // A custom material name is fine when every value is explicit.
  const Scene custom = ParseScene(
      "[ball]\nmaterial = \"my-resin\"\ndensity_kg_m3 = 1100\nyoungs_modulus_pa = 2e9\n"
      "poisson_ratio = 0.4\n",
      "");
  EXPECT_EQ(custom.ball.material, "my-resin");
}

TEST(SceneTest, MassAndDensityConflict) {
  ExpectMessage("[ball]\ndensity_kg_m3 = 7800\nmass_kg = 0.004\n",
                "s.toml:3: ball.mass_kg:", "density");
  ExpectMessage("[drop]\nheight_m = 0.2\nimpact_speed_m_s = 2\n",
                "s.toml:3: drop.impact_speed_m_s:", "height");
  Scene s;
  s.ball.mass_kg = 0.004;  // density 7800 still set
  std::string err;
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_NE(err.find("ball.mass_kg"), std::string::npos) << err;
}

TEST(SceneTest, EveryErrorNamesFileLineKeyAndValue) {
  struct Case {
    std::string text, prefix, has;
  };
  const std::vector<Case> cases = {
      {"[ball]\ndiameter_m = 0\n", "s.toml:2: ball.diameter_m:", "(got 0)"},
      {"\n[ball]\nmass_kg = -1.5\n", "s.toml:3: ball.mass_kg:", "(got -1.5)"},
      {"[ball]\ndiameter_m = nan\n", "s.toml:2: ball.diameter_m:", "finite"},
      {"[ball]\ndensity_kg_m3 = inf\n", "s.toml:2: ball.density_kg_m3:", "finite"},
      {"[ball]\ndiameter_m = \"1 cm\"\n", "s.toml:2: ball.diameter_m:", "(got \"1 cm\")"},
      {"[ball]\npoisson_ratio = 0.7\n", "s.toml:2: ball.poisson_ratio:", "(got 0.7)"},
      {"[ball]\ncolour = \"red\"\n", "s.toml:2: ball.colour:", "unknown key"},
      {"[ball]\nmaterial = \"unobtainium\"\n", "s.toml:2: ball.material:", "unobtainium"},
      {"[balll]\ndiameter_m = 0.01\n", "s.toml:1: balll:", "unknown"},
      {"ball = 3\n", "s.toml:1: ball:", "(got 3)"},
      {"[surface]\nkind = \"jelly\"\n", "s.toml:2: surface.kind:", "(got \"jelly\")"},
      {"[surface]\nkind = \"spring-mass\"\nmass_kg = 1\n", "s.toml:1: surface.kind:", "stiffness"},
      {"[surface]\ndamping_n_s_m = -1\n", "s.toml:2: surface.damping_n_s_m:", "(got -1)"},
      {"[environment]\ng_m_s2 = -9.8\n", "s.toml:2: environment.g_m_s2:", "(got -9.8)"},
      {"[environment]\nair_density_kg_m3 = -1\n",
       "s.toml:2: environment.air_density_kg_m3:", "(got -1)"},
      {"[drop]\nheight_m = 0\n", "s.toml:2: drop.height_m:", "(got 0)"},
      {"[drop]\nfirst_impact_time_s = true\n", "s.toml:2: drop.first_impact_time_s:", "(got true)"},
      {"[effects]\ndrag = \"cubic\"\n", "s.toml:2: effects.drag:", "(got \"cubic\")"},
      {"[effects]\nbuoyancy = 1\n", "s.toml:2: effects.buoyancy:", "(got 1)"},
      {"[effects]\nsurface_compliance = true\n",
       "s.toml:2: effects.surface_compliance:", "spring-mass"},
      {"[effects]\nbuoyancy = true\n[ball]\ndensity_kg_m3 = 0.5\n",
       "s.toml:2: effects.buoyancy:", "air"},
      {"[law]\nname = \"\"\n", "s.toml:2: law.name:", "empty"},
      {"[law]\nname = \"expression\"\n", "s.toml:1: law.expression:", "missing"},
      {"[law]\nname = \"linear-dashpot\"\nexpression = \"k*d\"\n",
       "s.toml:3: law.expression:", "only"},
      {"[law]\nname = \"linear-dashpot\"\n[law.parameters]\nk = \"big\"\n",
       "s.toml:4: law.parameters.k:", "(got \"big\")"},
      {"[law]\nname = \"linear-dashpot\"\n[law.parameters]\nk = nan\n",
       "s.toml:4: law.parameters.k:", "finite"},
      {"[limits]\nmax_impacts = 0\n", "s.toml:2: limits.max_impacts:", "(got 0)"},
      {"[limits]\nmax_impacts = 2.5\n", "s.toml:2: limits.max_impacts:", "(got 2.5)"},
      {"[limits]\nhorizon_s = -1\n", "s.toml:2: limits.horizon_s:", "(got -1)"},
      {"[limits]\nrest_speed_m_s = -1e-3\n", "s.toml:2: limits.rest_speed_m_s:", "(got -0.001)"},
      // TOML syntax errors carry toml++'s line.
      {"[ball]\ndiameter_m = 0.01\ndensity_kg_m3 = = 3\n", "s.toml:3: TOML syntax error", ""},
      {"[ball]\n[ball]\n", "s.toml:2: TOML syntax error", ""},
      {"[drop\nheight_m = 1\n", "s.toml:1: TOML syntax error", ""},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.text);
    ExpectMessage(c.text, c.prefix, c.has);
  }
}

TEST(SceneTest, FilesMissingOrDirectories) {
  const std::string dir = ::testing::TempDir();
  try {
    LoadSceneFile(dir + "/does-not-exist.toml");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInputMissing);
    EXPECT_NE(std::string(e.what()).find("does-not-exist.toml"), std::string::npos);
  }
  try {
    LoadSceneFile(dir);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInputMissing);
  }
  const std::string path = dir + "/scene_test_ok.toml";
  {
    std::ofstream out(path);
    out << "[drop]\nheight_m = 0.5\n[ball]\nmass_kg = = 1\n";
  }
  try {
    LoadSceneFile(path);
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadScene);
    EXPECT_EQ(std::string(e.what()).rfind(path + ":4:", 0), 0u) << e.what();
  }
  {
    std::ofstream out(path);
    out << "[drop]\nheight_m = 0.5\n";
  }
  const Scene s = LoadSceneFile(path);
  EXPECT_EQ(s.source, path);
  EXPECT_EQ(s.drop.height_m, 0.5);
  std::remove(path.c_str());
}

TEST(SceneTest, IsValidNamesKeyAndValue) {
  Scene s;
  s.source = "flags";
  s.ball.diameter_m = -1;
  std::string err;
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_EQ(err, "flags: ball.diameter_m: must be finite and > 0 (got -1)");
  s = Scene{};
  s.drop.height_m.reset();
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_NE(err.find("drop.height_m"), std::string::npos);
  s = Scene{};
  s.environment.g_m_s2 = std::nan("");
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_NE(err.find("environment.g_m_s2"), std::string::npos);
  s = Scene{};
  s.ball.poisson_ratio = 0.6;
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_NE(err.find("0.6"), std::string::npos);
  s = Scene{};
  s.limits.max_impacts = 0;
  EXPECT_FALSE(s.IsValid(&err));
  s = Scene{};
  s.law.parameters["k"] = INFINITY;
  EXPECT_FALSE(s.IsValid(&err));
  EXPECT_NE(err.find("law.parameters.k"), std::string::npos);
  EXPECT_TRUE(Scene{}.IsValid(nullptr));
}

TEST(SceneTest, BundledSceneFilesAreValidAndRoundTrip) {
  int count = 0;
  for (const char* sub : {"data", "data/scenes"}) {
    const std::filesystem::path dir = std::filesystem::path(BOUNCECAL_SOURCE_DIR) / sub;
    if (!std::filesystem::is_directory(dir)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir)) {
      if (entry.path().extension() != ".toml") continue;
      SCOPED_TRACE(entry.path().string());
      const Scene s = LoadSceneFile(entry.path().string());
      std::string err;
      EXPECT_TRUE(s.IsValid(&err)) << err;
      EXPECT_EQ(ParseScene(SceneToToml(s), s.source), s);
      ++count;
    }
  }
  EXPECT_GE(count, 4);
  // The ping-pong example (the synth preset's scene): mass given, density derived, drag on,
  // buoyancy off; turned on, it lowers g by rho_air / rho_ball = 1.2 / 80.6 = 1.5 %.
  Scene pp = LoadSceneFile(std::string(BOUNCECAL_SOURCE_DIR) + "/data/scenes/pingpong-wood.toml");
  EXPECT_EQ(pp.effects.drag, DragModel::kQuadratic);
  EXPECT_NEAR(pp.ball.Density(), 0.0027 / (M_PI / 6 * 0.04 * 0.04 * 0.04), 1e-9);
  EXPECT_EQ(pp.EffectiveGravity(), 9.8);
  pp.effects.buoyancy = true;
  EXPECT_LT(pp.EffectiveGravity(), 9.8 * 0.99);
}

TEST(SceneTest, DragModelNames) {
  for (DragModel m : {DragModel::kNone, DragModel::kLinear, DragModel::kQuadratic}) {
    DragModel back = DragModel::kNone;
    ASSERT_TRUE(ParseDragModel(DragModelName(m), &back));
    EXPECT_EQ(back, m);
  }
  DragModel m;
  EXPECT_FALSE(ParseDragModel("Quadratic", &m));
}

}  // namespace
}  // namespace bouncecal

namespace bouncecal {
namespace {

TEST(SceneTest, DropHeightSigmaParsesValidatesAndRoundTrips) {
  const Scene s = ParseScene("[drop]\nheight_m = 2.5\nheight_sigma_m = 0.01\n", "d.toml");
  ASSERT_TRUE(s.drop.height_sigma_m.has_value());
  EXPECT_DOUBLE_EQ(*s.drop.height_sigma_m, 0.01);
  EXPECT_EQ(ParseScene(SceneToToml(s), "d.toml"), s);
  EXPECT_FALSE(ParseScene("[drop]\nheight_m = 1\n", "").drop.height_sigma_m.has_value());
  auto message = [](const std::string& text) {
    try {
      ParseScene(text, "d.toml");
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kBadScene);
      return std::string(e.what());
    }
    return std::string("no error");
  };
  EXPECT_NE(message("[drop]\nheight_m = 1\nheight_sigma_m = -0.1\n")
                .find("d.toml:3: drop.height_sigma_m: must be >= 0"),
            std::string::npos);
  // A sigma without its height (here: an impact speed instead) contradicts the scene.
  const std::string orphan = message("[drop]\nimpact_speed_m_s = 2\nheight_sigma_m = 0.01\n");
  EXPECT_NE(
      orphan.find("drop.height_sigma_m: is the uncertainty of drop.height_m, which is not given"),
      std::string::npos)
      << orphan;
  Scene bad;
  bad.drop.height_sigma_m = std::nan("");
  std::string err;
  EXPECT_FALSE(bad.IsValid(&err));
  EXPECT_NE(err.find("drop.height_sigma_m"), std::string::npos) << err;
}

TEST(SceneTest, SceneFileKeysListWhatTheFileGives) {
  const std::string path = ::testing::TempDir() + "/keys_" + std::to_string(::getpid()) + ".toml";
  {
    std::ofstream(path) << "[ball]\ndiameter_m = 0.04\nmaterial = \"pingpong\"\n[effects]\ndrag = "
                           "\"quadratic\"\n[law.parameters]\nA = 1e-6\n";
  }
  const std::vector<std::string> keys = SceneFileKeys(path);
  const std::vector<std::string> want = {"ball.diameter_m", "ball.material", "effects.drag",
                                         "law.parameters.A"};
  EXPECT_EQ(keys, want);
  std::remove(path.c_str());
  EXPECT_THROW(SceneFileKeys(path), Error);  // gone: the same error as LoadSceneFile
}

}  // namespace
}  // namespace bouncecal
