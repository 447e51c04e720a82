#include "bouncecal/io/schema.hpp"

#include <charconv>
#include <cmath>
#include <memory>

#include "bouncecal/core/error.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/param_resolved.hpp"
#include "bouncecal/physics/law_registry.hpp"

namespace bouncecal {
namespace {

using nlohmann::json;

json IntOrNull(int v) { return v >= 0 ? json(v) : json(nullptr); }
json TextOrNull(const std::string& s) { return s.empty() ? json(nullptr) : json(s); }

// The fields every recording-based object starts with (detect, analyze).
void RecordingFields(const std::string& file, const DetectionResult& r, bool from_impacts_file,
                     json* j) {
  const AudioInfo& a = r.audio;
  const double rate = a.sample_rate_hz;
  (*j)["file"] = file;
  (*j)["sample_rate_hz"] = JsonNumber(rate > 0 ? rate : NAN);
  (*j)["channels"] = a.channels;
  (*j)["channel"] = IntOrNull(r.channel);
  (*j)["duration_s"] = JsonNumber(a.duration_s());
  (*j)["audio"] = {{"format", a.format},
                   {"codec", a.subtype},
                   {"decoder", a.decoder},
                   {"lossy", a.lossy},
                   {"codec_delay_samples", a.codec_delay_samples},
                   {"codec_delay_s",
                    JsonNumber(rate > 0 ? static_cast<double>(a.codec_delay_samples) / rate : NAN)},
                   {"codec_delay_trimmed", a.codec_delay_trimmed}};
  (*j)["source"] = from_impacts_file ? "impacts_file" : "detection";
}

json SequenceJson(const Sequence& s) {
  json q;
  q["impacts"] = json::array();
  for (const Impact& i : s.impacts) q["impacts"].push_back(ImpactJson(i));
  q["missed_after"] = s.missed_after;
  q["irregular_after"] = s.irregular_after;
  q["removed"] = json::array();
  for (const RemovedImpact& x : s.removed) {
    json rj = ImpactJson(x.impact);
    rj["code"] = x.code;
    q["removed"].push_back(rj);
  }
  q["end_reason"] = s.end_reason;
  return q;
}

// Parameter entries of the one law shape; `fit` (same order as specs) adds sigma and flags.
json ParametersJson(const std::vector<ParameterSpec>& specs, const std::vector<double>& values,
                    const std::vector<FittedParameter>* fit) {
  json out = json::object();
  for (size_t i = 0; i < specs.size(); ++i) {
    const ParameterSpec& s = specs[i];
    const FittedParameter* f = fit != nullptr && i < fit->size() ? &(*fit)[i] : nullptr;
    out[s.name] = {{"value", JsonNumber(i < values.size() ? values[i] : NAN)},
                   {"sigma", f ? JsonNumber(f->sigma) : json(nullptr)},
                   {"unit", s.unit},
                   {"lower", JsonNumber(s.lower)},
                   {"upper", JsonNumber(s.upper)},
                   {"damping", s.damping},
                   {"fixed", f ? json(f->fixed) : json(nullptr)},
                   {"determined", f ? json(f->determined) : json(nullptr)},
                   {"at_bound", f ? json(f->at_bound) : json(nullptr)},
                   {"description", TextOrNull(s.description)}};
  }
  return out;
}

}  // namespace

json JsonNumber(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

json JsonNumber(const std::optional<double>& v) { return v ? JsonNumber(*v) : json(nullptr); }

json WarningsJson(const std::vector<Warning>& warnings) {
  json out = json::array();
  for (const Warning& w : warnings) {
    out.push_back({{"code", w.code},
                   {"message", w.message},
                   {"impact", IntOrNull(w.impact)},
                   {"hint", w.hint}});
  }
  return out;
}

json ErrorJson(ErrorCode code, const std::string& message) {
  return {
      {"code", ErrorCodeName(code)}, {"exit_code", static_cast<int>(code)}, {"message", message}};
}

json FailedInputJson(const std::string& file, ErrorCode code, const std::string& message) {
  return {{"schema", kErrorSchema}, {"file", file}, {"error", ErrorJson(code, message)}};
}

json ImpactJson(const Impact& i) {
  // Members set in place (long recordings list thousands of impacts; see SimulationJson).
  json o(json::value_t::object);
  o["time_s"] = i.time_s;
  o["time_sigma_s"] = JsonNumber(i.sigma_s);
  o["amplitude"] = JsonNumber(i.amplitude);
  o["snr_db"] = JsonNumber(i.snr_db);
  o["score"] = JsonNumber(i.score);
  o["clipped"] = i.clipped;
  return o;
}

json SceneJson(const Scene& s, const SceneJsonOptions& options) {
  const bool drop = options.drop_known;
  const bool spring = s.surface.kind == Surface::Kind::kSpringMass;
  json j;
  j["source"] = TextOrNull(s.source);
  j["ball"] = {{"diameter_m", s.ball.diameter_m},
               {"mass_kg", JsonNumber(s.ball.Mass())},
               {"density_kg_m3", JsonNumber(s.ball.Density())},
               {"material", s.ball.material},
               {"youngs_modulus_pa", JsonNumber(s.ball.youngs_modulus_pa)},
               {"poisson_ratio", JsonNumber(s.ball.poisson_ratio)}};
  j["surface"] = {{"kind", spring ? "spring_mass" : "rigid"},
                  {"material", s.surface.material},
                  {"youngs_modulus_pa", JsonNumber(s.surface.youngs_modulus_pa)},
                  {"poisson_ratio", JsonNumber(s.surface.poisson_ratio)},
                  {"mass_kg", spring ? json(s.surface.mass_kg) : json(nullptr)},
                  {"stiffness_n_m", spring ? json(s.surface.stiffness_n_m) : json(nullptr)},
                  {"damping_n_s_m", spring ? json(s.surface.damping_n_s_m) : json(nullptr)}};
  j["environment"] = {{"g_m_s2", s.environment.g_m_s2},
                      {"air_density_kg_m3", s.environment.air_density_kg_m3},
                      {"air_viscosity_pa_s", s.environment.air_viscosity_pa_s},
                      {"drag_coefficient", s.environment.drag_coefficient}};
  j["drop"] = {{"height_m", drop ? JsonNumber(s.drop.height_m) : json(nullptr)},
               {"height_sigma_m",
                drop && s.drop.height_m ? JsonNumber(s.drop.height_sigma_m) : json(nullptr)},
               {"impact_speed_m_s", drop ? JsonNumber(s.drop.impact_speed_m_s) : json(nullptr)}};
  j["effects"] = {{"drag", DragModelName(s.effects.drag)},
                  {"buoyancy", s.effects.buoyancy},
                  {"contact_duration", s.effects.contact_duration},
                  {"surface_compliance", s.effects.surface_compliance}};
  return j;
}

json LawJson(const ContactLaw& law, const std::vector<double>& values,
             const std::string& expression) {
  return {{"name", law.Name()},
          {"formula", law.Formula()},
          {"source", law.Source()},
          {"expression", TextOrNull(expression)},
          {"parameters", ParametersJson(law.Parameters(), values, nullptr)}};
}

json LawJson(const Calibration& c) {
  // The specs (descriptions) from the registry; a law it cannot build keeps the fit's own.
  std::vector<ParameterSpec> specs;
  try {
    specs = CreateLaw(c.scene.law, c.scene)->Parameters();
  } catch (const Error&) {
    specs.clear();
  }
  if (specs.size() != c.parameters.size()) {
    specs.clear();
    for (const FittedParameter& p : c.parameters)
      specs.push_back({p.name, p.unit, "", p.lower, p.upper, p.value, p.damping});
  }
  std::vector<double> values;
  for (const FittedParameter& p : c.parameters) values.push_back(p.value);
  // The fit's bounds are the ones it used.
  for (size_t i = 0; i < specs.size(); ++i) {
    specs[i].lower = c.parameters[i].lower;
    specs[i].upper = c.parameters[i].upper;
    specs[i].damping = c.parameters[i].damping;
  }
  return {{"name", c.law},
          {"formula", c.formula},
          {"source", c.source},
          {"expression", TextOrNull(c.scene.law.expression)},
          {"parameters", ParametersJson(specs, values, &c.parameters)}};
}

json BounceJson(const Bounce& b) {
  return {{"index", b.index},
          {"time_s", b.time_s},
          {"time_sigma_s", JsonNumber(b.time_sigma_s)},
          {"interval_s", JsonNumber(b.interval_s)},
          {"v_in_m_s", JsonNumber(b.v_in_m_s)},
          {"v_in_sigma_m_s", JsonNumber(b.v_in_sigma_m_s)},
          {"v_out_m_s", JsonNumber(b.v_out_m_s)},
          {"v_out_sigma_m_s", JsonNumber(b.v_out_sigma_m_s)},
          {"e", JsonNumber(b.e)},
          {"e_sigma", JsonNumber(b.e_total_sigma)},
          {"e_timing_sigma", JsonNumber(b.e_sigma)},
          {"eta", JsonNumber(b.eta)},
          {"eta_sigma", JsonNumber(b.eta_sigma)},
          // 0 = the contact-duration correction is off (kinematics.hpp): not applicable.
          {"contact_s", b.contact_s > 0.0 ? JsonNumber(b.contact_s) : json(nullptr)},
          {"e_next_correlation", JsonNumber(b.e_next_correlation)},
          {"irregular", b.irregular}};
}

json DetectionJson(const std::string& file, const DetectionResult& r,
                   const DetectionJsonOptions& options) {
  json j;
  j["schema"] = kDetectSchema;
  RecordingFields(file, r, options.from_impacts_file, &j);
  j["window"] = {{"start_s", r.start_s}, {"end_s", r.end_s}};
  j["channel_scores"] = json::array();
  for (const ChannelScore& c : r.channel_scores)
    j["channel_scores"].push_back({{"channel", IntOrNull(c.channel)},
                                   {"score", JsonNumber(c.score)},
                                   {"impacts", c.impacts},
                                   {"failure", TextOrNull(c.failure)}});
  j["clipping"] = json::array();
  for (const ClippingReport& c : r.clipping)
    j["clipping"].push_back({{"channel", c.channel},
                             {"clipped_samples", c.clipped_samples},
                             {"peak", JsonNumber(c.peak)}});
  // Each impact once, in its sequence (bouncecal.detect/1 also listed the first chosen
  // sequence's impacts at the top level; editing that copy changed nothing).
  j["sequences"] = json::array();
  for (const Sequence& s : r.sequences) j["sequences"].push_back(SequenceJson(s));
  j["main_sequence"] = r.main_sequence;
  j["chosen_sequences"] = options.chosen;
  j["n_candidates"] = r.candidates.size();
  j["warnings"] = WarningsJson(r.warnings);
  return j;
}

json AnalysisJson(const std::string& file, const DetectionResult& det, int sequence,
                  const Scene& scene, const Analysis& an, const AnalysisJsonOptions& options) {
  const Sequence& seq = det.sequences.at(static_cast<size_t>(sequence));
  json j;
  j["schema"] = kAnalysisSchema;
  RecordingFields(file, det, options.from_impacts_file, &j);
  j["scene"] = SceneJson(scene, {.drop_known = options.drop_known});
  j["sequence"] = {{"n_sequences", det.sequences.size()},
                   {"main_sequence", det.main_sequence},
                   {"sequence", sequence},
                   {"n_impacts", seq.impacts.size()},
                   {"missed_after", seq.missed_after},
                   {"end_reason", seq.end_reason}};
  json bounces = json::array();
  int n_with_e = 0;
  double e_min = NAN, e_max = NAN;
  for (const Bounce& b : an.bounces) {
    bounces.push_back(BounceJson(b));
    if (!std::isfinite(b.e)) continue;
    ++n_with_e;
    e_min = std::isfinite(e_min) ? std::min(e_min, b.e) : b.e;
    e_max = std::isfinite(e_max) ? std::max(e_max, b.e) : b.e;
  }
  j["bounces"] = std::move(bounces);
  const bool height = options.drop_known && scene.drop.height_m.has_value();
  j["summary"] = {{"mean_eta_first3", JsonNumber(an.mean_eta_first3)},
                  {"mean_eta_first3_sigma", JsonNumber(an.mean_eta_first3_sigma)},
                  {"mean_eta_indices", an.mean_eta_indices},
                  {"first_e", JsonNumber(an.first_e)},
                  {"first_e_sigma", JsonNumber(an.first_e_sigma)},
                  {"scatter_e", JsonNumber(an.scatter_e)},
                  {"scatter_e_sigma", JsonNumber(an.scatter_e_sigma)},
                  {"drop_consistent", an.drop_consistent},
                  {"drop_height_sigma_m", height ? JsonNumber(an.height_sigma_m) : json(nullptr)},
                  {"drop_height_fit_m", JsonNumber(an.drop_height_fit_m)},
                  {"drag_effect_e", JsonNumber(an.drag_effect_e)},
                  {"effective_gravity_m_s2", JsonNumber(an.effective_gravity_m_s2)},
                  {"terminal_speed_m_s", JsonNumber(an.terminal_speed_m_s)},
                  {"n_bounces", an.bounces.size()},
                  {"n_with_e", n_with_e},
                  {"e_min", JsonNumber(e_min)},
                  {"e_max", JsonNumber(e_max)}};
  j["assumed"] = options.assumed.is_array() ? options.assumed : json::array();
  j["warnings"] = WarningsJson(options.warnings);
  return j;
}

json SimulationJson(const Scene& scene, const ContactLaw& law, const std::vector<double>& values,
                    const Simulation& s) {
  json j;
  j["schema"] = kSimulationSchema;
  j["scene"] = SceneJson(scene);
  j["law"] = LawJson(law, values, scene.law.expression);
  // Each impact's members set in place, the array moved in: the initializer-list form (every
  // member built as a two-element array first) and the copy into j took 240 M instructions
  // for simulate --json's 10 000 impacts, more than the dump; the same document.
  json impacts = json::array();
  impacts.get_ref<json::array_t&>().reserve(s.impacts.size());
  for (size_t k = 0; k < s.impacts.size(); ++k) {
    const SimImpact& i = s.impacts[k];
    json& o = impacts.emplace_back(json::value_t::object);
    o["index"] = k;
    o["time_s"] = i.time_s;
    o["v_in_m_s"] = i.v_in_m_s;
    o["v_out_m_s"] = i.v_out_m_s;
    o["e"] = i.v_in_m_s > 0.0 ? json(i.v_out_m_s / i.v_in_m_s) : json(nullptr);
    o["contact_s"] = i.contact_s;
    o["peak_overlap_m"] = i.peak_overlap_m;
    o["peak_force_n"] = i.peak_force_n;
    o["steps"] = i.steps;
  }
  j["impacts"] = std::move(impacts);
  const EnergyLedger& e = s.energy;
  j["energy"] = {{"initial_j", e.initial_j},
                 {"final_mechanical_j", e.final_mechanical_j},
                 {"dissipated_contact_j", e.dissipated_contact_j},
                 {"dissipated_drag_j", e.dissipated_drag_j},
                 {"internal_j", e.internal_j},
                 {"balance_error_j", e.balance_error_j}};
  j["stop_reason"] = StopReasonName(s.stop_reason);
  j["stop_detail"] = s.stop_detail;
  j["total_steps"] = s.total_steps;
  j["contact_map"] = {
      {"contacts", s.mapped_contacts}, {"panels", s.map_panels}, {"refused", s.map_panels_refused}};
  j["warnings"] = json::array();
  return j;
}

json LawListingJson(const ContactLaw& law, const std::string& summary,
                    const std::string& expression) {
  json j = LawJson(law, law.ParameterValues(), expression);
  j["summary"] = summary;
  j["end_rule"] = law.EndRule() == ContactEnd::kForceZero ? "force_zero" : "overlap_zero";
  j["state_size"] = law.StateSize();
  j["closed_forms"] = law.ClosedForms();
  return j;
}

json LawsJson(const std::vector<json>& entries) {
  return {{"schema", kLawsSchema}, {"laws", entries}};
}

json OptionsJson(const CalibrationOptions& o) {
  return {{"strategy", FitStrategyName(o.strategy)},
          {"free_parameters", o.free_parameters},
          {"fixed_parameters", o.fixed_parameters},
          {"derivatives", DerivativeModeName(o.derivatives)},
          {"rel_tolerance", o.rel_tolerance},
          {"loss", RobustLossName(o.loss)},
          {"loss_scale_sigma", o.loss_scale_sigma},
          {"max_iterations", o.max_iterations},
          {"estimate_scatter", o.estimate_scatter},
          {"use_drop", o.use_drop},
          {"seed_from_inverse_map", o.seed_from_inverse_map},
          {"max_starts", o.max_starts},
          {"e_of_v_points", o.e_of_v_points},
          {"undetermined_relative_sigma", o.undetermined_relative_sigma},
          {"poor_fit_p_value", o.poor_fit_p_value},
          {"misfit_tolerance_e", o.misfit_tolerance_e},
          {"plausible_scatter_e", o.plausible_scatter_e},
          {"analysis",
           {{"irregular_alpha", o.analysis.irregular_alpha},
            {"drop_z_max", o.analysis.drop_z_max},
            {"check_drag", o.analysis.check_drag},
            {"drag_effect_sigmas", o.analysis.drag_effect_sigmas}}}};
}

json CalibrationJson(const Calibration& c, const Provenance& prov, const json& options) {
  const bool traj = c.strategy == FitStrategy::kTrajectory;
  const std::string rms_key = traj ? "rms_residual_s" : "rms_residual_e";
  json j;
  j["schema"] = kParamFileSchema;
  j["law"] = LawJson(c);
  json ev = json::array();
  for (const auto& pt : c.e_of_v) {
    ev.push_back({{"v_m_s", JsonNumber(pt.v_m_s)},
                  {"e", JsonNumber(pt.e)},
                  {"e_sigma", JsonNumber(pt.sigma)}});
  }
  j["e_of_v"] = std::move(ev);
  j["fit"] = {{"strategy", FitStrategyName(c.strategy)},
              {"derivatives", DerivativeModeName(c.derivatives)},
              {"analytic_jacobian", c.analytic_jacobian},
              {"outcome", FitOutcomeName(c.outcome)},
              {"exit_code", static_cast<int>(FitOutcomeExitCode(c.outcome))},
              {"reason", c.reason},
              {"hint", c.hint},
              {"message", c.message},
              {"scatter_e", JsonNumber(c.scatter_e)},
              {"scatter_e_sigma", JsonNumber(c.scatter_e_sigma)},
              {"scatter_e_is_upper_limit", c.scatter_at_zero},
              {rms_key, JsonNumber(c.rms_residual)},
              {"chi2", JsonNumber(c.chi2)},
              {"chi2_dof", JsonNumber(c.chi2_dof)},
              {"dof", c.dof},
              {"num_residuals", c.num_residuals},
              {"num_free", c.num_free},
              {"trend_chi2", JsonNumber(c.trend_chi2)},
              {"trend_dof", c.trend_dof},
              {"misfit_p_value", JsonNumber(c.misfit_p_value)},
              {"misfit_e", JsonNumber(c.misfit_e)},
              {"misfit_tolerance_e", JsonNumber(c.misfit_tolerance_e)},
              {"misfit_scatter_e", JsonNumber(c.misfit_scatter_e)},
              {"neg_log_likelihood", JsonNumber(c.neg_log_likelihood)},
              {"aic", JsonNumber(c.aic)},
              {"bic", JsonNumber(c.bic)},
              {"starts", c.starts},
              {"starts_reached_best", c.starts_reached_best},
              {"iterations", c.iterations},
              {"simulations", c.simulations},
              {"v_min_m_s", JsonNumber(c.v_min_m_s)},
              {"v_max_m_s", JsonNumber(c.v_max_m_s)},
              {"determined", c.Determined()},
              {"undetermined", c.Undetermined()}};
  json recs = json::array();
  for (const auto& r : c.recordings) {
    json jr = {{"file", r.name}, {"impacts", r.impacts}, {rms_key, JsonNumber(r.rms_residual)}};
    if (traj) {
      jr["simulated_impacts"] = r.simulated_impacts;
      jr["impact_speed_m_s"] = JsonNumber(r.impact_speed_m_s);
      jr["impact_speed_sigma_m_s"] = JsonNumber(r.impact_speed_sigma_m_s);
      jr["impact_speed_fixed"] = r.impact_speed_fixed;
      jr["time_origin_s"] = JsonNumber(r.time_origin_s);
      jr["time_origin_sigma_s"] = JsonNumber(r.time_origin_sigma_s);
    }
    recs.push_back(std::move(jr));
  }
  j["recordings"] = std::move(recs);
  j["warnings"] = WarningsJson(c.warnings);
  j["assumed"] = json::array();  // the CLI lists the defaults it used
  j["scene"] = SceneJson(c.scene, {.drop_known = c.scene.drop.height_m.has_value() ||
                                                 c.scene.drop.impact_speed_m_s.has_value()});
  // Every resolved physical value, for simulators and replays (param_resolved.hpp, issue 12).
  try {
    j["resolved"] = ResolvedJson(c);
  } catch (const Error&) {
    j["resolved"] = nullptr;
  }
  try {
    j["scene_toml"] = SceneToToml(c.scene);
  } catch (const Error&) {
    j["scene_toml"] = nullptr;
  }
  json inputs = json::array();
  for (const auto& in : prov.inputs) inputs.push_back({{"file", in.path}, {"sha256", in.sha256}});
  j["provenance"] = {{"inputs", inputs},
                     {"bouncecal_version", prov.bouncecal_version},
                     {"options", options},
                     {"date_utc", prov.date_utc}};
  return j;
}

json LawComparisonJson(const std::vector<LawComparisonRow>& rows, const Provenance& prov,
                       const json& options, const json& assumed) {
  json j = {{"schema", kLawComparisonSchema}};
  json laws = json::array();
  int rank = 0;
  for (const auto& r : rows) {
    json l = CalibrationJson(r.fit, prov, options);
    l["adequate"] = r.adequate;
    l["rank"] = r.adequate ? json(++rank) : json(nullptr);
    l["delta_aic"] = JsonNumber(r.delta_aic);
    laws.push_back(std::move(l));
  }
  j["laws"] = std::move(laws);
  j["assumed"] = assumed.is_array() ? assumed : json::array();
  return j;
}

json CalibrationRowJson(const std::string& file, const Calibration* c, const Error* err) {
  json j = {{"schema", kCalibrationRowSchema}, {"file", file}};
  if (err != nullptr || c == nullptr) {
    j["status"] = "error";
    j["error"] = err != nullptr ? ErrorJson(err->code(), err->what())
                                : ErrorJson(ErrorCode::kInternal, "no result");
    for (const char* k : {"law", "outcome", "reason", "hint", "impacts", "scatter_e",
                          "scatter_e_sigma", "rms_residual", "residual_unit", "chi2_dof"})
      j[k] = nullptr;
    j["warnings"] = json::array();
    return j;
  }
  int impacts = 0;
  for (const auto& r : c->recordings) impacts += r.impacts;
  j["status"] = c->outcome == FitOutcome::kConverged ? "ok" : "fit";
  j["error"] = nullptr;
  j["law"] = LawJson(*c);
  j["outcome"] = FitOutcomeName(c->outcome);
  j["reason"] = c->reason;
  j["hint"] = c->hint;
  j["impacts"] = impacts;
  j["scatter_e"] = JsonNumber(c->scatter_e);
  j["scatter_e_sigma"] = JsonNumber(c->scatter_e_sigma);
  j["rms_residual"] = JsonNumber(c->rms_residual);
  j["residual_unit"] = c->residual_unit;
  j["chi2_dof"] = JsonNumber(c->chi2_dof);
  j["warnings"] = WarningsJson(c->warnings);
  return j;
}

std::string CsvNumber(double v) {
  if (!std::isfinite(v)) return "";
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);  // shortest round-trip form
  return std::string(buf, r.ptr);
}

std::string CsvNumber(const std::optional<double>& v) { return v ? CsvNumber(*v) : ""; }

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n\r") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

}  // namespace bouncecal
