// Hertz contact with Tsuji's viscous damping (Tsuji, Tanaka & Ishida, Powder Technol. 71 (1992)
// 239, eq. 12; the "Hertz-Mindlin" normal force of seeds 000 and 003; PHYSICS.md §3):
//   F = k delta^(3/2) + eta delta^(1/4) delta',  eta = alpha(e) sqrt(m* k).
// Parameterisation: the user (and the fitter) gives the TARGET RESTITUTION e, not alpha. The
// restitution of this law depends on alpha only (scaling delta = L x, t = (L/v) s with
// L = (m* v^2/k)^(2/5) turns the equation into x'' = -x^(3/2) - alpha x^(1/4) x', free of
// v, m*, k), so alpha(e) is one universal curve: it is computed once per process by integrating
// that equation (Boost.Odeint dopri5, rel. tol. 1e-12, end located by bisection) on 801 alpha
// nodes and inverted by cubic Hermite interpolation. e is therefore exact (to ~1e-9) at every
// speed; the contact time is t_c = tau(alpha) (m*/k)^(2/5) v^(-1/5) from the same curve.
// Default k = (4/3) E* sqrt(R*) from the scene's materials. The contact ends at delta = 0; the
// force turns slightly attractive before (kept, as in DEM codes). Beyond alpha ~ 2.3 the ball
// sticks (delta creeps to 0 and never returns), hence e >= 0.005.
#include <cmath>

#include "physics/laws/law_base.hpp"
#include "physics/laws/unit_contact.hpp"

namespace bouncecal::laws {
namespace {

constexpr double kAlphaMax = 2.0;  // e(2.0) = 0.00187
constexpr int kNodes = 801;

double UnitForce(double alpha, double x, double xd) {
  x = std::max(x, 0.0);
  return x * std::sqrt(x) + alpha * std::sqrt(std::sqrt(x)) * xd;
}

struct TsujiCurves {
  HermiteTable alpha_of_e;  // x = e (increasing), y = alpha
  HermiteTable tau_of_alpha;
};

const TsujiCurves& Curves() {
  static const TsujiCurves curves = [] {
    std::vector<double> alpha(kNodes), e(kNodes), de(kNodes), tau(kNodes), dtau(kNodes);
    for (int i = 0; i < kNodes; ++i) {
      const double a = kAlphaMax * i / (kNodes - 1);
      const double h = 1e-5;
      auto run = [](double aa) {
        return IntegrateUnitContact([aa](double x, double xd) { return UnitForce(aa, x, xd); },
                                    false);
      };
      const UnitContact mid = run(a), hi = run(a + h), lo = run(std::max(a - h, 0.0));
      const double span = a + h - std::max(a - h, 0.0);
      const size_t j = static_cast<size_t>(kNodes - 1 - i);  // e decreases with alpha
      alpha[j] = a;
      e[j] = mid.restitution;
      de[j] = span / (hi.restitution - lo.restitution);  // d alpha / d e
      tau[static_cast<size_t>(i)] = mid.contact_time;
      dtau[static_cast<size_t>(i)] = (hi.contact_time - lo.contact_time) / span;
    }
    std::vector<double> alpha_inc(alpha.rbegin(), alpha.rend());
    return TsujiCurves{HermiteTable(e, alpha, de), HermiteTable(alpha_inc, tau, dtau)};
  }();
  return curves;
}

class HertzTsuji final : public LawBase {
 public:
  explicit HertzTsuji(double default_k, const std::string& k_note) {
    specs_ = {
        Spec("k", "N/m^1.5", "Hertz stiffness; default (4/3) E* sqrt(R*) from materials" + k_note,
             kStiffnessLower, kStiffnessUpper, default_k, false),
        Spec("e", "1", "target restitution (speed-independent); alpha(e) solved exactly", 0.005,
             1.0, 0.8, true),
    };
  }
  std::string Name() const override { return "hertz-tsuji"; }
  std::string Formula() const override { return "F = k d^1.5 + alpha(e) sqrt(m* k) d^0.25 d'"; }
  std::string Source() const override {
    return "Tsuji et al., Powder Technol. 71 (1992) 239, eq. 12; alpha(e) exact (master curve)";
  }
  double Force(std::span<const double> p, const ContactBody& body, double delta_m,
               double delta_dot_m_s, const double*) const override {
    if (delta_m <= 0.0) return 0.0;
    // eta prepared once per contact by the integrator (p[2]), else from the alpha(e) table.
    const double eta = p.size() > 2 ? p[2] : Eta(p, body);
    const double sqrt_delta = std::sqrt(delta_m);
    return p[0] * delta_m * sqrt_delta + eta * std::sqrt(sqrt_delta) * delta_dot_m_s;
  }
  // No branches: one call instead of the default's second virtual dispatch to Force.
  double ForceOnBranch(std::span<const double> p, const ContactBody& body, double delta_m,
                       double delta_dot_m_s, const double* state, bool) const override {
    return HertzTsuji::Force(p, body, delta_m, delta_dot_m_s, state);
  }
  int PreparedSize() const override { return 1; }
  void PrepareParameters(std::span<const double> p, const ContactBody& body,
                         double* prepared) const override {
    prepared[0] = Eta(p, body);
  }
  double ElasticEnergy(std::span<const double> p, const ContactBody&, double delta_m,
                       const double*) const override {
    return delta_m > 0.0 ? 0.4 * p[0] * delta_m * delta_m * std::sqrt(delta_m) : 0.0;
  }
  std::optional<double> Restitution(std::span<const double> p, const ContactBody&,
                                    double) const override {
    return p[1];  // exact by construction of alpha(e)
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double v_in_m_s) const override {
    const double time_scale = std::pow(body.mass_kg / p[0], 0.4) * std::pow(v_in_m_s, -0.2);
    return Curves().tau_of_alpha(Alpha(p[1])) * time_scale;
  }
  std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                           const ContactBody&, double e,
                                                           double) const override {
    if (!(e >= specs_[1].lower && e <= 1.0)) return std::nullopt;
    std::vector<double> q(p.begin(), p.end());
    q[1] = e;
    return q;
  }
  bool RestitutionGradient(std::span<const double> p, const ContactBody&, double, double* e,
                           double* de_dp) const override {
    if (e) *e = p[1];
    if (de_dp) {
      de_dp[0] = 0.0;
      de_dp[1] = 1.0;
    }
    return true;
  }
  std::vector<std::string> ClosedForms() const override {
    return {kClosedRestitution, kClosedContactTime, kClosedInverse, kClosedGradient};
  }
  // The dimensionless damping alpha of Tsuji's eta = alpha sqrt(m* k) for restitution e.
  static double Alpha(double e) { return e >= 1.0 ? 0.0 : Curves().alpha_of_e(e); }
  // Tsuji's damping coefficient eta = alpha(e) sqrt(m* k) (eq. 12).
  static double Eta(std::span<const double> p, const ContactBody& body) {
    return Alpha(p[1]) * std::sqrt(body.mass_kg * p[0]);
  }
};

}  // namespace

double HertzTsujiAlpha(double e) { return HertzTsuji::Alpha(e); }

std::unique_ptr<LawBase> MakeHertzTsuji(const LawSpec&, const Scene& scene) {
  std::string why;
  const std::optional<double> k = HertzStiffnessFromScene(scene, &why);
  return std::make_unique<HertzTsuji>(k.value_or(kNaN), k ? "" : "; " + why);
}

}  // namespace bouncecal::laws
