// The TOML scene-file format: reading (with every problem named by file, line and key) and
// writing. Defaults, presets and validation are scene.cpp's.
//
// ---- Scene file format (TOML). Every key is optional; a missing key keeps its default. ----
//
//   # Defaults are the seed experiment (seed 002): 1 cm steel ball, 0.2 m, copper dish, g = 9.8.
//   [ball]
//   diameter_m = 0.01          # > 0
//   density_kg_m3 = 7800.0     # > 0; or mass_kg (> 0) -- giving both is an error
//   # mass_kg = 0.00408
//   material = "steel"         # preset: sets density (unless density/mass given), E and nu
//   youngs_modulus_pa = 2.0e11 # > 0, overrides the preset (used by Hertz laws, contact time;
//                              # they need E and nu of ball AND surface: EffectiveModulusPa)
//   poisson_ratio = 0.29       # in (-1, 0.5]
//
//   [surface]
//   kind = "rigid"             # "rigid" | "spring-mass" (needed by effects.surface_compliance)
//   material = "copper"        # preset for E and nu
//   youngs_modulus_pa = 1.2e11
//   poisson_ratio = 0.34
//   mass_kg = 0.5              # spring-mass only: plate mass (> 0)
//   stiffness_n_m = 1.0e6      # spring-mass only: support stiffness (> 0)
//   damping_n_s_m = 5.0        # spring-mass only: support damping (>= 0)
//
//   [environment]
//   g_m_s2 = 9.8               # > 0
//   air_density_kg_m3 = 1.2    # >= 0 (buoyancy, quadratic drag)
//   air_viscosity_pa_s = 1.81e-5   # >= 0 (linear/Stokes drag)
//   drag_coefficient = 0.47    # >= 0 (quadratic drag)
//
//   [drop]
//   height_m = 0.2             # > 0, release height of the ball's bottom; or
//   # impact_speed_m_s = 1.98  # > 0, first impact speed -- giving both is an error
//   height_sigma_m = 0.01      # >= 0, 1-sigma of height_m (only with height_m); unset = exact
//   first_impact_time_s = 0.0  # time of the first impact (simulation/synthesis)
//
//   [effects]                  # every effect is off unless turned on
//   drag = "none"              # "none" | "linear" | "quadratic"
//   buoyancy = false
//   contact_duration = false   # onsets include the previous impact's contact time
//   surface_compliance = false # plate as a mass on a spring (surface.kind = "spring-mass")
//
//   [law]
//   name = "walton-braun"      # registry name (bouncecal laws)
//   expression = ""            # force expression, only for a law whose registry row needs one
//                              # ("expression"); an expression without a name selects that law
//   [law.parameters]           # NAME = number; missing ones take the law's defaults
//   k = 1.0e7
//   gamma = 0.5
//
//   [limits]
//   horizon_s = 60.0           # > 0
//   max_impacts = 10000        # integer in [1, 1000000] (kMaxImpactsLimit)
//   rest_speed_m_s = 1e-4      # >= 0
//
// Material presets (density kg/m^3, E Pa, nu): see MaterialPresets() below and `bouncecal laws`.
// Unknown tables or keys, wrong types, non-finite or out-of-range values and conflicting values
// are errors: Error(kBadScene) "FILE:LINE: key: problem (got VALUE)". Integers are accepted
// where a number is expected.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include <toml++/toml.h>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/scene.hpp"
#include "scene_problem.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

// ---------------------------------------------------------------------------------------------
// TOML reading.

namespace {

std::string Describe(const toml::node& node) {
  if (auto s = node.value_exact<std::string>()) return "\"" + *s + "\"";
  if (auto i = node.value_exact<int64_t>()) return std::to_string(*i);
  if (auto d = node.value_exact<double>()) return FormatShortest(*d);
  if (auto b = node.value_exact<bool>()) return *b ? "true" : "false";
  if (node.is_table()) return "a table";
  if (node.is_array()) return "an array";
  return "a date/time";
}

class SceneReader {
 public:
  explicit SceneReader(std::string source) : source_(std::move(source)) {}

  [[noreturn]] void Fail(const toml::source_region& where, const std::string& key,
                         const std::string& problem) const {
    std::string loc = source_.empty() ? "<scene>" : source_;
    loc += ":" + std::to_string(where.begin.line);
    throw Error(ErrorCode::kBadScene, loc + ": " + key + ": " + problem);
  }
  [[noreturn]] void Fail(const toml::node& node, const std::string& key,
                         const std::string& problem) const {
    Fail(node.source(), key, problem + " (got " + Describe(node) + ")");
  }

  double Number(const toml::node& node, const std::string& key) const {
    double v = 0.0;
    if (auto d = node.value_exact<double>()) {
      v = *d;
    } else if (auto i = node.value_exact<int64_t>()) {
      v = static_cast<double>(*i);
    } else {
      Fail(node, key, "expected a number");
    }
    if (!std::isfinite(v)) Fail(node, key, "must be finite");
    return v;
  }
  double Positive(const toml::node& node, const std::string& key) const {
    const double v = Number(node, key);
    if (!(v > 0.0)) Fail(node, key, "must be > 0");
    return v;
  }
  double NonNegative(const toml::node& node, const std::string& key) const {
    const double v = Number(node, key);
    if (!(v >= 0.0)) Fail(node, key, "must be >= 0");
    return v;
  }
  double Poisson(const toml::node& node, const std::string& key) const {
    const double v = Number(node, key);
    if (!(v > -1.0 && v <= 0.5)) Fail(node, key, "must be in (-1, 0.5]");
    return v;
  }
  bool Bool(const toml::node& node, const std::string& key) const {
    auto b = node.value_exact<bool>();
    if (!b) Fail(node, key, "expected true or false");
    return *b;
  }
  std::string String(const toml::node& node, const std::string& key) const {
    auto s = node.value_exact<std::string>();
    if (!s) Fail(node, key, "expected a string");
    return *s;
  }
  const toml::table& Table(const toml::node& node, const std::string& key) const {
    if (!node.is_table()) Fail(node, key, "expected a table [" + key + "]");
    return *node.as_table();
  }

  Scene Read(const toml::table& root) const {
    Scene s;
    s.source = source_;
    for (auto&& [k, node] : root) {
      const std::string name(k.str());
      if (name == "ball") {
        ReadBall(Table(node, name), &s);
      } else if (name == "surface") {
        ReadSurface(Table(node, name), &s);
      } else if (name == "environment") {
        ReadEnvironment(Table(node, name), &s);
      } else if (name == "drop") {
        ReadDrop(Table(node, name), &s);
      } else if (name == "effects") {
        ReadEffects(Table(node, name), &s);
      } else if (name == "law") {
        ReadLaw(Table(node, name), &s);
      } else if (name == "limits") {
        ReadLimits(Table(node, name), &s);
      } else {
        Fail(k.source(), name,
             "unknown table or key (expected ball, surface, environment, drop, effects, law, "
             "limits)");
      }
    }
    // Cross-key rules (e.g. surface_compliance needs a spring-mass surface): reported at the
    // line of the offending key, or of its table, or line 1.
    const SceneProblem c = FirstSceneProblem(s, source_);
    if (!c.error.empty()) {
      toml::source_region where;
      where.begin.line = 1;
      std::string path = c.key;
      while (!path.empty()) {
        toml::node_view<const toml::node> n = root.at_path(path);
        if (n) {
          where = n.node()->source();
          break;
        }
        const size_t dot = path.rfind('.');
        path = dot == std::string::npos ? "" : path.substr(0, dot);
      }
      Fail(where, c.key, c.problem);
    }
    return s;
  }

 private:
  [[noreturn]] void Unknown(const toml::key& k, const std::string& table,
                            const std::string& expected) const {
    Fail(k.source(), table + "." + std::string(k.str()),
         "unknown key (expected one of: " + expected + ")");
  }

  void ReadBall(const toml::table& t, Scene* s) const {
    const toml::node* mass = t.get("mass_kg");
    const toml::node* density = t.get("density_kg_m3");
    if (mass && density) {
      Fail(*mass, "ball.mass_kg", "conflicts with ball.density_kg_m3 (give one of them)");
    }
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "ball." + key;
      if (key == "diameter_m") {
        s->ball.diameter_m = Positive(node, full);
      } else if (key == "mass_kg") {
        s->ball.mass_kg = Positive(node, full);
      } else if (key == "density_kg_m3") {
        s->ball.density_kg_m3 = Positive(node, full);
      } else if (key == "material") {
        s->ball.material = String(node, full);
      } else if (key == "youngs_modulus_pa") {
        s->ball.youngs_modulus_pa = Positive(node, full);
      } else if (key == "poisson_ratio") {
        s->ball.poisson_ratio = Poisson(node, full);
      } else {
        Unknown(k, "ball",
                "diameter_m, density_kg_m3, mass_kg, material, youngs_modulus_pa, poisson_ratio");
      }
    }
    // Presets: the material sets the density unless mass or density is given.
    if (const toml::node* mat = t.get("material")) {
      const MaterialPreset* p = FindMaterial(s->ball.material);
      const bool explicit_all =
          (mass || density) && t.contains("youngs_modulus_pa") && t.contains("poisson_ratio");
      if (p == nullptr && !explicit_all) {
        Fail(*mat, "ball.material", "unknown material (known: " + KnownMaterials() + ")");
      }
      if (p != nullptr && !mass && !density) s->ball.density_kg_m3 = p->density_kg_m3;
    }
    if (mass) s->ball.density_kg_m3.reset();
    if (density) s->ball.mass_kg.reset();
  }

  void ReadSurface(const toml::table& t, Scene* s) const {
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "surface." + key;
      if (key == "kind") {
        const std::string kind = String(node, full);
        if (kind == "rigid") {
          s->surface.kind = Surface::Kind::kRigid;
        } else if (kind == "spring-mass") {
          s->surface.kind = Surface::Kind::kSpringMass;
        } else {
          Fail(node, full, "expected \"rigid\" or \"spring-mass\"");
        }
      } else if (key == "material") {
        s->surface.material = String(node, full);
        const bool explicit_all = t.contains("youngs_modulus_pa") && t.contains("poisson_ratio");
        if (FindMaterial(s->surface.material) == nullptr && !explicit_all) {
          Fail(node, full, "unknown material (known: " + KnownMaterials() + ")");
        }
      } else if (key == "youngs_modulus_pa") {
        s->surface.youngs_modulus_pa = Positive(node, full);
      } else if (key == "poisson_ratio") {
        s->surface.poisson_ratio = Poisson(node, full);
      } else if (key == "mass_kg") {
        s->surface.mass_kg = Positive(node, full);
      } else if (key == "stiffness_n_m") {
        s->surface.stiffness_n_m = Positive(node, full);
      } else if (key == "damping_n_s_m") {
        s->surface.damping_n_s_m = NonNegative(node, full);
      } else {
        Unknown(k, "surface",
                "kind, material, youngs_modulus_pa, poisson_ratio, mass_kg, stiffness_n_m, "
                "damping_n_s_m");
      }
    }
    if (s->surface.kind == Surface::Kind::kSpringMass) {
      if (!t.contains("mass_kg") || !t.contains("stiffness_n_m")) {
        Fail(t.source(), "surface.kind",
             "\"spring-mass\" needs surface.mass_kg and surface.stiffness_n_m");
      }
    }
  }

  void ReadEnvironment(const toml::table& t, Scene* s) const {
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "environment." + key;
      if (key == "g_m_s2") {
        s->environment.g_m_s2 = Positive(node, full);
      } else if (key == "air_density_kg_m3") {
        s->environment.air_density_kg_m3 = NonNegative(node, full);
      } else if (key == "air_viscosity_pa_s") {
        s->environment.air_viscosity_pa_s = NonNegative(node, full);
      } else if (key == "drag_coefficient") {
        s->environment.drag_coefficient = NonNegative(node, full);
      } else {
        Unknown(k, "environment",
                "g_m_s2, air_density_kg_m3, air_viscosity_pa_s, drag_coefficient");
      }
    }
  }

  void ReadDrop(const toml::table& t, Scene* s) const {
    const toml::node* height = t.get("height_m");
    const toml::node* speed = t.get("impact_speed_m_s");
    if (height && speed) {
      Fail(*speed, "drop.impact_speed_m_s", "conflicts with drop.height_m (give one of them)");
    }
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "drop." + key;
      if (key == "height_m") {
        s->drop.height_m = Positive(node, full);
      } else if (key == "impact_speed_m_s") {
        s->drop.impact_speed_m_s = Positive(node, full);
      } else if (key == "first_impact_time_s") {
        s->drop.first_impact_time_s = Number(node, full);
      } else if (key == "height_sigma_m") {
        s->drop.height_sigma_m = NonNegative(node, full);
      } else {
        Unknown(k, "drop", "height_m, height_sigma_m, impact_speed_m_s, first_impact_time_s");
      }
    }
    if (speed) s->drop.height_m.reset();
    if (height) s->drop.impact_speed_m_s.reset();
  }

  void ReadEffects(const toml::table& t, Scene* s) const {
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "effects." + key;
      if (key == "drag") {
        const std::string d = String(node, full);
        if (!ParseDragModel(d, &s->effects.drag)) {
          Fail(node, full, "expected \"none\", \"linear\" or \"quadratic\"");
        }
      } else if (key == "buoyancy") {
        s->effects.buoyancy = Bool(node, full);
      } else if (key == "contact_duration") {
        s->effects.contact_duration = Bool(node, full);
      } else if (key == "surface_compliance") {
        s->effects.surface_compliance = Bool(node, full);
        if (s->effects.surface_compliance && s->surface.kind != Surface::Kind::kSpringMass) {
          // Only decidable once [surface] is read; toml++ iterates tables in key order, so
          // "effects" comes before "surface": checked again by IsValid at the end.
        }
      } else {
        Unknown(k, "effects", "drag, buoyancy, contact_duration, surface_compliance");
      }
    }
  }

  void ReadLaw(const toml::table& t, Scene* s) const {
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "law." + key;
      if (key == "name") {
        s->law.name = String(node, full);
        if (s->law.name.empty()) Fail(node, full, "must not be empty");
      } else if (key == "expression") {
        s->law.expression = String(node, full);
      } else if (key == "parameters") {
        for (auto&& [pk, pnode] : Table(node, full)) {
          const std::string pname(pk.str());
          s->law.parameters[pname] = Number(pnode, full + "." + pname);
        }
      } else {
        Unknown(k, "law", "name, expression, parameters");
      }
    }
    const toml::node* expr = t.get("expression");
    if (expr && !s->law.expression.empty() && !NeedsExpression(s->law.name)) {
      if (!t.contains("name")) {
        s->law.name = ExpressionLawName();
      } else {
        Fail(*expr, "law.expression",
             "only allowed with law.name = \"" + ExpressionLawName() + "\"");
      }
    }
    if (NeedsExpression(s->law.name) && s->law.expression.empty()) {
      Fail(t.source(), "law.expression",
           "missing: law \"" + Abbreviate(s->law.name) + "\" needs a force expression");
    }
  }

  void ReadLimits(const toml::table& t, Scene* s) const {
    for (auto&& [k, node] : t) {
      const std::string key(k.str());
      const std::string full = "limits." + key;
      if (key == "horizon_s") {
        s->limits.horizon_s = Positive(node, full);
      } else if (key == "max_impacts") {
        auto i = node.value_exact<int64_t>();
        if (!i) Fail(node, full, "expected an integer");
        if (*i < 1 || *i > kMaxImpactsLimit) {
          Fail(node, full,
               "must be in [1, " + std::to_string(kMaxImpactsLimit) +
                   "] (the limit keeps the output under ~300 MB of JSON)");
        }
        s->limits.max_impacts = static_cast<int>(*i);
      } else if (key == "rest_speed_m_s") {
        s->limits.rest_speed_m_s = NonNegative(node, full);
      } else {
        Unknown(k, "limits", "horizon_s, max_impacts, rest_speed_m_s");
      }
    }
  }

  std::string source_;
};

}  // namespace

Scene ParseScene(const std::string& toml_text, const std::string& source) {
  toml::table root;
  try {
    root = toml::parse(toml_text, source);
  } catch (const toml::parse_error& e) {
    std::string loc = source.empty() ? "<scene>" : source;
    loc += ":" + std::to_string(e.source().begin.line);
    throw Error(ErrorCode::kBadScene, loc + ": TOML syntax error: " + std::string(e.description()));
  }
  Scene s = SceneReader(source).Read(root);
  return s;
}

namespace {

std::string ReadSceneText(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) {
    throw Error(ErrorCode::kInputMissing, path + ": scene file does not exist");
  }
  if (std::filesystem::is_directory(status)) {
    throw Error(ErrorCode::kInputMissing, path + ": is a directory, expected a scene file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot open scene file");
  std::ostringstream text;
  text << in.rdbuf();
  if (in.bad()) throw Error(ErrorCode::kInputMissing, path + ": cannot read scene file");
  return text.str();
}

void CollectKeys(const toml::table& table, const std::string& prefix,
                 std::vector<std::string>* keys) {
  for (auto&& [k, node] : table) {
    const std::string key = prefix + std::string(k.str());
    if (node.is_table()) {
      CollectKeys(*node.as_table(), key + ".", keys);
    } else {
      keys->push_back(key);
    }
  }
}

}  // namespace

Scene LoadSceneFile(const std::string& path) { return ParseScene(ReadSceneText(path), path); }

std::vector<std::string> SceneFileKeys(const std::string& path) {
  return SceneTextKeys(ReadSceneText(path), path);
}

std::vector<std::string> SceneTextKeys(const std::string& toml_text, const std::string& source) {
  ParseScene(toml_text, source);  // the same checks (and errors) as LoadSceneFile
  std::vector<std::string> keys;
  CollectKeys(toml::parse(toml_text, source), "", &keys);
  return keys;
}

// ---------------------------------------------------------------------------------------------
// TOML writing. Numbers in shortest round-trip form, always as TOML floats (except integers).

namespace {

std::string TomlFloat(double v) {
  std::string s = FormatShortest(v);
  if (s.find_first_of(".eEn") == std::string::npos) s += ".0";  // "2" would read as an integer
  return s;
}

std::string TomlString(const std::string& v) {
  std::string out = "\"";
  for (char ch : v) {
    switch (ch) {
      case '"':
        out += "\\\"";
        break;
      case '\\':
        out += "\\\\";
        break;
      case '\n':
        out += "\\n";
        break;
      case '\t':
        out += "\\t";
        break;
      case '\r':
        out += "\\r";
        break;
      default:
        if (static_cast<unsigned char>(ch) < 0x20) {
          char buf[8];
          std::snprintf(buf, sizeof buf, "\\u%04x", static_cast<unsigned>(ch));
          out += buf;
        } else {
          out += ch;
        }
    }
  }
  return out + "\"";
}

std::string TomlKey(const std::string& k) {
  for (char ch : k) {
    const bool bare = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                      (ch >= '0' && ch <= '9') || ch == '_' || ch == '-';
    if (!bare) return TomlString(k);
  }
  return k.empty() ? "\"\"" : k;
}

}  // namespace

std::string SceneToToml(const Scene& s) {
  std::ostringstream o;
  o << "# bouncecal scene (format: src/physics/scene.cpp, README.md)\n";
  o << "[ball]\n";
  o << "diameter_m = " << TomlFloat(s.ball.diameter_m) << "\n";
  if (s.ball.mass_kg) o << "mass_kg = " << TomlFloat(*s.ball.mass_kg) << "\n";
  if (s.ball.density_kg_m3) o << "density_kg_m3 = " << TomlFloat(*s.ball.density_kg_m3) << "\n";
  o << "material = " << TomlString(s.ball.material) << "\n";
  if (s.ball.youngs_modulus_pa) {
    o << "youngs_modulus_pa = " << TomlFloat(*s.ball.youngs_modulus_pa) << "\n";
  }
  if (s.ball.poisson_ratio) o << "poisson_ratio = " << TomlFloat(*s.ball.poisson_ratio) << "\n";
  o << "\n[surface]\n";
  o << "kind = \"" << (s.surface.kind == Surface::Kind::kRigid ? "rigid" : "spring-mass") << "\"\n";
  o << "material = " << TomlString(s.surface.material) << "\n";
  if (s.surface.youngs_modulus_pa) {
    o << "youngs_modulus_pa = " << TomlFloat(*s.surface.youngs_modulus_pa) << "\n";
  }
  if (s.surface.poisson_ratio) {
    o << "poisson_ratio = " << TomlFloat(*s.surface.poisson_ratio) << "\n";
  }
  if (s.surface.mass_kg > 0.0) o << "mass_kg = " << TomlFloat(s.surface.mass_kg) << "\n";
  if (s.surface.stiffness_n_m > 0.0) {
    o << "stiffness_n_m = " << TomlFloat(s.surface.stiffness_n_m) << "\n";
  }
  if (s.surface.damping_n_s_m > 0.0) {
    o << "damping_n_s_m = " << TomlFloat(s.surface.damping_n_s_m) << "\n";
  }
  o << "\n[environment]\n";
  o << "g_m_s2 = " << TomlFloat(s.environment.g_m_s2) << "\n";
  o << "air_density_kg_m3 = " << TomlFloat(s.environment.air_density_kg_m3) << "\n";
  o << "air_viscosity_pa_s = " << TomlFloat(s.environment.air_viscosity_pa_s) << "\n";
  o << "drag_coefficient = " << TomlFloat(s.environment.drag_coefficient) << "\n";
  o << "\n[drop]\n";
  if (s.drop.height_m) o << "height_m = " << TomlFloat(*s.drop.height_m) << "\n";
  if (s.drop.height_sigma_m) o << "height_sigma_m = " << TomlFloat(*s.drop.height_sigma_m) << "\n";
  if (s.drop.impact_speed_m_s) {
    o << "impact_speed_m_s = " << TomlFloat(*s.drop.impact_speed_m_s) << "\n";
  }
  o << "first_impact_time_s = " << TomlFloat(s.drop.first_impact_time_s) << "\n";
  o << "\n[effects]\n";
  o << "drag = \"" << DragModelName(s.effects.drag) << "\"\n";
  o << "buoyancy = " << (s.effects.buoyancy ? "true" : "false") << "\n";
  o << "contact_duration = " << (s.effects.contact_duration ? "true" : "false") << "\n";
  o << "surface_compliance = " << (s.effects.surface_compliance ? "true" : "false") << "\n";
  o << "\n[law]\n";
  o << "name = " << TomlString(s.law.name) << "\n";
  if (!s.law.expression.empty()) o << "expression = " << TomlString(s.law.expression) << "\n";
  o << "\n[law.parameters]\n";
  for (const auto& [name, value] : s.law.parameters) {
    o << TomlKey(name) << " = " << TomlFloat(value) << "\n";
  }
  o << "\n[limits]\n";
  o << "horizon_s = " << TomlFloat(s.limits.horizon_s) << "\n";
  o << "max_impacts = " << s.limits.max_impacts << "\n";
  o << "rest_speed_m_s = " << TomlFloat(s.limits.rest_speed_m_s) << "\n";
  return o.str();
}

}  // namespace bouncecal
