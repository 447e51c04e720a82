// laws/jiang_liu.hpp — the derived coefficients of the Jiang-Liu law (internal header; the
// tests use them to integrate the heat of eq. 33 independently).
#pragma once

#include <span>

#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal::laws {

// Parameters, in Parameters() order: k (N/m^1.5), eta (prefactor of eq. 39, paper: 0.1),
// tau (prefactor of eq. 37, paper: 0.06).
// eta^relax = a * w_r^(1/4) * Theta(delta/d),  a = eta d^(-3/8) k^(1/4) m^(1/2)   (eq. 39)
double JiangLiuA(std::span<const double> p, const ContactBody& body);
// tau_relax = tau sqrt(m/k) / d^(1/4)                                             (eq. 37)
double JiangLiuTau(std::span<const double> p, const ContactBody& body);
// Smooth Heaviside Theta(x) = [tanh((x - x0)/x1) + 1]/2 (seed 000, below eq. 41), x = delta/d.
double JiangLiuTheta(double x);
constexpr double kJiangLiuX0 = 5e-12;  // relative to d: far below any overlap of interest
constexpr double kJiangLiuX1 = 1e-12;

}  // namespace bouncecal::laws
