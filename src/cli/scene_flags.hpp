// The scene flags shared by analyze, simulate, synth and calibrate: --scene FILE plus
// overrides. Flags override the file; the result is validated.
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal::cli {

struct SceneFlags {
  std::string scene_file;
  // TOML text read instead of the file when non-empty (the Python bindings' scene dict);
  // scene_file then only names it in messages.
  std::string scene_text;
  std::optional<double> height_m;
  std::optional<double> height_sigma_m;
  std::optional<double> impact_speed_m_s;
  std::optional<double> diameter_m;
  std::optional<double> density_kg_m3;
  std::optional<double> mass_kg;
  std::string material;
  std::string drag;  // "", none, linear, quadratic
  bool buoyancy = false;
  bool contact_duration = false;
  std::optional<double> g_m_s2;
  // Law selection (simulate/calibrate only): --law NAME --set NAME=VALUE ... --expression STR
  std::string law;
  std::vector<std::string> law_sets;
  std::string expression;
};

// Adds the scene flags to a subcommand. with_law adds --law/--set/--expression.
void AddSceneFlags(CLI::App* sub, SceneFlags* flags, bool with_law);
// Loads --scene (if any), applies the flags, validates. Throws Error(kBadScene / kBadParameter).
Scene ResolveScene(const SceneFlags& flags);

// The scene with what the user gave: the dotted keys set by the scene file or by flags
// ("ball.diameter_m", "drop.height_m", "law.parameters.A", ...). Every other value is a default.
struct GivenScene {
  Scene scene;
  std::set<std::string> given;
  // The user gave the drop (scene [drop] or --height/--impact-speed). Without it analyze and
  // calibrate treat the drop as unknown (the scene's built-in 0.2 m is never used silently).
  bool drop_given = false;
  // The user gave the ball (a diameter and a mass, density or material).
  bool ball_given = false;
  bool Given(const std::string& key) const { return given.count(key) > 0; }
};
GivenScene ResolveGivenScene(const SceneFlags& flags);

// A value a result depends on that the user did not give: key, value as printed, why it matters.
struct Assumed {
  std::string key;
  std::string value;
  std::string note;
};
// What analyze (for_calibration = false) or calibrate relies on without the user having given
// it: g, the effects, the air and ball values the effects use, the drop height's sigma, and
// (calibrate) the law and its held parameters.
std::vector<Assumed> AssumedValues(const GivenScene& gs, bool for_calibration);
nlohmann::json AssumedJson(const std::vector<Assumed>& assumed);
// "assumed (not given): key = value (note)" lines; nothing when the list is empty.
std::string AssumedText(const std::vector<Assumed>& assumed);

}  // namespace bouncecal::cli
