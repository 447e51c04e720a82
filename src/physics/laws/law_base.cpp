#include "physics/laws/law_base.hpp"

#include <cmath>

namespace bouncecal::laws {

std::optional<double> HertzStiffnessFromScene(const Scene& scene, std::string* why) {
  const MaterialPreset* ball_preset = FindMaterial(scene.ball.material);
  const double e1 =
      scene.ball.youngs_modulus_pa.value_or(ball_preset ? ball_preset->youngs_modulus_pa : kNaN);
  const double nu1 =
      scene.ball.poisson_ratio.value_or(ball_preset ? ball_preset->poisson_ratio : kNaN);
  if (!(e1 > 0.0) || !std::isfinite(e1) || !(nu1 > -1.0 && nu1 < 0.5)) {
    if (why) {
      *why = "the default is (4/3) E* sqrt(R*), but the ball (material '" + scene.ball.material +
             "') has no valid Young's modulus and Poisson ratio";
    }
    return std::nullopt;
  }
  double compliance = (1.0 - nu1 * nu1) / e1;  // 1/E*, Johnson eq. 4.22
  const MaterialPreset* surf_preset = FindMaterial(scene.surface.material);
  const double e2 =
      scene.surface.youngs_modulus_pa.value_or(surf_preset ? surf_preset->youngs_modulus_pa : kNaN);
  const double nu2 =
      scene.surface.poisson_ratio.value_or(surf_preset ? surf_preset->poisson_ratio : kNaN);
  if (e2 > 0.0 && std::isfinite(e2) && nu2 > -1.0 && nu2 < 0.5)
    compliance += (1.0 - nu2 * nu2) / e2;
  const double radius_m = scene.ball.Radius();
  return 4.0 / 3.0 * std::sqrt(radius_m) / compliance;
}

}  // namespace bouncecal::laws
