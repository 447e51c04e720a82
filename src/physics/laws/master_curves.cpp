// The master curves of the Hertz-type laws: the run-time computation (laws/master_curves.hpp).
// Compiled into the library and into the build-time generator (tools/generate/).
#include "physics/laws/master_curves.hpp"

#include <algorithm>
#include <cmath>

#include "physics/laws/unit_contact.hpp"

namespace bouncecal::laws {
namespace {

// One node: e and t_c of the unit contact at damping number x, with central-difference slopes
// (one-sided at x = 0); contacts longer than max_time (in units of T) count as stuck.
template <class Force>
void AddNode(double x, double h, double max_time, const Force& force_at, MasterNodes* out) {
  auto run = [&](double q) {
    return IntegrateUnitContact([&](double xx, double xd) { return force_at(q, xx, xd); }, false,
                                1e-12, max_time);
  };
  const double lo_x = std::max(x - h, 0.0);
  const UnitContact mid = run(x), hi = run(x + h), lo = run(lo_x);
  const double span = x + h - lo_x;
  out->damping.push_back(x);
  out->restitution.push_back(mid.restitution);
  out->restitution_slope.push_back((hi.restitution - lo.restitution) / span);
  out->contact_time.push_back(mid.contact_time);
  out->contact_time_slope.push_back((hi.contact_time - lo.contact_time) / span);
}

}  // namespace

MasterNodes ComputeTsujiNodes() {
  // x'' = -x^(3/2) - alpha x^(1/4) x' (Tsuji et al. 1992, eq. 12, in contact units).
  auto force = [](double alpha, double x, double xd) {
    x = std::max(x, 0.0);
    return x * std::sqrt(x) + alpha * std::sqrt(std::sqrt(x)) * xd;
  };
  MasterNodes n;
  for (int i = 0; i < kTsujiNodeCount; ++i) {
    AddNode(kTsujiAlphaMax * i / (kTsujiNodeCount - 1), 1e-5, 1e3, force, &n);
  }
  return n;
}

MasterNodes ComputeViscoelasticNodes() {
  // x'' = -x^(3/2) - b x^(1/2) x' (Brilliantov et al. 1996, in contact units).
  auto force = [](double b, double x, double xd) {
    x = std::max(x, 0.0);
    return x * std::sqrt(x) + b * std::sqrt(x) * xd;
  };
  MasterNodes n;
  for (int i = 0; i < kViscoelasticNodeCount; ++i) {
    const double u = static_cast<double>(i) / (kViscoelasticNodeCount - 1);
    const double b = kViscoelasticBMax * u * u;
    AddNode(b, 1e-5 * std::max(b, 0.01), 1e4, force, &n);
  }
  return n;
}

}  // namespace bouncecal::laws
