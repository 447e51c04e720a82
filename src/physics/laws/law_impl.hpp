// physics/laws/law_impl.hpp — the recipe a law's file follows (internal header).
//
// A law is one class L : LawImpl<L> in one file of src/physics/laws/, plus one row in the
// registry table (src/physics/law_registry.cpp). The class provides:
//   static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene&);   // sets specs_
//   template <class T> struct Constants {...};             // per-contact constants
//   template <class T> Constants<T> Prepare(const T* p, const ContactBody&) const;
//   template <class T> T Force(const Constants<T>&, const T& delta, const T& rate,
//                              const T* state, bool branch) const;
//   double ElasticEnergy(const Constants<double>&, double delta, const double* state) const;
// and, where it has them (defaults below): kStateSize, StateRate, InternalEnergy, StateScale,
// ElasticPowerLaw (the elastic energy's coefficient and exponent, if it is a power law),
// InlineHertzDamper (the force is HertzDamper's closed form: the integrator inlines it),
// kHasSwitch + Switch (+ AtSwitch, a state update at the switch), kOverlapRoot,
// kContinuesBelowZero (a formula that stays smooth for delta < 0); the closed
// forms its row lists, as the ContactLaw overrides.
// Prepare, Force, StateRate and Switch are templated on the scalar type: the same code runs in
// double and in ceres::Jet (forward sensitivities, automatic derivatives); write them with
// unqualified math (using std::sqrt; sqrt(x)), divide with Quotient (physics/scalar.hpp: the
// same value in both types) and compare values (Jet comparisons compare values). The file ends with
// the explicit instantiation
//   template std::unique_ptr<LawBase> MakeLaw<L>(const LawSpec&, const Scene&);
#pragma once

#include <ceres/jet.h>

#include <array>
#include <cmath>
#include <span>

#include "bouncecal/physics/contact_dynamics.hpp"
#include "physics/laws/law_base.hpp"
#include "physics/laws/unit_contact.hpp"
#include "physics/scalar.hpp"

namespace bouncecal::laws {

using scalar::Quotient;
using scalar::Value;

// A tabulated curve y(x) in either scalar type (the Jet carries dy/dx).
inline double Interpolate(const HermiteTable& table, double x) { return table(x); }
template <int N>
ceres::Jet<double, N> Interpolate(const HermiteTable& table, const ceres::Jet<double, N>& x) {
  ceres::Jet<double, N> y(table(x.a));
  y.v = table.Derivative(x.a) * x.v;
  return y;
}

template <class L>
class DynamicsOf;

template <class L>
class LawImpl : public LawBase {
 public:
  // Defaults; a law declares its own to change them (name hiding).
  static constexpr int kStateSize = 0;
  static constexpr int kOverlapRoot = 1;
  static constexpr bool kHasSwitch = false;
  static constexpr bool kContinuesBelowZero = false;

  int StateSize() const override { return L::kStateSize; }
  std::unique_ptr<ContactDynamics> Dynamics(std::span<const double> p,
                                            const ContactBody& body) const override {
    return std::make_unique<DynamicsOf<L>>(static_cast<const L&>(*this), p, body);
  }

  template <class T, class C>
  void StateRate(const C&, const T&, const T&, const T*, T*) const {}
  template <class T, class C>
  T Switch(const C&, const T&, const T&, const T*) const {
    return T(1.0);
  }
  template <class T, class C>
  void AtSwitch(const C&, const T&, T*) const {}
  template <class C>
  double InternalEnergy(const C&, const double*) const {
    return 0.0;
  }
  template <class C>
  double StateScale(const C&, int, double length_m, double) const {
    return length_m;
  }
  template <class C>
  bool ElasticPowerLaw(const C&, double*, double*) const {
    return false;
  }
  template <class C>
  bool InlineHertzDamper(const C&, HertzDamper*) const {
    return false;
  }
};

// The ContactDynamics of law L: its constants prepared once, in double and (with the
// parameters seeded as derivative directions 0..P-1) in SensitivityJet.
template <class L>
class DynamicsOf final : public ContactDynamics {
 public:
  using Jet = SensitivityJet;
  using C = typename L::template Constants<double>;
  using CJ = typename L::template Constants<Jet>;

  DynamicsOf(const L& law, std::span<const double> p, const ContactBody& body)
      : law_(law),
        n_params_(static_cast<int>(p.size())),
        end_rule_(law.EndRule()),
        c_(law.template Prepare<double>(p.data(), body)),
        cj_(PrepareJets(law, p, body)) {}

  int StateSize() const override { return L::kStateSize; }
  int ParameterCount() const override { return n_params_; }
  ContactEnd EndRule() const override { return end_rule_; }
  int OverlapRoot() const override { return L::kOverlapRoot; }
  bool HasSwitch() const override { return L::kHasSwitch; }
  bool ContinuesBelowZero() const override { return L::kContinuesBelowZero; }
  double StateScale(int i, double length_m, double energy_j) const override {
    return law_.StateScale(c_, i, length_m, energy_j);
  }
  double ForceOnBranch(double delta, double rate, const double* state, bool branch) const override {
    return law_.Force(c_, delta, rate, state, branch);
  }
  Jet ForceOnBranch(const Jet& delta, const Jet& rate, const Jet* state,
                    bool branch) const override {
    return law_.Force(cj_, delta, rate, state, branch);
  }
  void StateRate(double delta, double rate, const double* state, double* out) const override {
    law_.StateRate(c_, delta, rate, state, out);
  }
  void StateRate(const Jet& delta, const Jet& rate, const Jet* state, Jet* out) const override {
    law_.StateRate(cj_, delta, rate, state, out);
  }
  double Switch(double delta, double rate, const double* state) const override {
    return law_.Switch(c_, delta, rate, state);
  }
  Jet Switch(const Jet& delta, const Jet& rate, const Jet* state) const override {
    return law_.Switch(cj_, delta, rate, state);
  }
  void AtSwitch(double delta, double* state) const override { law_.AtSwitch(c_, delta, state); }
  void AtSwitch(const Jet& delta, Jet* state) const override { law_.AtSwitch(cj_, delta, state); }
  double ElasticEnergy(double delta, const double* state) const override {
    return law_.ElasticEnergy(c_, delta, state);
  }
  double InternalEnergy(const double* state) const override {
    return law_.InternalEnergy(c_, state);
  }
  bool ElasticPowerLaw(double* coefficient, double* exponent) const override {
    return law_.ElasticPowerLaw(c_, coefficient, exponent);
  }
  bool InlineHertzDamper(HertzDamper* form) const override {
    return law_.InlineHertzDamper(c_, form);
  }

 private:
  static CJ PrepareJets(const L& law, std::span<const double> p, const ContactBody& body) {
    std::array<Jet, 16> pj{};
    for (size_t i = 0; i < p.size() && i < pj.size(); ++i) {
      pj[i] = static_cast<int>(i) < kMaxSensitivityParameters ? Jet(p[i], static_cast<int>(i))
                                                              : Jet(p[i]);
    }
    return law.template Prepare<Jet>(pj.data(), body);
  }

  const L& law_;
  int n_params_;
  ContactEnd end_rule_;
  C c_;
  CJ cj_;
};

template <class L>
std::unique_ptr<LawBase> MakeLaw(const LawSpec& spec, const Scene& scene) {
  return L::Create(spec, scene);
}

}  // namespace bouncecal::laws
