// bouncecal/physics/scene.hpp — what is being dropped on what, and which effects are simulated.
//
// A Scene is the single description shared by every stage that needs physics: kinematics
// (analyze), the simulator, the test-recording renderer and the fitter. It is plain data; it is
// read from a TOML scene file (LoadSceneFile), overridden by CLI flags, and checked by
// IsValid before use. Effects are off unless the scene turns them on, and a disabled effect
// costs nothing downstream.
//
//   Scene s = LoadSceneFile("drop.toml");        // throws Error(kBadScene) with the line
//   s.effects.drag = DragModel::kQuadratic;       // a CLI override
//   std::string err; if (!s.IsValid(&err)) ...;
//
// Units are SI and carried in the member names. Defaults are the seed paper's experiment
// (seed 002: 1 cm steel ball from 0.2 m onto a copper dish, g = 9.8 m/s^2).
#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace bouncecal {

enum class DragModel { kNone, kLinear, kQuadratic };
const char* DragModelName(DragModel m);  // "none", "linear", "quadratic"

struct Ball {
  double diameter_m = 0.01;
  // Exactly one of mass/density is authoritative; the other is derived by Mass()/Density().
  std::optional<double> mass_kg;
  std::optional<double> density_kg_m3 = 7800.0;
  std::string material = "steel";  // preset name, informational once values are resolved
  // Elastic constants for laws that derive stiffness from materials (Hertz: E*, nu).
  std::optional<double> youngs_modulus_pa;
  std::optional<double> poisson_ratio;

  double Radius() const { return 0.5 * diameter_m; }
  double Volume() const;   // m^3
  double Mass() const;     // kg, from mass_kg or density * volume
  double Density() const;  // kg/m^3, from density_kg_m3 or mass / volume
  // Explicit value, else the material preset's, else NaN.
  double ResolvedYoungsModulusPa() const;
  double ResolvedPoissonRatio() const;
  friend bool operator==(const Ball&, const Ball&) = default;
};

struct Surface {
  enum class Kind { kRigid, kSpringMass };
  Kind kind = Kind::kRigid;
  std::string material = "copper";
  std::optional<double> youngs_modulus_pa;
  std::optional<double> poisson_ratio;
  // Only for kSpringMass (surface compliance effect): plate mass on a spring and dashpot.
  double mass_kg = 0.0;
  double stiffness_n_m = 0.0;
  double damping_n_s_m = 0.0;
  // Explicit value, else the material preset's, else NaN.
  double ResolvedYoungsModulusPa() const;
  double ResolvedPoissonRatio() const;
  friend bool operator==(const Surface&, const Surface&) = default;
};

struct Environment {
  double g_m_s2 = 9.8;                  // seed 002 uses 9.8
  double air_density_kg_m3 = 1.2;       // docs/physics.md §2
  double air_viscosity_pa_s = 1.81e-5;  // dry air, 20 °C (linear/Stokes drag)
  double drag_coefficient = 0.47;       // smooth sphere, docs/physics.md §2
  friend bool operator==(const Environment&, const Environment&) = default;
};

struct Drop {
  std::optional<double> height_m = 0.2;    // release height of the ball's bottom above the plate
  std::optional<double> impact_speed_m_s;  // first impact speed, instead of a height
  // 1-sigma uncertainty of height_m (only with a height); unset: the height is taken as exact
  // (calibrate/analyze then report that assumption).
  std::optional<double> height_sigma_m;
  double first_impact_time_s = 0.0;  // time origin of the first impact (simulation)
  friend bool operator==(const Drop&, const Drop&) = default;
};

struct Effects {
  DragModel drag = DragModel::kNone;
  bool buoyancy = false;
  bool contact_duration = false;    // onsets include the previous impact's contact time
  bool surface_compliance = false;  // plate as a mass on a spring (Surface::kSpringMass)
  friend bool operator==(const Effects&, const Effects&) = default;
};

// The contact law chosen by the scene: a registry name and its parameters by name.
struct LawSpec {
  std::string name = "walton-braun";
  std::map<std::string, double> parameters;  // missing ones take the law's defaults
  std::string expression;                    // only for the "expression" law
  friend bool operator==(const LawSpec&, const LawSpec&) = default;
};

// Largest limits.max_impacts accepted, checked before any work. `simulate --json` writes
// about 300 bytes per impact (measured: 12.4 kB for 36 impacts), so 10^6 impacts are ~300 MB of
// JSON and ~50 MB of impacts in memory; 10^8 (accepted before) meant ~30 GB.
inline constexpr int kMaxImpactsLimit = 1'000'000;

// Limits of a simulation run.
struct SimulationLimits {
  double horizon_s = 60.0;
  int max_impacts = 10000;
  double rest_speed_m_s = 1e-4;  // below this arrival speed the ball is considered at rest
  friend bool operator==(const SimulationLimits&, const SimulationLimits&) = default;
};

struct Scene {
  Ball ball;
  Surface surface;
  Environment environment;
  Drop drop;
  Effects effects;
  LawSpec law;
  SimulationLimits limits;
  std::string source;  // file the scene came from, or "" for defaults/flags

  // Effective gravity: g (1 - rho_air/rho_ball) with buoyancy, else g. docs/physics.md §2.
  double EffectiveGravity() const;
  // Checks every value (positive sizes, finite numbers, one of height/speed, ...).
  // The message names the key and the value, prefixed by source when set.
  bool IsValid(std::string* error) const;
  friend bool operator==(const Scene&, const Scene&) = default;
};

// The effective (contact) modulus E* of the ball on the surface, Pa (Hertz; Johnson, Contact
// Mechanics, 1985, eq. 4.22): 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2, each body's E and nu its
// explicit value or its material preset's. The one place E* is computed (Hertz stiffness
// defaults, the Hertz contact duration). Rule for a body whose elastic constants are unknown
// (a material without a preset and no explicit values) — the SURFACE included: nullopt, and
// `why` names the keys and the material ("surface.youngs_modulus_pa/poisson_ratio: unknown for
// material \"\""). An unknown surface is NOT taken as rigid: that would silently overstate E*
// (steel on steel: twice the true value) and shorten every Hertz contact by 24 %. A rigid wall
// is a surface with a very large youngs_modulus_pa.
std::optional<double> EffectiveModulusPa(const Scene& scene, std::string* why);

// Built-in material presets: density, Young's modulus, Poisson ratio.
struct MaterialPreset {
  std::string name;
  double density_kg_m3;
  double youngs_modulus_pa;
  double poisson_ratio;
};
const std::vector<MaterialPreset>& MaterialPresets();
const MaterialPreset* FindMaterial(const std::string& name);  // nullptr if unknown
// Parses "none" / "linear" / "quadratic"; false otherwise.
bool ParseDragModel(const std::string& text, DragModel* model);

// Reads a TOML scene file. Unknown keys, wrong types, bad values: Error(kBadScene) whose
// message has "FILE:LINE: key: problem". A missing file: Error(kInputMissing).
Scene LoadSceneFile(const std::string& path);
// Parses TOML text (source is used in messages).
Scene ParseScene(const std::string& toml_text, const std::string& source);
// Writes a scene as TOML that LoadSceneFile reads back to the same Scene.
std::string SceneToToml(const Scene& scene);
// The dotted keys a scene file sets ("ball.diameter_m", "drop.height_m", "law.parameters.A",
// ...), so that callers can tell given values from defaults (a scene file without [drop] means
// the drop is unknown to analyze/calibrate). Same errors as LoadSceneFile.
std::vector<std::string> SceneFileKeys(const std::string& path);
// The same for TOML text (source is used in messages).
std::vector<std::string> SceneTextKeys(const std::string& toml_text, const std::string& source);

}  // namespace bouncecal
