// Seed 002's "Walton-Braun" law (Zhong et al., Acta Phys. Sin. 2009, eqs. 3-4):
//   F = (1 + gamma) k delta while loading (delta' > 0), F = (1 - gamma) k delta while unloading.
// Closed forms (PHYSICS.md §1, §3): two half-periods of linear springs,
//   omega_load = sqrt((1 + gamma) k / m*), omega_unload = sqrt((1 - gamma) k / m*),
//   delta_max = v / omega_load, v_out = omega_unload delta_max, so
//   e^2 = (1 - gamma)/(1 + gamma), eta = 1 - e^2 = 2 gamma/(1 + gamma)     (seed 002 eq. 23)
//   t_c = (pi/2) (1/omega_load + 1/omega_unload)
//   inverse: gamma = (1 - e^2)/(1 + e^2) (= eta/(2 - eta)).
// The force jumps at delta' = 0 (the branch switch): SwitchFunction = delta' so the integrator
// stops its step there, and ForceOnBranch continues each branch past it (see contact_law.hpp).
// Contact ends at delta = 0 (the unloading force is never attractive).
#include <cmath>

#include "physics/laws/law_base.hpp"

namespace bouncecal::laws {
namespace {

class WaltonBraun final : public LawBase {
 public:
  WaltonBraun() {
    specs_ = {
        Spec("k", "N/m", "base stiffness (default 1e7 N/m, seed 002 k_n)", kStiffnessLower,
             kStiffnessUpper, 1e7, false),
        Spec("gamma", "1", "loading/unloading asymmetry, < 1 (default 0.5, seed 002's choice)", 0.0,
             0.9999, 0.5, true),
    };
  }
  std::string Name() const override { return "walton-braun"; }
  std::string Formula() const override {
    return "F = (1 + gamma) k d if d' > 0, (1 - gamma) k d otherwise";
  }
  std::string Source() const override {
    return "Zhong et al., Acta Phys. Sin. 58 (2009), eqs. 3-4 and 23 (seed 002)";
  }

  double Force(std::span<const double> p, const ContactBody&, double delta_m, double delta_dot_m_s,
               const double*) const override {
    if (delta_m < 0.0) return 0.0;
    const double factor = delta_dot_m_s > 0.0 ? 1.0 + p[1] : 1.0 - p[1];
    return factor * p[0] * delta_m;
  }
  double ForceOnBranch(std::span<const double> p, const ContactBody&, double delta_m, double,
                       const double*, bool loading) const override {
    if (delta_m < 0.0) return 0.0;
    return (loading ? 1.0 + p[1] : 1.0 - p[1]) * p[0] * delta_m;
  }
  double SwitchFunction(std::span<const double>, const ContactBody&, double, double delta_dot_m_s,
                        const double*) const override {
    return delta_dot_m_s;
  }
  // Recoverable energy: what the unloading branch gives back.
  double ElasticEnergy(std::span<const double> p, const ContactBody&, double delta_m,
                       const double*) const override {
    return delta_m > 0.0 ? 0.5 * (1.0 - p[1]) * p[0] * delta_m * delta_m : 0.0;
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
  std::vector<std::string> ClosedForms() const override {
    return {kClosedRestitution, kClosedContactTime, kClosedSolveContact, kClosedInverse,
            kClosedGradient};
  }
};

}  // namespace

std::unique_ptr<LawBase> MakeWaltonBraun(const LawSpec&, const Scene&) {
  return std::make_unique<WaltonBraun>();
}

}  // namespace bouncecal::laws
