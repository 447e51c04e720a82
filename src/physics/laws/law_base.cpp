#include "physics/laws/law_base.hpp"

#include <cmath>

namespace bouncecal::laws {

std::optional<double> HertzStiffnessFromScene(const Scene& scene, std::string* why) {
  const std::optional<double> e_star = EffectiveModulusPa(scene, why);
  if (!e_star) return std::nullopt;
  // k = (4/3) E* sqrt(R*) (Johnson, Contact Mechanics, eq. 4.22), R* = ball radius.
  return 4.0 / 3.0 * *e_star * std::sqrt(scene.ball.Radius());
}

ParameterSpec HertzStiffnessSpec(const Scene& scene, const std::string& unit,
                                 const std::string& description) {
  std::string why;
  const std::optional<double> k = HertzStiffnessFromScene(scene, &why);
  return Spec("k", unit,
              description + "; default (4/3) E* sqrt(R*) from materials" +
                  (k ? "" : " (not available here: " + why + ")"),
              kStiffnessLower, kStiffnessUpper, k.value_or(kNaN), false);
}

}  // namespace bouncecal::laws
