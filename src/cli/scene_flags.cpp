// The scene flags shared by analyze, simulate, synth and calibrate (scene_flags.hpp).
//
// Order of precedence: defaults < --scene FILE < flags. A flag that changes which quantity is
// authoritative resets the other one (--mass clears the density, --impact-speed clears the
// height, --material re-derives density/E/nu from the preset unless --density/--mass is given).
// Bad flag values: Error(kBadParameter) naming the flag and the value. A scene that is invalid
// after the overrides: Error(kBadScene).
#include "scene_flags.hpp"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <utility>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/law_registry.hpp"

namespace bouncecal::cli {
namespace {

// Shortest representation that reads back to the same double.
std::string Num(double v) {
  char buf[64];
  for (int prec = 1; prec <= 17; ++prec) {
    std::snprintf(buf, sizeof buf, "%.*g", prec, v);
    if (std::strtod(buf, nullptr) == v) break;
  }
  return buf;
}

double CheckNonNegative(const std::string& flag, double v) {
  if (!(std::isfinite(v) && v >= 0.0)) {
    throw Error(ErrorCode::kBadParameter, flag + ": must be finite and >= 0 (got " + Num(v) + ")");
  }
  return v;
}

double CheckPositive(const std::string& flag, double v) {
  if (!(std::isfinite(v) && v > 0.0)) {
    throw Error(ErrorCode::kBadParameter, flag + ": must be finite and > 0 (got " + Num(v) + ")");
  }
  return v;
}

std::string Trim(const std::string& s) {
  const size_t b = s.find_first_not_of(" \t");
  if (b == std::string::npos) return "";
  const size_t e = s.find_last_not_of(" \t");
  return s.substr(b, e - b + 1);
}

}  // namespace

void AddSceneFlags(CLI::App* sub, SceneFlags* flags, bool with_law) {
  sub->add_option("--scene", flags->scene_file, "scene file (TOML); flags override it");
  sub->add_option("--height", flags->height_m, "drop height of the ball's bottom, m");
  sub->add_option("--height-sigma", flags->height_sigma_m,
                  "1-sigma uncertainty of the drop height, m (default: the height is exact)");
  sub->add_option("--impact-speed", flags->impact_speed_m_s,
                  "first impact speed instead of a height, m/s");
  sub->add_option("--diameter", flags->diameter_m, "ball diameter, m");
  sub->add_option("--density", flags->density_kg_m3, "ball density, kg/m^3 (or --mass)");
  sub->add_option("--mass", flags->mass_kg, "ball mass, kg (or --density)");
  sub->add_option("--material", flags->material,
                  "ball material preset (steel, copper, glass, rubber, wood, pingpong, ...)");
  sub->add_option("--drag", flags->drag, "air drag: none, linear or quadratic");
  sub->add_flag("--buoyancy", flags->buoyancy, "correct gravity for air buoyancy");
  sub->add_flag(
      "--contact-duration", flags->contact_duration,
      "contact duration effect: intervals between onsets include each impact's contact time");
  sub->add_option("--g", flags->g_m_s2, "gravitational acceleration, m/s^2");
  if (with_law) {
    sub->add_option("--law", flags->law, "contact law (see `bouncecal laws`)");
    sub->add_option("--set", flags->law_sets,
                    "law parameter NAME=VALUE (repeatable: --set a=1 --set b=2)")
        ->allow_extra_args(false);
    sub->add_option("--expression", flags->expression,
                    "force expression for the \"expression\" law");
  }
}

namespace {

// " (set by --impact-speed)" when a scene message names a key that a flag set, so the user
// sees which input to change; empty otherwise.
std::string FlagsBehind(const SceneFlags& flags, const std::string& message) {
  const std::pair<bool, std::pair<const char*, const char*>> keys[] = {
      {flags.height_m.has_value(), {"drop.height_m", "--height"}},
      {flags.impact_speed_m_s.has_value(), {"drop.impact_speed_m_s", "--impact-speed"}},
      {flags.g_m_s2.has_value(), {"environment.g_m_s2", "--g"}},
      {flags.diameter_m.has_value(), {"ball.diameter_m", "--diameter"}},
      {flags.mass_kg.has_value(), {"ball.mass_kg", "--mass"}},
      {flags.density_kg_m3.has_value(), {"ball.density_kg_m3", "--density"}}};
  std::string out;
  for (const auto& [given, names] : keys) {
    if (given && message.find(names.first) != std::string::npos) {
      out += (out.empty() ? " (set by " : ", ") + std::string(names.second);
    }
  }
  return out.empty() ? out : out + ")";
}

}  // namespace

Scene ResolveScene(const SceneFlags& flags) {
  Scene scene;
  if (!flags.scene_text.empty()) {
    scene = ParseScene(flags.scene_text, flags.scene_file);
  } else if (!flags.scene_file.empty()) {
    scene = LoadSceneFile(flags.scene_file);
  }

  if (flags.mass_kg && flags.density_kg_m3) {
    throw Error(ErrorCode::kBadParameter, "--mass " + Num(*flags.mass_kg) + " and --density " +
                                              Num(*flags.density_kg_m3) + ": give one of them");
  }
  if (flags.height_m && flags.impact_speed_m_s) {
    throw Error(ErrorCode::kBadParameter, "--height " + Num(*flags.height_m) +
                                              " and --impact-speed " +
                                              Num(*flags.impact_speed_m_s) + ": give one of them");
  }
  if (!flags.material.empty()) {
    const MaterialPreset* preset = FindMaterial(flags.material);
    if (preset == nullptr) {
      std::string known;
      for (const MaterialPreset& p : MaterialPresets())
        known += (known.empty() ? "" : ", ") + p.name;
      throw Error(ErrorCode::kBadParameter,
                  "--material " + flags.material + ": unknown material (known: " + known + ")");
    }
    scene.ball.material = flags.material;
    scene.ball.youngs_modulus_pa.reset();
    scene.ball.poisson_ratio.reset();
    if (!flags.mass_kg && !flags.density_kg_m3) {
      scene.ball.density_kg_m3 = preset->density_kg_m3;
      scene.ball.mass_kg.reset();
    }
  }
  if (flags.diameter_m) scene.ball.diameter_m = CheckPositive("--diameter", *flags.diameter_m);
  if (flags.density_kg_m3) {
    scene.ball.density_kg_m3 = CheckPositive("--density", *flags.density_kg_m3);
    scene.ball.mass_kg.reset();
  }
  if (flags.mass_kg) {
    scene.ball.mass_kg = CheckPositive("--mass", *flags.mass_kg);
    scene.ball.density_kg_m3.reset();
  }
  if (flags.height_sigma_m && flags.impact_speed_m_s) {
    throw Error(ErrorCode::kBadParameter, "--height-sigma " + Num(*flags.height_sigma_m) +
                                              " is the uncertainty of a drop height, but "
                                              "--impact-speed " +
                                              Num(*flags.impact_speed_m_s) +
                                              " replaces the height");
  }
  if (flags.height_m) {
    scene.drop.height_m = CheckPositive("--height", *flags.height_m);
    scene.drop.impact_speed_m_s.reset();
    scene.drop.height_sigma_m.reset();  // the file's sigma belonged to the file's height
  }
  if (flags.impact_speed_m_s) {
    scene.drop.impact_speed_m_s = CheckPositive("--impact-speed", *flags.impact_speed_m_s);
    scene.drop.height_m.reset();
    scene.drop.height_sigma_m.reset();
  }
  if (flags.height_sigma_m) {
    CheckNonNegative("--height-sigma", *flags.height_sigma_m);
    if (!flags.height_m && (flags.scene_file.empty() || !scene.drop.height_m)) {
      throw Error(ErrorCode::kBadParameter,
                  "--height-sigma " + Num(*flags.height_sigma_m) +
                      ": the drop height it belongs to is not given (give --height, or a scene "
                      "file with [drop] height_m)");
    }
    scene.drop.height_sigma_m = *flags.height_sigma_m;
  }
  if (!flags.drag.empty() && !ParseDragModel(flags.drag, &scene.effects.drag)) {
    throw Error(ErrorCode::kBadParameter,
                "--drag " + flags.drag + ": expected none, linear or quadratic");
  }
  if (flags.buoyancy) scene.effects.buoyancy = true;
  if (flags.contact_duration) scene.effects.contact_duration = true;
  if (flags.g_m_s2) scene.environment.g_m_s2 = CheckPositive("--g", *flags.g_m_s2);

  // Law selection. Switching to another law drops the file's parameters for the old one.
  std::string law = flags.law;
  if (law.empty() && !flags.expression.empty()) law = ExpressionLawName();
  if (!law.empty() && law != scene.law.name) {
    scene.law.name = law;
    scene.law.parameters.clear();
    scene.law.expression.clear();
  }
  if (!flags.expression.empty()) {
    const LawInfo* row = FindLaw(scene.law.name);
    if (row == nullptr || !row->needs_expression) {
      throw Error(ErrorCode::kBadParameter, "--expression: only with --law " + ExpressionLawName() +
                                                " (got --law " + Abbreviate(scene.law.name) + ")");
    }
    scene.law.expression = flags.expression;
  }
  for (const std::string& set : flags.law_sets) {
    const size_t eq = set.find('=');
    if (eq == std::string::npos) {
      throw Error(ErrorCode::kBadParameter, "--set " + Abbreviate(set) + ": expected NAME=VALUE");
    }
    const std::string name = Trim(set.substr(0, eq));
    const std::string text = Trim(set.substr(eq + 1));
    if (name.empty())
      throw Error(ErrorCode::kBadParameter, "--set " + Abbreviate(set) + ": empty NAME");
    char* end = nullptr;
    errno = 0;
    const double value = text.empty() ? 0.0 : std::strtod(text.c_str(), &end);
    const std::string what = "--set " + Abbreviate(set) + ": value of " + Abbreviate(name);
    if (text.empty() || end == nullptr || *end != '\0') {
      throw Error(ErrorCode::kBadParameter, what + " is not a number");
    }
    if (errno == ERANGE && std::abs(value) <= std::numeric_limits<double>::min()) {
      // strtod flags underflow for magnitudes below the smallest normal double.
      throw Error(ErrorCode::kBadParameter,
                  what + " is too small: below " + Num(std::numeric_limits<double>::min()) +
                      " (the smallest normal double) it cannot be computed with; give 0 or a "
                      "larger value");
    }
    if (errno == ERANGE) {
      throw Error(ErrorCode::kBadParameter, what + " is too large: above " +
                                                Num(std::numeric_limits<double>::max()) +
                                                " (the largest double)");
    }
    if (!std::isfinite(value)) throw Error(ErrorCode::kBadParameter, what + " is not finite");
    scene.law.parameters[name] = value;
  }

  std::string error;
  if (!scene.IsValid(&error)) {
    throw Error(ErrorCode::kBadScene,
                (flags.scene_file.empty() ? std::string("scene from flags: ") : "") + error +
                    FlagsBehind(flags, error) +
                    (flags.scene_file.empty() ? "" : " (after command-line overrides)"));
  }
  return scene;
}

}  // namespace bouncecal::cli

namespace bouncecal::cli {

GivenScene ResolveGivenScene(const SceneFlags& flags) {
  GivenScene gs;
  gs.scene = ResolveScene(flags);
  if (!flags.scene_file.empty()) {
    const std::vector<std::string> keys = flags.scene_text.empty()
                                              ? SceneFileKeys(flags.scene_file)
                                              : SceneTextKeys(flags.scene_text, flags.scene_file);
    for (const std::string& k : keys) gs.given.insert(k);
  }
  auto mark = [&](bool on, const char* key) {
    if (on) gs.given.insert(key);
  };
  mark(flags.height_m.has_value(), "drop.height_m");
  mark(flags.height_sigma_m.has_value(), "drop.height_sigma_m");
  mark(flags.impact_speed_m_s.has_value(), "drop.impact_speed_m_s");
  mark(flags.diameter_m.has_value(), "ball.diameter_m");
  mark(flags.density_kg_m3.has_value(), "ball.density_kg_m3");
  mark(flags.mass_kg.has_value(), "ball.mass_kg");
  mark(!flags.material.empty(), "ball.material");
  mark(!flags.drag.empty(), "effects.drag");
  mark(flags.buoyancy, "effects.buoyancy");
  mark(flags.contact_duration, "effects.contact_duration");
  mark(flags.g_m_s2.has_value(), "environment.g_m_s2");
  mark(!flags.law.empty() || !flags.expression.empty(), "law.name");
  mark(!flags.expression.empty(), "law.expression");
  for (const std::string& set : flags.law_sets) {
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
  add("environment.g_m_s2", Num(s.environment.g_m_s2), "gravity; the seed paper's value");
  add("effects.drag", DragModelName(s.effects.drag), "air drag in the flights");
  add("effects.buoyancy", s.effects.buoyancy ? "true" : "false", "buoyancy in the flights");
  add("effects.contact_duration", s.effects.contact_duration ? "true" : "false",
      "contact time taken out of the intervals");
  const bool drag = s.effects.drag != DragModel::kNone;
  if (drag || s.effects.buoyancy) {
    add("environment.air_density_kg_m3", Num(s.environment.air_density_kg_m3),
        "air (drag, buoyancy)");
  }
  if (drag)
    add("environment.drag_coefficient", Num(s.environment.drag_coefficient), "smooth sphere");
  if (gs.drop_given && s.drop.height_m && !s.drop.height_sigma_m) {
    out.push_back({"drop.height_sigma_m", "0", "the drop height is taken as exact"});
  }
  const bool needs_ball =
      for_calibration || drag || s.effects.buoyancy || s.effects.contact_duration;
  if (needs_ball && !gs.ball_given) {
    add("ball.diameter_m", Num(s.ball.diameter_m), "the ball (seed 002's steel ball)");
    add("ball.density_kg_m3", Num(s.ball.Density()), "the ball's density");
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

}  // namespace bouncecal::cli
