// The Ceres solver settings every calibration solve uses (internal to the fit wing).
#pragma once

#include <ceres/ceres.h>

#include <cmath>
#include <mutex>
#include <optional>
#include <vector>

#include "bouncecal/fit/calibrate.hpp"
#include "fit/calibrate_stages.hpp"

namespace bouncecal::calib {

// Dense QR (a few parameters, up to a few hundred residuals), the options' iteration limit and
// no wall-clock limit (results must not depend on the machine); relative cost change and step
// 1e-10: far below any reported sigma, above the noise of differenced simulations (which
// otherwise keeps Levenberg-Marquardt crawling). One thread: fits of several laws or files run
// in parallel instead.
inline ceres::Solver::Options SolverOptions(const CalibrationOptions& o) {
  ceres::Solver::Options so;
  so.linear_solver_type = ceres::DENSE_QR;
  so.max_num_iterations = o.max_iterations;
  so.function_tolerance = 1e-10;
  so.parameter_tolerance = 1e-10;
  so.gradient_tolerance = 1e-12;
  so.num_threads = 1;
  so.logging_type = ceres::SILENT;
  return so;
}

// The last evaluation of a cost function's model, reused when Ceres asks for the same point
// again. Ceres 2.1 evaluates each accepted point of a bounded problem three times: with the
// Jacobian in the projected line search, residuals only for the candidate's cost, and with the
// Jacobian again for the next step (measured: 8 Jacobian and 4 residual evaluations in 4
// iterations of a restitution fit). Here every evaluation is a set of contact simulations and
// the model is deterministic, so a bitwise-equal point gives the same values: reused, the
// results are identical and two of the three evaluations cost nothing. The mutex keeps
// Evaluate safe if Ceres ever calls it from several threads.
template <typename Value>
class LastEvaluation {
 public:
  // The stored value for this key, if it was computed with a Jacobian when one is wanted.
  std::optional<Value> Find(const std::vector<double>& key, bool with_jacobian) const {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!value_ || key != key_ || (with_jacobian && !with_jacobian_)) return std::nullopt;
    return value_;
  }
  void Store(std::vector<double> key, bool with_jacobian, Value value) const {
    std::lock_guard<std::mutex> lock(mutex_);
    key_ = std::move(key);
    with_jacobian_ = with_jacobian;
    value_ = std::move(value);
  }

 private:
  mutable std::mutex mutex_;
  mutable std::vector<double> key_;
  mutable bool with_jacobian_ = false;
  mutable std::optional<Value> value_;
};

// The law's bounds on the block u of its active free parameters (scaled: x = scale * u).
inline void SetLawBounds(const LawSetup& s, const std::vector<int>& active, double* u,
                         ceres::Problem* problem) {
  for (size_t j = 0; j < active.size(); ++j) {
    const size_t a = static_cast<size_t>(active[j]);
    const ParameterSpec& sp = s.specs()[static_cast<size_t>(s.free[a])];
    if (std::isfinite(sp.lower)) {
      problem->SetParameterLowerBound(u, static_cast<int>(j), sp.lower / s.scale[a]);
    }
    if (std::isfinite(sp.upper)) {
      problem->SetParameterUpperBound(u, static_cast<int>(j), sp.upper / s.scale[a]);
    }
  }
}

}  // namespace bouncecal::calib
