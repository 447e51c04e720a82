// Scenes: defaults, material presets and validation. The TOML scene-file format is
// scene_file.cpp's.
#include "bouncecal/physics/scene.hpp"

#include <cmath>
#include <cstdio>
#include <string>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "scene_problem.hpp"

namespace bouncecal {

const char* DragModelName(DragModel m) {
  switch (m) {
    case DragModel::kNone:
      return "none";
    case DragModel::kLinear:
      return "linear";
    case DragModel::kQuadratic:
      return "quadratic";
  }
  return "none";
}

bool ParseDragModel(const std::string& text, DragModel* model) {
  if (text == "none") {
    *model = DragModel::kNone;
  } else if (text == "linear") {
    *model = DragModel::kLinear;
  } else if (text == "quadratic") {
    *model = DragModel::kQuadratic;
  } else {
    return false;
  }
  return true;
}

const std::vector<MaterialPreset>& MaterialPresets() {
  // Handbook values (room temperature). Hollow balls (pingpong, tennis) carry the density of the
  // whole ball (mass / volume) and an effective modulus: Hertz contact times for them are rough
  // estimates only (a shell is not a Hertzian solid).
  static const std::vector<MaterialPreset> kPresets = {
      {"steel", 7800.0, 2.00e11, 0.29},            // AISI 52100 bearing steel
      {"stainless-steel", 8000.0, 1.93e11, 0.29},  // AISI 304
      {"copper", 8960.0, 1.20e11, 0.34},
      {"brass", 8500.0, 1.00e11, 0.34},
      {"aluminium", 2700.0, 6.90e10, 0.33},
      {"glass", 2500.0, 7.00e10, 0.22},   // soda-lime
      {"ceramic", 2200.0, 5.50e9, 0.25},  // seed 003 beads (rho, E); nu assumed
      {"granite", 2700.0, 5.00e10, 0.25},
      {"rubber", 1150.0, 5.00e6, 0.49},     // polybutadiene "superball"
      {"wood", 700.0, 1.10e10, 0.30},       // along the grain, hardwood
      {"celluloid", 1350.0, 2.50e9, 0.35},  // the solid material
      {"pingpong", 80.6, 2.50e9, 0.35},     // 40 mm, 2.7 g celluloid shell: mass / volume
      {"tennis", 365.0, 5.00e6, 0.49},      // 67 mm, 57.5 g pressurised shell: effective
      {"plastic", 1200.0, 3.00e9, 0.35},    // generic rigid plastic (ABS/PMMA)
  };
  return kPresets;
}

const MaterialPreset* FindMaterial(const std::string& name) {
  for (const MaterialPreset& p : MaterialPresets()) {
    if (p.name == name) return &p;
  }
  if (name == "aluminum") return FindMaterial("aluminium");
  return nullptr;
}

namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

}  // namespace

double Ball::Volume() const { return M_PI * diameter_m * diameter_m * diameter_m / 6.0; }

double Ball::Mass() const {
  if (mass_kg) return *mass_kg;
  if (density_kg_m3) return *density_kg_m3 * Volume();
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->density_kg_m3 * Volume() : kNaN;
}

double Ball::Density() const {
  if (density_kg_m3) return *density_kg_m3;
  if (mass_kg) return *mass_kg / Volume();
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->density_kg_m3 : kNaN;
}

double Ball::ResolvedYoungsModulusPa() const {
  if (youngs_modulus_pa) return *youngs_modulus_pa;
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->youngs_modulus_pa : kNaN;
}

double Ball::ResolvedPoissonRatio() const {
  if (poisson_ratio) return *poisson_ratio;
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->poisson_ratio : kNaN;
}

double Surface::ResolvedYoungsModulusPa() const {
  if (youngs_modulus_pa) return *youngs_modulus_pa;
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->youngs_modulus_pa : kNaN;
}

double Surface::ResolvedPoissonRatio() const {
  if (poisson_ratio) return *poisson_ratio;
  const MaterialPreset* p = FindMaterial(material);
  return p ? p->poisson_ratio : kNaN;
}

std::optional<double> EffectiveModulusPa(const Scene& scene, std::string* why) {
  struct Body {
    const char* key;
    const std::string& material;
    double youngs_pa, poisson;
  };
  const Body bodies[] = {
      {"ball", scene.ball.material, scene.ball.ResolvedYoungsModulusPa(),
       scene.ball.ResolvedPoissonRatio()},
      {"surface", scene.surface.material, scene.surface.ResolvedYoungsModulusPa(),
       scene.surface.ResolvedPoissonRatio()},
  };
  double compliance_per_pa = 0.0;  // 1/E*
  for (const Body& b : bodies) {
    if (!(std::isfinite(b.youngs_pa) && b.youngs_pa > 0.0 && b.poisson > -1.0 &&
          b.poisson <= 0.5)) {
      if (why) {
        *why = std::string(b.key) + ".youngs_modulus_pa/poisson_ratio: unknown for material \"" +
               b.material + "\"";
      }
      return std::nullopt;
    }
    compliance_per_pa += (1.0 - b.poisson * b.poisson) / b.youngs_pa;
  }
  return 1.0 / compliance_per_pa;
}

double Scene::EffectiveGravity() const {
  // Archimedes: g_eff = g (1 - rho_air / rho_ball), docs/physics.md §2.
  if (!effects.buoyancy) return environment.g_m_s2;
  return environment.g_m_s2 * (1.0 - environment.air_density_kg_m3 / ball.Density());
}

namespace {

// Collects the first problem found; each check names the key, the rule and the value.
class Checker {
 public:
  explicit Checker(const std::string& source) : prefix_(source.empty() ? "" : source + ": ") {}
  bool ok() const { return error_.empty(); }
  const std::string& error() const { return error_; }
  const std::string& key() const { return key_; }
  const std::string& problem() const { return problem_; }

  void Fail(const std::string& key, const std::string& problem) {
    if (!error_.empty()) return;
    error_ = prefix_ + key + ": " + problem;
    key_ = key;
    problem_ = problem;
  }
  void Positive(const std::string& key, double v) {
    if (!(std::isfinite(v) && v > 0.0))
      Fail(key, "must be finite and > 0 (got " + FormatShortest(v) + ")");
  }
  void NonNegative(const std::string& key, double v) {
    if (!(std::isfinite(v) && v >= 0.0))
      Fail(key, "must be finite and >= 0 (got " + FormatShortest(v) + ")");
  }
  void Finite(const std::string& key, double v) {
    if (!std::isfinite(v)) Fail(key, "must be finite (got " + FormatShortest(v) + ")");
  }
  void Poisson(const std::string& key, double v) {
    if (!(std::isfinite(v) && v > -1.0 && v <= 0.5)) {
      Fail(key, "must be in (-1, 0.5] (got " + FormatShortest(v) + ")");
    }
  }
  void Material(const std::string& key, const std::string& name, bool all_explicit) {
    if (name.empty() || FindMaterial(name) != nullptr || all_explicit) return;
    Fail(key, "unknown material \"" + name + "\" (known: " + KnownMaterials() +
                  "; or give density/E/nu explicitly)");
  }

 private:
  std::string prefix_;
  std::string error_;
  std::string key_;
  std::string problem_;
};

void Validate(const Scene& scene, Checker* checker);

}  // namespace

bool NeedsExpression(const std::string& law_name) {
  const LawInfo* row = FindLaw(law_name);
  return row != nullptr && row->needs_expression;
}

std::string KnownMaterials() {
  std::string s;
  for (const MaterialPreset& p : MaterialPresets()) s += (s.empty() ? "" : ", ") + p.name;
  return s;
}

SceneProblem FirstSceneProblem(const Scene& s, const std::string& source) {
  Checker c(source);
  Validate(s, &c);
  return {c.error(), c.key(), c.problem()};
}

bool Scene::IsValid(std::string* error) const {
  Checker c(source);
  Validate(*this, &c);
  if (!c.ok() && error != nullptr) *error = c.error();
  return c.ok();
}

namespace {

// Values that pass their own checks can still overflow what is computed from them: the arrival
// speed sqrt(2 g h) (no drag: the fastest case), the kinetic energy m v^2 / 2 and the flight
// time 2 v / g (simulator.hpp, flight.hpp). Each must be finite, or every later stage would
// report "inf" or "nan" as a result. The message names the scene key that was given.
void CheckDropDoesNotOverflow(const Scene& s, Checker* checker) {
  const double g = s.environment.g_m_s2;
  const double two_g_h = s.drop.height_m ? 2.0 * g * *s.drop.height_m : 0.0;
  const double v = s.drop.impact_speed_m_s ? *s.drop.impact_speed_m_s : std::sqrt(two_g_h);
  const double mass_kg = s.ball.Mass();
  const std::string key = s.drop.impact_speed_m_s ? "drop.impact_speed_m_s" : "drop.height_m";
  const std::string given =
      s.drop.impact_speed_m_s ? FormatShortest(v) + " m/s"
                              : FormatShortest(*s.drop.height_m) +
                                    " m with environment.g_m_s2 = " + FormatShortest(g) + " m/s^2";
  if (!std::isfinite(two_g_h)) {
    checker->Fail(key, given + ": the arrival speed sqrt(2 g h) is not a finite number");
  } else if (!std::isfinite(0.5 * mass_kg * v * v)) {
    checker->Fail(
        key, given + ": the kinetic energy m v^2 / 2 = " + FormatShortest(0.5 * mass_kg * v * v) +
                 " J is not a finite number (ball mass " + FormatShortest(mass_kg) + " kg)");
  } else if (!std::isfinite(2.0 * v / g)) {
    checker->Fail(key, given + ": the flight time 2 v / g is not a finite number");
  }
}

void Validate(const Scene& s, Checker* checker) {
  Checker& c = *checker;
  const Ball& ball = s.ball;
  const Surface& surface = s.surface;
  const Environment& environment = s.environment;
  const Drop& drop = s.drop;
  const Effects& effects = s.effects;
  const LawSpec& law = s.law;
  const SimulationLimits& limits = s.limits;
  // Ball.
  c.Positive("ball.diameter_m", ball.diameter_m);
  if (ball.mass_kg && ball.density_kg_m3) {
    c.Fail("ball.mass_kg", "conflicts with ball.density_kg_m3: give one of them (got mass " +
                               FormatShortest(*ball.mass_kg) + " kg and density " +
                               FormatShortest(*ball.density_kg_m3) + " kg/m^3)");
  }
  if (ball.mass_kg) c.Positive("ball.mass_kg", *ball.mass_kg);
  if (ball.density_kg_m3) c.Positive("ball.density_kg_m3", *ball.density_kg_m3);
  if (!ball.mass_kg && !ball.density_kg_m3 && FindMaterial(ball.material) == nullptr) {
    c.Fail("ball.density_kg_m3", "missing: give density_kg_m3, mass_kg or a known material");
  }
  if (ball.youngs_modulus_pa) c.Positive("ball.youngs_modulus_pa", *ball.youngs_modulus_pa);
  if (ball.poisson_ratio) c.Poisson("ball.poisson_ratio", *ball.poisson_ratio);
  c.Material("ball.material", ball.material,
             (ball.mass_kg || ball.density_kg_m3) && ball.youngs_modulus_pa && ball.poisson_ratio);
  // Surface.
  if (surface.youngs_modulus_pa)
    c.Positive("surface.youngs_modulus_pa", *surface.youngs_modulus_pa);
  if (surface.poisson_ratio) c.Poisson("surface.poisson_ratio", *surface.poisson_ratio);
  c.Material("surface.material", surface.material,
             surface.youngs_modulus_pa.has_value() && surface.poisson_ratio.has_value());
  c.NonNegative("surface.mass_kg", surface.mass_kg);
  c.NonNegative("surface.stiffness_n_m", surface.stiffness_n_m);
  c.NonNegative("surface.damping_n_s_m", surface.damping_n_s_m);
  if (surface.kind == Surface::Kind::kSpringMass) {
    c.Positive("surface.mass_kg", surface.mass_kg);
    c.Positive("surface.stiffness_n_m", surface.stiffness_n_m);
  }
  // Environment.
  c.Positive("environment.g_m_s2", environment.g_m_s2);
  c.NonNegative("environment.air_density_kg_m3", environment.air_density_kg_m3);
  c.NonNegative("environment.air_viscosity_pa_s", environment.air_viscosity_pa_s);
  c.NonNegative("environment.drag_coefficient", environment.drag_coefficient);
  // Drop.
  if (drop.height_m && drop.impact_speed_m_s) {
    c.Fail("drop.impact_speed_m_s", "conflicts with drop.height_m: give one of them (got height " +
                                        FormatShortest(*drop.height_m) + " m and impact speed " +
                                        FormatShortest(*drop.impact_speed_m_s) + " m/s)");
  }
  if (!drop.height_m && !drop.impact_speed_m_s) {
    c.Fail("drop.height_m", "missing: give drop.height_m or drop.impact_speed_m_s");
  }
  if (drop.height_m) c.Positive("drop.height_m", *drop.height_m);
  if (drop.impact_speed_m_s) c.Positive("drop.impact_speed_m_s", *drop.impact_speed_m_s);
  if (drop.height_sigma_m) {
    c.NonNegative("drop.height_sigma_m", *drop.height_sigma_m);
    if (!drop.height_m) {
      c.Fail("drop.height_sigma_m",
             "is the uncertainty of drop.height_m, which is not given (got " +
                 FormatShortest(*drop.height_sigma_m) + " m)");
    }
  }
  c.Finite("drop.first_impact_time_s", drop.first_impact_time_s);
  if (c.ok()) CheckDropDoesNotOverflow(s, &c);
  // Effects.
  if (effects.surface_compliance && surface.kind != Surface::Kind::kSpringMass) {
    c.Fail("effects.surface_compliance",
           "needs surface.kind = \"spring-mass\" with mass_kg and stiffness_n_m (got kind rigid)");
  }
  if (effects.buoyancy && c.ok()) {
    const double rho = ball.Density();
    if (!(environment.air_density_kg_m3 < rho)) {
      c.Fail("effects.buoyancy", "ball density must exceed air density for it to fall (got " +
                                     FormatShortest(rho) + " kg/m^3 vs air " +
                                     FormatShortest(environment.air_density_kg_m3) + " kg/m^3)");
    }
  }
  // Law.
  if (law.name.empty()) c.Fail("law.name", "must not be empty");
  for (const auto& [name, value] : law.parameters) {
    if (name.empty()) c.Fail("law.parameters", "empty parameter name");
    c.Finite("law.parameters." + name, value);
  }
  if (NeedsExpression(law.name) && law.expression.empty()) {
    c.Fail("law.expression",
           "missing: law \"" + Abbreviate(law.name) + "\" needs a force expression");
  }
  if (!NeedsExpression(law.name) && !law.expression.empty()) {
    c.Fail("law.expression", "only allowed with law.name = \"" + ExpressionLawName() +
                                 "\" (got name \"" + Abbreviate(law.name) + "\")");
  }
  // Limits.
  c.Positive("limits.horizon_s", limits.horizon_s);
  if (limits.max_impacts < 1 || limits.max_impacts > kMaxImpactsLimit) {
    c.Fail("limits.max_impacts", "must be in [1, " + std::to_string(kMaxImpactsLimit) + "] (got " +
                                     std::to_string(limits.max_impacts) +
                                     "; the limit keeps the output under ~300 MB of JSON)");
  }
  c.NonNegative("limits.rest_speed_m_s", limits.rest_speed_m_s);
}

}  // namespace

}  // namespace bouncecal
