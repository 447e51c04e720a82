// laws/hertz_family.hpp — numbers of the Hertz-type laws that tests and the fitter may want
// directly (internal header).
#pragma once

namespace bouncecal::laws {

// Tsuji's dimensionless damping alpha (eta = alpha sqrt(m* k)) giving restitution e exactly
// under F = k d^1.5 + eta d^0.25 d' (hertz_tsuji.cpp).
double HertzTsujiAlpha(double e);

// Viscoelastic Hertz, F = k (d^1.5 + 1.5 A d^0.5 d'): e depends on b = beta v^(1/5) only,
// beta = 1.5 A (k/m*)^(2/5). The master curve e(b) (exact numerics) and the low-speed series of
// Ramirez, Poschel, Brilliantov & Schwager, PRE 60 (1999) 4465 (docs/physics.md §3.5):
//   e = 1 - C1 b + C2 b^2 - ...,  C1 = 1.15344, C2 = 0.79826.
double ViscoelasticRestitution(double b);
double ViscoelasticSeriesRestitution(double b);
constexpr double kRamirezC1 = 1.15344;
constexpr double kRamirezC2 = 0.79826;

}  // namespace bouncecal::laws
