// bouncecal/fit/calibrate.hpp — fit a contact law's damping to measured impacts (Ceres).
//
// Two strategies, both exposed:
//  - kTrajectory: simulate the whole bounce sequence (simulator.hpp, only the scene's effects)
//    and fit the simulated impact times to the measured onsets, each weighted by its timing
//    sigma. Nuisance parameters per recording: the time origin t0 (the release is silent) and
//    the first impact speed v0 (unless the options hold it at the scene's drop).
//  - kRestitution: fit the law's e(v) to the per-bounce (v_in, e ± e_sigma) points from
//    AnalyzeBounces (closed form where the law has one, one simulated contact per point
//    otherwise).
// Several recordings are fitted jointly: shared law parameters, per-recording nuisances.
//
//   CalibrationOptions o;                  // damping parameters free, trajectory strategy
//   o.free_parameters = {"k"};             // also free the stiffness
//   std::vector<CalibrationInput> recs = {{"drop.wav", detection.main()}};
//   Calibration c = Calibrate(recs, scene, o);   // scene.law names the law and its start values
//   if (c.outcome == FitOutcome::kConverged) std::cout << c.FullReport();
//
// Derivatives: kAuto uses the law's analytic dE/dp (RestitutionGradient) chained through the
// exact flight formulas where the law has it and the scene has no contact-duration or surface
// effect; everything else uses central differences with a relative step rtol^(1/3) (the optimum
// for a function whose own noise is ~rtol), above the simulator's noise by construction.
//
// Common mistakes: a constant-e law's stiffness does not change impact times (only the contact
// duration, which is off unless the scene turns it on) — freeing k then reports it undetermined;
// the detector's timing sigmas set the weights, so chi2/dof far from 1 means they are off (the
// reported sigmas are scaled by sqrt(chi2/dof) when it exceeds 1).
//
// Errors: Error(kFitFailed) when the data cannot determine the free parameters (too few
// impacts), when the law sticks at the start values, or when no step succeeds;
// Error(kBadParameter) for an unknown law or parameter name.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
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
  FitStrategy strategy = FitStrategy::kTrajectory;
  // Parameters freed in addition to the law's damping parameters (ParameterSpec::damping),
  // e.g. {"k"}. Unknown names: Error(kBadParameter).
  std::vector<std::string> free_parameters;
  // Damping parameters to hold at the scene's value instead of fitting.
  std::vector<std::string> fixed_parameters;
  DerivativeMode derivatives = DerivativeMode::kAuto;
  // Simulator relative tolerance inside the fit (absolute tolerance scales with it).
  double rel_tolerance = 1e-9;
  // Robust loss on each residual (in units of its sigma) with this scale, in sigmas.
  RobustLoss loss = RobustLoss::kHuber;
  double loss_scale_sigma = 3.0;
  int max_iterations = 60;  // Levenberg-Marquardt iterations
  // Trajectory: hold the first impact speed at the scene's drop (height or impact speed)
  // instead of fitting it as a nuisance parameter. Restitution: include the first impact's
  // e (from the drop height) among the points.
  bool use_drop = false;
  // Start values: seed damping from DampingForRestitution at the median measured e.
  bool seed_from_inverse_map = true;
  // Number of points of the e(v) table over the measured speed range.
  int e_of_v_points = 8;
  // A free parameter whose relative 1-sigma exceeds this (or that lies in the numerical null
  // space of the Jacobian) is reported undetermined.
  double undetermined_relative_sigma = 1.0;
  // Law comparison (CompareLaws): every law is ranked with this simulator tolerance and
  // iteration limit (ranking needs far less precision than the result), then the best law is
  // refitted with rel_tolerance and max_iterations.
  // Trajectory start values of the nuisances per recording (first impact speed, time origin);
  // empty: estimated from the first interval and the first onset.
  std::vector<double> start_impact_speeds_m_s;
  std::vector<double> start_time_origins_s;
  double comparison_rel_tolerance = 1e-7;
  int comparison_max_iterations = 25;
  bool IsValid(std::string* error) const;
};

// One recording's measured impacts (the main bounce sequence).
struct CalibrationInput {  // one recording
  std::string name;        // file name, for messages and the report
  Sequence sequence;       // impacts with timing sigmas
};

enum class FitOutcome {
  kConverged,        // usable: every free damping parameter is determined
  kNotDeterminable,  // converged, but a free damping parameter is not determined by the data
  kFailed,           // no usable result (solver failure, law sticks at the optimum, ...)
};
const char* FitOutcomeName(FitOutcome o);  // "converged", "not_determinable", "failed"

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
  FitStrategy strategy = FitStrategy::kTrajectory;
  DerivativeMode derivatives = DerivativeMode::kAuto;
  bool analytic_jacobian = false;  // kAuto found an analytic path for this law/scene
  FitOutcome outcome = FitOutcome::kFailed;
  std::string message;                      // why, when not converged; notes otherwise
  std::vector<FittedParameter> parameters;  // every law parameter, in the law's order
  std::vector<RecordingFit> recordings;
  std::vector<EOfVPoint> e_of_v;            // over the measured speed range
  double v_min_m_s = 0.0, v_max_m_s = 0.0;  // measured impact speed range
  int num_residuals = 0;
  int num_free = 0;  // free parameters including nuisances
  int dof = 0;
  double chi2 = 0.0;  // sum of squared weighted residuals (no robust loss)
  double chi2_dof = 0.0;
  double rms_residual = 0.0;    // s (trajectory) or e (restitution)
  std::string residual_unit;    // "s" or "1"
  double aic = 0.0, bic = 0.0;  // chi2 + 2 k, chi2 + k ln n (Gaussian, known sigmas)
  int iterations = 0;
  long simulations = 0;  // simulator calls (sequences or contacts)
  double solve_time_s = 0.0;
  std::string solver_report;  // ceres BriefReport
  Scene scene;                // the scene with the fitted law parameters

  std::vector<std::string> Determined() const;    // free law parameters with a finite sigma
  std::vector<std::string> Undetermined() const;  // law parameters the data cannot pin
  // One line: "walton-braun: gamma = 0.4081 ± 0.0012, rms 3.1 us, chi2/dof 1.02 (converged)".
  std::string BriefReport() const;
  // Parameters ± sigma with units, nuisances, fit statistics, determined/undetermined, e(v).
  std::string FullReport() const;
};

// Fits scene.law (its parameters are start values and the held values) to the recordings.
// Throws Error(kFitFailed / kBadParameter / kBadScene) as described above.
Calibration Calibrate(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                      const CalibrationOptions& options);

// Law comparison: fits every registered law (starting from its defaults; the "expression" law
// only when scene.law names it with an expression) and returns them ranked by AIC, best first.
// A law whose fit throws gets outcome kFailed and its message; the others still run. Ranking
// fits use comparison_rel_tolerance / comparison_max_iterations; the best is refitted with the
// full options (rows[0].fit is that refit). `jobs` laws are fitted concurrently.
struct LawComparisonRow {
  Calibration fit;
  double delta_aic = 0.0;  // AIC - best AIC
};
std::vector<LawComparisonRow> CompareLaws(const std::vector<CalibrationInput>& recordings,
                                          const Scene& scene, const CalibrationOptions& options,
                                          int jobs = 1);
// The ranked table as markdown-like text, with e(v) at `speeds` (m/s).
std::string LawComparisonTable(const std::vector<LawComparisonRow>& rows,
                               const std::vector<double>& speeds_m_s);

}  // namespace bouncecal
