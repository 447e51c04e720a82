// Viscoelastic Hertz (Brilliantov, Spahn, Hertzsch & Poschel, PRE 53 (1996) 5382; Kuwabara &
// Kono, Jpn. J. Appl. Phys. 26 (1987) 1230; docs/physics.md §3.5):
//   F = k (delta^(3/2) + (3/2) A delta^(1/2) delta'),  A = dissipative time constant (s).
// With delta = L x, t = (L/v) s, L = (m* v^2/k)^(2/5) the equation becomes
//   x'' = -x^(3/2) - b x^(1/2) x',  b = beta v^(1/5),  beta = (3/2) A (k/m*)^(2/5),
// so e falls with v through b alone. Closed forms: the low-speed series of Ramirez, Poschel,
// Brilliantov & Schwager, PRE 60 (1999) 4465, e = 1 - C1 b + C2 b^2 - ... (its explicit first
// coefficients; ViscoelasticSeriesRestitution, a test oracle); the
// Padé form of Muller & Poschel (2011) is NOT implemented (not reproduced reliably here).
// Restitution/ContactTime come from the exact master curves e(b), tau(b), whose nodes are
// computed at build time (laws/master_curves.hpp: 1201 nodes of b in [0, 12], dopri5 at rel.
// tol. 1e-12, ends by bisection) and Hermite-interpolated; beyond b = 12 (e < 3e-6) they
// return nullopt. Contact ends at delta = 0 (the force turns slightly attractive before; kept).
#include "physics/laws/hertz_family.hpp"
#include "physics/laws/law_impl.hpp"
#include "physics/laws/master_curves.hpp"

namespace bouncecal::laws {
namespace {

struct ViscoCurves {
  HermiteTable e_of_b;
  HermiteTable tau_of_b;
  HermiteTable b_of_e;
};

const ViscoCurves& Curves() {
  static const ViscoCurves curves = [] {
    const MasterNodes& n = ViscoelasticNodes();
    // e decreases with b: reverse the nodes for b(e), db/de = 1 / (de/db).
    const size_t count = n.damping.size();
    std::vector<double> e_inc(count), b_dec(count), db_de(count);
    for (size_t j = 0; j < count; ++j) {
      const size_t i = count - 1 - j;
      e_inc[j] = n.restitution[i];
      b_dec[j] = n.damping[i];
      db_de[j] = 1.0 / n.restitution_slope[i];
    }
    return ViscoCurves{HermiteTable(n.damping, n.restitution, n.restitution_slope),
                       HermiteTable(n.damping, n.contact_time, n.contact_time_slope),
                       HermiteTable(e_inc, b_dec, db_de)};
  }();
  return curves;
}

}  // namespace

class HertzViscoelastic final : public LawImpl<HertzViscoelastic> {
 public:
  static constexpr int kOverlapRoot = 2;  // delta^(1/2) damping, delta^(3/2) spring

  static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene& scene) {
    auto law = std::make_unique<HertzViscoelastic>();
    law->specs_ = {
        HertzStiffnessSpec(scene, "N/m^1.5", "Hertz stiffness"),
        Spec("A", "s", "dissipative time constant (default 1e-7 s)", 0.0, 1.0, 1e-7, true),
    };
    return law;
  }

  template <class T>
  struct Constants {
    T k;
    T damping;  // 1.5 k A
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody&) const {
    return {p[0], 1.5 * p[0] * p[1]};
  }
  template <class T>
  T Force(const Constants<T>& c, const T& delta, const T& rate, const T*, bool) const {
    using std::sqrt;
    if (!(delta > 0.0)) return T(0.0);
    const T root = sqrt(delta);
    return c.k * delta * root + c.damping * root * rate;
  }
  double ElasticEnergy(const Constants<double>& c, double delta_m, const double*) const {
    return delta_m > 0.0 ? 0.4 * c.k * delta_m * delta_m * std::sqrt(delta_m) : 0.0;
  }
  bool ElasticPowerLaw(const Constants<double>& c, double* coefficient, double* exponent) const {
    *coefficient = 0.4 * c.k;
    *exponent = 2.5;
    return true;
  }

  static double B(std::span<const double> p, const ContactBody& body, double v) {
    return 1.5 * p[1] * std::pow(p[0] / body.mass_kg, 0.4) * std::pow(v, 0.2);
  }
  std::optional<double> Restitution(std::span<const double> p, const ContactBody& body,
                                    double v_in_m_s) const override {
    const double b = B(p, body, v_in_m_s);
    if (!(b <= kViscoelasticBMax)) return std::nullopt;
    return Curves().e_of_b(b);
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double v_in_m_s) const override {
    const double b = B(p, body, v_in_m_s);
    if (!(b <= kViscoelasticBMax)) return std::nullopt;
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
    if (!(b <= kViscoelasticBMax)) return false;
    const double slope = Curves().e_of_b.Derivative(b);  // de/db
    if (e) *e = Curves().e_of_b(b);
    if (de_dp) {
      de_dp[0] = slope * 0.4 * b / p[0];  // b ~ k^(2/5)
      de_dp[1] = slope * 1.5 * std::pow(p[0] / body.mass_kg, 0.4) * std::pow(v_in_m_s, 0.2);
    }
    return true;
  }
};

double ViscoelasticRestitution(double b) { return Curves().e_of_b(b); }
double ViscoelasticSeriesRestitution(double b) {
  return 1.0 - kRamirezC1 * b + kRamirezC2 * b * b;  // Ramirez et al. 1999, 2 terms
}

template std::unique_ptr<LawBase> MakeLaw<HertzViscoelastic>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
