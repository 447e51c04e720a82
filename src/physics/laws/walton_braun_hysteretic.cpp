// Hysteretic Walton-Braun law (Walton & Braun, J. Rheol. 30 (1986) 949; docs/physics.md §3):
//   loading (delta at its running maximum delta_max): F = k1 delta
//   unloading / reloading below delta_max:            F = k2 (delta - delta0),
//   delta0 = delta_max (1 - k1/k2)  (the unloading line meets the loading line at delta_max).
// Written as one continuous expression, F = min(k1 delta, k2 (delta - delta0)) (>= 0 until the
// contact ends at F = 0), with
// delta0 from the law's memory delta_max = max(state, delta): the state records the peak
// overlap at each located switch from loading to unloading (delta' = 0; AtSwitch), and needs no
// differential equation. (Integrating d delta_max/dt = delta' while delta >= delta_max made the
// rate chatter between delta' and 0 as the integrated delta_max crossed delta, and cost the
// integrator its accuracy: e errors of 1e-5 at rtol 1e-9 before.) While loading,
// max(state, delta) = delta, so the force is k1 delta; on reloading below an earlier peak the
// unloading line holds until delta passes it.
// The contact ends when the unloading force reaches 0, i.e. at delta = delta0 > 0 (kForceZero:
// the plastic overlap delta0 is left behind). Closed forms (k2 constant, not LIGGGHTS' growing
// k2): e^2 = k1/k2, t_c = (pi/2)(sqrt(m*/k1) + sqrt(m*/k2)), inverse k2 = k1/e^2.
#include <algorithm>
#include <cmath>

#include "physics/laws/law_impl.hpp"

namespace bouncecal::laws {

class WaltonBraunHysteretic final : public LawImpl<WaltonBraunHysteretic> {
 public:
  static constexpr int kStateSize = 1;  // delta_max, the running maximum overlap
  static constexpr bool kHasSwitch = true;

  static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene&) {
    auto law = std::make_unique<WaltonBraunHysteretic>();
    law->specs_ = {
        Spec("k1", "N/m", "loading stiffness (default 1e7 N/m)", kStiffnessLower, kStiffnessUpper,
             1e7, false),
        Spec("k2", "N/m", "unloading stiffness, >= k1 (default 1e7/0.64: e = 0.8)", kStiffnessLower,
             kStiffnessUpper, 1e7 / 0.64, true),
    };
    return law;
  }
  bool IsValid(std::span<const double> p, const ContactBody& body,
               std::string* error) const override {
    if (!LawBase::IsValid(p, body, error)) return false;
    if (p[1] < p[0]) {
      if (error) {
        *error = Name() + ": parameter k2 = " + std::to_string(p[1]) +
                 " N/m must be >= k1 = " + std::to_string(p[0]) + " N/m (e^2 = k1/k2 <= 1)";
      }
      return false;
    }
    return true;
  }

  template <class T>
  struct Constants {
    T k1, k2;
    T plastic;  // 1 - k1/k2: delta0 = delta_max (1 - k1/k2)
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody&) const {
    return {p[0], p[1], 1.0 - Quotient(p[0], p[1])};
  }
  static constexpr bool kContinuesBelowZero = true;  // two lines in d
  template <class T>
  T Force(const Constants<T>& c, const T& delta, const T&, const T* state, bool) const {
    const T delta_max = state[0] > delta ? state[0] : delta;
    const T loading = c.k1 * delta;
    const T unloading = c.k2 * (delta - delta_max * c.plastic);
    // min(loading, unloading); not clipped at 0: the contact ends where the unloading line
    // reaches F = 0 (kForceZero), so within the contact F >= 0, and past the end the line is
    // the force's smooth continuation (the integrator's last step stays smooth).
    return loading < unloading ? loading : unloading;
  }
  template <class T, class C>
  void StateRate(const C&, const T&, const T&, const T*, T* out) const {
    out[0] = T(0.0);  // the memory changes only at switches (AtSwitch)
  }
  template <class T, class C>
  void AtSwitch(const C&, const T& delta, T* state) const {
    if (delta > state[0]) state[0] = delta;  // a peak: loading turns to unloading
  }
  template <class T, class C>
  T Switch(const C&, const T&, const T& rate, const T*) const {
    return rate;
  }
  double ElasticEnergy(const Constants<double>& c, double delta_m, const double* state) const {
    const double delta_max = std::max(state[0], delta_m);
    const double x = delta_m - delta_max * c.plastic;
    return x > 0.0 ? 0.5 * c.k2 * x * x : 0.0;
  }

  std::optional<double> Restitution(std::span<const double> p, const ContactBody&,
                                    double) const override {
    return std::sqrt(p[0] / p[1]);
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double) const override {
    return 0.5 * kPi * (std::sqrt(body.mass_kg / p[0]) + std::sqrt(body.mass_kg / p[1]));
  }
  std::optional<ContactOutcome> SolveContact(std::span<const double> p, const ContactBody& body,
                                             double v_in_m_s) const override {
    ContactOutcome out;
    out.restitution = std::sqrt(p[0] / p[1]);
    out.contact_time_s = *ContactTime(p, body, v_in_m_s);
    out.peak_overlap_m = v_in_m_s / std::sqrt(p[0] / body.mass_kg);
    out.peak_force_n = p[0] * out.peak_overlap_m;
    out.end_overlap_m = out.peak_overlap_m * (1.0 - p[0] / p[1]);
    return out;
  }
  std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                           const ContactBody&, double e,
                                                           double) const override {
    if (!(e > 0.0 && e <= 1.0)) return std::nullopt;
    std::vector<double> q(p.begin(), p.end());
    q[1] = p[0] / (e * e);
    return q;
  }
  bool RestitutionGradient(std::span<const double> p, const ContactBody&, double, double* e,
                           double* de_dp) const override {
    const double value = std::sqrt(p[0] / p[1]);
    if (e) *e = value;
    if (de_dp) {
      de_dp[0] = 0.5 * value / p[0];
      de_dp[1] = -0.5 * value / p[1];
    }
    return true;
  }
};

template std::unique_ptr<LawBase> MakeLaw<WaltonBraunHysteretic>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
