// bouncecal/fit/scene_checks.hpp — scene values that are probably in the wrong unit.
//
// A scene is valid when its numbers are positive and finite; it can still describe a 67 m
// ball (the user meant 67 mm) or a drop from 150 m (150 cm). SceneUnitWarnings flags values
// outside what a bouncing-ball experiment can be — ball diameter outside 0.1 mm .. 1 m, drop
// height above 50 m, ball density outside 10 .. 25 000 kg/m^3 (aerogel .. osmium; a mass in
// grams shows up here), g outside 1 .. 30 m/s^2 — as `units_suspect`, naming the likely unit.
//
//   for (const Warning& w : SceneUnitWarnings(scene, /*drop_used=*/true)) ...
#pragma once

#include <vector>

#include "bouncecal/core/warning.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

std::vector<Warning> SceneUnitWarnings(const Scene& scene, bool drop_used);

}  // namespace bouncecal
