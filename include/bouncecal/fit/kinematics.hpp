// bouncecal/fit/kinematics.hpp — impact times -> per-bounce speeds, restitution and energy loss.
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
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

struct Bounce {
  int index = 0;        // impact k (0 = first impact)
  double time_s = 0.0;  // impact onset
  double time_sigma_s = 0.0;
  double interval_s = 0.0;  // t_{k+1} - t_k (NaN for the last impact)
  double v_in_m_s = 0.0;    // arrival speed at impact k (NaN if unknown)
  double v_in_sigma_m_s = 0.0;
  double v_out_m_s = 0.0;  // rebound speed after impact k (NaN for the last)
  double v_out_sigma_m_s = 0.0;
  double e = 0.0;  // v_out / v_in (NaN where unknown)
  double e_sigma = 0.0;
  double eta = 0.0;  // 1 - e^2
  double eta_sigma = 0.0;
  double contact_s = 0.0;  // contact duration used for the correction (0 if off)
  // Correlation coefficient of e_k and e_{k+1} (they share t_k and t_{k+1}); NaN if unknown.
  double e_next_correlation = 0.0;
  // d e_k / d t_j for j = index-1, index, index+1 (1/s; NaN where e is unknown).
  double de_dt_prev = 0.0, de_dt_this = 0.0, de_dt_next = 0.0;
};

struct AnalysisOptions {
  // Contact duration model when scene.effects.contact_duration is on: a fixed value, or
  // (when <= 0) the Hertz estimate from the scene's materials (PHYSICS.md §2).
  double contact_time_s = 0.0;
  // Use the scene's drop (height or impact speed) for the first impact's arrival speed. The
  // CLI turns this off when the user gave neither a scene file nor --height/--impact-speed
  // (the default 0.2 m would otherwise be taken as known).
  bool use_drop = true;
  bool IsValid(std::string* error) const;
};

struct Analysis {
  std::vector<Bounce> bounces;
  // Mean eta of the first three impacts with a known e (as seed 002 reports), and its sigma.
  std::optional<double> mean_eta_first3;
  std::optional<double> mean_eta_first3_sigma;
  // First impact's restitution from the drop height (when the scene gives it).
  std::optional<double> first_e;
  std::optional<double> first_e_sigma;
  // Which bounces entered mean_eta_first3.
  std::vector<int> mean_eta_indices;
  // The flight model used: gravity (with buoyancy) and terminal speed (inf without drag).
  double effective_gravity_m_s2 = 0.0;
  double terminal_speed_m_s = 0.0;
  std::vector<Warning> warnings;  // coded: intervals that could not be used, e > 1, ...
};

// Hertz contact duration of the scene's ball on its surface at impact speed v (PHYSICS.md §2;
// Johnson, Contact Mechanics, eq. 11.24): tau = 2.87 (m*^2 / (R* E*^2 v))^(1/5), m* = m,
// R* = R (ball on a massive flat plate), 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2.
// Throws Error(kBadScene) when the materials' elastic constants are unknown.
double HertzContactTime(const Scene& scene, double impact_speed_m_s);

// Throws Error(kNoBounces) for fewer than two impacts, Error(kBadScene/kBadParameter) for an
// invalid scene or options.
Analysis AnalyzeBounces(const Sequence& sequence, const Scene& scene,
                        const AnalysisOptions& options = {});

}  // namespace bouncecal
