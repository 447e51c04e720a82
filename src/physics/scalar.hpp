// physics/scalar.hpp — the two scalar types of the physics code, double and ceres::Jet (forward
// sensitivities), written so that both compute the same values (internal header).
//
// The sensitivity path of the simulator must reproduce the plain path's numbers bit for bit
// (same steps, same events, same impacts): every operation on the value part must be the one the
// double code does. ceres::Jet divides by multiplying with the reciprocal (a * (1/b)), which
// differs from a / b in the last bit; Quotient divides the values exactly.
#pragma once

#include <ceres/jet.h>

namespace bouncecal::scalar {

inline double Value(double x) { return x; }
template <int N>
double Value(const ceres::Jet<double, N>& x) {
  return x.a;
}

inline double Quotient(double a, double b) { return a / b; }
template <int N>
ceres::Jet<double, N> Quotient(const ceres::Jet<double, N>& a, const ceres::Jet<double, N>& b) {
  ceres::Jet<double, N> q = a / b;
  q.a = a.a / b.a;
  return q;
}
template <int N>
ceres::Jet<double, N> Quotient(const ceres::Jet<double, N>& a, double b) {
  ceres::Jet<double, N> q = a / b;
  q.a = a.a / b;
  return q;
}

}  // namespace bouncecal::scalar
