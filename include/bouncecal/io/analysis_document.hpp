// bouncecal/io/analysis_document.hpp — what `analyze --json` prints for one recording, from the
// recording's sequences and the scene the user stated: one bouncecal.analysis/1 object per
// chosen sequence (schema.hpp AnalysisJson), with the scene's unit warnings, the detection's and
// the analysis's warnings, and the values assumed.
//
// The front ends that analyse a recording they did not get from the command line (the server's
// uploads and live takes, `bouncecal listen`, Python's arrays and Listener) build their result
// here, so that it equals `bouncecal analyze FILE --json` with the same scene.
//
//   GivenScene gs = ResolveGivenScene(overrides);
//   const AnalysisOptions o = AnalyzeOptionsFor(gs, std::nullopt);
//   LoadedRecording l = LoadRecording(path, nullptr, "", drop_options);
//   for (const nlohmann::json& doc : AnalysisDocuments("drop.wav", l, gs, o)) ...
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/io/given_scene.hpp"

namespace bouncecal {

// The analysis options of `analyze` for this scene: the first impact's e only when the drop was
// given, the drag check only when the ball was given and the drag left open; a given contact
// time turns the contact-duration correction on (gs.scene is changed accordingly).
// Throws Error(kBadParameter) naming contact_time_s when it is invalid.
AnalysisOptions AnalyzeOptionsFor(GivenScene* gs, std::optional<double> contact_time_s);

// One document per chosen sequence of `loaded` (named `name`). Throws Error(kNoBounces) naming
// `name` when a chosen sequence has fewer than two impacts.
std::vector<nlohmann::json> AnalysisDocuments(const std::string& name,
                                              const LoadedRecording& loaded, const GivenScene& gs,
                                              const AnalysisOptions& options);

}  // namespace bouncecal
