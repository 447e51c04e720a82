// Seed 002's "Walton-Braun" law (Zhong et al., Acta Phys. Sin. 2009, eqs. 3-4):
//   F = (1 + gamma) k delta while loading (delta' > 0), F = (1 - gamma) k delta while unloading.
// Closed forms (docs/physics.md §1, §3): two half-periods of linear springs,
//   omega_load = sqrt((1 + gamma) k / m*), omega_unload = sqrt((1 - gamma) k / m*),
//   delta_max = v / omega_load, v_out = omega_unload delta_max, so
//   e^2 = (1 - gamma)/(1 + gamma), eta = 1 - e^2 = 2 gamma/(1 + gamma)     (seed 002 eq. 23)
//   t_c = (pi/2) (1/omega_load + 1/omega_unload)
//   inverse: gamma = (1 - e^2)/(1 + e^2) (= eta/(2 - eta)).
// The force jumps at delta' = 0 (the branch switch): Switch = delta' so the integrator
// stops its step there, and Force on a branch continues it past the switch (contact_dynamics.hpp).
// Contact ends at delta = 0 (the unloading force is never attractive).
#include <cmath>

#include "physics/laws/law_impl.hpp"

namespace bouncecal::laws {

class WaltonBraun final : public LawImpl<WaltonBraun> {
 public:
  static constexpr bool kHasSwitch = true;

  static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene&) {
    auto law = std::make_unique<WaltonBraun>();
    law->specs_ = {
        Spec("k", "N/m", "base stiffness (default 1e7 N/m, seed 002 k_n)", kStiffnessLower,
             kStiffnessUpper, 1e7, false),
        Spec("gamma", "1", "loading/unloading asymmetry, < 1 (default 0.5, seed 002's choice)", 0.0,
             0.9999, 0.5, true),
    };
    return law;
  }

  template <class T>
  struct Constants {
    T load, unload;  // (1 + gamma) k and (1 - gamma) k
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody&) const {
    return {(1.0 + p[1]) * p[0], (1.0 - p[1]) * p[0]};
  }
  // The branch continued past the switch (contact_dynamics.hpp): loading = true.
  static constexpr bool kContinuesBelowZero = true;  // linear in d on each branch
  template <class T>
  T Force(const Constants<T>& c, const T& delta, const T&, const T*, bool loading) const {
    return (loading ? c.load : c.unload) * delta;
  }
  template <class T, class C>
  T Switch(const C&, const T&, const T& rate, const T*) const {
    return rate;
  }
  // Recoverable energy: what the unloading branch gives back.
  double ElasticEnergy(const Constants<double>& c, double delta_m, const double*) const {
    return delta_m > 0.0 ? 0.5 * c.unload * delta_m * delta_m : 0.0;
  }

  std::optional<double> Restitution(std::span<const double> p, const ContactBody&,
                                    double) const override {
    return std::sqrt((1.0 - p[1]) / (1.0 + p[1]));  // seed 002 eq. 23
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double) const override {
    const double m = body.mass_kg, k = p[0], g = p[1];
    return 0.5 * kPi * (std::sqrt(m / ((1.0 + g) * k)) + std::sqrt(m / ((1.0 - g) * k)));
  }
  std::optional<ContactOutcome> SolveContact(std::span<const double> p, const ContactBody& body,
                                             double v_in_m_s) const override {
    ContactOutcome out;
    out.restitution = *Restitution(p, body, v_in_m_s);
    out.contact_time_s = *ContactTime(p, body, v_in_m_s);
    const double omega_load = std::sqrt((1.0 + p[1]) * p[0] / body.mass_kg);
    out.peak_overlap_m = v_in_m_s / omega_load;
    out.peak_force_n = (1.0 + p[1]) * p[0] * out.peak_overlap_m;
    return out;
  }
  std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                           const ContactBody&, double e,
                                                           double) const override {
    if (!(e > 0.0 && e <= 1.0)) return std::nullopt;
    std::vector<double> q(p.begin(), p.end());
    q[1] = (1.0 - e * e) / (1.0 + e * e);
    return q;
  }
  bool RestitutionGradient(std::span<const double> p, const ContactBody&, double, double* e,
                           double* de_dp) const override {
    const double g = p[1];
    const double value = std::sqrt((1.0 - g) / (1.0 + g));
    if (e) *e = value;
    if (de_dp) {
      de_dp[0] = 0.0;
      de_dp[1] = -1.0 / (value * (1.0 + g) * (1.0 + g));  // d/dgamma sqrt((1-g)/(1+g))
    }
    return true;
  }
};

template std::unique_ptr<LawBase> MakeLaw<WaltonBraun>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
