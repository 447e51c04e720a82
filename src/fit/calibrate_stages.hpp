// The stages of Calibrate (calibrate.hpp), each testable on its own (tests/calibrate_stages_test):
//   1. SetUpProblem   the law with its free parameters, each recording's analysed bounces
//                     (kinematics + screen), the per-bounce data the fit uses
//   2. MakeStarts     start vectors: the law's inverse map at the median measured e, a scan of
//                     the damping, the scene's values
//   3. SolveRestitution / SolveTrajectory
//                     per-bounce restitution with scatter (GLS for theta alternating with REML
//                     for sigma_s) / impact times with the scatter propagated along the
//                     trajectory; each from every start, keeping the best
//   4. Uncertainty    identifiability, parameter covariance, e(v) band
//   5. Diagnose       outcome and its reason, goodness of fit, coded warnings
// Internal to the fit wing: include "fit/calibrate_stages.hpp" (src/ is on the tests' path).
#pragma once

#include <atomic>
#include <functional>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "bouncecal/core/warning.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/fit/scatter_model.hpp"
#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal::calib {

// ---- Stage 1: problem set-up ----------------------------------------------------------------

// The law with its parameter layout: which entries of the full vector are free.
struct LawSetup {
  std::shared_ptr<const ContactLaw> law;
  ContactBody body;
  std::vector<double> start;    // full parameter vector (start and held values)
  std::vector<int> free;        // indices into start of the free parameters
  std::vector<double> typical;  // magnitude per full index, for steps and scaling
  // Ceres sees each free parameter scaled by its typical magnitude (x = scale * u), so that
  // stiffnesses of 1e9 and dimensionless dampings of 0.4 give a well-conditioned J^T J.
  std::vector<double> scale;  // per free parameter
  bool has_gradient = false;  // RestitutionGradient works
  bool has_closed_e = false;  // Restitution works
  // Contacts may be simulated on several threads at once (CalibrationOptions::threads): every
  // law but the expression law, whose parser keeps state between evaluations.
  bool concurrent = true;
  // Integrator steps of one simulated contact at the median measured speed at the first start
  // point (ProbeContactCost; 0: not probed): what one contact of this law costs, for deciding
  // whether an evaluation is worth a thread.
  int contact_steps = 0;

  const std::vector<ParameterSpec>& specs() const { return law->Parameters(); }
  std::vector<double> Full(const double* u) const;  // free values (scaled) -> full vector
  std::vector<double> Scaled(const std::vector<double>& p) const;  // full -> free (scaled)
};

// Throws Error(kBadParameter) for an unknown law or parameter name (bad input).
LawSetup MakeLawSetup(const Scene& scene, const CalibrationOptions& options);

// Restitution at one speed: closed form when the law has it, one simulated contact (with
// gravity g during the contact) otherwise. Throws Error when the simulator fails.
double ModelRestitution(const LawSetup& s, const std::vector<double>& p, double v_m_s, double g,
                        const SimulatorOptions& sim, std::atomic<long>* simulations);

// Relative central-difference step for a function whose own noise is ~rtol: rtol^(1/3).
double RelativeStep(double rtol);

struct RecordingData {
  std::string name;
  Sequence sequence;
  Analysis analysis;       // kinematics with the screen (scatter, irregular, drop)
  bool drop_used = false;  // the first impact's speed comes from the scene's drop (consistent)
};

struct FitProblem {
  CalibrationOptions options;
  Scene scene;
  LawSetup setup;
  double g = 9.8;  // effective gravity (during contacts too)
  SimulatorOptions sim;
  std::vector<RecordingData> recordings;
  RestitutionData data;                   // the per-bounce points the fit uses
  std::vector<Warning> warnings;          // from the analyses
  std::string not_determinable;           // set when the data cannot determine the free parameters
  double e_median = 0.0, v_median = 0.0;  // of the points, for seeding
  double scatter_start = 0.0;             // sigma_s from the screens (start of the fit)
  std::string seed_note;                  // how the start values were chosen
};

// Sets setup.contact_steps from one contact at the points' median speed with parameters p
// (when the fit may spread its contacts over threads).
void ProbeContactCost(FitProblem* fp, const std::vector<double>& p);

// Runs task(k) for k in [0, n), each the `contacts` simulated contacts at one speed: on
// CalibrationOptions::threads threads when the law allows it (LawSetup::concurrent) and the
// work is worth a thread (n * contacts * LawSetup::contact_steps integrator steps); each k's
// result is computed as on one thread, so the values do not depend on the count.
void ForEachSpeed(const FitProblem& fp, std::size_t n, int contacts,
                  const std::function<void(std::size_t)>& task);

// Stage 1. Bad input throws (kUsage options, kBadScene scene, kBadParameter names); what the
// data cannot give is recorded in not_determinable.
FitProblem SetUpProblem(const std::vector<CalibrationInput>& recordings, const Scene& scene,
                        const CalibrationOptions& options);
// The kinematics and screen of every recording, and the per-bounce data. law_contact: when the
// scene has the contact-duration effect and the law a closed-form contact time, take the
// contacts out of the intervals with the law's own durations at these parameters (else the
// Hertz estimate).
void AnalyzeRecordings(FitProblem* problem, const std::vector<CalibrationInput>& recordings,
                       const std::vector<double>* law_contact);

// ---- Stage 2: starts ------------------------------------------------------------------------

// Full parameter vectors to start from, best guess first, without duplicates.
std::vector<std::vector<double>> MakeStarts(FitProblem* problem, std::atomic<long>* simulations);

// ---- Stage 3: solve -------------------------------------------------------------------------

struct Solution {
  bool ok = false;
  std::string failure;        // why not ok (a message naming the law and the problem)
  std::vector<double> p;      // full parameter vector
  std::vector<bool> held;     // per free parameter: held at its start (undetermined)
  ScatterFit scatter;         // sigma_s and the GLS quantities at the optimum
  Eigen::VectorXd residuals;  // model - measured (e for restitution, s for trajectory)
  Eigen::MatrixXd jacobian;   // d residuals / d u (scaled free parameters, then nuisances)
  Eigen::MatrixXd timing_cov;
  Eigen::MatrixXd design;  // scatter design G (empty: identity)
  double cost = 0.0;       // 1/2 chi2 at the start's sigma_s (compares starts)
  int iterations = 0;
  bool iteration_limit = false;
  std::string limit_note;
  // Trajectory nuisances per recording.
  std::vector<double> v0, t0, v0_sigma, t0_sigma;
  std::vector<bool> v0_free;
  std::vector<int> simulated_impacts;
  std::vector<std::vector<double>> v_in;  // simulated arrival speeds per recording
};

struct StartsReport {
  int tried = 0;
  int reached_best = 0;   // starts ending within the best's sigma
  bool disagree = false;  // another start ends elsewhere with an equally good fit
  std::string note;
};

// Per-bounce restitution with scatter from one start; sigma_start is the starting sigma_s.
// alternate = false: one solve at sigma_start, with the timing covariance and the gravity
// offsets taken at `reference` (so that solves from different starts are comparable).
Solution SolveRestitution(const FitProblem& problem, const std::vector<double>& start,
                          const std::vector<bool>& held, double sigma_start, bool alternate,
                          std::atomic<long>* simulations,
                          const std::vector<double>* reference = nullptr);
// How many impacts each flagged gap holds: count[k] for measured impact k (0 unless k is in
// sequence.missed_after). The detector flags a gap ("at least one impact missing between k and
// k + 1"); the trajectory needs the number, since measured impact k + 1 is simulated impact
// k + 1 + (all misses before it). The intervals inside a gap continue the sequence's geometric
// decay: with d the last interval before the gap (predicted, after an earlier gap) and r the
// median ratio of the last three regular intervals, n is the count whose n + 1 intervals
// d r + ... + d r^(n+1) come closest to the gap (1 <= n <= 50).
std::vector<int> MissedCounts(const Sequence& sequence);
// Impact times with the scatter sigma_s propagated along the trajectory, from one start.
Solution SolveTrajectory(const FitProblem& problem, const std::vector<double>& start,
                         const std::vector<bool>& held, double sigma_s,
                         std::atomic<long>* simulations);
// Runs the strategy's solver from every start; the best (lowest cost) first.
Solution SolveFromStarts(const FitProblem& problem, const std::vector<std::vector<double>>& starts,
                         const std::vector<bool>& held, StartsReport* report,
                         std::atomic<long>* simulations);

// ---- Stage 4: uncertainty -------------------------------------------------------------------

struct Uncertainty {
  std::vector<bool> undetermined;             // per free parameter
  std::vector<std::string> undetermined_why;  // per free parameter (empty when determined)
  std::vector<bool> held_determinable;        // per full index: a held parameter the data could fit
  Eigen::MatrixXd covariance;                 // of the free parameters, in their own units
  std::vector<double> sigma;                  // per full index (NaN when held/undetermined)
  std::vector<EOfVPoint> e_of_v;
  double v_min_m_s = 0.0, v_max_m_s = 0.0;
};

// Which free parameters the whitened Jacobian cannot determine (null space, or relative sigma
// above the threshold), each with a reason.
std::vector<bool> FindUndetermined(const Solution& s, const FitProblem& problem,
                                   std::vector<std::string>* why);
Uncertainty EstimateUncertainty(const FitProblem& problem, const Solution& s,
                                std::atomic<long>* simulations);

// ---- Stage 5: diagnostics -------------------------------------------------------------------

struct Diagnosis {
  FitOutcome outcome = FitOutcome::kConverged;
  std::string reason;  // one line
  std::string hint;    // the next step, one line
  std::vector<Warning> warnings;
  double trend_chi2 = 0.0;  // lack-of-fit statistic of the restitution model (LawMisfit::chi2)
  int trend_dof = 0;
  double misfit_p_value = std::numeric_limits<double>::quiet_NaN();
  double misfit_e = std::numeric_limits<double>::quiet_NaN();
  double misfit_tolerance_e = std::numeric_limits<double>::quiet_NaN();
  double misfit_scatter_e = std::numeric_limits<double>::quiet_NaN();
};

Diagnosis Diagnose(const FitProblem& problem, const Solution& s, const Uncertainty& u,
                   const StartsReport& starts);

// Stage 5a (law_misfit.cpp): the law's e(v) against a more flexible one, law + a x + b x^2 with
// x = ln(u / u_mean), each with its own sigma_s (ML profile), by their likelihood ratio; the
// misfit's size is the rms over the bounces of the two fitted curves' difference (each at its
// REML sigma_s). dof = 0: not tested (trajectory strategy, or too few points).
struct LawMisfit {
  int dof = 0;               // parameters the flexible e(v) adds (2; 1 with few points)
  double chi2 = 0.0;         // 2 (nll_law - nll_flexible)
  double p_value = 1.0;      // chi2(dof) upper tail
  double rms_e = 0.0;        // rms of flexible e(v) - law e(v) over the bounces
  double scatter_e = 0.0;    // sigma_s about the flexible e(v): the ball's own scatter
  double tolerance_e = 0.0;  // max(CalibrationOptions::misfit_tolerance_e, scatter_e)
  bool significant = false;  // p_value < CalibrationOptions::poor_fit_p_value
  bool matters = false;      // significant and rms_e > tolerance_e: poor_fit
};
LawMisfit TestLawMisfit(const FitProblem& problem, const Solution& s);
// The registered laws (the expression law aside) whose e changes with the impact speed, found
// by evaluating each at its default parameters a decade apart about the median measured speed.
std::vector<std::string> SpeedDependentLaws(const FitProblem& problem);
// What to try when a law's e(v) has the wrong shape: --law all, the speed-dependent laws other
// than `law`, the contact-duration effect when it is off, a drop height's sigma when it is exact.
std::string LawShapeHint(const FitProblem& problem, const std::string& law);
// One line with the misfit's numbers.
std::string MisfitText(const LawMisfit& m);

}  // namespace bouncecal::calib
