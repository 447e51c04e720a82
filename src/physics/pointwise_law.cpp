// Contact laws given by a force function only (pointwise_law.hpp).
#include "bouncecal/physics/pointwise_law.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace bouncecal {
namespace {

constexpr double kRelativeStep = 1e-6;  // central differences (pointwise_law.hpp)

// The overlap the force function is asked at: at delta <= 0 the smallest positive double, so the
// force there is its limit F(0+, delta') (a force function is 0 for delta <= 0 by convention,
// which would make the force jump at the end of a contact where F(0+, delta') != 0, as for a
// dashpot, and cost the integrator's last step its accuracy).
double Positive(double delta_m) {
  return delta_m > 0.0 ? delta_m : std::numeric_limits<double>::min();
}

}  // namespace

PointwiseDynamics::PointwiseDynamics(ForceFn force, EnergyFn energy, ContactEnd end_rule,
                                     std::span<const double> p)
    : force_(std::move(force)),
      energy_(std::move(energy)),
      end_rule_(end_rule),
      p_(p.begin(), p.end()) {}

double PointwiseDynamics::ForceOnBranch(double delta_m, double delta_dot_m_s, const double*,
                                        bool) const {
  return force_(p_, Positive(delta_m), delta_dot_m_s);
}

SensitivityJet PointwiseDynamics::ForceOnBranch(const SensitivityJet& delta_m,
                                                const SensitivityJet& delta_dot_m_s,
                                                const SensitivityJet*, bool) const {
  const double d = Positive(delta_m.a), v = delta_dot_m_s.a;
  SensitivityJet f(force_(p_, d, v));
  const double hd = kRelativeStep * d;
  const double hv = kRelativeStep * std::max(std::abs(v), 1e-3);
  const double df_dd = (force_(p_, d + hd, v) - force_(p_, d - hd, v)) / (2 * hd);
  const double df_dv = (force_(p_, d, v + hv) - force_(p_, d, v - hv)) / (2 * hv);
  f.v = df_dd * delta_m.v + df_dv * delta_dot_m_s.v;
  std::vector<double> q = p_;
  for (size_t j = 0; j < q.size() && static_cast<int>(j) < kMaxSensitivityParameters; ++j) {
    const double keep = q[j];
    const double h = kRelativeStep * std::max(std::abs(keep), 1e-12);
    q[j] = keep + h;
    const double hi = force_(q, d, v);
    q[j] = keep - h;
    const double lo = force_(q, d, v);
    q[j] = keep;
    f.v[static_cast<int>(j)] += (hi - lo) / (2 * h);
  }
  return f;
}

double PointwiseDynamics::ElasticEnergy(double delta_m, const double*) const {
  return energy_(p_, delta_m);
}

std::unique_ptr<ContactDynamics> PointwiseContactLaw::Dynamics(std::span<const double> p,
                                                               const ContactBody& body) const {
  const ContactBody b = body;
  return std::make_unique<PointwiseDynamics>(
      [this, b](std::span<const double> q, double d, double v) {
        return Force(q, b, d, v, nullptr);
      },
      [this, b](std::span<const double> q, double d) { return ElasticEnergy(q, b, d, nullptr); },
      EndRule(), p);
}

}  // namespace bouncecal
