// Hertz contact with Tsuji's viscous damping (Tsuji, Tanaka & Ishida, Powder Technol. 71 (1992)
// 239, eq. 12; the "Hertz-Mindlin" normal force of seeds 000 and 003; docs/physics.md §3):
//   F = k delta^(3/2) + eta delta^(1/4) delta',  eta = alpha(e) sqrt(m* k).
// Parameterisation: the user (and the fitter) gives the TARGET RESTITUTION e, not alpha. The
// restitution of this law depends on alpha only (scaling delta = L x, t = (L/v) s with
// L = (m* v^2/k)^(2/5) turns the equation into x'' = -x^(3/2) - alpha x^(1/4) x', free of
// v, m*, k), so alpha(e) is one universal curve: its nodes are computed at build time
// (laws/master_curves.hpp: 801 alpha nodes, dopri5 at rel. tol. 1e-12, ends by bisection) and
// inverted by cubic Hermite interpolation. e is therefore exact (to ~1e-9) at every speed; the
// contact time is t_c = tau(alpha) (m*/k)^(2/5) v^(-1/5) from the same curve. eta is prepared
// once per contact (Prepare). Default k = (4/3) E* sqrt(R*) from the scene's materials. The
// contact ends at delta = 0; the force turns slightly attractive before (kept, as in DEM
// codes). Beyond alpha ~ 2.3 the ball sticks (delta creeps to 0 and never returns), hence
// e >= 0.005.
#include "physics/laws/hertz_family.hpp"
#include "physics/laws/law_impl.hpp"
#include "physics/laws/master_curves.hpp"

namespace bouncecal::laws {
namespace {

struct TsujiCurves {
  HermiteTable alpha_of_e;  // x = e (increasing), y = alpha
  HermiteTable tau_of_alpha;
};

const TsujiCurves& Curves() {
  static const TsujiCurves curves = [] {
    const MasterNodes& n = TsujiNodes();
    // e decreases with alpha: reverse the nodes for alpha(e), d alpha / d e = 1 / (de/d alpha).
    const size_t count = n.damping.size();
    std::vector<double> e(count), alpha(count), dalpha_de(count);
    for (size_t j = 0; j < count; ++j) {
      const size_t i = count - 1 - j;
      e[j] = n.restitution[i];
      alpha[j] = n.damping[i];
      dalpha_de[j] = 1.0 / n.restitution_slope[i];
    }
    return TsujiCurves{HermiteTable(e, alpha, dalpha_de),
                       HermiteTable(n.damping, n.contact_time, n.contact_time_slope)};
  }();
  return curves;
}

}  // namespace

class HertzTsuji final : public LawImpl<HertzTsuji> {
 public:
  static constexpr int kOverlapRoot = 4;  // delta^(1/4) damping: smooth in delta^(1/4)

  static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene& scene) {
    auto law = std::make_unique<HertzTsuji>();
    law->specs_ = {
        HertzStiffnessSpec(scene, "N/m^1.5", "Hertz stiffness"),
        Spec("e", "1", "target restitution (speed-independent); alpha(e) solved exactly", 0.005,
             1.0, 0.8, true),
    };
    return law;
  }

  template <class T>
  struct Constants {
    T k;
    T eta;  // Tsuji's damping coefficient alpha(e) sqrt(m* k) (eq. 12)
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody& body) const {
    using std::sqrt;
    return {p[0], Alpha(p[1]) * sqrt(body.mass_kg * p[0])};
  }
  template <class T>
  T Force(const Constants<T>& c, const T& delta, const T& rate, const T*, bool) const {
    using std::sqrt;
    if (!(delta > 0.0)) return T(0.0);
    const T root = sqrt(delta);
    return c.k * delta * root + c.eta * sqrt(root) * rate;
  }
  double ElasticEnergy(const Constants<double>& c, double delta_m, const double*) const {
    return delta_m > 0.0 ? 0.4 * c.k * delta_m * delta_m * std::sqrt(delta_m) : 0.0;
  }
  bool ElasticPowerLaw(const Constants<double>& c, double* coefficient, double* exponent) const {
    *coefficient = 0.4 * c.k;
    *exponent = 2.5;
    return true;
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

  // The dimensionless damping alpha of Tsuji's eta = alpha sqrt(m* k) for restitution e.
  template <class T>
  static T Alpha(const T& e) {
    return e >= 1.0 ? T(0.0) : Interpolate(Curves().alpha_of_e, e);
  }
};

double HertzTsujiAlpha(double e) { return HertzTsuji::Alpha(e); }

template std::unique_ptr<LawBase> MakeLaw<HertzTsuji>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
