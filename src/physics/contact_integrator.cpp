// One contact, integrated in three phases with located events. See
// include/bouncecal/physics/contact_integrator.hpp for the model, the phases and the event
// strategy, physics/dopri5.hpp for the stepper.
#include "bouncecal/physics/contact_integrator.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>

#include "physics/contact_system.hpp"
#include "physics/dop853.hpp"
#include "physics/dopri5.hpp"
#include "physics/scalar.hpp"

namespace bouncecal {
namespace {

using namespace contact_system;  // NOLINT: the system's types are this file's vocabulary
using dopri5::ValueOf;
using scalar::Quotient;

// First crossing of a continuous g from g(lo) > 0 to g <= 0, inside [lo, hi] with g(hi) <= 0:
// Illinois regula falsi safeguarded by bisection every third step. Returns the end of the final
// bracket on the side of hi (the event has happened there), width <= tol. A point with g == 0
// counts as "happened": a clamped function (a force that is max(0, ...)) is exactly 0 on a whole
// interval after its root, and the first such point is wanted, not any of them.
template <class G>
double LocateRoot(const G& g, double lo, double hi, double g_lo, double g_hi, double tol) {
  int side = 0;
  for (int iter = 0; iter < 200 && hi - lo > tol; ++iter) {
    double c = (g_lo * hi - g_hi * lo) / (g_lo - g_hi);
    if (iter % 3 == 2 || !(c > lo && c < hi)) c = 0.5 * (lo + hi);
    const double g_c = g(c);
    if (!(g_c > 0.0)) {
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

// The maximum of f on [lo, hi], its abscissa located to about tol: Brent's minimiser (golden
// section accelerated by parabolic interpolation; R. P. Brent, Algorithms for Minimization
// without Derivatives, 1973, ch. 5) applied to -f. A smooth maximum takes ~8 evaluations where
// golden section alone took ~30.
template <class F>
double Maximum(const F& f, double lo, double hi, double tol) {
  constexpr double kGolden = 0.3819660112501051;  // (3 - sqrt(5)) / 2
  double a = lo, b = hi;
  double x = a + kGolden * (b - a), w = x, v = x;
  double fx = -f(x), fw = fx, fv = fx;
  double d = 0.0, e = 0.0;
  for (int iter = 0; iter < 100; ++iter) {
    const double m = 0.5 * (a + b);
    if (std::abs(x - m) <= 2.0 * tol - 0.5 * (b - a)) break;
    bool golden = true;
    if (std::abs(e) > tol) {  // parabola through (x, fx), (w, fw), (v, fv)
      const double r = (x - w) * (fx - fv);
      double q = (x - v) * (fx - fw);
      double p = (x - v) * q - (x - w) * r;
      q = 2.0 * (q - r);
      if (q > 0.0) p = -p;
      q = std::abs(q);
      const double e_before = e;
      e = d;
      if (std::abs(p) < std::abs(0.5 * q * e_before) && p > q * (a - x) && p < q * (b - x)) {
        d = p / q;
        const double u = x + d;
        if (u - a < 2.0 * tol || b - u < 2.0 * tol) d = m >= x ? tol : -tol;
        golden = false;
      }
    }
    if (golden) {
      e = x >= m ? a - x : b - x;
      d = kGolden * e;
    }
    const double u = std::abs(d) >= tol ? x + d : x + (d > 0.0 ? tol : -tol);
    const double fu = -f(u);
    if (fu <= fx) {
      (u >= x ? a : b) = x;
      v = w;
      fv = fw;
      w = x;
      fw = fx;
      x = u;
      fx = fu;
    } else {
      (u < x ? a : b) = u;
      if (fu <= fw || w == x) {
        v = w;
        fv = fw;
        w = u;
        fw = fu;
      } else if (fu <= fv || v == x || v == w) {
        v = u;
        fv = fu;
      }
    }
  }
  return -fx;
}

template <class T, size_t N>
std::array<double, N> Values(const std::array<T, N>& x) {
  std::array<double, N> v{};
  for (size_t i = 0; i < N; ++i) v[i] = ValueOf(x[i]);
  return v;
}

template <class T, size_t N>
bool AllFinite(const std::array<T, N>& x) {
  for (const T& v : x) {
    if (!std::isfinite(ValueOf(v))) return false;
  }
  return true;
}

// A quantity whose value is 0 and whose derivative part is that of g - value(g).
template <class T>
T DerivativePart(const T& g) {
  return g - T(ValueOf(g));
}

// One contact in scalar type T (double, or SensitivityJet for forward sensitivities), state
// size N. Run() is the list of stages; each After* handles one phase's accepted step.
template <class T, size_t N, class M>
class ContactIntegration {
 public:
  using State = std::array<T, N>;
  using ValueState = std::array<double, N>;

  ContactIntegration(const ContactDynamics& dyn, const ContactBody& body, double time_scale_s,
                     double v_in, double g, const PlateModel* plate,
                     const ContactRunOptions& options)
      : body_(body),
        v_in_(v_in),
        g_(g),
        options_(options),
        sys_(dyn, body, g, plate, MakeScales(dyn, body, time_scale_s, v_in)),
        n_(sys_.Active()),
        has_switch_(dyn.HasSwitch()),
        force_zero_end_(dyn.EndRule() == ContactEnd::kForceZero) {}

  ContactRun Run(ContactSensitivity* sensitivity) {
    Start();
    while (!done_) {
      if (run_.steps >= options_.max_steps) {
        StepLimit(" contact not resolved within " + std::to_string(options_.max_steps) +
                  " integrator steps");
        break;
      }
      if (!TryStep()) continue;
      switch (sys_.phase()) {
        case Phase::kApproach:
          AfterApproachStep();
          break;
        case Phase::kMiddle:
          AfterMiddleStep();
          break;
        case Phase::kExit:
          AfterExitStep();
          break;
      }
    }
    if (sensitivity != nullptr) *sensitivity = sensitivity_;
    return run_;
  }

 private:
  static Scales MakeScales(const ContactDynamics& dyn, const ContactBody& body, double time_s,
                           double v_in) {
    Scales sc;
    sc.time_s = time_s;
    sc.speed_m_s = v_in;
    sc.length_m = v_in * time_s;
    sc.energy_j = 0.5 * body.mass_kg * v_in * v_in;
    for (int i = 0; i < kMaxLawState; ++i) {
      const double s = i < dyn.StateSize() ? dyn.StateScale(i, sc.length_m, sc.energy_j) : 1.0;
      sc.state[i] = (std::isfinite(s) && s > 0.0) ? s : 1.0;
    }
    return sc;
  }

  // --- stages ---------------------------------------------------------------------------------
  void Start() {
    const ContactDynamics& dyn = sys_.dynamics();
    const Scales& sc = sys_.scales();
    run_.contact_time_scale_s = sc.time_s;
    x_ = State{};
    x_[1] = T(1.0);
    if constexpr (!std::is_same_v<T, double>) {
      // Direction P: the impact speed (the scales are constants, not differentiated).
      const int p = dyn.ParameterCount();
      if (p < kSensitivityDirections) x_[1].v[p] = 1.0 / sc.speed_m_s;
    }
    std::array<double, kMaxLawState> s0{};
    dyn.InitialState(s0.data());
    for (int i = 0; i < sys_.StateCount(); ++i) x_[sys_.StateOffset() + i] = T(s0[i] / sc.state[i]);
    const int q = dyn.OverlapRoot();
    use_exit_ = q > 1 && dyn.EndRule() == ContactEnd::kOverlapZero;
    sys_.SetPhase(q > 1 ? Phase::kApproach : Phase::kMiddle, q);
    indep_ = 0.0;
    sys_.SetBranch(sys_.Switch(sys_.Unscale(Values(x_), 0.0)) > 0.0);
    sys_(x_, f_, indep_);
    // The first step from the contact's own scale: u runs to about (0.34)^(1/q) at the peak
    // (Hertz: delta_max = v t_c / 2.94), time to 1.
    const double span =
        sys_.phase() == Phase::kApproach ? std::pow(kPeakOverlapEstimate, 1.0 / q) : 1.0;
    h_ = kTuning<M>.first_step *
         std::pow(kTuning<M>.tolerance_scale * options_.rel_tolerance, 1.0 / M::kOrder) * span;
    Refresh();
  }

  // The physical view of the current point (x_ at indep_), kept up to date.
  void Refresh() { here_ = sys_.Unscale(Values(x_), indep_); }

  // Attempts one step from (indep_, x_) of size h_; true if accepted (x_new_, f_new_, h_next_).
  bool TryStep() {
    ++run_.steps;
    if (sys_.phase() == Phase::kExit) h_ = std::max(h_, -indep_);  // land on u = 0 exactly
    sys_.WithRhs([&](const auto& rhs) {
      stepper_.Step(rhs, x_, f_, indep_, h_, x_new_, f_new_, n_, sys_.StageInputs());
    });
    if (!AllFinite(x_new_) || !AllFinite(f_new_)) {
      // Non-finite force at a stage (e.g. a law evaluated out of its domain): smaller step.
      h_ *= 0.25;
      if (std::abs(h_) < 1e-15) {
        std::ostringstream os;
        os << " the force is not finite at t = " << ValueOf(TauOf(x_, indep_)) * Scale().time_s
           << " s (step size underflow)";
        StepLimit(os.str());
      }
      return false;
    }
    // Accepted if the norm is <= 1: decided, and the next step sized, from its square.
    const dopri5::ErrorSquared e = SquaredErrorNorm();
    if (!(e.num <= e.den)) {
      ++run_.rejected;
      h_ *= controller_.Rejected(std::sqrt(e.num / e.den));
      return false;
    }
    h_next_ = h_ * controller_.Accepted(e);
    return true;
  }

  // The stepper's norm of err_i / (atol + tolerance_scale rtol max(1, |x_i|, |x_new_i|)) over the
  // active scaled variables, squared.
  dopri5::ErrorSquared SquaredErrorNorm() const {
    const double rtol = kTuning<M>.tolerance_scale * options_.rel_tolerance;
    std::array<double, N> sk;
    for (size_t i = 0; i < n_; ++i) {
      const double size =
          std::max(1.0, std::max(std::abs(ValueOf(x_[i])), std::abs(ValueOf(x_new_[i]))));
      sk[i] = options_.abs_tolerance + rtol * size;
    }
    return stepper_.SquaredError(sk, n_);
  }

  // Accepts the step to x_new_, whose physical view is `end`.
  void Commit(const PhysN<double, N>& end) {
    indep_ += h_;
    if (sys_.phase() == Phase::kExit && indep_ < 0.0) indep_ = 0.0;
    x_ = x_new_;
    f_ = f_new_;
    h_ = h_next_;
    here_ = end;
  }

  // --- approach phase (independent variable u) -------------------------------------------------
  void AfterApproachStep() {
    const PhysN<double, N> end = sys_.Unscale(Values(x_new_), indep_ + h_);
    TrackPeaks(indep_, indep_ + h_, end);
    Commit(end);
    CheckStuck();
    if (done_) return;
    const double end_overlap_m =
        ApproachEndOverlapFraction() * kPeakOverlapEstimate * Scale().length_m;
    if (here_.delta_dot < kTuning<M>.approach_end_speed * Scale().speed_m_s ||
        here_.delta > end_overlap_m) {
      ToTime();
    }
  }

  // From u (approach or exit) to time, at the current point: tau becomes the independent
  // variable; derivatives move from "at fixed u" to "at fixed tau" (x|tau = x|u - x' dtau).
  void ToTime() {
    const double u = indep_;
    const ValueState xv = Values(x_);
    const double rho = sys_.Rho(xv, u);
    ValueState dt{};
    sys_.TimeRates(xv, sys_.Unscale(xv, u), dt);
    const T dtau = DerivativePart(x_[0]);
    T z_s(0.0);
    if constexpr (N > 4) {
      if (sys_.StateOffset() == 5) z_s = x_[3];
    }
    const double tau = xv[0];
    for (size_t i = 1; i < n_; ++i) x_[i] = x_[i] - dt[i] * dtau;
    x_[0] = z_s + sys_.UPower(u) - xv[1] * dtau;
    sys_.SetPhase(Phase::kMiddle, sys_.root());
    indep_ = tau;
    h_ *= rho;
    sys_(x_, f_, indep_);
    Refresh();
  }

  // From time to u (exit): u = (delta / L)^(1/q) at the current point; tau becomes a state.
  void ToExit() {
    const ValueState xv = Values(x_);
    const PhysN<double, N> ph = sys_.Unscale(xv, indep_);
    const double delta_s = ph.delta / Scale().length_m;
    const double delta_dot_s = ph.delta_dot / Scale().speed_m_s;
    const double u = std::pow(delta_s, 1.0 / sys_.root());
    // At fixed u the crossing time moves by -d(delta)/delta'.
    T delta_jet = x_[0];
    if constexpr (N > 4) {
      if (sys_.StateOffset() == 5) delta_jet = x_[0] - x_[3];
    }
    const T dtau = -DerivativePart(delta_jet) / delta_dot_s;
    ValueState dt{};
    sys_.TimeRates(xv, ph, dt);
    for (size_t i = 1; i < n_; ++i) x_[i] = x_[i] + dt[i] * dtau;
    x_[0] = T(indep_) + dtau;
    const double rho_inverse = delta_dot_s / sys_.UPowerSlope(u);  // du/dtau
    sys_.SetPhase(Phase::kExit, sys_.root());
    indep_ = u;
    h_ = -std::abs(h_ * rho_inverse) * kTuning<M>.exit_first_step;
    exit_entry_speed_ = std::abs(delta_dot_s);
    sys_(x_, f_, indep_);
    Refresh();
  }

  // --- exit phase (u down to 0) ----------------------------------------------------------------
  void AfterExitStep() {
    const PhysN<double, N> end = sys_.Unscale(Values(x_new_), indep_ + h_);
    TrackPeaks(indep_, indep_ + h_, end);
    Commit(end);
    CheckStuck();
    if (done_) return;
    if (indep_ == 0.0) return Separated(x_, indep_, x_[0]);
    if (std::abs(here_.delta_dot) < kExitSpeedFloor * exit_entry_speed_ * Scale().speed_m_s) {
      exit_disabled_ = true;  // a creeping ball: the stuck tests live in the time phase
      ToTime();
    }
  }

  // --- middle phase (time) ---------------------------------------------------------------------
  void AfterMiddleStep();
  bool LocateSwitch(double t, double t1, const PhysN<double, N>& end, double* t_w);
  double LocateEnd(double t, double t_w, const PhysN<double, N>& pw, bool* found);
  void FinishAtEnd(double t, double t_end);
  void RestartOnOtherBranch(double t, double t_w, const State& x_dense);
  void CheckStuck();
  bool EnterExit() const;
  double ApproachEndOverlapFraction() const {
    return sys_.root() > 4 ? kTuning<M>.approach_end_overlap_q6 : kTuning<M>.approach_end_overlap;
  }
  double ExitOverlapFraction() const {
    return sys_.root() == 2 ? kTuning<M>.exit_overlap_q2 : kExitOverlapFraction;
  }

  // Dense output of the step just taken ([indep_, indep_ + h_], values).
  PhysN<double, N> Dense(double at) {
    const double theta = h_ != 0.0 ? (at - indep_) / h_ : 0.0;
    sys_.WithRhs([&](const auto& rhs) {
      stepper_.Dense(rhs, indep_, theta, x_, x_new_, f_, f_new_, h_, xd_, n_);
    });
    return sys_.Unscale(Values(xd_), at);
  }

  // Peak overlap and peak force over the step [a, b] from the current point (b's view given).
  void TrackPeaks(double a, double b, const PhysN<double, N>& pb);

  // Derivative along the trajectory of g (central difference along f at x, in the phase's
  // independent variable).
  template <class G>
  double RateAlong(const G& g, const ValueState& x, const ValueState& f, double at) const {
    constexpr double kEps = 1e-7;
    ValueState hi = x, lo = x;
    for (size_t i = 0; i < n_; ++i) {
      hi[i] += kEps * f[i];
      lo[i] -= kEps * f[i];
    }
    return (g(sys_.Unscale(hi, at + kEps)) - g(sys_.Unscale(lo, at - kEps))) / (2.0 * kEps);
  }

  // --- endings ---------------------------------------------------------------------------------
  enum class StuckKind { kSliding, kCreeping, kEnergy, kTooLong };
  void Fill(const PhysN<double, N>& ph) {
    run_.contact_s = ph.tau * Scale().time_s;
    run_.work_j = ph.work;
    run_.elastic_end_j = sys_.Elastic(ph);
    run_.plate_end_j = sys_.PlateEnergy(ph);
    run_.internal_end_j = sys_.Internal(ph);
    run_.ball_energy_end_j = sys_.BallEnergy(ph);
    run_.separation_depth_m = ph.y;
  }
  // The ball left at scaled time tau (a state in the u phases, the located event in time).
  void Separated(const State& x, double indep, const T& tau) {
    const PhysN<T, N> pj = sys_.Unscale(x, indep);
    PhysN<double, N> ph = sys_.Unscale(Values(x), indep);
    ph.tau = ValueOf(tau);
    Fill(ph);
    run_.v_out_m_s = std::max(0.0, -ph.yd);
    run_.end = ContactRun::End::kSeparated;
    if constexpr (!std::is_same_v<T, double>) {
      for (int j = 0; j < kSensitivityDirections; ++j) {
        sensitivity_.v_out[j] = -pj.yd.v[j];
        sensitivity_.contact_s[j] = tau.v[j] * Scale().time_s;
        sensitivity_.separation_depth_m[j] = pj.y.v[j];
      }
    }
    done_ = true;
  }
  void Stuck(const PhysN<double, N>& ph, StuckKind kind, double e_left) {
    Fill(ph);
    run_.end = ContactRun::End::kStuck;
    const double t_s = ph.tau * Scale().time_s;
    std::ostringstream os;
    switch (kind) {
      case StuckKind::kSliding:
        os << "the ball rests in contact on the law's branch switch (repeated switches without "
              "progress at t = "
           << t_s << " s into the contact)";
        break;
      case StuckKind::kCreeping:
        os << "the ball creeps slower than " << options_.stuck_speed_m_s
           << " m/s with negligible acceleration (overdamped; t = " << t_s
           << " s into the contact)";
        break;
      case StuckKind::kEnergy:
        os << "the ball stays in contact: energy left " << e_left
           << " J cannot lift it off faster than " << options_.stuck_speed_m_s
           << " m/s (t = " << t_s << " s into the contact)";
        break;
      case StuckKind::kTooLong:
        os << "the ball stays in contact for more than " << options_.max_contact_time_factor
           << " contact-time estimates (" << t_s << " s)";
        break;
    }
    run_.detail = os.str();
    done_ = true;
  }
  void StepLimit(const std::string& why) {
    const PhysN<double, N> ph = sys_.Unscale(Values(x_), indep_);
    Fill(ph);
    run_.end = ContactRun::End::kStepLimit;
    std::ostringstream os;
    os << options_.label << ":" << why << " (t = " << ph.tau * Scale().time_s
       << " s, v_in = " << v_in_ << " m/s)";
    run_.detail = os.str();
    done_ = true;
  }

  const Scales& Scale() const { return sys_.scales(); }
  T TauOf(const State& x, double indep) const {
    return sys_.phase() == Phase::kMiddle ? T(indep) : x[0];
  }

  const ContactBody& body_;
  double v_in_;
  double g_;
  const ContactRunOptions& options_;
  System<N> sys_;
  size_t n_;
  bool has_switch_;      // the law's HasSwitch (asked once, not at every step)
  bool force_zero_end_;  // the law ends at F = 0
  typename M::template Stepper<T, N> stepper_;
  typename M::Controller controller_;
  State x_{}, f_{}, x_new_{}, f_new_{}, xd_{};
  PhysN<double, N> here_{};  // physical view of x_ at indep_
  double indep_ = 0.0, h_ = 0.0, h_next_ = 0.0;
  bool use_exit_ = false, exit_disabled_ = false;
  double exit_entry_speed_ = 0.0;
  bool was_loaded_ = false;   // F > 0 seen (for the F = 0 end rule)
  bool force_rising_ = true;  // the first force maximum is still ahead
  int stalled_switches_ = 0;  // consecutive switches without progress in time
  bool done_ = false;
  ContactRun run_;
  ContactSensitivity sensitivity_;
};

template <class T, size_t N, class M>
void ContactIntegration<T, N, M>::TrackPeaks(double a, double b, const PhysN<double, N>& pb) {
  const PhysN<double, N>& pa = here_;
  // At the end of a whole step the force is known from the ball's acceleration (the FSAL
  // derivative): y'' = g - F/m (in the u phases y'' = (dx1/du) / (dtau/du)).
  double fb = 0.0;
  const double fsal0 = ValueOf(f_new_[0]), fsal1 = ValueOf(f_new_[1]);
  if (b == indep_ + h_ && (sys_.phase() == Phase::kMiddle || fsal0 != 0.0)) {
    const double accel_s = sys_.phase() == Phase::kMiddle ? fsal1 : fsal1 / fsal0;
    fb = body_.mass_kg * (g_ - accel_s * Scale().speed_m_s / Scale().time_s);
  } else {
    fb = sys_.Force(pb);
  }
  run_.peak_overlap_m = std::max(run_.peak_overlap_m, pb.delta);
  run_.peak_force_n = std::max(run_.peak_force_n, fb);
  if (sys_.phase() == Phase::kMiddle && pa.delta_dot > 0.0 && pb.delta_dot <= 0.0) {
    // The overlap is stationary there: a time error dt moves it by delta'' dt^2 / 2, so 1e-8 of
    // the step leaves it within ~1e-16 of the contact's scale (the event tolerance, 1e-14 of the
    // contact time, took three times the dense evaluations for digits nothing reads).
    const double tol = kPeakTolerance * std::abs(b - a);
    auto gv = [&](double at) { return Dense(at).delta_dot; };
    const PhysN<double, N> pm = Dense(LocateRoot(gv, a, b, pa.delta_dot, pb.delta_dot, tol));
    run_.peak_overlap_m = std::max(run_.peak_overlap_m, pm.delta);
    run_.peak_force_n = std::max(run_.peak_force_n, sys_.Force(pm));
  }
  // Force maximum inside the step: F rising at its start, falling at its end (searched until the
  // first maximum is found; later local maxima are sampled at step ends).
  if (!force_rising_ || b == a || sys_.phase() == Phase::kExit) return;
  // Still rising at the end? F a little before b: along the step's end derivative at the end
  // of a whole step, on the dense output inside a cut one.
  constexpr double kBack = 1e-6;
  const double span = b - a;
  double f_before = 0.0;
  if (b == indep_ + h_) {
    ValueState back = Values(x_new_);
    const ValueState fv = Values(f_new_);
    for (size_t i = 0; i < n_; ++i) back[i] -= kBack * span * fv[i];
    f_before = sys_.Force(sys_.Unscale(back, b - kBack * span));
  } else {
    f_before = sys_.Force(Dense(b - kBack * span));
  }
  if (fb > f_before) return;
  // Near its maximum F is quadratic in time: locating it to 1e-6 of the step leaves F within
  // ~1e-12 relative of the maximum.
  auto force_at = [&](double at) { return sys_.Force(Dense(at)); };
  const double f_max = Maximum(force_at, std::min(a, b), std::max(a, b), 1e-6 * std::abs(span));
  run_.peak_force_n = std::max(run_.peak_force_n, f_max);
  force_rising_ = false;
}

// 1. Branch switch: the step ran on the old branch continued past the switch, so the dense
// output is smooth; locate the sign change and end the step window there. True if switched.
template <class T, size_t N, class M>
bool ContactIntegration<T, N, M>::LocateSwitch(double t, double t1, const PhysN<double, N>& end,
                                               double* t_w) {
  *t_w = t1;
  if (!has_switch_) return false;
  const double sign = sys_.positive_branch() ? 1.0 : -1.0;
  const double g1 = sys_.Switch(end) * sign;
  if (g1 > 0.0) return false;
  const double g0 = sys_.Switch(here_) * sign;
  auto gs = [&](double at) { return sys_.Switch(Dense(at)) * sign; };
  const double tol = kEventTolerance * std::max(1.0, t1);
  *t_w = g0 > 0.0 ? LocateRoot(gs, t, t1, g0, g1, tol) : t;
  return true;
}

// 2. Contact end within the window [t, t_w]: delta returns to 0 (or F to 0 for kForceZero laws).
template <class T, size_t N, class M>
double ContactIntegration<T, N, M>::LocateEnd(double t, double t_w, const PhysN<double, N>& pw,
                                              bool* found) {
  const bool force_zero_end = force_zero_end_;
  const double fw = force_zero_end ? sys_.Force(pw) : 0.0;
  const double tol = kEventTolerance * std::max(1.0, t_w);
  double t_end = -1.0;
  if (pw.delta <= 0.0 && t_w > 0.0) {
    auto gd = [&](double at) { return Dense(at).delta; };
    t_end = here_.delta > 0.0 ? LocateRoot(gd, t, t_w, here_.delta, pw.delta, tol) : t_w;
  }
  if (force_zero_end && was_loaded_ && fw <= 0.0) {
    const double f0 = sys_.Force(here_);
    auto gf = [&](double at) { return sys_.Force(Dense(at)); };
    const double tf = f0 > 0.0 ? LocateRoot(gf, t, t_w, f0, fw, tol) : t;
    if (t_end < 0.0 || tf < t_end) t_end = tf;
  }
  if (fw > 0.0) was_loaded_ = true;
  *found = t_end >= 0.0;
  return t_end;
}

// The contact ended at t_end inside the step from t. The dense output is one order below the
// step: the end state is recomputed with one step of exactly t_end - t (valid: no event
// inside), then corrected to the event in time to first order: the value by a Newton step for
// delta = 0 (end rule kOverlapZero), the derivative parts by the implicit-function rule
// d t_end / d theta = -(d g / d theta) / g'.
template <class T, size_t N, class M>
void ContactIntegration<T, N, M>::FinishAtEnd(double t, double t_end) {
  const bool force_zero_end = force_zero_end_;
  State xe = x_new_, fe = f_new_;
  if (t_end > t) {
    sys_.WithRhs([&](const auto& rhs) {
      stepper_.Step(rhs, x_, f_, t, t_end - t, xe, fe, n_, sys_.StageInputs());
    });
    if (!AllFinite(xe)) {
      xe = x_new_;
      fe = f_new_;
    }
  }
  const ValueState xv = Values(xe), fv = Values(fe);
  T dtau(0.0);
  if (!force_zero_end) {
    T delta_jet = xe[0];
    if constexpr (N > 4) {
      if (sys_.StateOffset() == 5) delta_jet = xe[0] - xe[3];
    }
    const PhysN<double, N> pe = sys_.Unscale(xv, t_end);
    const double rate = pe.delta_dot / Scale().speed_m_s;
    if (rate < 0.0) {
      dtau = Quotient(-delta_jet, rate);
      const bool apply = std::abs(ValueOf(dtau)) < 1e-3 * (t_end - t) && AllFinite(xe);
      if (!apply) dtau = DerivativePart(dtau);
    }
  } else {
    auto force = [&](const PhysN<double, N>& ph) { return sys_.Force(ph); };
    const double rate = RateAlong(force, xv, fv, t_end);
    if (rate != 0.0 && std::isfinite(rate)) {
      dtau = -DerivativePart(sys_.Force(sys_.Unscale(xe, t_end))) / rate;
    }
  }
  for (size_t i = 0; i < n_; ++i) xe[i] = xe[i] + fe[i] * dtau;
  Separated(xe, t_end, T(t_end) + dtau);
}

// The step ended at a located switch t_w: restart the integrator on the other branch there,
// from a state recomputed by one step of exactly t_w - t on the old branch (continued past the
// switch, so the step is smooth). The derivative parts jump by (f- - f+) d t_w / d theta.
template <class T, size_t N, class M>
void ContactIntegration<T, N, M>::RestartOnOtherBranch(double t, double t_w, const State& x_dense) {
  State xw = x_dense, f_minus = f_new_;
  if (t_w > t) {
    sys_.WithRhs([&](const auto& rhs) {
      stepper_.Step(rhs, x_, f_, t, t_w - t, xw, f_minus, n_, sys_.StageInputs());
    });
    if (!AllFinite(xw)) {
      xw = x_dense;
      sys_(xw, f_minus, t_w);
    }
  } else {
    sys_(xw, f_minus, t_w);
  }
  const ValueState xv = Values(xw), fv = Values(f_minus);
  auto sw = [&](const PhysN<double, N>& ph) { return sys_.Switch(ph); };
  const double rate = RateAlong(sw, xv, fv, t_w);
  T dtau(0.0);
  if (rate != 0.0 && std::isfinite(rate)) {
    dtau = -DerivativePart(sys_.Switch(sys_.Unscale(xw, t_w))) / rate;
  }
  // The law's memory update at the switch (a jump of its state), then the other branch.
  if (sys_.StateCount() > 0) {
    const PhysN<T, N> ph = sys_.Unscale(xw, t_w);
    auto state = ph.state;
    sys_.dynamics().AtSwitch(Clamp0(ph.delta), state.data());
    for (int i = 0; i < sys_.StateCount(); ++i) {
      xw[sys_.StateOffset() + i] = Quotient(state[i], Scale().state[i]);
    }
  }
  sys_.SetBranch(!sys_.positive_branch());
  State f_plus;
  sys_(xw, f_plus, t_w);
  for (size_t i = 0; i < n_; ++i) xw[i] = xw[i] + (f_minus[i] - f_plus[i]) * dtau;
  x_ = xw;
  sys_(x_, f_, t_w);
  stalled_switches_ = t_w - t < 1e-12 ? stalled_switches_ + 1 : 0;
  indep_ = t_w;
  Refresh();
  ++run_.switches;
}

// 3. Stuck: the energy left cannot send the ball off faster than stuck_speed, or the contact
// lasts far longer than any rebound would.
template <class T, size_t N, class M>
void ContactIntegration<T, N, M>::CheckStuck() {
  const ValueState xv = Values(x_), fv = Values(f_);
  const bool in_time = sys_.phase() == Phase::kMiddle;
  const PhysN<double, N>& pc = here_;
  // Creeping (time phase): the ball moves slower than stuck_speed and its acceleration cannot
  // change that within a contact time (overdamped: delta' never returns to 0). Cheap.
  const double v_stuck = options_.stuck_speed_m_s / Scale().speed_m_s;
  const bool creeping = in_time && std::abs(xv[1]) < v_stuck && std::abs(fv[1]) < v_stuck;
  // Sliding on the switch surface: repeated switches without progress (Walton-Braun's ball
  // resting under gravity between its loading and unloading equilibria).
  const bool sliding = in_time && stalled_switches_ >= 4;
  // Energy (every phase): the mechanical energy left (ball kinetic + potential relative to
  // first touch + elastic + plate + the law's internal buffer) bounds the speed the ball can
  // leave with, at any moment of the contact (energy only leaves the system). Cheap precheck:
  // elastic, plate and internal energies are >= 0, so the ball's own energy must already be
  // below the threshold. (A stiff overdamped contact creeps at its numerical stability limit,
  // where the acceleration test of `creeping` is not reliable; this test is.)
  const double stuck_energy =
      0.5 * body_.mass_kg * options_.stuck_speed_m_s * options_.stuck_speed_m_s;
  const double ball_j = sys_.BallEnergy(pc);
  double e_left = 0.0;
  bool energy_gone = false;
  if (stuck_energy > 0.0 && ball_j < stuck_energy) {
    e_left = ball_j + sys_.Elastic(pc) + sys_.PlateEnergy(pc) + sys_.Internal(pc);
    energy_gone = e_left < stuck_energy && pc.delta > 0.0;
  }
  if (sliding) return Stuck(pc, StuckKind::kSliding, 0.0);
  if (creeping) return Stuck(pc, StuckKind::kCreeping, 0.0);
  if (energy_gone) return Stuck(pc, StuckKind::kEnergy, e_left);
  if (pc.tau > options_.max_contact_time_factor) return Stuck(pc, StuckKind::kTooLong, 0.0);
}

// Time for the exit phase: the ball moves out and the overlap is below a fraction of its peak.
template <class T, size_t N, class M>
bool ContactIntegration<T, N, M>::EnterExit() const {
  if (!use_exit_ || exit_disabled_) return false;
  return here_.delta_dot < 0.0 && here_.delta > 0.0 &&
         here_.delta < ExitOverlapFraction() * run_.peak_overlap_m;
}

template <class T, size_t N, class M>
void ContactIntegration<T, N, M>::AfterMiddleStep() {
  const double t = indep_, t1 = indep_ + h_;
  const PhysN<double, N> end = sys_.Unscale(Values(x_new_), t1);
  double t_w = t1;
  const bool switched = LocateSwitch(t, t1, end, &t_w);
  State x_w = x_new_;
  PhysN<double, N> pw = end;
  if (t_w < t1) {
    pw = Dense(t_w);
    x_w = xd_;
  }
  bool ended = false;
  const double t_end = LocateEnd(t, t_w, pw, &ended);
  const double t_hi = ended ? t_end : t_w;
  TrackPeaks(t, t_hi, t_hi < t_w ? Dense(t_hi) : pw);
  if (ended) return FinishAtEnd(t, t_end);
  if (switched) {
    RestartOnOtherBranch(t, t_w, x_w);
    h_ = h_next_;
  } else {
    Commit(end);
    stalled_switches_ = 0;
  }
  CheckStuck();
  if (!done_ && EnterExit()) ToExit();
}

template <class T, size_t N>
ContactRun Integrate(const ContactDynamics& dyn, const ContactBody& body, double time_scale_s,
                     double v_in, double g, const PlateModel* plate,
                     const ContactRunOptions& options, ContactSensitivity* sensitivity) {
  const bool high_order =
      options.method == ContactMethod::kDop853 ||
      (options.method == ContactMethod::kAuto && options.rel_tolerance <= kHighOrderTolerance);
  if (high_order) {
    ContactIntegration<T, N, dop853::Method> integration(dyn, body, time_scale_s, v_in, g, plate,
                                                         options);
    return integration.Run(sensitivity);
  }
  ContactIntegration<T, N, dopri5::Method> integration(dyn, body, time_scale_s, v_in, g, plate,
                                                       options);
  return integration.Run(sensitivity);
}

// Elastic energy of the law at overlap d with the initial state (NaN-safe).
double ElasticAt(const ContactDynamics& dyn, const double* s0, double d) {
  const double w = dyn.ElasticEnergy(d, s0);
  return std::isfinite(w) ? w : 0.0;
}

}  // namespace

double EstimateContactTime(const ContactLaw& law, std::span<const double> p,
                           const ContactDynamics& dynamics, const ContactBody& body,
                           double v_in_m_s) {
  if (auto tc = law.ContactTime(p, body, v_in_m_s); tc && std::isfinite(*tc) && *tc > 0.0) {
    return *tc;
  }
  const double target = 0.5 * body.mass_kg * v_in_m_s * v_in_m_s;
  // Linear spring: t_c = pi delta_max / v; Hertz: 2.94 delta_max / v (docs/physics.md §2).
  constexpr double kTimeOverCrossing = 3.0;
  // The search below brackets delta_max between these (m, and in ball radii).
  constexpr double kSmallestOverlap = 1e-18, kLargestOverlapRadii = 1e3;
  double coefficient = 0.0, exponent = 0.0;
  if (dynamics.ElasticPowerLaw(&coefficient, &exponent) && coefficient > 0.0 && exponent > 0.0) {
    // W = a delta^b: delta_max = (m v^2 / (2 a))^(1/b), what the search finds (to rounding)
    // with one pow instead of ~80 energy evaluations; outside the search's bracket the search
    // decides, as before.
    const double delta_max_m = std::pow(target / coefficient, 1.0 / exponent);
    if (delta_max_m >= kSmallestOverlap && delta_max_m <= kLargestOverlapRadii * body.radius_m) {
      return kTimeOverCrossing * delta_max_m / v_in_m_s;
    }
  }
  std::array<double, kMaxLawState> s0{};
  if (dynamics.StateSize() <= kMaxLawState) dynamics.InitialState(s0.data());
  // Bracket delta_max on a log scale between 1e-18 m and 1e3 R, then bisect in log space.
  double lo = kSmallestOverlap, hi = kSmallestOverlap;
  while (hi < kLargestOverlapRadii * body.radius_m && ElasticAt(dynamics, s0.data(), hi) < target) {
    lo = hi;
    hi *= 10.0;
  }
  if (ElasticAt(dynamics, s0.data(), hi) >= target) {
    for (int i = 0; i < 60; ++i) {
      const double mid = std::sqrt(lo * hi);
      (ElasticAt(dynamics, s0.data(), mid) < target ? lo : hi) = mid;
    }
    return kTimeOverCrossing * hi / v_in_m_s;
  }
  // No usable elastic energy (a purely dissipative user law): the time to cross 1e-3 R.
  return 1e-3 * body.radius_m / v_in_m_s;
}

ContactRun RunContact(const ContactDynamics& dynamics, const ContactBody& body,
                      double contact_time_scale_s, double v_in_m_s, double g_m_s2,
                      const PlateModel* plate, const ContactRunOptions& options,
                      ContactSensitivity* sensitivity) {
  const int n_state = dynamics.StateSize();
  if (n_state > kMaxLawState || n_state < 0) {
    ContactRun r;
    r.end = ContactRun::End::kStepLimit;
    r.detail = options.label + ": " + std::to_string(n_state) +
               " internal state variables (at most " + std::to_string(kMaxLawState) + " supported)";
    return r;
  }
  const bool small = plate == nullptr && n_state <= 1;
  if (sensitivity != nullptr) {
    *sensitivity = ContactSensitivity{};
    if (dynamics.ParameterCount() <= kMaxSensitivityParameters) {
      // Small fixed-size state when nothing but the ball and at most one law variable is
      // integrated: a disabled effect (the plate) costs nothing.
      return small ? Integrate<SensitivityJet, 4>(dynamics, body, contact_time_scale_s, v_in_m_s,
                                                  g_m_s2, nullptr, options, sensitivity)
                   : Integrate<SensitivityJet, 5 + kMaxLawState>(
                         dynamics, body, contact_time_scale_s, v_in_m_s, g_m_s2, plate, options,
                         sensitivity);
    }
  }
  return small ? Integrate<double, 4>(dynamics, body, contact_time_scale_s, v_in_m_s, g_m_s2,
                                      nullptr, options, nullptr)
               : Integrate<double, 5 + kMaxLawState>(dynamics, body, contact_time_scale_s, v_in_m_s,
                                                     g_m_s2, plate, options, nullptr);
}

ContactRun RunContact(const ContactLaw& law, std::span<const double> p, const ContactBody& body,
                      double v_in_m_s, double g_m_s2, const PlateModel* plate,
                      const ContactRunOptions& options) {
  const std::unique_ptr<ContactDynamics> dynamics = law.Dynamics(p, body);
  ContactRunOptions o = options;
  if (o.label == ContactRunOptions{}.label) o.label = law.Name();
  return RunContact(*dynamics, body, EstimateContactTime(law, p, *dynamics, body, v_in_m_s),
                    v_in_m_s, g_m_s2, plate, o);
}

}  // namespace bouncecal
