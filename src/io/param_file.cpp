#include "bouncecal/io/param_file.hpp"

#include <cmath>
#include <fstream>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/param_resolved.hpp"

namespace bouncecal {
namespace {

using nlohmann::json;

// NaN/Inf are not JSON numbers: absent values are null.
json Num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
json Opt(const std::optional<double>& v) { return v ? Num(*v) : json(nullptr); }

}  // namespace

json SceneJson(const Scene& s) {
  json j;
  j["ball"] = {{"diameter_m", s.ball.diameter_m},
               {"mass_kg", Num(s.ball.Mass())},
               {"density_kg_m3", Num(s.ball.Density())},
               {"material", s.ball.material},
               {"youngs_modulus_pa", Opt(s.ball.youngs_modulus_pa)},
               {"poisson_ratio", Opt(s.ball.poisson_ratio)}};
  j["surface"] = {{"kind", s.surface.kind == Surface::Kind::kRigid ? "rigid" : "spring_mass"},
                  {"material", s.surface.material},
                  {"youngs_modulus_pa", Opt(s.surface.youngs_modulus_pa)},
                  {"poisson_ratio", Opt(s.surface.poisson_ratio)}};
  if (s.surface.kind == Surface::Kind::kSpringMass) {
    j["surface"]["mass_kg"] = s.surface.mass_kg;
    j["surface"]["stiffness_n_m"] = s.surface.stiffness_n_m;
    j["surface"]["damping_n_s_m"] = s.surface.damping_n_s_m;
  }
  j["environment"] = {{"g_m_s2", s.environment.g_m_s2},
                      {"air_density_kg_m3", s.environment.air_density_kg_m3},
                      {"air_viscosity_pa_s", s.environment.air_viscosity_pa_s},
                      {"drag_coefficient", s.environment.drag_coefficient}};
  j["drop"] = {{"height_m", Opt(s.drop.height_m)},
               {"impact_speed_m_s", Opt(s.drop.impact_speed_m_s)}};
  j["effects"] = {{"drag", DragModelName(s.effects.drag)},
                  {"buoyancy", s.effects.buoyancy},
                  {"contact_duration", s.effects.contact_duration},
                  {"surface_compliance", s.effects.surface_compliance}};
  json params = json::object();
  for (const auto& [k, v] : s.law.parameters) params[k] = Num(v);
  j["law"] = {{"name", s.law.name}, {"parameters", params}};
  if (!s.law.expression.empty()) j["law"]["expression"] = s.law.expression;
  return j;
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
          {"plausible_scatter_e", o.plausible_scatter_e},
          {"analysis",
           {{"irregular_alpha", o.analysis.irregular_alpha},
            {"drop_z_max", o.analysis.drop_z_max},
            {"check_drag", o.analysis.check_drag},
            {"drag_effect_sigmas", o.analysis.drag_effect_sigmas}}}};
}

json ParamFileJson(const Calibration& c, const Provenance& prov, const json& options) {
  const bool traj = c.strategy == FitStrategy::kTrajectory;
  const std::string rms_key = traj ? "rms_residual_s" : "rms_residual_e";
  json j;
  j["schema"] = kParamFileSchema;
  j["law"] = c.law;
  j["formula"] = c.formula;
  j["source"] = c.source;
  json params = json::object();
  for (const auto& p : c.parameters) {
    params[p.name] = {
        {"value", Num(p.value)},  {"sigma", Num(p.sigma)},      {"unit", p.unit},
        {"fixed", p.fixed},       {"determined", p.determined}, {"damping", p.damping},
        {"at_bound", p.at_bound}, {"lower", Num(p.lower)},      {"upper", Num(p.upper)}};
  }
  j["parameters"] = params;
  json ev = json::array();
  for (const auto& pt : c.e_of_v) {
    ev.push_back({{"v_m_s", Num(pt.v_m_s)}, {"e", Num(pt.e)}, {"sigma", Num(pt.sigma)}});
  }
  j["e_of_v"] = ev;
  j["fit"] = {{"strategy", FitStrategyName(c.strategy)},
              {"derivatives", DerivativeModeName(c.derivatives)},
              {"analytic_jacobian", c.analytic_jacobian},
              {"outcome", FitOutcomeName(c.outcome)},
              {"exit_code", static_cast<int>(FitOutcomeExitCode(c.outcome))},
              {"reason", c.reason},
              {"message", c.message},
              {"scatter_e", Num(c.scatter_e)},
              {"scatter_e_sigma", Num(c.scatter_e_sigma)},
              {"scatter_e_is_upper_limit", c.scatter_at_zero},
              {rms_key, Num(c.rms_residual)},
              {"chi2", Num(c.chi2)},
              {"chi2_dof", Num(c.chi2_dof)},
              {"dof", c.dof},
              {"num_residuals", c.num_residuals},
              {"num_free", c.num_free},
              {"trend_chi2", Num(c.trend_chi2)},
              {"trend_dof", c.trend_dof},
              {"neg_log_likelihood", Num(c.neg_log_likelihood)},
              {"aic", Num(c.aic)},
              {"bic", Num(c.bic)},
              {"starts", c.starts},
              {"starts_reached_best", c.starts_reached_best},
              {"iterations", c.iterations},
              {"simulations", c.simulations},
              {"v_min_m_s", Num(c.v_min_m_s)},
              {"v_max_m_s", Num(c.v_max_m_s)},
              {"determined", c.Determined()},
              {"undetermined", c.Undetermined()}};
  json recs = json::array();
  for (const auto& r : c.recordings) {
    json jr = {{"path", r.name}, {"impacts", r.impacts}, {rms_key, Num(r.rms_residual)}};
    if (traj) {
      jr["simulated_impacts"] = r.simulated_impacts;
      jr["impact_speed_m_s"] = Num(r.impact_speed_m_s);
      jr["impact_speed_sigma_m_s"] = Num(r.impact_speed_sigma_m_s);
      jr["impact_speed_fixed"] = r.impact_speed_fixed;
      jr["time_origin_s"] = Num(r.time_origin_s);
      jr["time_origin_sigma_s"] = Num(r.time_origin_sigma_s);
    }
    recs.push_back(jr);
  }
  j["recordings"] = recs;
  json warnings = json::array();
  for (const Warning& w : c.warnings) {
    warnings.push_back({{"code", w.code},
                        {"message", w.message},
                        {"impact", w.impact >= 0 ? json(w.impact) : json(nullptr)}});
  }
  j["warnings"] = warnings;
  j["scene"] = SceneJson(c.scene);
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
  for (const auto& in : prov.inputs) inputs.push_back({{"path", in.path}, {"sha256", in.sha256}});
  j["provenance"] = {{"inputs", inputs},
                     {"bouncecal_version", prov.bouncecal_version},
                     {"options", options},
                     {"date_utc", prov.date_utc}};
  return j;
}

void WriteParamFile(const std::string& path, const json& doc, const WriteOptions& options) {
  WriteFileAtomically(path, DumpJson(doc, 2) + "\n", options);
}

ParamFile ReadParamFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot open parameter file");
  std::stringstream ss;
  ss << in.rdbuf();
  auto bad = [&](const std::string& m) { return Error(ErrorCode::kBadParameter, path + ": " + m); };
  json doc = json::parse(ss.str(), nullptr, false);
  if (doc.is_discarded() || !doc.is_object()) throw bad("not a JSON object");
  ParamFile pf;
  if (!doc.contains("schema") || !doc["schema"].is_string()) throw bad("missing key 'schema'");
  pf.schema = doc["schema"].get<std::string>();
  if (pf.schema != kParamFileSchema) {
    const std::string family = "bouncecal.params/";
    const bool newer = pf.schema.rfind(family, 0) == 0 && pf.schema > kParamFileSchema;
    throw bad("schema '" + pf.schema + "' is " +
              (newer ? "newer than this bouncecal reads (" + std::string(kParamFileSchema) +
                           "): upgrade bouncecal"
                     : "unknown (expected " + std::string(kParamFileSchema) + ")"));
  }
  if (!doc.contains("law") || !doc["law"].is_string()) throw bad("missing key 'law'");
  pf.law.name = doc["law"].get<std::string>();
  if (!doc.contains("parameters") || !doc["parameters"].is_object()) {
    throw bad("missing key 'parameters'");
  }
  for (const auto& [name, p] : doc["parameters"].items()) {
    if (!p.is_object() || !p.contains("value") || !p["value"].is_number()) {
      throw bad("parameters." + name + ".value: expected a number");
    }
    pf.law.parameters[name] = p["value"].get<double>();
    if (p.contains("sigma") && p["sigma"].is_number()) pf.sigma[name] = p["sigma"].get<double>();
  }
  if (doc.contains("scene") && doc["scene"].contains("law") &&
      doc["scene"]["law"].contains("expression") && doc["scene"]["law"]["expression"].is_string()) {
    pf.law.expression = doc["scene"]["law"]["expression"].get<std::string>();
  }
  if (doc.contains("fit") && doc["fit"].contains("outcome") && doc["fit"]["outcome"].is_string()) {
    pf.outcome = doc["fit"]["outcome"].get<std::string>();
  }
  if (doc.contains("warnings") && doc["warnings"].is_array()) {
    for (const auto& w : doc["warnings"]) {
      if (w.is_object() && w.contains("code") && w["code"].is_string()) {
        pf.warnings.push_back(w["code"].get<std::string>());
      }
    }
  }
  pf.doc = std::move(doc);
  return pf;
}

}  // namespace bouncecal
