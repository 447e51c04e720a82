// The first problem of a scene, with the key it concerns (internal to the library, src/): what
// Scene::IsValid reports, and where the scene-file reader (scene_file.cpp) points.
#pragma once

#include <string>

#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

struct SceneProblem {
  std::string error;    // "SOURCE: key: problem"; empty when the scene is valid
  std::string key;      // "ball.diameter_m"
  std::string problem;  // "must be finite and > 0 (got -0.01)"
};
// The first rule `s` breaks (the checks of Scene::IsValid, in their order); `source` prefixes
// the error.
SceneProblem FirstSceneProblem(const Scene& s, const std::string& source);

// The material presets' names, comma-separated (for messages).
std::string KnownMaterials();
// The law's registry row says whether it is defined by an expression (no name checks here).
bool NeedsExpression(const std::string& law_name);

}  // namespace bouncecal
