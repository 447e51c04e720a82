// bouncecal/physics/pointwise_law.hpp — a contact law given only by a stateless force
// F(p, body, delta, delta') and its elastic energy.
//
// The registered laws are written once, templated on the scalar type (src/physics/laws/
// law_impl.hpp). Laws that cannot be — the user's muParser expression, the export wing's native
// simulator forms (export/native_law.hpp) — give these two functions instead; PointwiseDynamics
// turns them into ContactDynamics: the force as given (the contact ends at delta = 0 or where
// the law's EndRule says; at delta <= 0 the dynamics give the limit F(0+, delta'), so the force
// does not jump at the end of a contact), derivatives for forward sensitivities by central
// differences (relative step 1e-6 in delta, delta' and each parameter: ~1e-12 truncation error
// for smooth forces).
//
//   class MyLaw final : public PointwiseContactLaw { ... Force, ElasticEnergy, identity ... };
//   SimulateContact(law, p, body, v, 0.0);   // integrates it like any law
#pragma once

#include <functional>
#include <memory>
#include <span>
#include <vector>

#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/contact_law.hpp"

namespace bouncecal {

// ContactDynamics from a force function F(p, delta, delta') and an energy function W(p, delta)
// at fixed parameters p (copied). The functions are called with p or with p varied by one
// parameter (the sensitivities' central differences).
class PointwiseDynamics final : public ContactDynamics {
 public:
  using ForceFn =
      std::function<double(std::span<const double> p, double delta_m, double delta_dot_m_s)>;
  using EnergyFn = std::function<double(std::span<const double> p, double delta_m)>;

  PointwiseDynamics(ForceFn force, EnergyFn energy, ContactEnd end_rule, std::span<const double> p);

  int StateSize() const override { return 0; }
  int ParameterCount() const override { return static_cast<int>(p_.size()); }
  ContactEnd EndRule() const override { return end_rule_; }
  double ForceOnBranch(double delta_m, double delta_dot_m_s, const double*, bool) const override;
  SensitivityJet ForceOnBranch(const SensitivityJet& delta_m, const SensitivityJet& delta_dot_m_s,
                               const SensitivityJet*, bool) const override;
  double ElasticEnergy(double delta_m, const double*) const override;

 private:
  ForceFn force_;
  EnergyFn energy_;
  ContactEnd end_rule_;
  std::vector<double> p_;
};

class PointwiseContactLaw : public ContactLaw {
 public:
  // Normal force on the ball (N, positive = repulsive) at overlap delta >= 0 and rate delta'.
  virtual double Force(std::span<const double> p, const ContactBody& body, double delta_m,
                       double delta_dot_m_s, const double* state) const = 0;
  // The work of the rate-independent part, integral_0^delta F(x, 0) dx (J).
  virtual double ElasticEnergy(std::span<const double> p, const ContactBody& body, double delta_m,
                               const double* state) const = 0;

  int StateSize() const override { return 0; }
  std::vector<std::string> ClosedForms() const override { return {}; }
  std::unique_ptr<ContactDynamics> Dynamics(std::span<const double> p,
                                            const ContactBody& body) const override;
};

}  // namespace bouncecal
