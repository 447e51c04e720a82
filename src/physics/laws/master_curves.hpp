// laws/master_curves.hpp — the master curves of the Hertz-type laws (internal header).
//
// Hertz-type laws scale (laws/unit_contact.hpp): e and t_c / T depend on one dimensionless
// damping number only (alpha for Tsuji, b = beta v^(1/5) for viscoelastic Hertz). Their curves
// are computed by integrating the dimensionless contact precisely at a few hundred nodes. That
// takes 0.15-0.3 s, so it is done at BUILD time: tools/generate/master_curves.cpp calls the
// Compute* functions below and writes the nodes as a generated source file (CMake runs it);
// the laws read the generated nodes (Tsuji/ViscoelasticNodes). tests/master_curves_test.cpp
// recomputes them at run time and checks that the two agree.
#pragma once

#include <span>
#include <vector>

namespace bouncecal::laws {

// Nodes of one family of unit contacts, all of the same length, increasing damping number.
struct MasterNodes {
  std::vector<double> damping;             // alpha (Tsuji) or b (viscoelastic)
  std::vector<double> restitution;         // e at the node
  std::vector<double> restitution_slope;   // de / d(damping)
  std::vector<double> contact_time;        // t_c in units of T = L / v
  std::vector<double> contact_time_slope;  // d(t_c/T) / d(damping)
};

// Tsuji, x'' = -x^(3/2) - alpha x^(1/4) x': 801 nodes, alpha in [0, kTsujiAlphaMax].
constexpr double kTsujiAlphaMax = 2.0;  // e(2.0) = 0.00187
constexpr int kTsujiNodeCount = 801;
// Viscoelastic Hertz, x'' = -x^(3/2) - b x^(1/2) x': 1201 nodes, b = 12 u^2, u uniform in [0, 1]
// (denser at small b, where e changes fastest relative to its size).
constexpr double kViscoelasticBMax = 12.0;  // e(12) < 3e-6
constexpr int kViscoelasticNodeCount = 1201;

// The run-time computations (Boost.Odeint dopri5, rel. tol. 1e-12, ends located by bisection;
// slopes by central differences of width 2e-5 in the damping number).
MasterNodes ComputeTsujiNodes();
MasterNodes ComputeViscoelasticNodes();

// The build-time tables (generated source), read once per process.
const MasterNodes& TsujiNodes();
const MasterNodes& ViscoelasticNodes();

// The generated data: 5 values per node, in MasterNodes field order.
std::span<const double> GeneratedTsujiNodeData();
std::span<const double> GeneratedViscoelasticNodeData();

}  // namespace bouncecal::laws
