// The scene flags shared by analyze, simulate, synth and calibrate: --scene FILE plus
// overrides. Flags override the file; the result is validated.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal::cli {

struct SceneFlags {
  std::string scene_file;
  std::optional<double> height_m;
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

}  // namespace bouncecal::cli
