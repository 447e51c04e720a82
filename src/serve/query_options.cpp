// A request's query parameters as the library's options
// (include/bouncecal/serve/query_options.hpp).
#include "bouncecal/serve/query_options.hpp"

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/bundled_scenes.hpp"

namespace bouncecal::serve {

SceneOverrides TakeSceneQuery(Query& q, bool with_law) {
  SceneOverrides f;
  if (auto name = q.TakeString("scene")) {
    f.scene_text = BundledSceneText(*name);  // Error(kBadParameter) naming the known ones
    f.scene_file = "data/scenes/" + *name + ".toml";
  }
  f.height_m = q.TakeDouble("height");
  f.height_sigma_m = q.TakeDouble("height_sigma");
  f.impact_speed_m_s = q.TakeDouble("impact_speed");
  f.diameter_m = q.TakeDouble("diameter");
  f.density_kg_m3 = q.TakeDouble("density");
  f.mass_kg = q.TakeDouble("mass");
  f.material = q.TakeString("material").value_or("");
  f.drag = q.TakeString("drag").value_or("");
  f.buoyancy = q.TakeFlag("buoyancy");
  f.contact_duration = q.TakeFlag("contact_duration");
  f.g_m_s2 = q.TakeDouble("g");
  if (with_law) {
    f.law = q.TakeString("law").value_or("");
    f.law_sets = q.TakeAll("set");
    f.expression = q.TakeString("expression").value_or("");
  }
  return f;
}

DropInputOptions TakeDropQuery(Query& q) {
  DropInputOptions o;
  o.detect.channel = ParseChannelSelection(q.TakeString("channel").value_or("auto"));
  if (auto v = q.TakeDouble("start")) o.detect.start_s = *v;
  o.detect.end_s = q.TakeDouble("end");
  if (auto v = q.TakeDouble("min_snr_db")) o.detect.min_snr_db = *v;
  o.sequence = ParseSequenceChoice(q.TakeString("sequence").value_or("main"));
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kUsage, QueryText(why));
  return o;
}

CalibrationOptions TakeCalibrationQuery(Query& q, const GivenScene& gs, int threads) {
  CalibrationOptions c;
  c.strategy = ParseFitStrategy(q.TakeString("strategy").value_or("restitution"));
  c.free_parameters = q.TakeAll("free");
  c.fixed_parameters = q.TakeAll("fix");
  c.loss = ParseRobustLoss(q.TakeString("loss").value_or("none"));
  if (auto v = q.TakeInt("starts")) c.max_starts = *v;
  if (auto v = q.TakeInt("max_iterations")) c.max_iterations = *v;
  const bool ignore_drop = q.TakeFlag("ignore_drop");
  c.estimate_scatter = !q.TakeFlag("no_scatter");
  c.use_drop = gs.drop_given && !ignore_drop;
  c.analysis.check_drag = !gs.Given("effects.drag");  // drag off by the user's choice
  c.threads = threads;
  std::string why;
  if (!c.IsValid(&why)) throw Error(ErrorCode::kUsage, QueryText(why));
  return c;
}

namespace {

// Field names -> parameter names, each replaced as a whole name.
constexpr NameInFrontEnd kParameters[] = {
    {"SceneOverrides::height_m", "height"},
    {"SceneOverrides::height_sigma_m", "height_sigma"},
    {"SceneOverrides::impact_speed_m_s", "impact_speed"},
    {"SceneOverrides::diameter_m", "diameter"},
    {"SceneOverrides::density_kg_m3", "density"},
    {"SceneOverrides::mass_kg", "mass"},
    {"SceneOverrides::material", "material"},
    {"SceneOverrides::drag", "drag"},
    {"SceneOverrides::g_m_s2", "g"},
    {"SceneOverrides::law", "law"},
    {"SceneOverrides::law_sets", "set"},
    {"SceneOverrides::expression", "expression"},
    {"DetectOptions::start_s/end_s", "start/end"},
    {"DetectOptions::start_s", "start"},
    {"DetectOptions::end_s", "end"},
    {"DetectOptions::min_snr_db", "min_snr_db"},
    {"DetectOptions::channel", "channel"},
    {"ExportOptions::force", "force"},
    {"ExportOptions::allow_approximation", "allow_approximation"},
};

}  // namespace

std::string QueryText(const std::string& message) { return RenameFields(message, kParameters); }

}  // namespace bouncecal::serve
