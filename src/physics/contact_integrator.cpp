// One contact, integrated with Boost.Odeint dopri5 and located events. See
// include/bouncecal/physics/contact_integrator.hpp for the model and the event strategy.
#include "bouncecal/physics/contact_integrator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>

#include <boost/numeric/odeint.hpp>

namespace bouncecal {
namespace {

namespace odeint = boost::numeric::odeint;

constexpr int kMaxLawState = 7;
// Room for a law's parameters plus its prepared constants (ContactLaw::PrepareParameters).
constexpr size_t kMaxPrepared = 32;
// Event times are located to this relative precision (in units of the contact time).
constexpr double kEventTolerance = 1e-14;

// Scale factors from physical to integrated (dimensionless) variables.
struct Scales {
  double time_s = 1.0;
  double speed_m_s = 1.0;
  double length_m = 1.0;
  double energy_j = 1.0;
  std::array<double, kMaxLawState> state{};
};

// Physical view of one scaled state vector.
struct Phys {
  double y = 0.0, yd = 0.0, z = 0.0, zd = 0.0, work = 0.0;
  double delta = 0.0, delta_dot = 0.0;
  std::array<double, kMaxLawState> state{};
};

// The scaled ODE system. Layout: [y, y', work, (z, z' if plate), law state...].
template <size_t N>
class ScaledContact {
 public:
  using State = std::array<double, N>;
  // The large layout has room for the plate (z, z' at 3, 4); the small one has none.
  static constexpr bool kBig = N > 4;

  // p: the law's parameters; pe: p followed by the law's prepared constants
  // (ContactLaw::PrepareParameters), passed to the per-evaluation dynamics functions.
  ScaledContact(const ContactLaw& law, std::span<const double> p, std::span<const double> pe,
                const ContactBody& body, double g_m_s2, const PlateModel* plate,
                const Scales& scales, int n_state)
      : law_(law),
        p_(p),
        pe_(pe),
        body_(body),
        g_(g_m_s2),
        plate_(plate),
        sc_(scales),
        n_state_(n_state),
        s0_(kBig ? 5 : 3),
        inv_mass_(1.0 / body.mass_kg),
        accel_scale_(scales.time_s / scales.speed_m_s),
        power_scale_(scales.time_s / scales.energy_j) {}

  size_t StateOffset() const { return s0_; }
  const Scales& scales() const { return sc_; }

  Phys Unscale(const State& x) const {
    Phys ph;
    ph.y = x[0] * sc_.length_m;
    ph.yd = x[1] * sc_.speed_m_s;
    ph.work = x[2] * sc_.energy_j;
    if constexpr (kBig) {
      if (plate_) {
        ph.z = x[3] * sc_.length_m;
        ph.zd = x[4] * sc_.speed_m_s;
      }
    }
    ph.delta = ph.y - ph.z;
    ph.delta_dot = ph.yd - ph.zd;
    for (int i = 0; i < n_state_; ++i) ph.state[i] = x[s0_ + i] * sc_.state[i];
    return ph;
  }

  // The law's force on the current branch (ContactLaw::ForceOnBranch: every trial point of a
  // step stays on the branch the step started on), extended continuously past delta = 0 by
  // F(0, delta') so that the dense output around the end event stays smooth.
  double Force(const Phys& ph) const {
    return law_.ForceOnBranch(pe_, body_, std::max(ph.delta, 0.0), ph.delta_dot, ph.state.data(),
                              positive_branch_);
  }
  void SetBranch(bool positive) { positive_branch_ = positive; }
  bool positive_branch() const { return positive_branch_; }
  double Switch(const Phys& ph) const {
    return law_.SwitchFunction(pe_, body_, std::max(ph.delta, 0.0), ph.delta_dot, ph.state.data());
  }
  double PlateEnergy(const Phys& ph) const {
    if (!plate_) return 0.0;
    return 0.5 * plate_->mass_kg * ph.zd * ph.zd + 0.5 * plate_->stiffness_n_m * ph.z * ph.z;
  }
  double BallEnergy(const Phys& ph) const {
    const double m = body_.mass_kg;
    return 0.5 * m * ph.yd * ph.yd - m * g_ * ph.y;
  }
  double Elastic(const Phys& ph) const {
    return law_.ElasticEnergy(p_, body_, std::max(ph.delta, 0.0), ph.state.data());
  }
  double Internal(const Phys& ph) const {
    return law_.InternalEnergy(p_, body_, std::max(ph.delta, 0.0), ph.state.data());
  }

  void operator()(const State& x, State& dx, double /*tau*/) const {
    const Phys ph = Unscale(x);
    const double f = Force(ph);
    const double t = sc_.time_s;
    dx.fill(0.0);
    dx[0] = x[1];                                 // L = V T
    dx[1] = accel_scale_ * (g_ - f * inv_mass_);  // m y'' = m g - F
    dx[2] = power_scale_ * f * ph.yd;             // d(work)/dt = F y'
    if constexpr (kBig) {
      if (plate_) {
        dx[3] = x[4];
        dx[4] = t / sc_.speed_m_s *
                (f - plate_->stiffness_n_m * ph.z - plate_->damping_n_s_m * ph.zd) /
                plate_->mass_kg;  // M z'' = F - K z - C z'
      }
    }
    if (n_state_ > 0) {
      std::array<double, kMaxLawState> rate{};
      law_.StateRate(pe_, body_, std::max(ph.delta, 0.0), ph.delta_dot, ph.state.data(),
                     rate.data());
      for (int i = 0; i < n_state_; ++i) dx[s0_ + i] = t * rate[i] / sc_.state[i];
    }
  }

 private:
  const ContactLaw& law_;
  std::span<const double> p_;
  std::span<const double> pe_;
  const ContactBody& body_;
  double g_;
  const PlateModel* plate_;
  Scales sc_;
  int n_state_;
  size_t s0_;
  // Constant factors of the right-hand side (multiplications instead of divisions per call).
  double inv_mass_;     // 1/m*, 1/kg
  double accel_scale_;  // T/V: physical acceleration -> scaled
  double power_scale_;  // T/E: physical power -> scaled
  bool positive_branch_ = true;
};

// Root of a continuous g on [lo, hi] with g(lo), g(hi) of opposite signs (or g(hi) == 0):
// Illinois regula falsi safeguarded by bisection every third step. Returns the end of the final
// bracket on the side of hi (the event has happened there), width <= tol.
template <class G>
double LocateRoot(const G& g, double lo, double hi, double g_lo, double g_hi, double tol) {
  int side = 0;
  for (int iter = 0; iter < 200 && hi - lo > tol; ++iter) {
    double c = (g_lo * hi - g_hi * lo) / (g_lo - g_hi);
    if (iter % 3 == 2 || !(c > lo && c < hi)) c = 0.5 * (lo + hi);
    const double g_c = g(c);
    if (g_c == 0.0) return c;
    if ((g_c > 0.0) == (g_hi > 0.0)) {
      hi = c;
      g_hi = g_c;
      if (side == -1) g_lo *= 0.5;
      side = -1;
    } else {
      lo = c;
      g_lo = g_c;
      if (side == +1) g_hi *= 0.5;
      side = +1;
    }
  }
  return hi;
}

template <size_t N>
bool AllFinite(const std::array<double, N>& x) {
  for (double v : x) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

template <size_t N>
ContactRun Integrate(const ContactLaw& law, std::span<const double> p,
                     std::span<const double> p_prepared, const ContactBody& body, double v_in,
                     double g, const PlateModel* plate, const ContactRunOptions& options) {
  using State = std::array<double, N>;
  using Stepper = odeint::runge_kutta_dopri5<State>;
  ContactRun run;
  const int n_state = law.StateSize();

  Scales sc;
  sc.time_s = EstimateContactTime(law, p, body, v_in);
  sc.speed_m_s = v_in;
  sc.length_m = v_in * sc.time_s;
  sc.energy_j = 0.5 * body.mass_kg * v_in * v_in;
  run.contact_time_scale_s = sc.time_s;

  // Law state: initial value, and a scale from the initial value and a probe of the rate.
  std::array<double, kMaxLawState> s0{}, rate{};
  law.InitialState(p, body, v_in, s0.data());
  if (n_state > 0) {
    law.StateRate(p, body, 0.3 * sc.length_m, 0.5 * v_in, s0.data(), rate.data());
  }
  for (int i = 0; i < kMaxLawState; ++i) {
    double s = std::max(std::abs(s0[i]), std::abs(rate[i]) * sc.time_s);
    sc.state[i] = (std::isfinite(s) && s > 0.0) ? s : 1.0;
  }

  ScaledContact<N> sys(law, p, p_prepared, body, g, plate, sc, n_state);
  State x{};
  x[1] = 1.0;
  for (int i = 0; i < n_state; ++i) x[sys.StateOffset() + i] = s0[i] / sc.state[i];
  State f{};
  sys(x, f, 0.0);

  auto ctrl = odeint::make_controlled(options.abs_tolerance, options.rel_tolerance, Stepper());
  const double stuck_energy =
      0.5 * body.mass_kg * options.stuck_speed_m_s * options.stuck_speed_m_s;
  const bool force_zero_end = law.EndRule() == ContactEnd::kForceZero;

  double t = 0.0;
  double dt = 1e-3;
  sys.SetBranch(sys.Switch(sys.Unscale(x)) > 0.0);
  bool was_loaded = false;   // F > 0 seen (for the F = 0 end rule)
  bool force_rising = true;  // the first force maximum is still ahead
  int stalled_switches = 0;  // consecutive switches without progress in time
  State x_new{}, f_new{}, xd{};

  auto finish = [&](const State& xe, double te) {
    const Phys ph = sys.Unscale(xe);
    run.contact_s = te * sc.time_s;
    run.work_j = ph.work;
    run.elastic_end_j = sys.Elastic(ph);
    run.plate_end_j = sys.PlateEnergy(ph);
    run.internal_end_j = sys.Internal(ph);
    run.ball_energy_end_j = sys.BallEnergy(ph);
    run.separation_depth_m = ph.y;
    return ph;
  };

  while (true) {
    if (run.steps >= options.max_steps) {
      finish(x, t);
      run.end = ContactRun::End::kStepLimit;
      std::ostringstream os;
      os << law.Name() << ": contact not resolved within " << options.max_steps
         << " integrator steps (t = " << t * sc.time_s << " s, v_in = " << v_in << " m/s)";
      run.detail = os.str();
      return run;
    }
    ++run.steps;
    double t1 = t;
    const double dt_try = dt;
    if (ctrl.try_step(std::ref(sys), x, f, t1, x_new, f_new, dt) == odeint::fail) continue;
    if (!AllFinite(x_new) || !AllFinite(f_new)) {
      // Non-finite force at a stage (e.g. a law evaluated out of its domain): smaller step.
      dt = 0.25 * dt_try;
      if (dt < 1e-15) {
        finish(x, t);
        run.end = ContactRun::End::kStepLimit;
        run.detail = law.Name() +
                     ": the force is not finite at t = " + std::to_string(t * sc.time_s) +
                     " s (step size underflow)";
        return run;
      }
      continue;
    }
    const double tol_tau = kEventTolerance * std::max(1.0, t1);
    // Dense output of the accepted step [t, t1] (dopri5's 4th-order continuous extension).
    auto dense = [&](double tau) {
      ctrl.stepper().calc_state(tau, xd, x, f, t, x_new, f_new, t1);
      return sys.Unscale(xd);
    };

    // 1. Branch switch: the step ran on the old branch continued past the switch, so the
    // dense output is smooth; locate the sign change and end the step window there.
    const double sign = sys.positive_branch() ? 1.0 : -1.0;
    double t_w = t1;  // end of the window of this step that is valid
    bool switched = false;
    {
      const double g1 = sys.Switch(sys.Unscale(x_new)) * sign;
      if (!(g1 > 0.0)) {
        const double g0 = sys.Switch(sys.Unscale(x)) * sign;
        auto gs = [&](double tau) { return sys.Switch(dense(tau)) * sign; };
        t_w = g0 > 0.0 ? LocateRoot(gs, t, t1, g0, g1, tol_tau) : t;
        switched = true;
      }
    }
    State x_w = x_new;
    if (t_w < t1) {
      dense(t_w);
      x_w = xd;
    }

    // 2. Contact end within the window: delta returns to 0 (or F to 0 for kForceZero laws).
    const Phys pw = sys.Unscale(x_w);
    const double fw = force_zero_end ? sys.Force(pw) : 0.0;
    double t_end = -1.0;
    if (pw.delta <= 0.0 && t_w > 0.0) {
      const Phys p0 = sys.Unscale(x);
      auto gd = [&](double tau) { return dense(tau).delta; };
      t_end = p0.delta > 0.0 ? LocateRoot(gd, t, t_w, p0.delta, pw.delta, tol_tau) : t_w;
    }
    if (force_zero_end && was_loaded && fw <= 0.0) {
      const double f0 = sys.Force(sys.Unscale(x));
      auto gf = [&](double tau) { return sys.Force(dense(tau)); };
      const double tf = f0 > 0.0 ? LocateRoot(gf, t, t_w, f0, fw, tol_tau) : t;
      if (t_end < 0.0 || tf < t_end) t_end = tf;
    }
    if (fw > 0.0) was_loaded = true;

    // Peaks over [t, t_hi].
    const double t_hi = t_end >= 0.0 ? t_end : t_w;
    State x_hi = x_w;
    if (t_hi < t_w) {
      dense(t_hi);
      x_hi = xd;
    }
    {
      const Phys a = sys.Unscale(x);
      const Phys b = sys.Unscale(x_hi);
      // At the step end the force is known from the ball's acceleration (the FSAL derivative):
      // y'' = g - F/m, so no extra force evaluation is needed.
      const double fb =
          t_hi == t1 ? body.mass_kg * (g - f_new[1] * sc.speed_m_s / sc.time_s) : sys.Force(b);
      run.peak_overlap_m = std::max(run.peak_overlap_m, b.delta);
      run.peak_force_n = std::max(run.peak_force_n, fb);
      if (a.delta_dot > 0.0 && b.delta_dot <= 0.0) {
        auto gv = [&](double tau) { return dense(tau).delta_dot; };
        const Phys pm = dense(LocateRoot(gv, t, t_hi, a.delta_dot, b.delta_dot, tol_tau));
        run.peak_overlap_m = std::max(run.peak_overlap_m, pm.delta);
        run.peak_force_n = std::max(run.peak_force_n, sys.Force(pm));
      }
      // Force maximum inside the window: F rising at its start, falling at its end (searched
      // until the first maximum is found; later local maxima are sampled at step ends).
      const double h_step = t_hi - t;
      const bool rising_end =
          !force_rising || (h_step > 0.0 && fb > sys.Force(dense(t_hi - 1e-6 * h_step)));
      if (force_rising && !rising_end && h_step > 0.0) {
        double lo = t, hi = t_hi;  // golden-section search for the maximum of F
        constexpr double kInvPhi = 0.6180339887498949;
        double c1 = hi - kInvPhi * (hi - lo), c2 = lo + kInvPhi * (hi - lo);
        double f1c = sys.Force(dense(c1)), f2c = sys.Force(dense(c2));
        for (int i = 0; i < 60 && hi - lo > tol_tau; ++i) {
          if (f1c < f2c) {
            lo = c1;
            c1 = c2;
            f1c = f2c;
            c2 = lo + kInvPhi * (hi - lo);
            f2c = sys.Force(dense(c2));
          } else {
            hi = c2;
            c2 = c1;
            f2c = f1c;
            c1 = hi - kInvPhi * (hi - lo);
            f1c = sys.Force(dense(c1));
          }
        }
        run.peak_force_n = std::max(run.peak_force_n, std::max(f1c, f2c));
        force_rising = false;
      }
    }

    if (t_end >= 0.0) {
      // The dense output is one order below the step: recompute the end state with one dopri5
      // step of exactly t_end - t (valid: no event inside), then a Newton correction in time
      // for delta = 0 (end rule kOverlapZero).
      if (t_end > t) {
        ctrl.stepper().do_step(std::ref(sys), x, f, t, x_hi, f_new, t_end - t);
        const Phys pe = sys.Unscale(x_hi);
        if (!force_zero_end && pe.delta_dot < 0.0 && AllFinite(x_hi)) {
          const double dtau = -(pe.delta / sc.length_m) / (pe.delta_dot / sc.speed_m_s);
          if (std::abs(dtau) < 1e-3 * (t_end - t)) {
            for (size_t i = 0; i < N; ++i) x_hi[i] += f_new[i] * dtau;
            t_end += dtau;
          }
        }
      }
      const Phys pe = finish(x_hi, t_end);
      run.v_out_m_s = std::max(0.0, -pe.yd);
      run.end = ContactRun::End::kSeparated;
      return run;
    }

    const double t_before = t;
    if (switched) {
      // Restart the integrator on the other branch at the located switch, from a state
      // recomputed by one step of exactly t_w - t on the old branch (continued past the switch,
      // so the step is smooth).
      if (t_w > t) {
        const State x_dense = x_w;
        ctrl.stepper().do_step(std::ref(sys), x, f, t, x_w, f_new, t_w - t);
        if (!AllFinite(x_w)) x_w = x_dense;
      }
      x = x_w;
      t = t_w;
      stalled_switches = t_w - t_before < 1e-12 ? stalled_switches + 1 : 0;
      sys.SetBranch(!sys.positive_branch());
      sys(x, f, t);
      ++run.switches;
    } else {
      x = x_w;
      t = t_w;
      f = f_new;
      stalled_switches = 0;
    }

    // 3. Stuck: the energy left cannot send the ball off faster than stuck_speed, or the
    // contact lasts far longer than any rebound would.
    // Creeping: the ball moves slower than stuck_speed and its acceleration cannot change that
    // within a contact time (overdamped: delta' never returns to 0). Cheap, every step.
    const double v_stuck = options.stuck_speed_m_s / sc.speed_m_s;
    const bool creeping = std::abs(x[1]) < v_stuck && std::abs(f[1]) < v_stuck;
    // Sliding on the switch surface: repeated switches without progress (Walton-Braun's ball
    // resting under gravity between its loading and unloading equilibria).
    const bool sliding = stalled_switches >= 4;
    // Energy: checked while the ball moves out, or once the contact outlasts 1.5 estimates.
    bool energy_gone = false;
    double e_left = 0.0;
    // Cheap precheck: elastic, plate and internal energies are >= 0, so the ball's own energy
    // (kinetic + potential) must already be below the threshold.
    const double y_m = x[0] * sc.length_m, yd_m_s = x[1] * sc.speed_m_s;
    const double ball_j = 0.5 * body.mass_kg * yd_m_s * yd_m_s - body.mass_kg * g * y_m;
    if (stuck_energy > 0.0 && ball_j < stuck_energy &&
        (x[1] <= 0.0 || t >= 1.5 || creeping || sliding)) {
      const Phys pc = sys.Unscale(x);
      e_left = sys.BallEnergy(pc) + sys.Elastic(pc) + sys.PlateEnergy(pc) + sys.Internal(pc);
      energy_gone = e_left < stuck_energy && pc.delta > 0.0;
    }
    if (energy_gone || creeping || sliding || t > options.max_contact_time_factor) {
      finish(x, t);
      run.end = ContactRun::End::kStuck;
      std::ostringstream os;
      if (sliding) {
        os << "the ball rests in contact on the law's branch switch (repeated switches without "
              "progress at t = "
           << t * sc.time_s << " s into the contact)";
      } else if (creeping) {
        os << "the ball creeps slower than " << options.stuck_speed_m_s
           << " m/s with negligible acceleration (overdamped; t = " << t * sc.time_s
           << " s into the contact)";
      } else if (energy_gone) {
        os << "the ball stays in contact: energy left " << e_left
           << " J cannot lift it off faster than " << options.stuck_speed_m_s
           << " m/s (t = " << t * sc.time_s << " s into the contact)";
      } else {
        os << "the ball stays in contact for more than " << options.max_contact_time_factor
           << " contact-time estimates (" << t * sc.time_s << " s)";
      }
      run.detail = os.str();
      return run;
    }
  }
}

// Elastic energy of the law at overlap d with the initial state (NaN-safe).
double ElasticAt(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                 const double* s0, double d) {
  const double w = law.ElasticEnergy(p, body, d, s0);
  return std::isfinite(w) ? w : 0.0;
}

}  // namespace

double EstimateContactTime(const ContactLaw& law, std::span<const double> p,
                           const ContactBody& body, double v_in_m_s) {
  if (auto tc = law.ContactTime(p, body, v_in_m_s); tc && std::isfinite(*tc) && *tc > 0.0) {
    return *tc;
  }
  std::array<double, kMaxLawState> s0{};
  law.InitialState(p, body, v_in_m_s, s0.data());
  const double target = 0.5 * body.mass_kg * v_in_m_s * v_in_m_s;
  // Bracket delta_max on a log scale between 1e-18 m and 1e3 R, then bisect in log space.
  double lo = 1e-18, hi = 1e-18;
  while (hi < 1e3 * body.radius_m && ElasticAt(law, p, body, s0.data(), hi) < target) {
    lo = hi;
    hi *= 10.0;
  }
  if (ElasticAt(law, p, body, s0.data(), hi) >= target) {
    for (int i = 0; i < 60; ++i) {
      const double mid = std::sqrt(lo * hi);
      (ElasticAt(law, p, body, s0.data(), mid) < target ? lo : hi) = mid;
    }
    // Linear spring: t_c = pi delta_max / v; Hertz: 2.94 delta_max / v (PHYSICS.md §2).
    return 3.0 * hi / v_in_m_s;
  }
  // No usable elastic energy (a purely dissipative user law): the time to cross 1e-3 R.
  return 1e-3 * body.radius_m / v_in_m_s;
}

ContactRun RunContact(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                      double v_in_m_s, double g_m_s2, const PlateModel* plate,
                      const ContactRunOptions& options) {
  const int n_state = law.StateSize();
  if (n_state > kMaxLawState || n_state < 0) {
    ContactRun r;
    r.end = ContactRun::End::kStepLimit;
    r.detail = law.Name() + ": " + std::to_string(n_state) + " internal state variables (at most " +
               std::to_string(kMaxLawState) + " supported)";
    return r;
  }
  // The law's constants derived from (p, body), computed once per contact instead of at every
  // force evaluation (ContactLaw::PrepareParameters); without room for them, plain p.
  std::array<double, kMaxPrepared> pe_buf{};
  std::span<const double> pe = p;
  const int n_prep = law.PreparedSize();
  if (n_prep > 0 && p.size() + static_cast<size_t>(n_prep) <= pe_buf.size()) {
    std::copy(p.begin(), p.end(), pe_buf.begin());
    law.PrepareParameters(p, body, pe_buf.data() + p.size());
    pe = std::span<const double>(pe_buf.data(), p.size() + static_cast<size_t>(n_prep));
  }
  // Small fixed-size state when nothing but the ball and at most one law variable is
  // integrated: a disabled effect (the plate) costs nothing.
  if (plate == nullptr && n_state <= 1) {
    return Integrate<4>(law, p, pe, body, v_in_m_s, g_m_s2, nullptr, options);
  }
  return Integrate<5 + kMaxLawState>(law, p, pe, body, v_in_m_s, g_m_s2, plate, options);
}

}  // namespace bouncecal
