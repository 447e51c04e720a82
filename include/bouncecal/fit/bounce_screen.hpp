// bouncecal/fit/bounce_screen.hpp — what the bounces say about themselves, before any law.
//
// AnalyzeBounces (kinematics.hpp) calls these after computing e per bounce:
//  - ScreenBounces fits a smooth e(v) curve (terms 1, ln v, v, (ln v)^2, one to four by the
//    number of bounces) with the per-bounce scatter model (scatter_model.hpp, REML), which gives
//    the ball's scatter sigma_s (Analysis::scatter_e) without assuming any contact law. A bounce
//    whose residual exceeds the two-sided normal quantile of irregular_alpha / n (Bonferroni
//    over the n bounces) is flagged `irregular_bounce` and the curve is refitted without it.
//    Then the drop: the local trend of the next (up to 8) bounces, quadratic in ln v, gives the
//    arrival speed u* that the first rebound agrees with (v_out,0 / u* = e(u*), so the trend is
//    only evaluated near its data however wrong the stated drop is); a stated arrival speed
//    beyond drop_z_max sigmas of u* (trend, scatter, timing, the trend's form, the height's
//    sigma) makes the drop `drop_height_inconsistent`, with the height that would agree and the
//    likely cause (file starts after the drop, a unit slip, the height of the hand instead of
//    the ball's bottom).
//  - CheckDrag (scene without drag): recomputes e with quadratic drag for the ball and reports
//    `drag_likely_needed` with the size of the effect when, at some bounce, it exceeds
//    drag_effect_sigmas of that bounce's sigma of e.
// Fits use the same flags: irregular bounces and an inconsistent first impact are left out.
#pragma once

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

// Fills analysis->scatter_e(_sigma), each bounce's e_total_sigma and irregular flag,
// drop_consistent / drop_height_fit_m, and adds the warnings.
void ScreenBounces(const Scene& scene, const AnalysisOptions& options, Analysis* analysis);

// Fills analysis->drag_effect_e and adds drag_likely_needed when it matters (scene without drag).
void CheckDrag(const Sequence& sequence, const Scene& scene, const AnalysisOptions& options,
               Analysis* analysis);

// The drop height (ball's bottom above the plate) whose fall ends at arrival speed v under the
// scene's flight model; NaN when no height gives that speed (v at or above the terminal speed).
double HeightForArrivalSpeed(const Scene& scene, double v_m_s);

}  // namespace bouncecal
