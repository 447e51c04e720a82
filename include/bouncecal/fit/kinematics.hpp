// bouncecal/fit/kinematics.hpp — impact times -> per-bounce speeds, restitution and energy loss.
//
// docs/physics.md §1-2 (seed 002 eqs. 7-12): with the flight model of the scene
// (no/linear/quadratic drag, buoyancy) each measured interval T_k = t_{k+1} - t_k (less the contact
// duration of impact k when the scene turns that effect on) gives the rebound speed v_out,k by
// inverting the exact flight time, and the arrival speed at k+1 from the same flight. Then e_k =
// v_out,k / v_in,k and eta_k = 1 - e_k^2, with uncertainties propagated from the onset timing
// sigmas (full covariance of the three times involved) and, for the first impact, from the drop
// height's sigma.
//
// Then the bounces are screened against a smooth e(v) curve with the per-bounce scatter model
// (bounce_screen.hpp): the ball's scatter sigma_s from bounce to bounce (scatter_e), bounces
// far off the curve (irregular_bounce), a drop height the first interval cannot follow from
// (drop_height_inconsistent); and, when the scene has no drag, whether quadratic drag would
// change e beyond its timing sigma (drag_likely_needed).
//
//   Analysis a = AnalyzeBounces(result.main(), scene, {});
#pragma once

#include <functional>
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
  double e = 0.0;        // v_out / v_in (NaN where unknown)
  double e_sigma = 0.0;  // from the timing (and drop height) sigmas: this bounce's measured e
  // e_sigma and the ball's scatter sigma_s together: e as an estimate of the ball's e at this
  // speed (what comparisons between bounces or recordings need); e_sigma if sigma_s is unknown.
  double e_total_sigma = 0.0;
  bool irregular = false;  // far off the smooth e(v) curve of the other bounces
  double eta = 0.0;        // 1 - e^2
  double eta_sigma = 0.0;
  double contact_s = 0.0;  // contact duration used for the correction (0 if off)
  // Correlation coefficient of e_k and e_{k+1} (they share t_k and t_{k+1}); NaN if unknown.
  double e_next_correlation = 0.0;
  // d e_k / d t_j for j = index-1, index, index+1 (1/s; NaN where e is unknown).
  double de_dt_prev = 0.0, de_dt_this = 0.0, de_dt_next = 0.0;
  // d v_in,k / d t_j for j = index-1, index (m/s per s; 0 when v_in comes from the drop).
  double dv_in_dt_prev = 0.0, dv_in_dt_this = 0.0;
  // First impact with v_in from a stated drop height h: d v_in / d h (1/s) and d e / d h (1/m).
  double dv_in_dh = 0.0, de_dh = 0.0;
};

struct AnalysisOptions {
  // Contact duration model when scene.effects.contact_duration is on: a fixed value, or
  // (when <= 0) the Hertz estimate from the scene's materials (docs/physics.md §2).
  double contact_time_s = 0.0;
  // When set, the contact duration at an impact speed (m/s -> s), e.g. the contact law's own
  // (calibrate uses the fitted law's); it replaces contact_time_s and the Hertz estimate.
  std::function<double(double)> contact_time_of_speed;
  // Use the scene's drop (height or impact speed) for the first impact's arrival speed. The
  // CLI turns this off when the user gave neither a scene file nor --height/--impact-speed
  // (the default 0.2 m would otherwise be taken as known).
  bool use_drop = true;
  // Screen the bounces with the scatter model (scatter, irregular bounces, drop consistency).
  bool screen = true;
  // Family-wise false-alarm probability of the irregular-bounce test over all bounces
  // (Bonferroni: each bounce is flagged beyond the two-sided normal quantile of alpha / n).
  double irregular_alpha = 0.01;
  // A stated first arrival speed further than this many sigmas from the one the next bounces'
  // trend agrees with makes the drop height inconsistent (p ~ 6e-5 for a Gaussian: a single
  // test per recording, with margin for the trend's form beyond its stated variance).
  double drop_z_max = 4.0;
  // When the scene has no drag: warn (drag_likely_needed) if quadratic drag would change some
  // e by more than this many of its timing sigmas. The CLI turns the check off when the user
  // chose drag = none explicitly.
  bool check_drag = true;
  double drag_effect_sigmas = 3.0;
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
  // The drop used for the first impact (height and its sigma; 0 when exact or unused).
  double height_sigma_m = 0.0;
  // Scatter of e from bounce to bounce about a smooth e(v) curve (REML; bounce_screen.hpp),
  // with its 1-sigma (a one-sided 68 % upper limit when scatter_e is 0). Unset: too few bounces.
  std::optional<double> scatter_e;
  std::optional<double> scatter_e_sigma;
  // The first impact's e does not follow from the stated drop (drop_height_inconsistent);
  // drop_height_fit_m is the height that would agree with the next bounces' trend.
  bool drop_consistent = true;
  std::optional<double> drop_height_fit_m;
  // Size of the quadratic-drag effect on e when the scene has none (max |e_drag - e| over the
  // bounces), with the ball's terminal speed; unset when not checked.
  std::optional<double> drag_effect_e;
  std::vector<Warning> warnings;  // coded: intervals that could not be used, e > 1, ...
};

// Hertz contact duration of the scene's ball on its surface at impact speed v (docs/physics.md
// §2.3; Johnson, Contact Mechanics, eq. 11.24): tau = 2.87 (m*^2 / (R* E*^2 v))^(1/5), R* = R
// (ball on a flat), 1/E* = (1-nu1^2)/E1 + (1-nu2^2)/E2, m* = m — or, with
// effects.surface_compliance, the reduced mass m M / (m + M) with the plate mass M.
// Throws Error(kBadScene) when the materials' elastic constants are unknown.
double HertzContactTime(const Scene& scene, double impact_speed_m_s);

// Throws Error(kNoBounces) for fewer than two impacts, Error(kBadScene/kBadParameter) for an
// invalid scene or options.
Analysis AnalyzeBounces(const Sequence& sequence, const Scene& scene,
                        const AnalysisOptions& options = {});

}  // namespace bouncecal
