// The Ceres solver settings every calibration solve uses (internal to the fit wing).
#pragma once

#include <ceres/ceres.h>

#include <cmath>
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
