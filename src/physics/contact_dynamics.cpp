// Defaults of ContactDynamics (contact_dynamics.hpp) for laws without state or switch.
#include "bouncecal/physics/contact_dynamics.hpp"

#include <algorithm>

namespace bouncecal {

void ContactDynamics::InitialState(double* state) const {
  std::fill(state, state + StateSize(), 0.0);
}

double ContactDynamics::StateScale(int, double length_m, double) const { return length_m; }

void ContactDynamics::StateRate(double, double, const double*, double*) const {}

void ContactDynamics::StateRate(const SensitivityJet&, const SensitivityJet&, const SensitivityJet*,
                                SensitivityJet*) const {}

double ContactDynamics::Switch(double, double, const double*) const { return 1.0; }

SensitivityJet ContactDynamics::Switch(const SensitivityJet&, const SensitivityJet&,
                                       const SensitivityJet*) const {
  return SensitivityJet(1.0);
}

void ContactDynamics::AtSwitch(double, double*) const {}

void ContactDynamics::AtSwitch(const SensitivityJet&, SensitivityJet*) const {}

double ContactDynamics::InternalEnergy(const double*) const { return 0.0; }

bool ContactDynamics::ElasticPowerLaw(double*, double*) const { return false; }

bool ContactDynamics::InlineHertzDamper(HertzDamper*) const { return false; }

}  // namespace bouncecal
