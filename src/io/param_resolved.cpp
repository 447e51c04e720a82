// The parameter file's "resolved" section and the replay scene (param_resolved.hpp).
#include "bouncecal/io/param_resolved.hpp"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <optional>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

using nlohmann::json;

json Num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }

// Shortest text that reads back to the same double.
// E* of ball on surface: the one rule (EffectiveModulusPa, scene.hpp); NaN (null in the file)
// when either body's elastic constants are unknown.
double EffectiveModulus(const Scene& s) {
  const std::optional<double> e_star = EffectiveModulusPa(s, nullptr);
  return e_star ? *e_star : std::nan("");
}

// The drag-free release height (ball bottom) that arrives at v: v^2 / 2g.
double ReleaseHeight(double v_m_s, double g_m_s2) { return v_m_s * v_m_s / (2.0 * g_m_s2); }

json ContactsJson(const Scene& scene, const std::vector<double>& speeds_m_s) {
  json out = json::array();
  const std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);
  const std::vector<double> p = law->ParameterValues();
  const ContactBody body = BodyFromScene(scene);
  for (double v : speeds_m_s) {
    if (!(v > 0.0)) continue;
    const ContactOutcome c = SimulateContact(*law, p, body, v, 0.0);
    out.push_back({{"v_m_s", v},
                   {"e", Num(c.restitution)},
                   {"contact_time_s", c.stuck ? json(nullptr) : Num(c.contact_time_s)},
                   {"peak_overlap_m", Num(c.peak_overlap_m)}});
  }
  return out;
}

// Drop of the replay: a positive fitted first impact speed wins over the scene's drop.
void ApplyReplayDrop(Scene* s, double replay_impact_speed_m_s) {
  if (replay_impact_speed_m_s > 0.0) {
    s->drop.impact_speed_m_s = replay_impact_speed_m_s;
    s->drop.height_m.reset();
  }
}

}  // namespace

json ResolvedJson(const Scene& scene_in, const std::vector<double>& speeds_m_s,
                  double replay_impact_speed_m_s) {
  Scene s = scene_in;
  ApplyReplayDrop(&s, replay_impact_speed_m_s);
  const std::unique_ptr<ContactLaw> law = CreateLaw(s.law, s);
  const ContactBody body = BodyFromScene(s);
  const double g = s.EffectiveGravity();
  json j;
  j["ball"] = {{"diameter_m", s.ball.diameter_m},
               {"radius_m", s.ball.Radius()},
               {"mass_kg", Num(s.ball.Mass())},
               {"density_kg_m3", Num(s.ball.Density())},
               {"youngs_modulus_pa", Num(s.ball.ResolvedYoungsModulusPa())},
               {"poisson_ratio", Num(s.ball.ResolvedPoissonRatio())}};
  j["surface"] = {{"kind", s.surface.kind == Surface::Kind::kRigid ? "rigid" : "spring_mass"},
                  {"youngs_modulus_pa", Num(s.surface.ResolvedYoungsModulusPa())},
                  {"poisson_ratio", Num(s.surface.ResolvedPoissonRatio())}};
  j["contact"] = {
      {"effective_mass_kg", body.mass_kg},
      {"effective_radius_m", body.radius_m},
      {"effective_modulus_pa", Num(EffectiveModulus(s))},
      {"contact_end", law->EndRule() == ContactEnd::kForceZero ? "force_zero" : "overlap_zero"}};
  j["environment"] = {{"g_m_s2", s.environment.g_m_s2}, {"effective_g_m_s2", g}};
  double v0 = s.drop.impact_speed_m_s.value_or(std::nan(""));
  if (s.drop.height_m) v0 = std::sqrt(2.0 * g * *s.drop.height_m);  // drag-free
  j["drop"] = {{"impact_speed_m_s", Num(v0)},
               {"release_height_m", Num(ReleaseHeight(v0, g))},
               {"from", replay_impact_speed_m_s > 0.0 ? "recording 0 fit" : "scene"}};
  j["contacts"] = ContactsJson(s, speeds_m_s);
  return j;
}

json ResolvedJson(const Calibration& c) {
  std::vector<double> speeds;
  for (const EOfVPoint& pt : c.e_of_v) speeds.push_back(pt.v_m_s);
  double v0 = 0.0;
  if (c.strategy == FitStrategy::kTrajectory && !c.recordings.empty() &&
      std::isfinite(c.recordings[0].impact_speed_m_s)) {
    v0 = c.recordings[0].impact_speed_m_s;
  }
  return ResolvedJson(c.scene, speeds, v0);
}

namespace {

// A number at doc[a][b] or NaN.
double At(const json& doc, const char* a, const char* b) {
  if (!doc.contains(a) || !doc[a].is_object() || !doc[a].contains(b)) return std::nan("");
  const json& v = doc[a][b];
  return v.is_number() ? v.get<double>() : std::nan("");
}

// A resolved value that must equal what the scene gives (relative 1e-9; both absent is fine).
void CheckResolved(const json& resolved, const char* a, const char* b, double expected,
                   const std::string& path) {
  const double stored = At(resolved, a, b);
  if (std::isnan(stored) && std::isnan(expected)) return;
  const double tol = 1e-9 * std::max(std::abs(expected), std::abs(stored));
  if (!(std::abs(stored - expected) <= tol)) {
    throw Error(ErrorCode::kBadParameter,
                path + ": resolved." + a + "." + b + " = " + FormatShortest(stored) +
                    " disagrees with the file's scene (" + FormatShortest(expected) +
                    "); edit the scene (scene_toml), not the resolved values");
  }
}

Scene SceneOfFile(const ParamFile& file, const std::string& path) {
  const json& doc = file.doc;
  if (!doc.contains("scene_toml") || !doc["scene_toml"].is_string()) {
    throw Error(ErrorCode::kBadParameter,
                path + ": scene_toml: expected the fit's scene as TOML text (got " +
                    (doc.contains("scene_toml") ? DumpJson(doc["scene_toml"]) : "nothing") +
                    "); this file cannot be replayed");
  }
  try {
    return ParseScene(doc["scene_toml"].get<std::string>(), path + ":scene_toml");
  } catch (const Error& e) {
    throw Error(ErrorCode::kBadParameter, e.what());
  }
}

}  // namespace

Replay ReplayFromParamFile(const ParamFile& file, const std::string& path) {
  Replay r;
  r.scene = SceneOfFile(file, path);
  r.scene.law = file.law;  // the fitted values (held ones included)
  const LawInfo* row = FindLaw(r.scene.law.name);
  if (r.scene.law.expression.empty() && row != nullptr && row->needs_expression) {
    throw Error(ErrorCode::kBadParameter,
                path + ": law " + r.scene.law.name + " without scene.law.expression");
  }
  const json& doc = file.doc;
  double v0 = 0.0;
  if (doc.contains("resolved") && doc["resolved"].contains("drop") &&
      doc["resolved"]["drop"].value("from", "") == "recording 0 fit") {
    v0 = At(doc["resolved"], "drop", "impact_speed_m_s");
  } else if (!doc.contains("resolved") && doc.contains("fit") &&
             doc["fit"].value("strategy", "") == "trajectory" && doc.contains("recordings") &&
             doc["recordings"].is_array() && !doc["recordings"].empty() &&
             doc["recordings"][0].contains("impact_speed_m_s") &&
             doc["recordings"][0]["impact_speed_m_s"].is_number()) {
    v0 = doc["recordings"][0]["impact_speed_m_s"].get<double>();  // files before "resolved"
  }
  ApplyReplayDrop(&r.scene, v0);
  r.drop_from = v0 > 0.0 ? "recording 0 fit" : "scene";
  if (doc.contains("resolved")) {
    const json& res = doc["resolved"];
    const Scene& s = r.scene;
    CheckResolved(res, "ball", "diameter_m", s.ball.diameter_m, path);
    CheckResolved(res, "ball", "mass_kg", s.ball.Mass(), path);
    CheckResolved(res, "ball", "youngs_modulus_pa", s.ball.ResolvedYoungsModulusPa(), path);
    CheckResolved(res, "ball", "poisson_ratio", s.ball.ResolvedPoissonRatio(), path);
    CheckResolved(res, "surface", "youngs_modulus_pa", s.surface.ResolvedYoungsModulusPa(), path);
    CheckResolved(res, "surface", "poisson_ratio", s.surface.ResolvedPoissonRatio(), path);
    CheckResolved(res, "environment", "g_m_s2", s.environment.g_m_s2, path);
  }
  // Every constant explicit: the replay no longer depends on the preset tables.
  const double eb = r.scene.ball.ResolvedYoungsModulusPa(),
               nb = r.scene.ball.ResolvedPoissonRatio();
  if (std::isfinite(eb) && std::isfinite(nb)) {
    r.scene.ball.youngs_modulus_pa = eb;
    r.scene.ball.poisson_ratio = nb;
  }
  const double es = r.scene.surface.ResolvedYoungsModulusPa();
  const double ns = r.scene.surface.ResolvedPoissonRatio();
  if (std::isfinite(es) && std::isfinite(ns)) {
    r.scene.surface.youngs_modulus_pa = es;
    r.scene.surface.poisson_ratio = ns;
  }
  for (const auto& pt : doc.value("e_of_v", json::array())) {
    if (pt.contains("v_m_s") && pt["v_m_s"].is_number()) {
      r.speeds_m_s.push_back(pt["v_m_s"].get<double>());
    }
  }
  r.v_min_m_s = doc.contains("fit") ? At(doc, "fit", "v_min_m_s") : 0.0;
  r.v_max_m_s = doc.contains("fit") ? At(doc, "fit", "v_max_m_s") : 0.0;
  if (!std::isfinite(r.v_min_m_s)) r.v_min_m_s = 0.0;
  if (!std::isfinite(r.v_max_m_s)) r.v_max_m_s = 0.0;
  std::string why;
  if (!r.scene.IsValid(&why)) throw Error(ErrorCode::kBadParameter, path + ": " + why);
  try {
    CreateLaw(r.scene.law, r.scene);  // the law accepts the file's parameters
  } catch (const Error& e) {
    throw Error(ErrorCode::kBadParameter, path + ": " + e.what());
  }
  return r;
}

}  // namespace bouncecal
