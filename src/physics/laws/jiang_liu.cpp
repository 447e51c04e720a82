// The Jiang-Liu thermodynamic contact law, normal direction (Jiang & Liu, Acta Phys. Sin. 67
// (2018) 044502, seed 000; PHYSICS.md §4).
//
// With lambda_n = 0 (eq. 37) the elastic deformation follows the overlap, u_n = -delta, so the
// spring force is plain Hertz, pi_n = k delta^(3/2) (eq. 8 with u_t = 0, c = 0). With the gear
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
// which is Lipschitz and leaves s = 0 on the dissipative branch without a seed (PHYSICS.md §4).
// tau is tiny (~ t_c/190 for steel): the relaxation is stiff; the adaptive integrator copes.
// The contact ends at delta = 0 (the viscous force makes F slightly attractive near the end;
// clipping it would break eq. 17). Internal energy = w_r. Parameters are the two prefactors
// of eqs. 37 and 39 (the paper's 0.06 and 0.1 are defaults; those are what a calibration fits).
// Note: eqs. 37 and 39 are not dimensionally homogeneous as printed (tau comes out in
// s*m^(1/2)); they are used as printed, in SI units, with m = grain mass and d = grain diameter.
#include "physics/laws/jiang_liu.hpp"

#include <cmath>

#include "physics/laws/law_base.hpp"

namespace bouncecal::laws {

double JiangLiuA(std::span<const double> p, const ContactBody& body) {
  const double d = body.ball_diameter_m, m = body.ball_mass_kg;
  return p[1] * std::pow(d, -0.375) * std::pow(p[0], 0.25) * std::sqrt(m);  // eq. 39
}

double JiangLiuTau(std::span<const double> p, const ContactBody& body) {
  return p[2] * std::sqrt(body.ball_mass_kg / p[0]) /
         std::pow(body.ball_diameter_m, 0.25);  // eq. 37
}

double JiangLiuTheta(double x) { return 0.5 * (std::tanh((x - kJiangLiuX0) / kJiangLiuX1) + 1.0); }

namespace {

class JiangLiu final : public LawBase {
 public:
  JiangLiu(double default_k, const std::string& k_note) {
    specs_ = {
        Spec("k", "N/m^1.5", "Hertz spring constant (eq. 8); default (4/3) E* sqrt(R*)" + k_note,
             kStiffnessLower, kStiffnessUpper, default_k, false),
        Spec("eta", "1", "prefactor of eta^relax, eq. 39 (paper: 0.1)", 0.0, 1e6, 0.1, true),
        Spec("tau", "1", "prefactor of tau_relax, eq. 37 (paper: 0.06)", 1e-9, 1e6, 0.06, false),
    };
  }
  std::string Name() const override { return "jiang-liu"; }
  std::string Formula() const override {
    return "F = k d^1.5 + a w_r^0.25 Theta(d/D) d', dw_r/dt = a w_r^0.25 Theta d'^2 - w_r/tau";
  }
  std::string Source() const override {
    return "Jiang & Liu, Acta Phys. Sin. 67 (2018) 044502, eqs. 28-33, 37-39 (seed 000)";
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
  int StateSize() const override { return 1; }
  void InitialState(std::span<const double>, const ContactBody&, double,
                    double* state) const override {
    state[0] = 0.0;  // s = w_r^(3/4): separated grains carry no relaxation energy
  }
  double Force(std::span<const double> p, const ContactBody& body, double delta_m,
               double delta_dot_m_s, const double* state) const override {
    if (delta_m <= 0.0) return 0.0;
    const double theta = JiangLiuTheta(delta_m / body.ball_diameter_m);
    const double eta = JiangLiuA(p, body) * std::cbrt(std::max(state[0], 0.0)) * theta;
    return p[0] * delta_m * std::sqrt(delta_m) + eta * delta_dot_m_s;
  }
  void StateRate(std::span<const double> p, const ContactBody& body, double delta_m,
                 double delta_dot_m_s, const double* state, double* rate) const override {
    const double theta = delta_m > 0.0 ? JiangLiuTheta(delta_m / body.ball_diameter_m) : 0.0;
    rate[0] = 0.75 * (JiangLiuA(p, body) * theta * delta_dot_m_s * delta_dot_m_s -
                      state[0] / JiangLiuTau(p, body));
  }
  double ElasticEnergy(std::span<const double> p, const ContactBody&, double delta_m,
                       const double*) const override {
    return delta_m > 0.0 ? 0.4 * p[0] * delta_m * delta_m * std::sqrt(delta_m) : 0.0;  // eq. 8
  }
  double InternalEnergy(std::span<const double>, const ContactBody&, double,
                        const double* state) const override {
    return std::pow(std::max(state[0], 0.0), 4.0 / 3.0);  // w_r = s^(4/3)
  }
};

}  // namespace

std::unique_ptr<LawBase> MakeJiangLiu(const LawSpec&, const Scene& scene) {
  std::string why;
  const std::optional<double> k = HertzStiffnessFromScene(scene, &why);
  return std::make_unique<JiangLiu>(k.value_or(kNaN), k ? "" : "; " + why);
}

}  // namespace bouncecal::laws
