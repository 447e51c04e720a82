// Scene values in a probably wrong unit (scene_checks.hpp).
#include "bouncecal/fit/scene_checks.hpp"
#include "bouncecal/core/format.hpp"
#include "fit/text.hpp"

#include <cmath>
#include <cstdio>
#include <string>

namespace bouncecal {
namespace {

// Plausible ranges of a bouncing-ball experiment (scene_checks.hpp).
constexpr double kMinDiameterM = 1e-4, kMaxDiameterM = 1.0;
constexpr double kMaxHeightM = 50.0;
constexpr double kMinDensity = 10.0, kMaxDensity = 25000.0;
constexpr double kMinG = 1.0, kMaxG = 30.0;

// The units (in the given order of likelihood) that would bring v, read as metres, into
// [lo, hi]: "centimetres (1.5 m) or millimetres (0.15 m)", or "".
std::string LengthUnits(double v, double lo, double hi, bool cm_first) {
  std::string out;
  const std::pair<const char*, double> mm{"millimetres", 1e-3}, cm{"centimetres", 1e-2};
  for (const auto& [name, f] : cm_first ? std::vector{cm, mm} : std::vector{mm, cm}) {
    if (v * f >= lo && v * f <= hi)
      out += (out.empty() ? "" : " or ") + std::string(name) + Printf(" (%g m)", v * f);
  }
  return out;
}

}  // namespace

std::vector<Warning> SceneUnitWarnings(const Scene& scene, bool drop_used) {
  std::vector<Warning> out;
  const double d = scene.ball.diameter_m;
  if (d > kMaxDiameterM || d < kMinDiameterM) {
    const std::string unit =
        d > kMaxDiameterM ? LengthUnits(d, kMinDiameterM, kMaxDiameterM, false) : "";
    out.push_back(
        {"units_suspect",
         Printf("ball.diameter_m = %g m is outside a ball's 0.1 mm .. 1 m", d) +
             (unit.empty() ? std::string(": is it in metres?") : ": it looks like " + unit),
         -1, "give the diameter in metres (--diameter, [ball] diameter_m)"});
  }
  if (drop_used && scene.drop.height_m && *scene.drop.height_m > kMaxHeightM) {
    const double h = *scene.drop.height_m;
    const std::string unit = LengthUnits(h, 0.0, kMaxHeightM, true);
    out.push_back(
        {"units_suspect",
         Printf("drop.height_m = %g m is higher than a drop experiment (50 m)", h) +
             (unit.empty() ? std::string(": is it in metres?") : ": it looks like " + unit),
         -1, "give the height in metres (--height, [drop] height_m)"});
  }
  const double rho = scene.ball.Density();
  if (std::isfinite(rho) && (rho < kMinDensity || rho > kMaxDensity)) {
    std::string hint = ": check the ball's mass and diameter units";
    if (scene.ball.mass_kg && rho > kMaxDensity && rho * 1e-3 >= kMinDensity &&
        rho * 1e-3 <= kMaxDensity) {
      hint = Printf(": ball.mass_kg = %g looks like grams (%g kg)", *scene.ball.mass_kg,
                    *scene.ball.mass_kg * 1e-3);
    } else if (scene.ball.density_kg_m3 && rho < kMinDensity && rho * 1e3 >= kMinDensity &&
               rho * 1e3 <= kMaxDensity) {
      hint = Printf(": ball.density_kg_m3 = %g looks like g/cm^3 (%g kg/m^3)", rho, rho * 1e3);
    }
    out.push_back({"units_suspect",
                   Printf("the ball's density %g kg/m^3 is outside 10 .. 25000 kg/m^3", rho) + hint,
                   -1, "give the mass in kg (--mass) or the density in kg/m^3 (--density)"});
  }
  const double g = scene.environment.g_m_s2;
  if (g < kMinG || g > kMaxG) {
    out.push_back({"units_suspect",
                   Printf("environment.g_m_s2 = %g is outside 1 .. 30 m/s^2", g) +
                       (g > 100.0 && g * 1e-3 >= kMinG && g * 1e-3 <= kMaxG
                            ? Printf(": it looks like mm/s^2 (%g m/s^2)", g * 1e-3)
                            : std::string(": is it in m/s^2?")),
                   -1, "give g in m/s^2 (--g, [environment] g_m_s2)"});
  }
  return out;
}

}  // namespace bouncecal
