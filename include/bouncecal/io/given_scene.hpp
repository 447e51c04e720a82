// bouncecal/io/given_scene.hpp — the scene a user stated: a scene file (or its text) plus
// overrides of single values, the record of which values the user gave, and the list of values
// a result relies on that the user did not give.
//
// Order of precedence: defaults < scene file < overrides. An override that changes which
// quantity is authoritative resets the other one (mass_kg clears the density, impact_speed_m_s
// clears the height, material re-derives density/E/nu from the preset unless density_kg_m3 or
// mass_kg is given). The command line (src/cli/scene_flags.cpp) and the Python bindings fill
// SceneOverrides from their flags / keywords; messages here name the SceneOverrides fields
// ("SceneOverrides::height_m 0: must be finite and > 0"), which each front end maps to its own
// names.
//
//   SceneOverrides o;  o.scene_file = "drop.toml";  o.height_m = 0.3;
//   GivenScene gs = ResolveGivenScene(o);          // gs.scene, gs.Given("drop.height_m")
//   for (const Assumed& a : AssumedValues(gs, /*for_calibration=*/true)) ...
#pragma once

#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

struct SceneOverrides {
  std::string scene_file;  // TOML scene file read first ("" = the built-in defaults)
  // TOML text read instead of the file when non-empty (a scene given as a dict); scene_file then
  // only names it in messages.
  std::string scene_text;
  std::optional<double> height_m;
  std::optional<double> height_sigma_m;
  std::optional<double> impact_speed_m_s;
  std::optional<double> diameter_m;
  std::optional<double> density_kg_m3;
  std::optional<double> mass_kg;
  std::string material;  // "" = not given; else a material preset (MaterialPresets)
  std::string drag;      // "" = not given; none, linear or quadratic
  bool buoyancy = false;
  bool contact_duration = false;
  std::optional<double> g_m_s2;
  // Law selection: a registry name, parameters as "NAME=VALUE" (later ones win), and the force
  // expression of a law whose registry row needs one.
  std::string law;
  std::vector<std::string> law_sets;
  std::string expression;
  // Checks every override on its own and against the others (not the scene file): the message
  // names the field, the value and the rule. ResolveScene checks it first.
  bool IsValid(std::string* error) const;
};

// Loads the scene file (if any), applies the overrides, validates. Throws Error(kBadParameter)
// for an invalid override (IsValid's message), Error(kBadScene) for a malformed file or a scene
// that is invalid after the overrides (naming the overrides that set the offending key).
Scene ResolveScene(const SceneOverrides& overrides);

// The scene with what the user gave: the dotted keys set by the scene file or by overrides
// ("ball.diameter_m", "drop.height_m", "law.parameters.A", ...). Every other value is a default.
struct GivenScene {
  Scene scene;
  std::set<std::string> given;
  // The user gave the drop (scene [drop] or height_m/impact_speed_m_s). Without it analyze and
  // calibrate treat the drop as unknown (the scene's built-in 0.2 m is never used silently).
  bool drop_given = false;
  // The user gave the ball (a diameter and a mass, density or material).
  bool ball_given = false;
  bool Given(const std::string& key) const { return given.count(key) > 0; }
};
GivenScene ResolveGivenScene(const SceneOverrides& overrides);

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
// [{"key", "value", "note"}...]
nlohmann::json AssumedJson(const std::vector<Assumed>& assumed);
// "assumed (not given): key = value (note)" lines; nothing when the list is empty.
std::string AssumedText(const std::vector<Assumed>& assumed);

}  // namespace bouncecal
