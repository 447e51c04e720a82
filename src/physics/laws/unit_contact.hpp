// laws/unit_contact.hpp — one contact of a dimensionless power-law oscillator, integrated
// precisely; the master curves of the Hertz-type laws are built from it.
//
// Hertz-type laws scale: with L = (m* v^2 / k)^(2/5) and T = L / v, delta = L x, t = T s, the
// equation m* delta'' = -F becomes x'' = -f(x, x') with x(0) = 0, x'(0) = 1 and a force f
// that depends on one dimensionless damping number only (alpha for Tsuji, beta v^(1/5) for
// viscoelastic Hertz, alpha v for Hunt-Crossley). So e and t_c / T are functions of that number:
// master curves, computed once and interpolated.
#pragma once

#include <functional>
#include <vector>

namespace bouncecal::laws {

struct UnitContact {
  double restitution = 0.0;   // -x'(end)
  double contact_time = 0.0;  // in units of T
  double peak_overlap = 0.0;  // in units of L
  bool stuck = false;         // no end before max_time
};

// Integrates x'' = -force(x, x') from (0, 1) with Boost.Odeint dopri5 (dense output) and
// locates the end (x = 0, or force = 0 while x' < 0 when force_zero_end) and the peak by
// bisection on the dense output.
UnitContact IntegrateUnitContact(const std::function<double(double, double)>& force,
                                 bool force_zero_end, double rel_tol = 1e-12,
                                 double max_time = 1e3);

// A smooth monotone map y(x) tabulated at nodes x_i with values y_i and slopes dy_i,
// evaluated by cubic Hermite interpolation (binary search for the cell; clamped outside).
class HermiteTable {
 public:
  HermiteTable() = default;
  HermiteTable(std::vector<double> x, std::vector<double> y, std::vector<double> dy);
  double operator()(double x) const;
  double Derivative(double x) const;
  double XMin() const { return x_.front(); }
  double XMax() const { return x_.back(); }

 private:
  size_t Cell(double x) const;
  std::vector<double> x_, y_, dy_;
};

}  // namespace bouncecal::laws
