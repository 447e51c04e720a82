// Viscoelastic Hertz (Brilliantov, Spahn, Hertzsch & Poschel, PRE 53 (1996) 5382; Kuwabara &
// Kono, Jpn. J. Appl. Phys. 26 (1987) 1230; PHYSICS.md §3):
//   F = k (delta^(3/2) + (3/2) A delta^(1/2) delta'),  A = dissipative time constant (s).
// With delta = L x, t = (L/v) s, L = (m* v^2/k)^(2/5) the equation becomes
//   x'' = -x^(3/2) - b x^(1/2) x',  b = beta v^(1/5),  beta = (3/2) A (k/m*)^(2/5),
// so e falls with v through b alone. Closed forms: the low-speed series of Schwager & Poschel
// (2008), e = 1 - C1 b + C2 b^2 - ... (ViscoelasticSeriesRestitution, a test oracle); the
// Padé form of Muller & Poschel (2011) is NOT implemented (not reproduced reliably here).
// Restitution/ContactTime come from the exact master curves e(b), tau(b), computed once per
// process by integrating the dimensionless equation (dopri5, rel. tol. 1e-12, bisection end)
// on 1201 nodes of b in [0, 12] and Hermite-interpolated; beyond b = 12 (e < 3e-6) they
// return nullopt. Contact ends at delta = 0 (the force turns slightly attractive before; kept).
#include <cmath>

#include "physics/laws/hertz_family.hpp"
#include "physics/laws/law_base.hpp"
#include "physics/laws/unit_contact.hpp"

namespace bouncecal::laws {
namespace {

constexpr double kBMax = 12.0;
constexpr int kNodes = 1201;

struct ViscoCurves {
  HermiteTable e_of_b;
  HermiteTable tau_of_b;
  HermiteTable b_of_e;
};

const ViscoCurves& Curves() {
  static const ViscoCurves curves = [] {
    std::vector<double> b(kNodes), e(kNodes), de(kNodes), tau(kNodes), dtau(kNodes);
    for (int i = 0; i < kNodes; ++i) {
      // Nodes denser at small b where e changes fastest relative to its size.
      const double u = static_cast<double>(i) / (kNodes - 1);
      const double bb = kBMax * u * u;
      auto run = [](double q) {
        return IntegrateUnitContact(
            [q](double x, double xd) {
              x = std::max(x, 0.0);
              return x * std::sqrt(x) + q * std::sqrt(x) * xd;
            },
            false, 1e-12, 1e4);
      };
      const double h = 1e-5 * std::max(bb, 0.01);
      const UnitContact mid = run(bb), hi = run(bb + h), lo = run(std::max(bb - h, 0.0));
      const double span = bb + h - std::max(bb - h, 0.0);
      const size_t j = static_cast<size_t>(i);
      b[j] = bb;
      e[j] = mid.restitution;
      de[j] = (hi.restitution - lo.restitution) / span;
      tau[j] = mid.contact_time;
      dtau[j] = (hi.contact_time - lo.contact_time) / span;
    }
    std::vector<double> e_inc(e.rbegin(), e.rend()), b_dec(b.rbegin(), b.rend()), db(kNodes);
    for (size_t j = 0; j < static_cast<size_t>(kNodes); ++j) db[j] = 1.0 / de[kNodes - 1 - j];
    return ViscoCurves{HermiteTable(b, e, de), HermiteTable(b, tau, dtau),
                       HermiteTable(e_inc, b_dec, db)};
  }();
  return curves;
}

class HertzViscoelastic final : public LawBase {
 public:
  HertzViscoelastic(double default_k, const std::string& k_note) {
    specs_ = {
        Spec("k", "N/m^1.5", "Hertz stiffness; default (4/3) E* sqrt(R*) from materials" + k_note,
             kStiffnessLower, kStiffnessUpper, default_k, false),
        Spec("A", "s", "dissipative time constant (default 1e-7 s)", 0.0, 1.0, 1e-7, true),
    };
  }
  std::string Name() const override { return "hertz-viscoelastic"; }
  std::string Formula() const override { return "F = k (d^1.5 + 1.5 A d^0.5 d')"; }
  std::string Source() const override {
    return "Brilliantov et al., PRE 53 (1996) 5382; Schwager & Poschel, PRE 78 (2008) 051304";
  }
  double Force(std::span<const double> p, const ContactBody&, double delta_m, double delta_dot_m_s,
               const double*) const override {
    if (delta_m <= 0.0) return 0.0;
    const double root = std::sqrt(delta_m);
    return p[0] * (delta_m * root + 1.5 * p[1] * root * delta_dot_m_s);
  }
  double ElasticEnergy(std::span<const double> p, const ContactBody&, double delta_m,
                       const double*) const override {
    return delta_m > 0.0 ? 0.4 * p[0] * delta_m * delta_m * std::sqrt(delta_m) : 0.0;
  }
  static double B(std::span<const double> p, const ContactBody& body, double v) {
    return 1.5 * p[1] * std::pow(p[0] / body.mass_kg, 0.4) * std::pow(v, 0.2);
  }
  std::optional<double> Restitution(std::span<const double> p, const ContactBody& body,
                                    double v_in_m_s) const override {
    const double b = B(p, body, v_in_m_s);
    if (!(b <= kBMax)) return std::nullopt;
    return Curves().e_of_b(b);
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double v_in_m_s) const override {
    const double b = B(p, body, v_in_m_s);
    if (!(b <= kBMax)) return std::nullopt;
    return Curves().tau_of_b(b) * std::pow(body.mass_kg / p[0], 0.4) * std::pow(v_in_m_s, -0.2);
  }
  std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                           const ContactBody& body, double e,
                                                           double v_in_m_s) const override {
    const ViscoCurves& c = Curves();
    if (!(e >= c.b_of_e.XMin() && e <= 1.0) || !(v_in_m_s > 0.0)) return std::nullopt;
    std::vector<double> q(p.begin(), p.end());
    const double b = e >= 1.0 ? 0.0 : c.b_of_e(e);
    q[1] = b / (1.5 * std::pow(p[0] / body.mass_kg, 0.4) * std::pow(v_in_m_s, 0.2));
    return q;
  }
  bool RestitutionGradient(std::span<const double> p, const ContactBody& body, double v_in_m_s,
                           double* e, double* de_dp) const override {
    const double b = B(p, body, v_in_m_s);
    if (!(b <= kBMax)) return false;
    const double slope = Curves().e_of_b.Derivative(b);  // de/db
    if (e) *e = Curves().e_of_b(b);
    if (de_dp) {
      de_dp[0] = slope * 0.4 * b / p[0];  // b ~ k^(2/5)
      de_dp[1] = slope * 1.5 * std::pow(p[0] / body.mass_kg, 0.4) * std::pow(v_in_m_s, 0.2);
    }
    return true;
  }
  std::vector<std::string> ClosedForms() const override {
    return {kClosedRestitution, kClosedContactTime, kClosedInverse, kClosedGradient};
  }
};

}  // namespace

double ViscoelasticRestitution(double b) { return Curves().e_of_b(b); }
double ViscoelasticSeriesRestitution(double b) {
  return 1.0 - kSchwagerPoschelC1 * b + kSchwagerPoschelC2 * b * b;  // S&P 2008, 2 terms
}

std::unique_ptr<LawBase> MakeHertzViscoelastic(const LawSpec&, const Scene& scene) {
  std::string why;
  const std::optional<double> k = HertzStiffnessFromScene(scene, &why);
  return std::make_unique<HertzViscoelastic>(k.value_or(kNaN), k ? "" : "; " + why);
}

}  // namespace bouncecal::laws
