// Linear spring-dashpot (Cundall & Strack 1979): F = k delta + c delta_dot.
//
// Closed form (any damping): m* delta'' + c delta' + k delta = 0, delta(0) = 0, delta'(0) = v.
// With omega = sqrt(k/m*), zeta = c / (2 sqrt(m* k)) (docs/physics.md §3):
//  - underdamped (zeta < 1): delta = (v/wd) exp(-sigma t) sin(wd t), sigma = zeta omega,
//    wd = omega sqrt(1 - zeta^2);
//      end at delta = 0:  t_c = pi/wd, e = exp(-pi zeta / sqrt(1 - zeta^2))
//      end at F = 0 (F = -m* delta'' = 0): wd t_c = pi - atan2(c wd, k - c sigma),
//        e = -delta'(t_c)/v  (the ball leaves with delta > 0; e = 0.8 under the delta = 0 rule
//        gives ~0.808 under this rule, docs/physics.md §3)
//  - critically/overdamped (zeta >= 1), roots r1,2 = -sigma +- omega sqrt(zeta^2 - 1):
//      end at delta = 0: never (the ball sticks: e = 0, t_c = inf)
//      end at F = 0: t_c = 2 ln(r2/r1)/(r1 - r2), e = exp(r1 t_c) r1/r2
//        (critical: omega t_c = 2, e = exp(-2)).
// Inverse (delta = 0 rule): zeta = -ln e / sqrt(pi^2 + ln^2 e), c = 2 zeta sqrt(m* k).
// Registered twice, with one class: "linear-dashpot" (delta = 0 end) and
// "linear-dashpot-force-zero"; the end rule is a column of the row (EndRule()).
#include <ceres/jet.h>

#include <cmath>

#include "physics/laws/law_impl.hpp"

namespace bouncecal::laws {
namespace {

using std::atan2;
using std::cos;
using std::exp;
using std::log;
using std::sin;
using std::sqrt;

// Restitution and contact time, templated so ceres::Jet gives exact derivatives.
template <typename T>
struct LinearEnd {
  T restitution;
  T time_s;
  bool stuck;
};

template <typename T>
LinearEnd<T> SolveLinearEnd(const T& k, const T& c, double m, bool force_zero) {
  const T omega = sqrt(k / m);
  const T zeta = c / (2.0 * sqrt(m * k));
  if (zeta < 1.0) {
    const T sigma = zeta * omega;
    const T wd = omega * sqrt(1.0 - zeta * zeta);
    if (!force_zero) return {exp(-kPi * sigma / wd), T(kPi) / wd, false};
    const T theta = kPi - atan2(c * wd, k - c * sigma);
    // delta'(t) / v = exp(-sigma t) (cos(wd t) - (sigma/wd) sin(wd t))
    const T rate = exp(-sigma * theta / wd) * (cos(theta) - sigma / wd * sin(theta));
    return {-rate, theta / wd, false};
  }
  if (!force_zero) return {T(0.0), T(kInf), true};
  if (zeta == 1.0) return {T(exp(-2.0)), 2.0 / omega, false};
  const T root = omega * sqrt(zeta * zeta - 1.0);
  const T r1 = -zeta * omega + root;  // slow root (closer to 0)
  const T r2 = -zeta * omega - root;
  const T t = 2.0 * log(r2 / r1) / (r1 - r2);
  return {exp(r1 * t) * r1 / r2, t, false};
}

}  // namespace

class LinearDashpot final : public LawImpl<LinearDashpot> {
 public:
  static std::unique_ptr<LawBase> Create(const LawSpec& spec, const Scene& scene) {
    // Default c: e = 0.8 under the overlap-zero rule for the scene's ball and the k in use.
    const auto given_k = spec.parameters.find("k");
    const double kDefaultK = 1e7;
    const double k_n_m = given_k == spec.parameters.end() ? kDefaultK : given_k->second;
    const double mass_kg = scene.ball.Mass();
    const double ln_e = std::log(0.8);
    const double zeta = -ln_e / std::sqrt(kPi * kPi + ln_e * ln_e);
    const double c_default =
        mass_kg > 0.0 && std::isfinite(mass_kg) && k_n_m > 0.0 && std::isfinite(k_n_m)
            ? 2.0 * zeta * std::sqrt(mass_kg * k_n_m)
            : 0.0;
    auto law = std::make_unique<LinearDashpot>();
    law->specs_ = {
        Spec("k", "N/m", "spring stiffness (default 1e7 N/m, seed 002 k_n)", kStiffnessLower,
             kStiffnessUpper, kDefaultK, false),
        Spec("c", "N*s/m",
             "dashpot coefficient (default: e = 0.8 for the scene's ball, overlap-zero rule)", 0.0,
             1e12, c_default, true),
    };
    return law;
  }

  template <class T>
  struct Constants {
    T k, c;
  };
  template <class T>
  Constants<T> Prepare(const T* p, const ContactBody&) const {
    return {p[0], p[1]};
  }
  // k d + c d' for every d: smooth through d = 0 (past the end the integrator continues it).
  static constexpr bool kContinuesBelowZero = true;
  template <class T>
  T Force(const Constants<T>& cs, const T& delta, const T& rate, const T*, bool) const {
    return cs.k * delta + cs.c * rate;
  }
  double ElasticEnergy(const Constants<double>& cs, double delta_m, const double*) const {
    return delta_m > 0.0 ? 0.5 * cs.k * delta_m * delta_m : 0.0;
  }
  // The row's end rule (the two rows of this class differ only there).
  bool ForceZero() const { return EndRule() == ContactEnd::kForceZero; }

  std::optional<double> Restitution(std::span<const double> p, const ContactBody& body,
                                    double) const override {
    return SolveLinearEnd<double>(p[0], p[1], body.mass_kg, ForceZero()).restitution;
  }
  std::optional<double> ContactTime(std::span<const double> p, const ContactBody& body,
                                    double) const override {
    return SolveLinearEnd<double>(p[0], p[1], body.mass_kg, ForceZero()).time_s;
  }

  std::optional<ContactOutcome> SolveContact(std::span<const double> p, const ContactBody& body,
                                             double v_in_m_s) const override {
    const double k = p[0], c = p[1], m = body.mass_kg, v = v_in_m_s;
    const LinearEnd<double> end = SolveLinearEnd<double>(k, c, m, ForceZero());
    ContactOutcome out;
    out.restitution = end.restitution;
    out.contact_time_s = end.time_s;
    out.stuck = end.stuck;
    const double omega = std::sqrt(k / m);
    const double zeta = c / (2.0 * std::sqrt(m * k));
    const double sigma = zeta * omega;
    out.peak_force_n = c * v;  // F at first touch; the maximum unless an interior peak exceeds it
    if (zeta < 1.0) {
      const double wd = omega * std::sqrt(1.0 - zeta * zeta);
      const double amp = v / wd;
      auto overlap = [&](double theta) {
        return amp * std::exp(-sigma * theta / wd) * std::sin(theta);
      };
      out.peak_overlap_m = overlap(std::atan2(wd, sigma));  // delta' = 0
      // F = m* amp exp(-sigma t) ((wd^2 - sigma^2) sin + 2 sigma wd cos); dF/dt = 0 at theta*.
      if (wd * wd > 3.0 * sigma * sigma) {
        const double theta = std::atan2(wd * (wd * wd - 3.0 * sigma * sigma),
                                        sigma * (3.0 * wd * wd - sigma * sigma));
        const double f =
            m * amp * std::exp(-sigma * theta / wd) *
            ((wd * wd - sigma * sigma) * std::sin(theta) + 2.0 * sigma * wd * std::cos(theta));
        out.peak_force_n = std::max(out.peak_force_n, f);
      }
      out.end_overlap_m = ForceZero() ? overlap(end.time_s * wd) : 0.0;
    } else if (zeta == 1.0) {
      out.peak_overlap_m = v / (omega * std::exp(1.0));
      out.end_overlap_m = ForceZero() ? v * end.time_s * std::exp(-omega * end.time_s) : 0.0;
    } else {
      const double root = omega * std::sqrt(zeta * zeta - 1.0);
      const double r1 = -sigma + root, r2 = -sigma - root;
      auto overlap = [&](double t) {
        return v / (r1 - r2) * (std::exp(r1 * t) - std::exp(r2 * t));
      };
      out.peak_overlap_m = overlap(std::log(r2 / r1) / (r1 - r2));
      out.end_overlap_m = ForceZero() ? overlap(end.time_s) : 0.0;
    }
    if (end.stuck) out.end_overlap_m = 0.0;  // approached asymptotically
    return out;
  }

  std::optional<std::vector<double>> DampingForRestitution(std::span<const double> p,
                                                           const ContactBody& body, double e,
                                                           double) const override {
    if (!(e > 0.0 && e <= 1.0)) return std::nullopt;
    std::vector<double> q(p.begin(), p.end());
    const double crit = 2.0 * std::sqrt(body.mass_kg * p[0]);  // c at zeta = 1
    if (!ForceZero()) {
      const double ln_e = std::log(e);
      q[1] = -ln_e / std::sqrt(kPi * kPi + ln_e * ln_e) * crit;
      return q;
    }
    // F = 0 rule: e(zeta) falls monotonically from 1 (zeta = 0) to 0 (zeta -> inf); bisect in
    // log(zeta) (no closed inverse).
    auto e_of = [&](double zeta) {
      return SolveLinearEnd<double>(p[0], zeta * crit, body.mass_kg, true).restitution;
    };
    if (e >= 1.0) {
      q[1] = 0.0;
      return q;
    }
    double lo = -30.0, hi = 30.0;  // log(zeta)
    if (e_of(std::exp(hi)) > e) return std::nullopt;
    for (int i = 0; i < 200 && hi - lo > 1e-15; ++i) {
      const double mid = 0.5 * (lo + hi);
      (e_of(std::exp(mid)) > e ? lo : hi) = mid;
    }
    q[1] = std::exp(0.5 * (lo + hi)) * crit;
    return q;
  }

  bool RestitutionGradient(std::span<const double> p, const ContactBody& body, double, double* e,
                           double* de_dp) const override {
    using Jet = ceres::Jet<double, 2>;
    const LinearEnd<Jet> end =
        SolveLinearEnd<Jet>(Jet(p[0], 0), Jet(p[1], 1), body.mass_kg, ForceZero());
    if (e) *e = end.restitution.a;
    if (de_dp) {
      de_dp[0] = end.restitution.v[0];
      de_dp[1] = end.restitution.v[1];
    }
    return true;
  }
};

template std::unique_ptr<LawBase> MakeLaw<LinearDashpot>(const LawSpec&, const Scene&);

}  // namespace bouncecal::laws
