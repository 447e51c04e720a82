// tests/law_oracle.hpp — the independent reference integrator the law tests compare against.
//
// Integrates m* delta'' = -F(delta, delta', state) (+ g) from first touch (delta = 0,
// delta' = v_in) with Boost.Odeint's runge_kutta_dopri5 (dense output, relative tolerance
// 1e-12 by default) and LOCATES every event by bisection on the dense output:
//   - the end of the contact (delta = 0, or F = 0 after the peak for kForceZero laws),
//   - the peak overlap (delta' = 0),
//   - branch switches reported by SwitchFunction (the stepper is restarted there, so no step
//     straddles a discontinuity of the force).
// It shares no code with the simulator or with the laws' closed forms: only the law's dynamics
// (ContactLaw::Dynamics: ForceOnBranch, StateRate, InitialState, Switch, AtSwitch) and EndRule.
#pragma once

#include <algorithm>
#include <cmath>
#include <functional>
#include <span>
#include <vector>

#include <boost/numeric/odeint.hpp>

#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/contact_law.hpp"

namespace oracle {

using State = std::vector<double>;

struct Options {
  double rel_tol = 1e-12;
  double g_m_s2 = 0.0;        // gravity pushing the ball into the surface
  double max_time_s = 1e300;  // declare "stuck" beyond this
  long max_steps = 1000000;   // or beyond this many steps
  // Optional extra integral (e.g. the heat of Jiang-Liu): d(extra)/dt = extra_rate(delta,
  // delta_dot, law state).
  std::function<double(double, double, const double*)> extra_rate;
};

struct Result {
  double restitution = 0.0;
  double contact_time_s = 0.0;
  double peak_overlap_m = 0.0;
  double peak_force_n = 0.0;
  double end_overlap_m = 0.0;
  double v_out_m_s = 0.0;
  double extra = 0.0;
  State end_state;  // law state at the end
  bool stuck = false;
  long steps = 0;
};

inline Result Integrate(const bouncecal::ContactLaw& law, std::span<const double> p,
                        const bouncecal::ContactBody& body, double v_in, Options opt = {}) {
  namespace odeint = boost::numeric::odeint;
  const int ns = law.StateSize();
  const size_t n = static_cast<size_t>(2 + ns + 1);  // delta, delta_dot, law state, extra
  const double m = body.mass_kg;
  const std::unique_ptr<bouncecal::ContactDynamics> dyn = law.Dynamics(p, body);
  // As before the dynamics existed: the law is asked at the raw overlap (every law gives 0 force
  // for delta < 0).
  auto force = [&](const State& x) { return dyn->Force(x[0], x[1], x.data() + 2); };
  bool branch = true;  // side of the switch the current step started on
  auto rhs = [&](const State& x, State& dxdt, double) {
    dxdt[0] = x[1];
    dxdt[1] = opt.g_m_s2 - dyn->ForceOnBranch(x[0], x[1], x.data() + 2, branch) / m;
    if (ns > 0) dyn->StateRate(x[0], x[1], x.data() + 2, dxdt.data() + 2);
    dxdt[n - 1] = opt.extra_rate ? opt.extra_rate(x[0], x[1], x.data() + 2) : 0.0;
  };
  auto switch_fn = [&](const State& x) { return dyn->Switch(x[0], x[1], x.data() + 2); };
  const bool force_end = law.EndRule() == bouncecal::ContactEnd::kForceZero;
  // End of contact, evaluated only once the ball moves outwards (delta' < 0).
  auto ended = [&](const State& x) {
    if (x[1] >= 0.0) return false;
    if (x[0] <= 0.0) return true;
    return force_end && force(x) <= 0.0;
  };

  State x(n, 0.0);
  x[1] = v_in;
  if (ns > 0) dyn->InitialState(x.data() + 2);
  auto dense = odeint::make_dense_output(1e-300, opt.rel_tol, odeint::runge_kutta_dopri5<State>());
  double t = 0.0;
  branch = switch_fn(x) > 0.0;
  dense.initialize(x, t, 1e-12);
  Result r;
  r.peak_force_n = force(x);
  State a(n), b(n), mid(n);
  // Bisection on the dense output inside [t0, t1] for the first time pred() becomes true.
  auto bisect = [&](double t0, double t1, const std::function<bool(const State&)>& pred) {
    for (int i = 0; i < 200 && t1 - t0 > 1e-15 * t1; ++i) {
      const double tm = 0.5 * (t0 + t1);
      dense.calc_state(tm, mid);
      (pred(mid) ? t1 : t0) = tm;
    }
    return t1;
  };
  while (true) {
    const double t0 = dense.current_time();
    a = dense.current_state();
    dense.do_step(rhs);
    ++r.steps;
    const double t1 = dense.current_time();
    b = dense.current_state();
    r.peak_force_n = std::max(r.peak_force_n, force(b));
    if (a[1] > 0.0 && b[1] <= 0.0) {  // peak overlap
      const double tp = bisect(t0, t1, [](const State& s) { return s[1] <= 0.0; });
      dense.calc_state(tp, mid);
      r.peak_overlap_m = mid[0];
    }
    if (ended(b)) {
      const double te = bisect(t0, t1, ended);
      dense.calc_state(te, mid);
      r.contact_time_s = te;
      r.v_out_m_s = -mid[1];
      r.restitution = -mid[1] / v_in;
      r.end_overlap_m = std::max(0.0, mid[0]);
      r.extra = mid[n - 1];
      r.end_state.assign(mid.begin() + 2, mid.begin() + 2 + ns);
      return r;
    }
    if ((switch_fn(b) > 0.0) != branch) {  // branch switch: locate it, restart on the other side
      const bool from_positive = branch;
      const double ts =
          bisect(t0, t1, [&](const State& s) { return (switch_fn(s) > 0.0) != from_positive; });
      dense.calc_state(ts, mid);
      dyn->AtSwitch(mid[0], mid.data() + 2);  // the law's memory update at the switch
      branch = !branch;
      dense.initialize(mid, ts, (t1 - t0) * 1e-3);
    }
    if (t1 > opt.max_time_s || r.steps >= opt.max_steps) {
      r.stuck = true;
      r.contact_time_s = t1;
      r.extra = b[n - 1];
      return r;
    }
  }
}

}  // namespace oracle
