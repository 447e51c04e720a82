// physics/laws/law_base.hpp — what the registry knows of a law (internal header, not installed).
//
// Every law derives from LawBase, which holds the law's registry row (name, formula, source,
// end rule, closed forms: set by the registry, so a law never states its own name), its
// parameter specs (names, units, bounds, defaults, computed once by the law's factory from the
// scene) and the values it was created with. The registry (src/physics/law_registry.cpp) builds
// a law with MakeLaw<L>, fills the values by name, validates them and hands the law out as a
// ContactLaw. Laws keep no other mutable state: everything a force evaluation needs comes from
// the parameter vector p and the body (ContactLaw::Dynamics), so the fitter can vary p.
//
// A law's file includes laws/law_impl.hpp instead (the templated recipe); this header is all
// the registry needs.
#pragma once

#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal::laws {

class LawBase : public ContactLaw {
 public:
  std::string Name() const override { return row_.name; }
  std::string Formula() const override { return row_.formula; }
  std::string Source() const override { return row_.source; }
  ContactEnd EndRule() const override { return row_.end_rule; }
  std::vector<std::string> ClosedForms() const override { return row_.closed_forms; }
  const std::vector<ParameterSpec>& Parameters() const override { return specs_; }
  std::vector<double> ParameterValues() const override { return values_; }

  // Set by the registry (CreateLaw), in this order, before the law is handed out.
  void SetRow(LawInfo row) { row_ = std::move(row); }
  void SetValues(std::vector<double> values) { values_ = std::move(values); }

 protected:
  std::vector<ParameterSpec> specs_;
  std::vector<double> values_;

 private:
  LawInfo row_;
};

// A law's factory: builds the law with its parameter specs (defaults may come from the scene,
// e.g. Hertz stiffness from the materials). Throws Error(kBadParameter) for a bad LawSpec
// (expression that does not parse, ...). Parameter values are set by the registry.
using LawFactory = std::unique_ptr<LawBase> (*)(const LawSpec& spec, const Scene& scene);

// The factory of law class L (L::Create). Declared here for the registry table, which names
// the class in its row (`MakeLaw<class HertzTsuji>` declares the class there); defined in
// laws/law_impl.hpp and explicitly instantiated by the law's own file, so a law needs no other
// declaration anywhere (a missing instantiation is a link error naming the class).
template <class L>
std::unique_ptr<LawBase> MakeLaw(const LawSpec& spec, const Scene& scene);

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
// Johnson, Contact Mechanics, eq. 4.22), E* from EffectiveModulusPa (scene.hpp: both bodies'
// elastic constants are needed), R* = ball radius (flat surface). nullopt if E* is unknown;
// `why` then receives the reason.
std::optional<double> HertzStiffnessFromScene(const Scene& scene, std::string* why);
// The spec of a Hertz-type law's stiffness "k": default from HertzStiffnessFromScene, or NaN
// (required: CreateLaw then asks for a value and quotes the description, with the reason).
ParameterSpec HertzStiffnessSpec(const Scene& scene, const std::string& unit,
                                 const std::string& description);

}  // namespace bouncecal::laws
