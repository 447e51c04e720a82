// physics/laws/law_base.hpp — internal helpers shared by the contact laws in src/physics/laws/ (not
// installed).
//
// Every law derives from LawBase, which stores the parameter specs (names, units, bounds,
// defaults, computed once by the law's factory from the scene) and the values the law was
// created with. The registry (src/physics/law_registry.cpp) fills the values by name, validates
// them and hands the law out as a ContactLaw. Laws keep no other mutable state: everything a force
// evaluation needs comes from the parameter vector p and the body, so the fitter can vary p.
#pragma once

#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal::laws {

class LawBase : public ContactLaw {
 public:
  const std::vector<ParameterSpec>& Parameters() const override { return specs_; }
  std::vector<double> ParameterValues() const override { return values_; }
  void SetValues(std::vector<double> values) { values_ = std::move(values); }

 protected:
  std::vector<ParameterSpec> specs_;
  std::vector<double> values_;
};

// A law's factory: builds the law with its parameter specs (defaults may come from the scene,
// e.g. Hertz stiffness from the materials). Throws Error(kBadParameter) for a bad LawSpec
// (expression that does not parse, ...). Parameter values are set by the registry.
using LawFactory = std::unique_ptr<LawBase> (*)(const LawSpec& spec, const Scene& scene);

inline ParameterSpec Spec(std::string name, std::string unit, std::string description, double lower,
                          double upper, double default_value, bool damping) {
  return ParameterSpec{std::move(name), std::move(unit), std::move(description), lower, upper,
                       default_value,   damping};
}

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kPi = 3.14159265358979323846;

// Stiffness bounds shared by the laws (N/m or N/m^1.5): wide enough for the hard cases
// (1e3 .. 1e12 in the law's units) and finite so the fitter can use them.
constexpr double kStiffnessLower = 1e-3;
constexpr double kStiffnessUpper = 1e16;

// Hertz stiffness of the scene's ball on its surface, k = (4/3) E* sqrt(R*) (Hertz 1882;
// Johnson, Contact Mechanics, eq. 4.22), 1/E* = (1 - nu1^2)/E1 + (1 - nu2^2)/E2, R* = ball
// radius (flat surface). Elastic constants come from the explicit values or the material
// presets; a surface without elastic data counts as rigid (1/E2 = 0). nullopt if the ball has
// no Young's modulus. `why` receives the reason.
std::optional<double> HertzStiffnessFromScene(const Scene& scene, std::string* why);

// Names of the closed forms a law provides, for `bouncecal laws`.
inline constexpr const char* kClosedRestitution = "restitution";
inline constexpr const char* kClosedContactTime = "contact_time";
inline constexpr const char* kClosedSolveContact = "solve_contact";
inline constexpr const char* kClosedInverse = "damping_for_restitution";
inline constexpr const char* kClosedGradient = "restitution_gradient";

}  // namespace bouncecal::laws
