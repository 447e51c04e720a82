// bouncecal/kinematics.hpp — impact times -> per-bounce speeds, restitution and energy loss.
//
// PHYSICS.md §1-2 (seed 002 eqs. 7-12): with the flight model of the scene (no/linear/quadratic
// drag, buoyancy) each measured interval T_k = t_{k+1} - t_k (less the contact duration of
// impact k when the scene turns that effect on) gives the rebound speed v_out,k by inverting the
// exact flight time, and the arrival speed at k+1 from the same flight. Then
// e_k = v_out,k / v_in,k and eta_k = 1 - e_k^2, with uncertainties propagated from the onset
// timing sigmas (full covariance of the three times involved).
//
//   std::vector<Bounce> b = AnalyzeBounces(result.main(), scene, {});
#pragma once

#include <optional>
#include <vector>

#include "bouncecal/detect.hpp"
#include "bouncecal/scene.hpp"

namespace bouncecal {

struct Bounce {
  int index = 0;                 // impact k (0 = first impact)
  double time_s = 0.0;           // impact onset
  double time_sigma_s = 0.0;
  double interval_s = 0.0;       // t_{k+1} - t_k (NaN for the last impact)
  double v_in_m_s = 0.0;         // arrival speed at impact k (NaN if unknown)
  double v_in_sigma_m_s = 0.0;
  double v_out_m_s = 0.0;        // rebound speed after impact k (NaN for the last)
  double v_out_sigma_m_s = 0.0;
  double e = 0.0;                // v_out / v_in (NaN where unknown)
  double e_sigma = 0.0;
  double eta = 0.0;              // 1 - e^2
  double eta_sigma = 0.0;
  double contact_s = 0.0;        // contact duration used for the correction (0 if off)
};

struct AnalysisOptions {
  // Contact duration model when scene.effects.contact_duration is on: a fixed value, or
  // (when <= 0) the Hertz estimate from the scene's materials (PHYSICS.md §2).
  double contact_time_s = 0.0;
};

struct Analysis {
  std::vector<Bounce> bounces;
  // Mean eta of the first three impacts with a known e (as seed 002 reports), and its sigma.
  std::optional<double> mean_eta_first3;
  std::optional<double> mean_eta_first3_sigma;
  // First impact's restitution from the drop height (when the scene gives it).
  std::optional<double> first_e;
};

Analysis AnalyzeBounces(const Sequence& sequence, const Scene& scene,
                        const AnalysisOptions& options = {});

}  // namespace bouncecal
