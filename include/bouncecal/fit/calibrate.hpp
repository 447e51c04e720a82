// bouncecal/fit/calibrate.hpp — fit a contact law's damping to measured impacts (Ceres).
//
// The error model (docs/physics.md §6; scatter_model.hpp): a real ball's restitution scatters from
// bounce to bounce, e_k = e(u_k; theta) + eps_k, eps_k ~ N(0, sigma_s^2), on top of the timing
// noise of the onsets. sigma_s (reported as scatter_e with its sigma) is estimated with the
// law's parameters theta by restricted maximum likelihood, so chi2/dof of the full model is ~1
// when the law is right and the parameter sigmas include the scatter. Two strategies:
//  - kRestitution (default): per bounce, the measured e_k (three onsets, with the scene's drag,
//    buoyancy and contact duration) against the law's e at the measured arrival speed u_k;
//    residuals per bounce with their full banded timing covariance (neighbours share onsets;
//    u_k is measured too), so one irregular bounce does not shift the others. theta by
//    generalized least squares alternating with the REML profile of sigma_s (sigma_s = 0 on a
//    clean recording: the timing-only fit).
//  - kTrajectory: the whole bounce sequence simulated (simulator.hpp) against the onsets, the
//    scatter sigma_s of the restitution fit propagated along the trajectory (each bounce's eps
//    moves every later impact): C = C_t + sigma_s^2 G G^T, G = dt/deps. Nuisances per
//    recording: time origin t0 and first impact speed v0 (held, or tied to a stated drop
//    height through its sigma). Started from the restitution fit and from other starts.
// Several recordings are fitted jointly: shared law parameters, per-recording nuisances.
// Bounces that the screen (bounce_screen.hpp) flags irregular, and a first impact whose stated
// drop is inconsistent, are left out.
//
//   CalibrationOptions o;                  // damping parameters free, restitution strategy
//   o.free_parameters = {"k"};             // also free the stiffness
//   std::vector<CalibrationInput> recs = {{"drop.wav", detection.main()}};
//   Calibration c = Calibrate(recs, scene, o);   // scene.law names the law and its start values
//   if (c.outcome == FitOutcome::kConverged) std::cout << c.FullReport();
//
// Outcomes (FitOutcome): converged; iteration_limit (the solver stopped at max_iterations, or
// sigma_s did not settle); poor_fit (the law is rejected by its own goodness of fit: its e(v)
// misses a more flexible e(v) significantly, p < poor_fit_p_value, AND by more than
// misfit_tolerance_e and the ball's own scatter — a smaller significant misfit is converged
// with the warning law_misfit_small; sigma_s beyond plausible_scatter_e; or trajectory chi2
// beyond its p < poor_fit_p_value quantile); not_determinable (the data cannot pin a free
// damping parameter; says which and why); failed (no usable result). Data that defeat a fit
// are outcomes with a one-line reason and a hint (what to try next), not exceptions; bad input
// (options, scene, names) throws Error. No wall-clock limit: results do not depend on the
// machine.
//
// Derivatives: kAuto uses the law's analytic de/dp (RestitutionGradient) where it has one (for
// the trajectory: chained through the exact flight formulas when the scene has no
// contact-duration or surface effect); everything else uses central differences with a
// relative step rtol^(1/3), above the simulator's noise by construction.
//
// Physical constraints in every fit: the law's parameter bounds (so e <= 1); for the
// trajectory v0 >= the first rebound speed (e0 <= 1) and t0 within half the first interval of
// the first detected impact.
#pragma once

#include <functional>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/warning.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

enum class FitStrategy { kTrajectory, kRestitution };
enum class DerivativeMode { kAuto, kNumeric };
enum class RobustLoss { kNone, kHuber, kCauchy };
const char* FitStrategyName(FitStrategy s);        // "trajectory", "restitution"
const char* DerivativeModeName(DerivativeMode d);  // "auto", "numeric"
const char* RobustLossName(RobustLoss l);          // "none", "huber", "cauchy"
// Parse the names above; throw Error(kUsage) naming the value and the choices.
FitStrategy ParseFitStrategy(const std::string& s);
DerivativeMode ParseDerivativeMode(const std::string& s);
RobustLoss ParseRobustLoss(const std::string& s);

struct CalibrationOptions {
  FitStrategy strategy = FitStrategy::kRestitution;
  // Parameters freed in addition to the law's damping parameters (ParameterSpec::damping),
  // e.g. {"k"}. Unknown names: Error(kBadParameter).
  std::vector<std::string> free_parameters;
  // Damping parameters to hold at the scene's value instead of fitting.
  std::vector<std::string> fixed_parameters;
  DerivativeMode derivatives = DerivativeMode::kAuto;
  // Simulator relative tolerance inside the fit (absolute tolerance scales with it).
  double rel_tolerance = 1e-9;
  // Robust loss on each whitened residual (in units of its sigma) with this scale, in sigmas.
  // Off by default: the scatter model and the bounce screen handle irregular bounces; with a
  // loss, sigmas and chi2 are those of the plain Gaussian model at the robust optimum.
  RobustLoss loss = RobustLoss::kNone;
  double loss_scale_sigma = 3.0;
  int max_iterations = 100;  // Levenberg-Marquardt iterations per solve
  // Estimate the per-bounce scatter sigma_s; false: sigma_s = 0 (timing noise only).
  bool estimate_scatter = true;
  // Use the scene's drop (height with its sigma, or impact speed) for the first impact when it
  // is consistent with the next bounces: its e becomes a data point (restitution), v0 is tied to
  // it (trajectory). The CLI turns this off when the user gave no drop.
  bool use_drop = true;
  // The kinematics and the bounce screen (irregular bounces, drop consistency, drag check).
  AnalysisOptions analysis;
  // Start values: seed damping from DampingForRestitution at the median measured e.
  bool seed_from_inverse_map = true;
  // Start points tried (the best fit wins; others that end elsewhere with an equally good fit
  // give starts_disagree). 1 = only the best guess.
  int max_starts = 4;
  // Threads for the simulated contacts of a law without a closed-form e(v): the contacts at
  // the points' speeds (and their difference quotients) of one evaluation run concurrently.
  // The result does not depend on it (each contact is computed as on one thread). The
  // expression law (its parser keeps state) always uses one.
  int threads = 1;
  // Number of points of the e(v) table over the measured speed range.
  int e_of_v_points = 8;
  // A free parameter whose relative 1-sigma exceeds this (or that lies in the numerical null
  // space of the Jacobian) is reported undetermined.
  double undetermined_relative_sigma = 1.0;
  // Goodness of fit: the model is rejected (poor_fit) when a test's p-value is below this ...
  double poor_fit_p_value = 1e-3;
  // ... and, for the law's e(v) against a more flexible one, when the misfit (rms over the
  // bounces) also exceeds this and the ball's own scatter about the flexible e(v). 0.002: the
  // e per impact the exporters' decks must reproduce in the simulators (export integration
  // suite), so a smaller misfit is below what the downstream DEM runs are held to.
  double misfit_tolerance_e = 0.002;
  // ... or when sigma_s exceeds this by more than two of its sigmas: real balls scatter by
  // 0.005-0.03 (docs/physics.md §6, misfit of the law included); beyond 0.05 the law does not
  // describe the bounces, or they are not one ball's bounces.
  double plausible_scatter_e = 0.05;
  // Trajectory start values of the nuisances per recording (first impact speed, time origin);
  // empty: estimated from the first interval and the first onset.
  std::vector<double> start_impact_speeds_m_s;
  std::vector<double> start_time_origins_s;
  bool IsValid(std::string* error) const;
};

// One recording's measured impacts (the main bounce sequence).
struct CalibrationInput {  // one recording
  std::string name;        // file name, for messages and the report
  Sequence sequence;       // impacts with timing sigmas
};

enum class FitOutcome {
  kConverged,        // usable: converged, every free damping parameter determined, fit adequate
  kIterationLimit,   // the solver stopped at the iteration limit: not at an optimum
  kPoorFit,          // the law is rejected by its own goodness of fit
  kNotDeterminable,  // a free damping parameter is not determined by the data
  kFailed,           // no usable result (solver failure, the law sticks, ...)
};
// "converged", "iteration_limit", "poor_fit", "not_determinable", "failed"
const char* FitOutcomeName(FitOutcome o);
// The process exit code of an outcome (error.hpp): 0, 13, 14, 15, 10.
ErrorCode FitOutcomeExitCode(FitOutcome o);

struct FittedParameter {
  std::string name;
  std::string unit;
  double value = 0.0;
  double sigma = 0.0;  // 1-sigma; NaN when fixed or undetermined
  double lower = 0.0, upper = 0.0;
  bool damping = false;
  bool fixed = false;       // held at the scene's value
  bool determined = false;  // free: fitted with a finite sigma; fixed: would be if freed
  bool at_bound = false;    // the fit stopped on a bound
};

// Per-recording nuisance parameters (trajectory strategy).
struct RecordingFit {
  std::string name;
  int impacts = 0;                      // measured impacts used
  int simulated_impacts = 0;            // impacts in the simulated sequence at the optimum
  double impact_speed_m_s = 0.0;        // first impact speed v0
  double impact_speed_sigma_m_s = 0.0;  // NaN when held
  bool impact_speed_fixed = false;
  double time_origin_s = 0.0;  // time of the first impact in the file
  double time_origin_sigma_s = 0.0;
  double rms_residual = 0.0;      // s (trajectory) or e (restitution)
  std::vector<double> residuals;  // model - measured, same unit
};

struct EOfVPoint {
  double v_m_s = 0.0;
  double e = 0.0;
  double sigma = 0.0;
};

struct Calibration {
  std::string law;      // registry name
  std::string formula;  // the law's one-line formula and its source (paper + equation)
  std::string source;
  FitStrategy strategy = FitStrategy::kRestitution;
  DerivativeMode derivatives = DerivativeMode::kAuto;
  bool analytic_jacobian = false;  // kAuto found an analytic path for this law/scene
  FitOutcome outcome = FitOutcome::kFailed;
  std::string reason;                       // one line: why this outcome
  std::string hint;                         // one line: what to try next (flags, laws, scene)
  std::string message;                      // notes (start values, starts, ...)
  std::vector<Warning> warnings;            // coded diagnostics (docs/cli.md lists the codes)
  std::vector<FittedParameter> parameters;  // every law parameter, in the law's order
  std::vector<RecordingFit> recordings;
  std::vector<EOfVPoint> e_of_v;            // over the measured speed range
  double v_min_m_s = 0.0, v_max_m_s = 0.0;  // measured impact speed range
  // Per-bounce scatter sigma_s of e and its 1-sigma (a one-sided 68 % upper limit when
  // scatter_e is 0, scatter_at_zero).
  double scatter_e = 0.0;
  double scatter_e_sigma = 0.0;
  bool scatter_at_zero = false;
  int num_residuals = 0;
  int num_free = 0;  // free parameters including nuisances (not sigma_s)
  int dof = 0;
  double chi2 = 0.0;          // r^T C^-1 r of the full model (timing + scatter)
  double chi2_dof = 0.0;      // ~1 when the model is right
  double rms_residual = 0.0;  // s (trajectory) or e (restitution)
  std::string residual_unit;  // "s" or "1"
  // The law's e(v) against a more flexible e(v), each with its own scatter (docs/physics.md
  // §9.4): likelihood-ratio chi2 with trend_dof degrees of freedom (0: not tested) and its
  // p-value; the misfit, rms over the bounces of the two curves' difference; the tolerance it
  // was judged against (max of misfit_tolerance_e and misfit_scatter_e, the ball's scatter
  // about the flexible e(v)). NaN when not tested.
  double trend_chi2 = 0.0;
  int trend_dof = 0;
  double misfit_p_value = std::numeric_limits<double>::quiet_NaN();
  double misfit_e = std::numeric_limits<double>::quiet_NaN();
  double misfit_tolerance_e = std::numeric_limits<double>::quiet_NaN();
  double misfit_scatter_e = std::numeric_limits<double>::quiet_NaN();
  double neg_log_likelihood = 0.0;  // Gaussian -log L at the optimum
  // 2 nll + 2 k and 2 nll + k ln n (docs/physics.md §9.4), k = num_free (the fitted law
  // parameters and the trajectory's nuisances) + 1 for the scatter when it is estimated.
  double aic = 0.0, bic = 0.0;
  int starts = 0;               // start points tried
  int starts_reached_best = 0;  // of which ended at the best fit
  int iterations = 0;
  long simulations = 0;  // simulator calls (sequences or contacts)
  double solve_time_s = 0.0;
  Scene scene;  // the scene with the fitted law parameters (drop cleared when not used)

  std::vector<std::string> Determined() const;    // free law parameters with a finite sigma
  std::vector<std::string> Undetermined() const;  // law parameters the data cannot pin
  // One line: "walton-braun: gamma = 0.4081 ± 0.0012, scatter 0.004, chi2/dof 1.02 (converged)".
  std::string BriefReport() const;
  // Parameters ± sigma with units, scatter, nuisances, fit statistics, determined/undetermined,
  // e(v), warnings.
  std::string FullReport() const;
};

// Fits scene.law (its parameters are start values and the held values) to the recordings.
// Bad input throws Error(kUsage / kBadParameter / kBadScene); what the data do to the fit is
// the outcome.
Calibration Calibrate(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                      const CalibrationOptions& options);

// Law comparison: fits every registered law as a single Calibrate would (same options, starting
// from its defaults; the "expression" law only when scene.law names it with an expression) and
// ranks the adequate fits (outcome converged) by AIC, best first; the others follow, each with
// its outcome and reason. `jobs` laws are fitted concurrently (the output does not depend on
// it).
struct LawComparisonRow {
  Calibration fit;
  bool adequate = false;   // converged: ranked
  double delta_aic = 0.0;  // AIC - best adequate AIC (NaN when not adequate)
};
std::vector<LawComparisonRow> CompareLaws(const std::vector<CalibrationInput>& recordings,
                                          const Scene& scene, const CalibrationOptions& options,
                                          int jobs = 1);
// The ranked table as markdown-like text, with e(v) at `speeds` (m/s).
std::string LawComparisonTable(const std::vector<LawComparisonRow>& rows,
                               const std::vector<double>& speeds_m_s);

}  // namespace bouncecal
