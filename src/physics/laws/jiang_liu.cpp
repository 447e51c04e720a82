// The Jiang-Liu thermodynamic contact law, normal direction (Jiang & Liu, Acta Phys. Sin. 67
// (2018) 044502, seed 000; docs/physics.md §4).
//
// With lambda_n = 0 (eq. 37) the elastic deformation follows the overlap, u_n = -delta, so the
// spring force is plain Hertz, pi_n = k delta^(3/2) (the energy of eq. 19 with u_t = 0, c = 0;
// force eq. 20). With the gear
// ratio alpha_n = 1 - Theta(delta/d) (eq. 38) and eta^heat = 0 the normal force (eq. 28) is
//   F = k delta^(3/2) + eta^relax delta',  eta^relax = a w_r^(1/4) Theta(delta/d)  (eq. 39)
// (the elastic part is kept at full weight for delta > 0: Theta only gates the viscosity; with
// x0, x1 -> 0+ the two coincide, and this keeps the elastic force exactly -dw_e/d delta so that
// eq. 17 holds exactly). The relaxation energy obeys (eq. 32)
//   dw_r/dt = eta^relax delta'^2 - w_r / tau,   heat rate R = w_r / tau (eq. 33),
// and mechanical + w_r + integral R dt is conserved (eq. 17). Because eta^relax ~ w_r^(1/4), the
// w_r equation is not Lipschitz at w_r = 0 (w_r = 0 is a spurious elastic solution). The state
// integrated here is s = w_r^(3/4):
//   ds/dt = (3/4) (a Theta delta'^2 - s / tau),  w_r = s^(4/3),  eta^relax = a s^(1/3) Theta,
// which is Lipschitz and leaves s = 0 on the dissipative branch without a seed (docs/physics.md
// §4). tau is tiny (~ t_c/250 for the 1 cm steel ball): the relaxation is stiff. How the integrator
// copes (contact_integrator.hpp), measured with bench_simulate:
//  - the constants of eqs. 37 and 39 (five pow calls) are prepared once per simulation
//    (Prepare), not at every force evaluation (they were 37 % of this law's time);
//  - the change of variables s = w_r^(3/4) (Lipschitz, see above) and, near first touch where
//    s grows like t, the independent variable u = delta^(1/6) (kOverlapRoot = 6): the force is
//    smooth in u there;
//  - the error of s is measured against the contact's energy scale (StateScale: s in units of
//    (m v^2/2)^(3/4), i.e. w_r in energy units), not relative to s itself: near maximum
//    compression s falls towards 0 and its s^(1/3) has no bounded derivatives, so a relative
//    error test shrank the steps there (the old integrator's 870 steps per contact at rtol
//    1e-9; now ~180, no rejected step around maximum compression);
//  - what is left is the stiffness itself: with explicit Dormand-Prince the step stays below
//    ~4 tau (stability), so at loose tolerances (rtol >= 1e-5) a contact costs ~70 steps where
//    Hertz needs 20-30. At the tolerances fits use (1e-7 .. 1e-9) the steps are set by accuracy
//    and a contact costs 2-2.5x a Hertz-Tsuji contact at the same accuracy (bench_simulate,
//    "Every law at the same accuracy").
// The contact ends at delta = 0 (the viscous force makes F slightly attractive near the end;
// clipping it would break eq. 17). Internal energy = w_r. Parameters are the two prefactors
// of eqs. 37 and 39 (the paper's 0.06 and 0.1 are defaults; those are what a calibration fits).
// Eqs. 37 and 39 are used as printed, in SI units, with m = grain mass and d = grain diameter;
// with k in kg/(s^2 m^(1/2)) (= N/m^1.5, the paper below eq. 19) tau comes out in s and
// eta^relax in kg/s (docs/physics.md §4).
#include "physics/laws/jiang_liu.hpp"

#include <cmath>

#include "physics/laws/law_impl.hpp"

namespace bouncecal::laws {
namespace {

// eq. 39: a = eta d^(-3/8) k^(1/4) m^(1/2); eq. 37: tau = tau' sqrt(m/k) / d^(1/4).
template <class T>
T RelaxationViscosityFactor(const T* p, const ContactBody& body) {
  using std::pow;
  using std::sqrt;
  return p[1] * std::pow(body.ball_diameter_m, -0.375) * pow(p[0], 0.25) *
         std::sqrt(body.ball_mass_kg);
}
template <class T>
T RelaxationTime(const T* p, const ContactBody& body) {
  using std::sqrt;
  return Quotient(p[2] * sqrt(body.ball_mass_kg / p[0]), std::pow(body.ball_diameter_m, 0.25));
}
template <class T>
T Theta(const T& x) {
  using std::tanh;
  return 0.5 * (tanh(Quotient(x - kJiangLiuX0, kJiangLiuX1)) + 1.0);
}

}  // namespace

double JiangLiuA(std::span<const double> p, const ContactBody& body) {
  return RelaxationViscosityFactor(p.data(), body);
}
double JiangLiuTau(std::span<const double> p, const ContactBody& body) {
  return RelaxationTime(p.data(), body);
}
double JiangLiuTheta(double x) { return Theta(x); }

class JiangLiu final : public LawImpl<JiangLiu> {
 public:
  static constexpr int kStateSize = 1;  // s = w_r^(3/4)
  // Near first touch s grows like t (so eta^relax like t^(1/3) = delta^(1/3)) and the spring
  // like delta^(3/2): both smooth in delta^(1/6).
  static constexpr int kOverlapRoot = 6;

  static std::unique_ptr<LawBase> Create(const LawSpec&, const Scene& scene) {
    auto law = std::make_unique<JiangLiu>();
    law->specs_ = {
        HertzStiffnessSpec(scene, "N/m^1.5", "Hertz spring constant (eqs. 19-20)"),
        Spec("eta", "1", "prefactor of eta^relax, eq. 39 (paper: 0.1)", 0.0, 1e6, 0.1, true),
        Spec("tau", "1", "prefactor of tau_relax, eq. 37 (paper: 0.06)", 1e-9, 1e6, 0.06, false),
    };
    return law;
  }
  bool IsValid(std::span<const double> p, const ContactBody& body,
               std::string* error) const override {
    if (!LawBase::IsValid(p, body, error)) return false;
    if (!(body.ball_mass_kg > 0.0) || !(body.ball_diameter_m > 0.0)) {
      if (error) *error = Name() + ": the grain mass and diameter must be positive";
      return false;
    }
    return true;
  }

  // Per-contact constants of eqs. 37 and 39, computed once (Prepare), not per evaluation.
  template <class T>
  struct Constants {
    T k;
    T a;           // eta^relax = a s^(1/3) Theta(delta/d)
    T inv_tau;     // 1 / tau_relax
    double inv_d;  // 1 / d
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody& body) const {
    return {p[0], RelaxationViscosityFactor(p, body), 1.0 / RelaxationTime(p, body),
            1.0 / body.ball_diameter_m};
  }
  template <class T>
  static T Viscosity(const Constants<T>& c, const T& delta, const T* state) {
    using std::cbrt;
    if (!(state[0] > 0.0)) return T(0.0);  // s^(1/3) has no derivative at 0
    return c.a * cbrt(state[0]) * Theta(delta * c.inv_d);
  }
  template <class T>
  T Force(const Constants<T>& c, const T& delta, const T& rate, const T* state, bool) const {
    using std::sqrt;
    if (!(delta > 0.0)) return T(0.0);
    return c.k * delta * sqrt(delta) + Viscosity(c, delta, state) * rate;
  }
  template <class T, class C>
  void StateRate(const C& c, const T& delta, const T& rate, const T* state, T* out) const {
    const T theta = delta > 0.0 ? Theta(delta * c.inv_d) : T(0.0);
    out[0] = 0.75 * (c.a * theta * rate * rate - state[0] * c.inv_tau);
  }
  // s = w_r^(3/4): errors of s are measured against the contact's energy scale to the 3/4.
  double StateScale(const Constants<double>&, int, double, double energy_j) const {
    return std::pow(energy_j, 0.75);
  }
  double ElasticEnergy(const Constants<double>& c, double delta_m, const double*) const {
    return delta_m > 0.0 ? 0.4 * c.k * delta_m * delta_m * std::sqrt(delta_m) : 0.0;  // eq. 19
  }
  bool ElasticPowerLaw(const Constants<double>& c, double* coefficient, double* exponent) const {
    *coefficient = 0.4 * c.k;  // eq. 19 (independent of the state: u_n = -delta)
    *exponent = 2.5;
    return true;
  }
  double InternalEnergy(const Constants<double>&, const double* state) const {
    return std::pow(std::max(state[0], 0.0), 4.0 / 3.0);  // w_r = s^(4/3)
  }
};

template std::unique_ptr<LawBase> MakeLaw<JiangLiu>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
