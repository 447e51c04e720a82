// bouncecal/serve/query_options.hpp — a request's query parameters as the library's options:
// the CLI's flags without their dashes (height=0.2, min_snr_db=12 or min-snr-db=12), the same
// names the Python keywords use. Flags are `name`, `name=1` or `name=true`.
//
//   Query q(ParseTarget(target).query);
//   SceneOverrides scene = TakeSceneQuery(q, /*with_law=*/true);
//   DropInputOptions drops = TakeDropQuery(q);
//   q.Finish("/api/calibrate");
//
// A scene is given by its values (height, diameter, material, ...) or by the name of a bundled
// scene (scene=steel-copper: data/scenes/NAME.toml, built into the program): a request never
// names a file on the server.
#pragma once

#include <optional>
#include <string>

#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/given_scene.hpp"
#include "bouncecal/serve/requests.hpp"

namespace bouncecal::serve {

// scene (a bundled scene's name), height, height_sigma, impact_speed, diameter, density, mass,
// material, drag, buoyancy, contact_duration, g; with_law adds law, set (repeatable NAME=VALUE),
// expression.
SceneOverrides TakeSceneQuery(Query& q, bool with_law);
// channel (N, mix or auto: the default, as the CLI), start, end, sequence, min_snr_db.
DropInputOptions TakeDropQuery(Query& q);
// strategy, free, fix (repeatable), loss, starts, max_iterations, ignore_drop, no_scatter, as
// `calibrate`; the drop and drag checks follow the scene as there.
CalibrationOptions TakeCalibrationQuery(Query& q, const GivenScene& gs, int threads);
// The library's messages in parameter names ("SceneOverrides::height_m" -> "height").
std::string QueryText(const std::string& message);

}  // namespace bouncecal::serve
