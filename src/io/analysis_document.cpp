// What `analyze --json` prints for one recording (include/bouncecal/io/analysis_document.hpp).
#include "bouncecal/io/analysis_document.hpp"

#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/scene_checks.hpp"
#include "bouncecal/io/schema.hpp"

namespace bouncecal {

AnalysisOptions AnalyzeOptionsFor(GivenScene* gs, std::optional<double> contact_time_s) {
  AnalysisOptions o;
  if (contact_time_s) gs->scene.effects.contact_duration = true;  // a given duration is used
  o.use_drop = gs->drop_given;
  // Drag off by the user's choice, or no ball to compute it for: no drag check.
  o.check_drag = !gs->Given("effects.drag") && gs->ball_given;
  if (contact_time_s) o.contact_time_s = *contact_time_s;
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "contact_time_s: " + why);
  return o;
}

std::vector<nlohmann::json> AnalysisDocuments(const std::string& name,
                                              const LoadedRecording& loaded, const GivenScene& gs,
                                              const AnalysisOptions& options) {
  std::vector<nlohmann::json> out;
  const DetectionResult& det = loaded.result;
  const nlohmann::json assumed = AssumedJson(AssumedValues(gs, false));
  for (int s : loaded.chosen) {
    Analysis an;
    try {
      an = AnalyzeBounces(det.sequences.at(static_cast<std::size_t>(s)), gs.scene, options);
    } catch (const Error& e) {
      if (e.code() == ErrorCode::kNoBounces) throw Error(e.code(), name + ": " + e.what());
      throw;
    }
    std::vector<Warning> warnings = SceneUnitWarnings(gs.scene, gs.drop_given);
    warnings.insert(warnings.end(), det.warnings.begin(), det.warnings.end());
    warnings.insert(warnings.end(), an.warnings.begin(), an.warnings.end());
    out.push_back(AnalysisJson(name, det, s, gs.scene, an,
                               {.drop_known = gs.drop_given,
                                .from_impacts_file = !loaded.impacts_file.empty(),
                                .assumed = assumed,
                                .warnings = warnings}));
  }
  return out;
}

}  // namespace bouncecal
