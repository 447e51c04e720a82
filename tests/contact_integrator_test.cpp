// The contact integrator as a unit (issue 11 item 8): its Dormand-Prince stepper against
// Boost.Odeint's and for its order, the DOP853 stepper for its orders (step, dense output, error
// estimate), the controllers, analytic contacts (undamped spring: e = 1, t_c = pi sqrt(m/k);
// undamped Hertz) and DOP853's order of convergence on them, the same located events with
// either method, errors falling with the tolerance, the smooth end of the u phase (the contact
// ends exactly at delta = 0), energy bookkeeping with a compliant plate, the stuck and
// step-limit endings, the contact-time estimate, and one contact's forward sensitivities
// against central differences with either method.
#include <gtest/gtest.h>

#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <string>
#include <vector>

#include <boost/numeric/odeint.hpp>

#include "bouncecal/physics/contact_integrator.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "law_oracle.hpp"
#include "physics/dop853.hpp"
#include "physics/dopri5.hpp"

namespace bouncecal {
namespace {

using State2 = std::array<double, 2>;

// y'' = -y, from (0, 1): y = sin t.
struct Harmonic {
  void operator()(const State2& x, State2& dx, double) const {
    dx[0] = x[1];
    dx[1] = -x[0];
  }
};

// Errors of one step from (0, 1) on y = sin t, at its end and at mid-step on the dense output
// (run(h, x, f, x1, mid) takes the step and evaluates the dense output at theta = 1/2).
template <class Run>
std::pair<double, double> SineErrors(double h, const Run& run) {
  const State2 x{0.0, 1.0};
  State2 f, x1, mid;
  Harmonic()(x, f, 0.0);
  run(h, x, f, x1, mid);
  return {std::hypot(x1[0] - std::sin(h), x1[1] - std::cos(h)),
          std::hypot(mid[0] - std::sin(0.5 * h), mid[1] - std::cos(0.5 * h))};
}

TEST(Dopri5, OneStepEqualsBoostOdeintsDopri5) {
  dopri5::Stepper<double, 2> mine;
  boost::numeric::odeint::runge_kutta_dopri5<State2> reference;
  const State2 x{0.3, 0.9};
  State2 f;
  Harmonic()(x, f, 0.0);
  for (double h : {0.5, 0.1, 0.01}) {
    State2 x1, f1, x1_ref, f1_ref, err_ref;
    std::array<double, 2> err;
    mine.Step(Harmonic(), x, f, 0.0, h, x1, f1, err, 2);
    reference.do_step(Harmonic(), x, f, 0.0, x1_ref, f1_ref, h, err_ref);
    for (int i = 0; i < 2; ++i) {
      EXPECT_NEAR(x1[i], x1_ref[i], 1e-15) << h;
      EXPECT_NEAR(f1[i], f1_ref[i], 1e-15) << h;
      EXPECT_NEAR(std::abs(err[i]), std::abs(err_ref[i]), 1e-16) << h;  // odeint: b^ - b
    }
  }
}

TEST(Dopri5, StepIsFifthOrderAndDenseOutputFourth) {
  // Local errors from y = sin t (both components): the step O(h^6), the dense output at
  // mid-step O(h^5): halving h divides them by ~64 and ~32.
  double step_prev = 0.0, dense_prev = 0.0;
  for (double h : {0.4, 0.2, 0.1}) {
    const auto [step_err, dense_err] =
        SineErrors(h, [](double step, const State2& x, const State2& f, State2& x1, State2& mid) {
          dopri5::Stepper<double, 2> s;
          State2 f1, end;
          std::array<double, 2> err;
          s.Step(Harmonic(), x, f, 0.0, step, x1, f1, err, 2);
          s.Dense(0.5, x, x1, f, f1, step, mid, 2);
          // The dense output reproduces both ends exactly.
          s.Dense(1.0, x, x1, f, f1, step, end, 2);
          EXPECT_EQ(end[0], x1[0]);
        });
    if (step_prev > 0.0) {
      EXPECT_NEAR(std::log2(step_prev / step_err), 6.0, 0.3) << h;
      EXPECT_NEAR(std::log2(dense_prev / dense_err), 5.0, 0.3) << h;
    }
    step_prev = step_err;
    dense_prev = dense_err;
  }
}

TEST(Dopri5, ControllerGrowsBoundedAndNeverRightAfterARejection) {
  dopri5::Controller c;
  EXPECT_LE(c.Accepted(1e-12), 10.0);  // at most tenfold
  EXPECT_GT(c.Accepted(1e-12), 1.0);
  EXPECT_NEAR(c.Rejected(1e6), 0.2, 1e-12);  // at most fivefold smaller
  EXPECT_LT(c.Rejected(2.0), 1.0);
  EXPECT_LE(c.Accepted(1e-6), 1.0);  // no growth right after a rejection
  EXPECT_GT(c.Accepted(1e-6), 1.0);
  EXPECT_LT(c.Accepted(0.99), 1.0);  // an error just below 1: a slightly smaller next step
}

// The controllers' 2^y takes floor(y) by truncation (no library call): the same float as
// std::floor for every y they meet (|y| < 126), integers, negatives and -0 included; and the
// value stays within 0.4 % of 2^y (the quadratic on [0, 1)).
TEST(Dopri5, ApproxExp2FloorsLikeStdFloor) {
  const auto with_std_floor = [](float y) {
    const float n = std::floor(y);
    const float f = y - n;
    const float m = 1.0f + f * (0.6565f + 0.3435f * f);
    const std::uint32_t e = static_cast<std::uint32_t>(static_cast<int>(n) + 127) << 23;
    return std::bit_cast<float>((std::bit_cast<std::uint32_t>(m) & 0x7fffffu) | e) *
           (m >= 2.0f ? 2.0f : 1.0f);
  };
  int checked = 0;
  for (float y = -125.0f; y < 125.0f; y += 0.0078125f) {  // 2^-7 steps: integers exactly
    for (const float v : {y, std::nextafter(y, -200.0f), std::nextafter(y, 200.0f)}) {
      ASSERT_EQ(dopri5::ApproxExp2(v), with_std_floor(v)) << v;
      ++checked;
    }
  }
  EXPECT_EQ(dopri5::ApproxExp2(-0.0f), with_std_floor(-0.0f));
  EXPECT_EQ(checked, 3 * 32000);
  for (const float y : {-20.5f, -3.25f, -1.0f, -0.1f, 0.0f, 0.7f, 5.0f, 13.9f}) {
    EXPECT_NEAR(dopri5::ApproxExp2(y) / std::exp2(y), 1.0, 4e-3) << y;
  }
}

TEST(Dop853, StepIsEighthOrderAndDenseOutputSeventh) {
  // Local errors from y = sin t (both components): the step O(h^9), the dense output at
  // mid-step O(h^8): halving h divides them by ~512 and ~256 (measured log2 ratios 8.9-9.0 and
  // 7.9-8.0).
  double step_prev = 0.0, dense_prev = 0.0;
  for (double h : {0.8, 0.4, 0.2}) {
    const auto [step_err, dense_err] =
        SineErrors(h, [](double step, const State2& x, const State2& f, State2& x1, State2& mid) {
          dop853::Stepper<double, 2> s;
          State2 f1, start, end;
          s.Step(Harmonic(), x, f, 0.0, step, x1, f1, 2);
          s.Dense(Harmonic(), 0.0, 0.5, x, x1, f, f1, step, mid, 2);
          // The dense output reproduces both ends (to rounding: x + (x1 - x) at theta = 1).
          s.Dense(Harmonic(), 0.0, 0.0, x, x1, f, f1, step, start, 2);
          s.Dense(Harmonic(), 0.0, 1.0, x, x1, f, f1, step, end, 2);
          EXPECT_EQ(start[0], x[0]);
          EXPECT_NEAR(end[0], x1[0], 1e-16);
          EXPECT_NEAR(end[1], x1[1], 1e-16);
        });
    std::printf("[ measured ] h %.2f: step error %.3g, mid-step dense error %.3g\n", h, step_err,
                dense_err);
    if (step_prev > 0.0) {
      EXPECT_NEAR(std::log2(step_prev / step_err), 9.0, 0.3) << h;
      EXPECT_NEAR(std::log2(dense_prev / dense_err), 8.0, 0.3) << h;
    }
    step_prev = step_err;
    dense_prev = dense_err;
  }
}

TEST(Dop853, ErrorEstimateFollowsTheLocalError) {
  // The estimate (HNW §II.10: |h| err5^2 / sqrt(err5^2 + 0.01 err3^2)) is O(h^8) (measured
  // log2 ratios 8.0) and bounds the true local error of the step, O(h^9), from above.
  const State2 x{0.3, 0.9};
  State2 f;
  Harmonic()(x, f, 0.0);
  const std::array<double, 2> unit{1.0, 1.0};
  double prev = 0.0;
  for (double h : {0.4, 0.2, 0.1}) {
    dop853::Stepper<double, 2> s;
    State2 x1, f1;
    s.Step(Harmonic(), x, f, 0.0, h, x1, f1, 2);
    const double est = s.ErrorNorm(unit, 2);
    // Exact: rotation of (y, y') by the angle h.
    const double y = x[0] * std::cos(h) + x[1] * std::sin(h);
    const double yd = -x[0] * std::sin(h) + x[1] * std::cos(h);
    const double err = std::hypot(x1[0] - y, x1[1] - yd) / std::sqrt(2.0);
    EXPECT_GE(est, err) << h;
    if (prev > 0.0) {
      EXPECT_NEAR(std::log2(prev / est), 8.0, 0.3) << h;
    }
    prev = est;
  }
}

TEST(Dop853, ControllerGrowsBoundedAndNeverRightAfterARejection) {
  dop853::Controller c;
  EXPECT_LE(c.Accepted(1e-12), 6.0);  // at most sixfold
  EXPECT_GT(c.Accepted(1e-12), 1.0);
  EXPECT_NEAR(c.Rejected(1e6), 1.0 / 3.0, 1e-12);  // at most threefold smaller
  EXPECT_LT(c.Rejected(2.0), 1.0);
  EXPECT_LE(c.Accepted(1e-6), 1.0);  // no growth right after a rejection
  EXPECT_GT(c.Accepted(1e-6), 1.0);
  EXPECT_LT(c.Accepted(0.99), 1.0);
}

// ------------------------------------------------------------------------------------------
std::unique_ptr<ContactLaw> Law(const std::string& name, std::map<std::string, double> params,
                                const Scene& scene = Scene{}) {
  LawSpec spec;
  spec.name = name;
  spec.parameters = std::move(params);
  return CreateLaw(spec, scene);
}

ContactRunOptions Tight() {
  ContactRunOptions o;
  o.rel_tolerance = 1e-11;
  o.abs_tolerance = 1e-14;
  return o;
}

TEST(ContactIntegrator, UndampedSpringIsTheHalfSine) {
  const ContactBody body = BodyFromScene(Scene{});
  const double k = 1e7, m = body.mass_kg, v = 1.3;
  const auto law = Law("linear-dashpot", {{"k", k}, {"c", 0.0}});
  const ContactRun r = RunContact(*law, law->ParameterValues(), body, v, 0.0, nullptr, Tight());
  ASSERT_EQ(r.end, ContactRun::End::kSeparated) << r.detail;
  EXPECT_NEAR(r.v_out_m_s / v, 1.0, 1e-10);
  EXPECT_NEAR(r.contact_s, M_PI * std::sqrt(m / k), 1e-10 * std::sqrt(m / k));
  EXPECT_NEAR(r.peak_overlap_m, v * std::sqrt(m / k), 1e-10 * v * std::sqrt(m / k));
  EXPECT_NEAR(r.peak_force_n, k * v * std::sqrt(m / k), 1e-9 * k * v * std::sqrt(m / k));
  EXPECT_NEAR(r.work_j, 0.0, 1e-10 * 0.5 * m * v * v);
  EXPECT_EQ(r.switches, 0);
  EXPECT_FALSE(r.closed_form);
}

// Errors of one undamped contact against its closed form (e = 1 and the contact time), no
// gravity: the linear spring (t_c = pi sqrt(m/k); its end located in time on the dense output)
// and Hertz (hunt-crossley with alpha = 0; t_c from hertz-tsuji's closed form; approach and
// exit in u).
struct ConvergencePoint {
  double rtol, err_e, err_t, steps;
};
std::vector<ConvergencePoint> UndampedErrors(const std::string& name, ContactMethod method) {
  const ContactBody body = BodyFromScene(Scene{});
  const double v = 1.3;
  std::unique_ptr<ContactLaw> law;
  double t_exact = 0.0;
  if (name == "linear") {
    const double k = 1e7;
    law = Law("linear-dashpot", {{"k", k}, {"c", 0.0}});
    t_exact = M_PI * std::sqrt(body.mass_kg / k);
  } else {
    law = Law("hunt-crossley", {{"alpha", 0.0}});
    const auto tsuji = Law("hertz-tsuji", {{"e", 1.0}});
    t_exact = *tsuji->ContactTime(tsuji->ParameterValues(), body, v);
  }
  std::vector<ConvergencePoint> out;
  for (int ex = 7; ex <= 11; ++ex) {
    ContactRunOptions o;
    o.rel_tolerance = std::pow(10.0, -ex);
    o.abs_tolerance = 1e-3 * o.rel_tolerance;
    o.method = method;
    const ContactRun r = RunContact(*law, law->ParameterValues(), body, v, 0.0, nullptr, o);
    EXPECT_EQ(r.end, ContactRun::End::kSeparated) << r.detail;
    out.push_back({o.rel_tolerance, std::abs(r.v_out_m_s / v - 1.0),
                   std::abs(r.contact_s - t_exact) / t_exact, static_cast<double>(r.steps)});
  }
  return out;
}

TEST(ContactIntegrator, Dop853ConvergesAtItsOrderOnUndampedContacts) {
  for (const char* name : {"linear", "hertz"}) {
    SCOPED_TRACE(name);
    const auto p8 = UndampedErrors(name, ContactMethod::kDop853);
    const auto p5 = UndampedErrors(name, ContactMethod::kDopri5);
    // Order: over rtol 1e-7 .. 1e-11 the contact-time error against the work,
    // -log(err) / log(steps): measured 9.2 (linear) and 8.9 (hertz) for DOP853, 6.0 and 6.1 for
    // dopri5 (whose errors fall faster than rtol here).
    auto slope = [](const std::vector<ConvergencePoint>& p) {
      return std::log(p.back().err_t / p.front().err_t) /
             std::log(p.back().steps / p.front().steps);
    };
    std::printf("[ measured ] %s: order DOP853 %.2f, dopri5 %.2f\n", name, -slope(p8), -slope(p5));
    for (size_t i = 0; i < p8.size(); ++i) {
      std::printf(
          "[ measured ]   rtol %.0e: DOP853 e %.2e t %.2e (%g steps), dopri5 e %.2e t %.2e (%g "
          "steps)\n",
          p8[i].rtol, p8[i].err_e, p8[i].err_t, p8[i].steps, p5[i].err_e, p5[i].err_t, p5[i].steps);
    }
    EXPECT_GT(-slope(p8), 7.5);
    EXPECT_LT(-slope(p5), 7.0);
    for (size_t i = 0; i < p8.size(); ++i) {
      // Within the tolerance asked for, and in fewer steps than dopri5.
      EXPECT_LT(p8[i].err_e, p8[i].rtol) << p8[i].rtol;
      EXPECT_LT(p8[i].err_t, p8[i].rtol) << p8[i].rtol;
      EXPECT_LT(p8[i].steps, p5[i].steps) << p8[i].rtol;
    }
  }
}

// The events located inside steps (the contact end in time, the switch, the overlap and force
// maxima) come out the same with either method at a tight tolerance.
TEST(ContactIntegrator, BothMethodsLocateTheSameEvents) {
  const ContactBody body = BodyFromScene(Scene{});
  for (const char* name : {"linear-dashpot", "linear-dashpot-force-zero", "walton-braun",
                           "walton-braun-hysteretic", "hertz-tsuji", "jiang-liu"}) {
    SCOPED_TRACE(name);
    const auto law = Law(name, {});
    ContactRunOptions o = Tight();
    o.method = ContactMethod::kDopri5;
    const ContactRun a = RunContact(*law, law->ParameterValues(), body, 1.7, 9.8, nullptr, o);
    o.method = ContactMethod::kDop853;
    const ContactRun b = RunContact(*law, law->ParameterValues(), body, 1.7, 9.8, nullptr, o);
    ASSERT_EQ(a.end, ContactRun::End::kSeparated) << a.detail;
    ASSERT_EQ(b.end, ContactRun::End::kSeparated) << b.detail;
    EXPECT_EQ(a.switches, b.switches);
    // Measured differences <= 3.3e-12 relative (rtol 1e-11), bounds 30x that.
    EXPECT_NEAR(b.contact_s, a.contact_s, 1e-10 * a.contact_s);
    EXPECT_NEAR(b.v_out_m_s, a.v_out_m_s, 1e-10 * 1.7);
    EXPECT_NEAR(b.peak_overlap_m, a.peak_overlap_m, 1e-10 * a.peak_overlap_m);
    EXPECT_NEAR(b.peak_force_n, a.peak_force_n, 1e-9 * a.peak_force_n);
    EXPECT_NEAR(b.separation_depth_m, a.separation_depth_m, 1e-10 * a.peak_overlap_m);
    EXPECT_LT(b.steps, a.steps);
  }
}

TEST(ContactIntegrator, HertzContactEndsExactlyAtZeroOverlap) {
  // The exit phase integrates u = (delta / L)^(1/q) down to 0: the end is the end of a step.
  const ContactBody body = BodyFromScene(Scene{});
  for (const char* name : {"hertz-tsuji", "hertz-viscoelastic", "hunt-crossley", "jiang-liu"}) {
    const auto law = Law(name, {});
    const ContactRun r =
        RunContact(*law, law->ParameterValues(), body, 1.5, 9.8, nullptr, ContactRunOptions{});
    ASSERT_EQ(r.end, ContactRun::End::kSeparated) << name << r.detail;
    EXPECT_EQ(r.separation_depth_m, 0.0) << name;
    EXPECT_GT(r.v_out_m_s, 0.0) << name;
  }
}

// The error of one contact's e against the oracle (rel. tol. 1e-13) at each rel_tolerance.
std::vector<double> RestitutionErrors(const ContactLaw& law, double v, const PlateModel* plate) {
  const ContactBody body = BodyFromScene(Scene{});
  const std::vector<double> p = law.ParameterValues();
  oracle::Options oo;
  oo.rel_tol = 1e-13;
  oo.g_m_s2 = 9.8;
  const double e_ref = oracle::Integrate(law, p, body, v, oo).restitution;
  std::vector<double> errors;
  for (int ex = 5; ex <= 11; ++ex) {
    ContactRunOptions o;
    o.rel_tolerance = std::pow(10.0, -ex);
    o.abs_tolerance = 1e-3 * o.rel_tolerance;
    const ContactRun r = RunContact(law, p, body, v, 9.8, plate, o);
    errors.push_back(std::abs(r.v_out_m_s / v - e_ref));
  }
  return errors;
}

TEST(ContactIntegrator, ErrorFallsWithTheToleranceForEveryLaw) {
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;
    SCOPED_TRACE(info.name);
    const auto law = Law(info.name, {});
    const std::vector<double> err = RestitutionErrors(*law, 1.5, nullptr);
    // Below rtol 1e-5 every tenfold tighter tolerance leaves a smaller error, until rounding
    // (~1e-13) takes over (measured: about 2-3 rtol per contact for every law), or one already
    // below a tenth of the tighter tolerance: a value can be luckily small (hunt-crossley 4.6e-8
    // at 1e-5, 9.1e-8 at 1e-6; jiang-liu 3.8e-13 at 1e-10, 6.1e-13 at 1e-11); and the error
    // stays within 10x the tolerance asked for.
    for (size_t i = 2; i < err.size(); ++i) {
      const double tighter_rtol = std::pow(10.0, -(5.0 + static_cast<double>(i)));
      if (err[i - 1] > 1e-13 && err[i] >= 0.1 * tighter_rtol) {
        EXPECT_LT(err[i], err[i - 1]) << "rtol 1e-" << 5 + i;
      }
    }
    for (size_t i = 0; i < err.size(); ++i) {
      EXPECT_LT(err[i], 10.0 * std::pow(10.0, -(5.0 + static_cast<double>(i))) + 1e-13)
          << "rtol 1e-" << 5 + i;
    }
  }
}

TEST(ContactIntegrator, WaltonBraunSwitchIsLocatedOnce) {
  const ContactBody body = BodyFromScene(Scene{});
  const auto law = Law("walton-braun", {{"gamma", 0.4}});
  const ContactRun r = RunContact(*law, law->ParameterValues(), body, 2.0, 0.0, nullptr, Tight());
  EXPECT_EQ(r.switches, 1);
  EXPECT_NEAR(r.v_out_m_s / 2.0, std::sqrt(0.6 / 1.4), 1e-10);
}

TEST(ContactIntegrator, PlateEnergyBalances) {
  // Energy in = ball energy out + work done on the contact; the work splits into what the plate
  // and the law hold at the end and what is dissipated.
  const ContactBody body = BodyFromScene(Scene{});
  const PlateModel plate{0.05, 2e5, 2.0};
  for (const char* name : {"hertz-tsuji", "walton-braun-hysteretic", "linear-dashpot"}) {
    const auto law = Law(name, {});
    const double v = 1.0, e0 = 0.5 * body.mass_kg * v * v;
    const ContactRun r = RunContact(*law, law->ParameterValues(), body, v, 9.8, &plate, Tight());
    ASSERT_EQ(r.end, ContactRun::End::kSeparated) << name << r.detail;
    EXPECT_NEAR(r.ball_energy_end_j + r.work_j, e0, 1e-9 * e0) << name;
    EXPECT_GT(r.plate_end_j, 0.0) << name;  // the plate still moves when the ball leaves
    EXPECT_LE(r.plate_end_j + r.elastic_end_j, r.work_j) << name;
  }
}

TEST(ContactIntegrator, OverdampedContactSticksQuickly) {
  const ContactBody body = BodyFromScene(Scene{});
  const double m = body.mass_kg, k = 1e6;
  const auto law = Law("linear-dashpot", {{"k", k}, {"c", 2.0 * 1e6 * std::sqrt(m * k)}});
  ContactRunOptions o;
  o.stuck_speed_m_s = 1e-4;
  const ContactRun r = RunContact(*law, law->ParameterValues(), body, 2.0, 9.8, nullptr, o);
  EXPECT_EQ(r.end, ContactRun::End::kStuck);
  EXPECT_NE(r.detail.find("energy left"), std::string::npos) << r.detail;
  EXPECT_LT(r.steps, 200);  // measured 86
}

TEST(ContactIntegrator, StepLimitIsReportedWithTheLawsName) {
  const ContactBody body = BodyFromScene(Scene{});
  const auto law = Law("hertz-tsuji", {});
  ContactRunOptions o;
  o.max_steps = 10;
  const ContactRun r = RunContact(*law, law->ParameterValues(), body, 2.0, 9.8, nullptr, o);
  EXPECT_EQ(r.end, ContactRun::End::kStepLimit);
  EXPECT_EQ(r.steps, 10);
  EXPECT_NE(r.detail.find("hertz-tsuji"), std::string::npos) << r.detail;
  EXPECT_NE(r.detail.find("10 integrator steps"), std::string::npos) << r.detail;
}

TEST(ContactIntegrator, NonFiniteForceEndsWithAMessageNotAHang) {
  Scene scene;
  scene.law.name = "expression";
  scene.law.expression = "k * d * sqrt(2e-6 - d)";  // NaN beyond 2 um of overlap
  scene.law.parameters = {{"k", 1e7}};
  const auto law = CreateLaw(scene.law, scene);
  const ContactRun r = RunContact(*law, law->ParameterValues(), BodyFromScene(scene), 2.0, 9.8,
                                  nullptr, ContactRunOptions{});
  EXPECT_EQ(r.end, ContactRun::End::kStepLimit);
  EXPECT_NE(r.detail.find("not finite"), std::string::npos) << r.detail;
}

TEST(ContactIntegrator, ContactTimeEstimateFromTheElasticEnergy) {
  // Without a closed form the estimate is 3 delta_max / v (Hertz's exact factor is 2.94).
  const ContactBody body = BodyFromScene(Scene{});
  const auto hc = Law("hunt-crossley", {{"alpha", 0.0}});
  const auto tsuji = Law("hertz-tsuji", {{"e", 1.0}});  // the same elastic Hertz, closed form
  const std::vector<double> p = hc->ParameterValues();
  const auto dyn = hc->Dynamics(p, body);
  const double estimate = EstimateContactTime(*hc, p, *dyn, body, 1.0);
  const std::vector<double> q = tsuji->ParameterValues();
  const double exact = *tsuji->ContactTime(q, body, 1.0);
  EXPECT_NEAR(estimate / exact, 3.0 / 2.94, 0.01);
}

TEST(ContactIntegrator, DeclaredElasticPowerLawsAreTheLawsElasticEnergy) {
  // The contact-time estimate solves ElasticEnergy(delta_max) = m v^2 / 2 in closed form for a
  // law that declares its elastic energy a power law a delta^b: the declaration must be that
  // energy (a law whose energy changes without its declaration would be scaled wrongly).
  const ContactBody body = BodyFromScene(Scene{});
  int declared = 0;
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;
    SCOPED_TRACE(info.name);
    const auto law = Law(info.name, {});
    const auto dyn = law->Dynamics(law->ParameterValues(), body);
    double a = 0.0, b = 0.0;
    if (!dyn->ElasticPowerLaw(&a, &b)) continue;
    ++declared;
    std::array<double, 8> s0{};
    dyn->InitialState(s0.data());
    for (double d : {1e-9, 1e-6, 1e-4}) {
      EXPECT_NEAR(dyn->ElasticEnergy(d, s0.data()) / (a * std::pow(d, b)), 1.0, 1e-12) << d;
    }
  }
  EXPECT_GE(declared, 7);  // hertz-tsuji, hertz-viscoelastic, jiang-liu, four hunt-crossley
}

TEST(ContactIntegrator, ClosedFormContactTimeScaleIsWhatTheEnergySearchFinds) {
  // Hunt-Crossley with n = 2 (no ContactTime closed form): 3 delta_max / v with delta_max from
  // bisection on the law's own ElasticEnergy, here in the test.
  const ContactBody body = BodyFromScene(Scene{});
  const auto hc = Law("hunt-crossley", {{"n", 2.0}, {"alpha", 0.05}});
  const std::vector<double> p = hc->ParameterValues();
  const auto dyn = hc->Dynamics(p, body);
  for (double v : {1e-3, 0.3, 2.0}) {
    const double target = 0.5 * body.mass_kg * v * v;
    double lo = 0.0, hi = body.radius_m;
    for (int i = 0; i < 200; ++i) {
      const double mid = 0.5 * (lo + hi);
      (dyn->ElasticEnergy(mid, nullptr) < target ? lo : hi) = mid;
    }
    EXPECT_NEAR(EstimateContactTime(*hc, p, *dyn, body, v) / (3.0 * hi / v), 1.0, 1e-12) << v;
  }
}

TEST(ContactIntegrator, OneContactsSensitivitiesMatchCentralDifferences) {
  const ContactBody body = BodyFromScene(Scene{});
  const PlateModel plate{0.2, 5e6, 10.0};
  ContactRunOptions o = Tight();
  for (ContactMethod method : {ContactMethod::kDopri5, ContactMethod::kDop853}) {
    o.method = method;
    for (const char* name :
         {"hertz-tsuji", "walton-braun-hysteretic", "jiang-liu", "linear-dashpot-force-zero"}) {
      for (const PlateModel* pl : {static_cast<const PlateModel*>(nullptr), &plate}) {
        SCOPED_TRACE(std::string(name) + (pl ? " with plate" : "") +
                     (method == ContactMethod::kDop853 ? " (DOP853)" : " (dopri5)"));
        const auto law = Law(name, {});
        const std::vector<double> p = law->ParameterValues();
        auto run = [&](const std::vector<double>& q, double v, ContactSensitivity* s) {
          const auto dyn = law->Dynamics(q, body);
          return RunContact(*dyn, body, EstimateContactTime(*law, q, *dyn, body, v), v, 9.8, pl, o,
                            s);
        };
        const double v = 1.2;
        ContactSensitivity s;
        const ContactRun r = run(p, v, &s);
        ASSERT_EQ(r.end, ContactRun::End::kSeparated) << r.detail;
        for (size_t j = 0; j <= p.size(); ++j) {
          const double x = j < p.size() ? p[j] : v;
          const double h = 1e-6 * std::abs(x);
          std::vector<double> hi = p, lo = p;
          double vh = v, vl = v;
          if (j < p.size()) {
            hi[j] += h;
            lo[j] -= h;
          } else {
            vh += h;
            vl -= h;
          }
          const ContactRun a = run(hi, vh, nullptr), b = run(lo, vl, nullptr);
          const double dv = (a.v_out_m_s - b.v_out_m_s) / (2 * h);
          const double dt = (a.contact_s - b.contact_s) / (2 * h);
          // Relative to the natural scales v / x and t_c / x; central differences at rel. tol.
          // 1e-11 carry ~1e-5 of them (noise / h); measured agreement 1e-7..1e-6.
          EXPECT_NEAR(s.v_out[j], dv, 2e-5 * v / std::abs(x)) << "d v_out / d theta_" << j;
          EXPECT_NEAR(s.contact_s[j], dt, 2e-5 * r.contact_s / std::abs(x))
              << "d t_c / d theta_" << j;
        }
      }
    }
  }
}

}  // namespace
}  // namespace bouncecal
