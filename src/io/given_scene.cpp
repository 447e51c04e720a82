// The scene a user stated (given_scene.hpp): scene file + overrides, what was given, what was
// assumed. Messages name the SceneOverrides fields; the front ends map them to their flags.
#include "bouncecal/io/given_scene.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <utility>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/law_registry.hpp"

namespace bouncecal {
namespace {

// Shortest representation that reads back to the same double.
std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  const size_t e = s.find_last_not_of(" \t");
  return s.substr(b, e - b + 1);
}

// A "NAME=VALUE" law parameter: the name and the value, or false and the problem.
bool ParseLawSet(const std::string& set, std::string* name, double* value, std::string* why) {
  const std::string field = "SceneOverrides::law_sets " + Abbreviate(set);
  const size_t eq = set.find('=');
  if (eq == std::string::npos) {
    *why = field + ": expected NAME=VALUE";
    return false;
  }
  *name = Trim(set.substr(0, eq));
  const std::string text = Trim(set.substr(eq + 1));
  if (name->empty()) {
    *why = field + ": empty NAME";
    return false;
  }
  char* end = nullptr;
  errno = 0;
  *value = text.empty() ? 0.0 : std::strtod(text.c_str(), &end);
  const std::string what = field + ": value of " + Abbreviate(*name);
  if (text.empty() || end == nullptr || *end != '\0') {
    *why = what + " is not a number";
  } else if (errno == ERANGE && std::abs(*value) <= std::numeric_limits<double>::min()) {
    // strtod flags underflow for magnitudes below the smallest normal double.
    *why = what + " is too small: below " + FormatShortest(std::numeric_limits<double>::min()) +
           " (the smallest normal double) it cannot be computed with; give 0 or a larger value";
  } else if (errno == ERANGE) {
    *why = what + " is too large: above " + FormatShortest(std::numeric_limits<double>::max()) +
           " (the largest double)";
  } else if (!std::isfinite(*value)) {
    *why = what + " is not finite";
  } else {
    return true;
  }
  return false;
}

// " (set by SceneOverrides::impact_speed_m_s)" when a scene message names a key that an
// override set, so the user sees which input to change; empty otherwise.
std::string OverridesBehind(const SceneOverrides& o, const std::string& message) {
  const std::pair<bool, std::pair<const char*, const char*>> keys[] = {
      {o.height_m.has_value(), {"drop.height_m", "SceneOverrides::height_m"}},
      {o.impact_speed_m_s.has_value(),
       {"drop.impact_speed_m_s", "SceneOverrides::impact_speed_m_s"}},
      {o.g_m_s2.has_value(), {"environment.g_m_s2", "SceneOverrides::g_m_s2"}},
      {o.diameter_m.has_value(), {"ball.diameter_m", "SceneOverrides::diameter_m"}},
      {o.mass_kg.has_value(), {"ball.mass_kg", "SceneOverrides::mass_kg"}},
      {o.density_kg_m3.has_value(), {"ball.density_kg_m3", "SceneOverrides::density_kg_m3"}}};
  std::string out;
  for (const auto& [given, names] : keys) {
    if (given && message.find(names.first) != std::string::npos) {
      out += (out.empty() ? " (set by " : ", ") + std::string(names.second);
    }
  }
  return out.empty() ? out : out + ")";
}

// The ball and drop overrides applied to the scene (IsValid has checked them).
void ApplyBallAndDrop(const SceneOverrides& o, Scene* scene) {
  if (!o.material.empty()) {
    const MaterialPreset* preset = FindMaterial(o.material);
    scene->ball.material = o.material;
    scene->ball.youngs_modulus_pa.reset();
    scene->ball.poisson_ratio.reset();
    if (!o.mass_kg && !o.density_kg_m3) {
      scene->ball.density_kg_m3 = preset->density_kg_m3;
      scene->ball.mass_kg.reset();
    }
  }
  if (o.diameter_m) scene->ball.diameter_m = *o.diameter_m;
  if (o.density_kg_m3) {
    scene->ball.density_kg_m3 = *o.density_kg_m3;
    scene->ball.mass_kg.reset();
  }
  if (o.mass_kg) {
    scene->ball.mass_kg = *o.mass_kg;
    scene->ball.density_kg_m3.reset();
  }
  if (o.height_m) {
    scene->drop.height_m = *o.height_m;
    scene->drop.impact_speed_m_s.reset();
    scene->drop.height_sigma_m.reset();  // the file's sigma belonged to the file's height
  }
  if (o.impact_speed_m_s) {
    scene->drop.impact_speed_m_s = *o.impact_speed_m_s;
    scene->drop.height_m.reset();
    scene->drop.height_sigma_m.reset();
  }
  if (o.height_sigma_m) {
    if (!o.height_m && (o.scene_file.empty() || !scene->drop.height_m)) {
      throw Error(ErrorCode::kBadParameter,
                  "SceneOverrides::height_sigma_m " + FormatShortest(*o.height_sigma_m) +
                      ": the drop height it belongs to is not given (give "
                      "SceneOverrides::height_m, or a scene file with [drop] height_m)");
    }
    scene->drop.height_sigma_m = *o.height_sigma_m;
  }
}

// Law selection. Switching to another law drops the file's parameters for the old one.
void ApplyLaw(const SceneOverrides& o, Scene* scene) {
  std::string law = o.law;
  if (law.empty() && !o.expression.empty()) law = ExpressionLawName();
  if (!law.empty() && law != scene->law.name) {
    scene->law.name = law;
    scene->law.parameters.clear();
    scene->law.expression.clear();
  }
  if (!o.expression.empty()) {
    const LawInfo* row = FindLaw(scene->law.name);
    if (row == nullptr || !row->needs_expression) {
      throw Error(ErrorCode::kBadParameter,
                  "SceneOverrides::expression: only with SceneOverrides::law " +
                      ExpressionLawName() + " (got SceneOverrides::law " +
                      Abbreviate(scene->law.name) + ")");
    }
    scene->law.expression = o.expression;
  }
  for (const std::string& set : o.law_sets) {
    std::string name, why;
    double value = 0.0;
    ParseLawSet(set, &name, &value, &why);  // IsValid has checked it
    scene->law.parameters[name] = value;
  }
}

}  // namespace

bool SceneOverrides::IsValid(std::string* error) const {
  std::string why;
  auto positive = [&why](const std::optional<double>& v, const char* field, bool zero_ok) {
    if (!v || (std::isfinite(*v) && (zero_ok ? *v >= 0.0 : *v > 0.0))) return true;
    why = std::string("SceneOverrides::") + field + ": must be finite and " +
          (zero_ok ? ">= 0" : "> 0") + " (got " + FormatShortest(*v) + ")";
    return false;
  };
  if (mass_kg && density_kg_m3) {
    why = "SceneOverrides::mass_kg " + FormatShortest(*mass_kg) +
          " and SceneOverrides::density_kg_m3 " + FormatShortest(*density_kg_m3) +
          ": give one of them";
  } else if (height_m && impact_speed_m_s) {
    why = "SceneOverrides::height_m " + FormatShortest(*height_m) +
          " and SceneOverrides::impact_speed_m_s " + FormatShortest(*impact_speed_m_s) +
          ": give one of them";
  } else if (!material.empty() && FindMaterial(material) == nullptr) {
    std::string known;
    for (const MaterialPreset& p : MaterialPresets()) known += (known.empty() ? "" : ", ") + p.name;
    why = "SceneOverrides::material " + material + ": unknown material (known: " + known + ")";
  } else if (!positive(diameter_m, "diameter_m", false) ||
             !positive(density_kg_m3, "density_kg_m3", false) ||
             !positive(mass_kg, "mass_kg", false)) {
  } else if (height_sigma_m && impact_speed_m_s) {
    why = "SceneOverrides::height_sigma_m " + FormatShortest(*height_sigma_m) +
          " is the uncertainty of a drop height, but SceneOverrides::impact_speed_m_s " +
          FormatShortest(*impact_speed_m_s) + " replaces the height";
  } else if (!positive(height_m, "height_m", false) ||
             !positive(impact_speed_m_s, "impact_speed_m_s", false) ||
             !positive(height_sigma_m, "height_sigma_m", true)) {
  } else if (DragModel m; !drag.empty() && !ParseDragModel(drag, &m)) {
    why = "SceneOverrides::drag " + drag + ": expected none, linear or quadratic";
  } else if (!positive(g_m_s2, "g_m_s2", false)) {
  } else {
    for (const std::string& set : law_sets) {
      std::string name;
      double value = 0.0;
      if (!ParseLawSet(set, &name, &value, &why)) break;
    }
  }
  if (why.empty()) return true;
  if (error) *error = why;
  return false;
}

Scene ResolveScene(const SceneOverrides& o) {
  Scene scene;
  if (!o.scene_text.empty()) {
    scene = ParseScene(o.scene_text, o.scene_file);
  } else if (!o.scene_file.empty()) {
    scene = LoadSceneFile(o.scene_file);
  }
  std::string error;
  if (!o.IsValid(&error)) throw Error(ErrorCode::kBadParameter, error);
  ApplyBallAndDrop(o, &scene);
  if (!o.drag.empty()) ParseDragModel(o.drag, &scene.effects.drag);
  if (o.buoyancy) scene.effects.buoyancy = true;
  if (o.contact_duration) scene.effects.contact_duration = true;
  if (o.g_m_s2) scene.environment.g_m_s2 = *o.g_m_s2;
  ApplyLaw(o, &scene);
  if (!scene.IsValid(&error)) {
    throw Error(ErrorCode::kBadScene,
                (o.scene_file.empty() ? std::string("scene from overrides: ") : "") + error +
                    OverridesBehind(o, error) +
                    (o.scene_file.empty() ? "" : " (after the overrides)"));
  }
  return scene;
}

GivenScene ResolveGivenScene(const SceneOverrides& o) {
  GivenScene gs;
  gs.scene = ResolveScene(o);
  if (!o.scene_file.empty()) {
    const std::vector<std::string> keys = o.scene_text.empty()
                                              ? SceneFileKeys(o.scene_file)
                                              : SceneTextKeys(o.scene_text, o.scene_file);
    for (const std::string& k : keys) gs.given.insert(k);
  }
  auto mark = [&](bool on, const char* key) {
    if (on) gs.given.insert(key);
  };
  mark(o.height_m.has_value(), "drop.height_m");
  mark(o.height_sigma_m.has_value(), "drop.height_sigma_m");
  mark(o.impact_speed_m_s.has_value(), "drop.impact_speed_m_s");
  mark(o.diameter_m.has_value(), "ball.diameter_m");
  mark(o.density_kg_m3.has_value(), "ball.density_kg_m3");
  mark(o.mass_kg.has_value(), "ball.mass_kg");
  mark(!o.material.empty(), "ball.material");
  mark(!o.drag.empty(), "effects.drag");
  mark(o.buoyancy, "effects.buoyancy");
  mark(o.contact_duration, "effects.contact_duration");
  mark(o.g_m_s2.has_value(), "environment.g_m_s2");
  mark(!o.law.empty() || !o.expression.empty(), "law.name");
  mark(!o.expression.empty(), "law.expression");
  for (const std::string& set : o.law_sets) {
    gs.given.insert("law.parameters." + Trim(set.substr(0, set.find('='))));
  }
  const Drop& d = gs.scene.drop;
  gs.drop_given = (d.height_m && (gs.Given("drop.height_m"))) ||
                  (d.impact_speed_m_s && gs.Given("drop.impact_speed_m_s"));
  gs.ball_given =
      gs.Given("ball.diameter_m") &&
      (gs.Given("ball.mass_kg") || gs.Given("ball.density_kg_m3") || gs.Given("ball.material"));
  return gs;
}

std::vector<Assumed> AssumedValues(const GivenScene& gs, bool for_calibration) {
  std::vector<Assumed> out;
  const Scene& s = gs.scene;
  auto add = [&](const std::string& key, const std::string& value, const std::string& note) {
    if (!gs.Given(key)) out.push_back({key, value, note});
  };
  add("environment.g_m_s2", FormatShortest(s.environment.g_m_s2),
      "gravity; the seed paper's value");
  add("effects.drag", DragModelName(s.effects.drag), "air drag in the flights");
  add("effects.buoyancy", s.effects.buoyancy ? "true" : "false", "buoyancy in the flights");
  add("effects.contact_duration", s.effects.contact_duration ? "true" : "false",
      "contact time taken out of the intervals");
  const bool drag = s.effects.drag != DragModel::kNone;
  if (drag || s.effects.buoyancy) {
    add("environment.air_density_kg_m3", FormatShortest(s.environment.air_density_kg_m3),
        "air (drag, buoyancy)");
  }
  if (drag)
    add("environment.drag_coefficient", FormatShortest(s.environment.drag_coefficient),
        "smooth sphere");
  if (gs.drop_given && s.drop.height_m && !s.drop.height_sigma_m) {
    out.push_back({"drop.height_sigma_m", "0", "the drop height is taken as exact"});
  }
  const bool needs_ball =
      for_calibration || drag || s.effects.buoyancy || s.effects.contact_duration;
  if (needs_ball && !gs.ball_given) {
    add("ball.diameter_m", FormatShortest(s.ball.diameter_m), "the ball (seed 002's steel ball)");
    add("ball.density_kg_m3", FormatShortest(s.ball.Density()), "the ball's density");
  }
  if (s.effects.contact_duration || for_calibration) {
    add("ball.material", s.ball.material, "elastic constants (Hertz stiffness, contact time)");
    add("surface.material", s.surface.material,
        "elastic constants (Hertz stiffness, contact time)");
  }
  if (for_calibration) {
    add("law.name", s.law.name, "the contact law fitted");
  }
  return out;
}

nlohmann::json AssumedJson(const std::vector<Assumed>& assumed) {
  nlohmann::json out = nlohmann::json::array();
  for (const Assumed& a : assumed)
    out.push_back({{"key", a.key}, {"value", a.value}, {"note", a.note}});
  return out;
}

std::string AssumedText(const std::vector<Assumed>& assumed) {
  std::string out;
  for (const Assumed& a : assumed) {
    out += "assumed (not given): " + a.key + " = " + a.value + " (" + a.note + ")\n";
  }
  return out;
}

}  // namespace bouncecal
