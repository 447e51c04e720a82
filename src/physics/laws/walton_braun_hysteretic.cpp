// Hysteretic Walton-Braun law (Walton & Braun, J. Rheol. 30 (1986) 949; PHYSICS.md §3):
//   loading (delta at its running maximum delta_max): F = k1 delta
//   unloading / reloading below delta_max:            F = k2 (delta - delta0),
//   delta0 = delta_max (1 - k1/k2)  (the unloading line meets the loading line at delta_max).
// Written as one continuous expression, F = max(0, min(k1 delta, k2 (delta - delta0))), with
// the internal state delta_max (d delta_max/dt = delta' while delta >= delta_max and delta' > 0).
// The contact ends when the unloading force reaches 0, i.e. at delta = delta0 > 0 (kForceZero:
// the plastic overlap delta0 is left behind). Closed forms (k2 constant, not LIGGGHTS' growing
// k2): e^2 = k1/k2, t_c = (pi/2)(sqrt(m*/k1) + sqrt(m*/k2)), inverse k2 = k1/e^2.
#include <algorithm>
#include <cmath>

#include "physics/laws/law_base.hpp"

namespace bouncecal::laws {
namespace {

class WaltonBraunHysteretic final : public LawBase {
 public:
  WaltonBraunHysteretic() {
    specs_ = {
        Spec("k1", "N/m", "loading stiffness (default 1e7 N/m)", kStiffnessLower, kStiffnessUpper,
             1e7, false),
        Spec("k2", "N/m", "unloading stiffness, >= k1 (default 1e7/0.64: e = 0.8)", kStiffnessLower,
             kStiffnessUpper, 1e7 / 0.64, true),
    };
  }
  std::string Name() const override { return "walton-braun-hysteretic"; }
  std::string Formula() const override {
    return "F = k1 d loading, k2 (d - d0) unloading, d0 = dmax (1 - k1/k2)";
  }
  std::string Source() const override {
    return "Walton & Braun, J. Rheol. 30 (1986) 949; e^2 = k1/k2 (PHYSICS.md §3)";
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
  ContactEnd EndRule() const override { return ContactEnd::kForceZero; }
  int StateSize() const override { return 1; }
  void InitialState(std::span<const double>, const ContactBody&, double,
                    double* state) const override {
    state[0] = 0.0;
  }
  void StateRate(std::span<const double>, const ContactBody&, double delta_m, double delta_dot_m_s,
                 const double* state, double* rate) const override {
    rate[0] = (delta_dot_m_s > 0.0 && delta_m >= state[0]) ? delta_dot_m_s : 0.0;
  }
  double SwitchFunction(std::span<const double>, const ContactBody&, double, double delta_dot_m_s,
                        const double*) const override {
    return delta_dot_m_s;
  }
  double Force(std::span<const double> p, const ContactBody&, double delta_m, double,
               const double* state) const override {
    if (delta_m <= 0.0) return 0.0;
    const double delta0 = PlasticOverlap(p, delta_m, state);
    return std::max(0.0, std::min(p[0] * delta_m, p[1] * (delta_m - delta0)));
  }
  double ElasticEnergy(std::span<const double> p, const ContactBody&, double delta_m,
                       const double* state) const override {
    const double delta0 = PlasticOverlap(p, delta_m, state);
    const double x = delta_m - delta0;
    return x > 0.0 ? 0.5 * p[1] * x * x : 0.0;
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
  std::vector<std::string> ClosedForms() const override {
    return {kClosedRestitution, kClosedContactTime, kClosedSolveContact, kClosedInverse,
            kClosedGradient};
  }

 private:
  static double PlasticOverlap(std::span<const double> p, double delta_m, const double* state) {
    const double delta_max = std::max(state[0], delta_m);
    return delta_max * (1.0 - p[0] / p[1]);
  }
};

}  // namespace

std::unique_ptr<LawBase> MakeWaltonBraunHysteretic(const LawSpec&, const Scene&) {
  return std::make_unique<WaltonBraunHysteretic>();
}

}  // namespace bouncecal::laws
