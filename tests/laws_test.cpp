// Contact-law tests: closed forms against the independent integrator (tests/law_oracle.hpp),
// the seed paper's relation, inverse maps, gradients, and every invalid-input case.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include <sys/wait.h>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "law_oracle.hpp"
#include "physics/laws/hertz_family.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

constexpr double kClosedTol = 1e-6;  // issue 3: closed forms vs integration, relative

Scene SteelScene() { return Scene{}; }  // seed 002: 1 cm steel ball on copper

std::unique_ptr<ContactLaw> Make(const std::string& name, std::map<std::string, double> params,
                                 const Scene& scene = SteelScene()) {
  LawSpec spec;
  spec.name = name;
  spec.parameters = std::move(params);
  return CreateLaw(spec, scene);
}

double Rel(double a, double b) { return std::abs(a - b) / std::max(std::abs(b), 1e-300); }

// Worst relative disagreement seen per law (printed by the Summary test at the end).
std::map<std::string, std::pair<double, double>>& Worst() {
  static std::map<std::string, std::pair<double, double>> worst;
  return worst;
}

// Closed-form e, contact time and SolveContact against the oracle.
void ExpectClosedFormsMatch(const ContactLaw& law, const ContactBody& body, double v) {
  const std::vector<double> p = law.ParameterValues();
  const oracle::Result r = oracle::Integrate(law, p, body, v);
  ASSERT_FALSE(r.stuck);
  const auto e = law.Restitution(p, body, v);
  const auto tc = law.ContactTime(p, body, v);
  ASSERT_TRUE(e.has_value()) << law.Name();
  ASSERT_TRUE(tc.has_value()) << law.Name();
  EXPECT_LT(Rel(*e, r.restitution), kClosedTol)
      << law.Name() << " e " << *e << " vs " << r.restitution;
  EXPECT_LT(Rel(*tc, r.contact_time_s), kClosedTol)
      << law.Name() << " t_c " << *tc << " vs " << r.contact_time_s;
  auto& w = Worst()[law.Name()];
  w.first = std::max(w.first, Rel(*e, r.restitution));
  w.second = std::max(w.second, Rel(*tc, r.contact_time_s));
  if (auto out = law.SolveContact(p, body, v)) {
    EXPECT_LT(Rel(out->restitution, r.restitution), kClosedTol) << law.Name();
    EXPECT_LT(Rel(out->contact_time_s, r.contact_time_s), kClosedTol) << law.Name();
    EXPECT_LT(Rel(out->peak_overlap_m, r.peak_overlap_m), kClosedTol) << law.Name();
    EXPECT_LT(Rel(out->peak_force_n, r.peak_force_n), 1e-4) << law.Name();    // sampled max
    EXPECT_GE(out->peak_force_n, r.peak_force_n * (1 - 1e-9)) << law.Name();  // true max
    EXPECT_NEAR(out->end_overlap_m, r.end_overlap_m, 1e-6 * r.peak_overlap_m) << law.Name();
  }
}

// ------------------------------------------------------------------------ linear spring-dashpot
TEST(LinearDashpot, ClosedFormsMatchIntegrationAcrossDamping) {
  const Scene scene = SteelScene();
  const ContactBody body = BodyFromScene(scene);
  const double crit = 2.0 * std::sqrt(body.mass_kg * 1e7);
  for (double zeta : {0.0, 0.01, 0.1, 0.3, 0.6, 0.9}) {
    for (const char* name : {"linear-dashpot", "linear-dashpot-force-zero"}) {
      auto law = Make(name, {{"k", 1e7}, {"c", zeta * crit}});
      ExpectClosedFormsMatch(*law, body, 1.98);
    }
  }
  // F = 0 rule also ends critically and over-damped contacts in finite time.
  for (double zeta : {1.0, 1.5, 4.0}) {
    auto law = Make("linear-dashpot-force-zero", {{"k", 1e7}, {"c", zeta * crit}});
    ExpectClosedFormsMatch(*law, body, 1.98);
  }
}

TEST(LinearDashpot, RestitutionFormulaAndSpeedIndependence) {
  const ContactBody body = ContactBody::BallOnRigidWall(0.01, 0.005);
  auto law = Make("linear-dashpot", {{"k", 1e5}, {"c", 2.0}});
  const auto p = law->ParameterValues();
  const double zeta = 2.0 / (2.0 * std::sqrt(0.01 * 1e5));
  const double expected = std::exp(-M_PI * zeta / std::sqrt(1 - zeta * zeta));
  for (double v : {0.01, 1.0, 10.0}) {
    EXPECT_NEAR(*law->Restitution(p, body, v), expected, 1e-14);
    EXPECT_LT(Rel(oracle::Integrate(*law, p, body, v).restitution, expected), kClosedTol);
  }
}

TEST(LinearDashpot, OverdampedSticksUnderOverlapZeroRule) {
  const ContactBody body = ContactBody::BallOnRigidWall(0.01, 0.005);
  const double crit = 2.0 * std::sqrt(0.01 * 1e5);
  auto law = Make("linear-dashpot", {{"k", 1e5}, {"c", 1.2 * crit}}, SteelScene());
  const auto p = law->ParameterValues();
  const auto out = law->SolveContact(p, body, 1.0);
  ASSERT_TRUE(out.has_value());
  EXPECT_TRUE(out->stuck);
  EXPECT_EQ(out->restitution, 0.0);
  EXPECT_TRUE(std::isinf(out->contact_time_s));
  oracle::Options opt;
  opt.max_time_s = 1.0;  // ~ 1000 natural periods
  EXPECT_TRUE(oracle::Integrate(*law, p, body, 1.0, opt).stuck);
}

TEST(LinearDashpot, ForceZeroRuleGivesAbout0808WhenTunedTo08) {
  const Scene scene = SteelScene();
  const ContactBody body = BodyFromScene(scene);
  auto law = Make("linear-dashpot", {{"k", 1e7}});
  const auto tuned = law->DampingForRestitution(law->ParameterValues(), body, 0.8, 1.0);
  ASSERT_TRUE(tuned.has_value());
  auto zero_rule = Make("linear-dashpot", {{"k", 1e7}, {"c", (*tuned)[1]}});
  auto force_rule = Make("linear-dashpot-force-zero", {{"k", 1e7}, {"c", (*tuned)[1]}});
  const double e_zero = oracle::Integrate(*zero_rule, *tuned, body, 1.0).restitution;
  const double e_force = oracle::Integrate(*force_rule, *tuned, body, 1.0).restitution;
  EXPECT_NEAR(e_zero, 0.8, 1e-9);
  EXPECT_NEAR(e_force, 0.808, 0.001);  // docs/physics.md §3
  std::printf(
      "[ measured ] linear dashpot tuned to e = 0.8 (overlap-zero rule): %.9f; "
      "force-zero rule: %.6f\n",
      e_zero, e_force);
  EXPECT_GT(e_force, e_zero);
  EXPECT_NEAR(*force_rule->Restitution(*tuned, body, 1.0), e_force, 1e-9);
}

// ------------------------------------------------------------------------ seed 002 Walton-Braun
TEST(WaltonBraun, SeedEnergyLossIsTwoGammaOverOnePlusGamma) {
  const Scene scene = SteelScene();
  const ContactBody body = BodyFromScene(scene);
  for (double gamma : {0.1, 0.3, 0.5, 0.7, 0.9}) {
    auto law = Make("walton-braun", {{"k", 1e7}, {"gamma", gamma}});
    const auto p = law->ParameterValues();
    const oracle::Result r = oracle::Integrate(*law, p, body, 1.98);
    const double eta = 1.0 - r.restitution * r.restitution;                    // seed 002 eq. 12
    EXPECT_NEAR(eta, 2.0 * gamma / (1.0 + gamma), 1e-9) << "gamma " << gamma;  // eq. 23
    ExpectClosedFormsMatch(*law, body, 1.98);
  }
}

TEST(WaltonBraun, SeedCalibrationInverse) {
  // docs/physics.md §1: the exact inverse of eta = 0.58 is gamma = eta/(2 - eta) = 0.408.
  auto law = Make("walton-braun", {});
  const ContactBody body = BodyFromScene(SteelScene());
  const double e = std::sqrt(1.0 - 0.58);
  const auto q = law->DampingForRestitution(law->ParameterValues(), body, e, 1.0);
  ASSERT_TRUE(q.has_value());
  EXPECT_NEAR((*q)[1], 0.58 / (2.0 - 0.58), 1e-12);
  EXPECT_NEAR((*q)[1], 0.408, 5e-4);
}

// ------------------------------------------------------------------------ hysteretic
TEST(WaltonBraunHysteretic, ClosedFormsMatchAndLeavePlasticOverlap) {
  const ContactBody body = BodyFromScene(SteelScene());
  for (double e : {0.2, 0.5, 0.8, 0.99}) {
    auto law = Make("walton-braun-hysteretic", {{"k1", 1e7}, {"k2", 1e7 / (e * e)}});
    ExpectClosedFormsMatch(*law, body, 1.5);
    const auto p = law->ParameterValues();
    EXPECT_NEAR(*law->Restitution(p, body, 1.5), e, 1e-12);
    const auto r = oracle::Integrate(*law, p, body, 1.5);
    EXPECT_NEAR(r.end_overlap_m, r.peak_overlap_m * (1 - e * e), 1e-6 * r.peak_overlap_m);
  }
}

// ------------------------------------------------------------------------ Hertz-Tsuji
TEST(HertzTsuji, RestitutionIsExactAndSpeedIndependent) {
  const Scene scene = SteelScene();
  const ContactBody body = BodyFromScene(scene);
  for (double e : {0.05, 0.3, 0.5, 0.8, 0.95, 0.999}) {
    auto law = Make("hertz-tsuji", {{"e", e}});
    const auto p = law->ParameterValues();
    const double e_slow = oracle::Integrate(*law, p, body, 0.1).restitution;
    const double e_fast = oracle::Integrate(*law, p, body, 10.0).restitution;
    EXPECT_LT(Rel(e_slow, e), kClosedTol) << e;
    EXPECT_LT(Rel(e_fast, e), kClosedTol) << e;
    EXPECT_NEAR(e_slow, e_fast, 1e-8) << e;  // speed-independent
    for (double v : {0.1, 1.0, 10.0}) ExpectClosedFormsMatch(*law, body, v);
  }
}

TEST(HertzTsuji, DefaultStiffnessFromMaterials) {
  Scene scene = SteelScene();
  scene.ball.youngs_modulus_pa = 200e9;
  scene.ball.poisson_ratio = 0.3;
  scene.surface.youngs_modulus_pa = 120e9;
  scene.surface.poisson_ratio = 0.34;
  auto law = Make("hertz-tsuji", {}, scene);
  const double e_star = 1.0 / ((1 - 0.09) / 200e9 + (1 - 0.34 * 0.34) / 120e9);
  const double k = 4.0 / 3.0 * e_star * std::sqrt(0.005);  // Johnson eq. 4.22, R* = R
  EXPECT_NEAR(law->ParameterValues()[0], k, 1e-6 * k);
  // Hertz contact time of the elastic limit: 2.87 (m*^2/(R* E*^2 v))^(1/5) (docs/physics.md §2).
  auto elastic = Make("hertz-tsuji", {{"e", 1.0}}, scene);
  const ContactBody body = BodyFromScene(scene);
  const double m = body.mass_kg, v = 1.0;
  const double hertz = 2.87 * std::pow(m * m / (0.005 * e_star * e_star * v), 0.2);
  EXPECT_NEAR(*elastic->ContactTime(elastic->ParameterValues(), body, v), hertz, 0.002 * hertz);
}

TEST(HertzTsuji, AlphaMatchesKnownValue) {
  // Independent check of the master curve: integrate alpha = 0.3 and read alpha(e) back.
  auto law = Make("hertz-tsuji", {{"e", 0.5}});
  const ContactBody body = BodyFromScene(SteelScene());
  std::vector<double> p = law->ParameterValues();
  const double alpha = laws::HertzTsujiAlpha(0.5);
  const double eta = alpha * std::sqrt(body.mass_kg * p[0]);
  LawSpec spec;
  spec.name = "expression";
  spec.expression = "k * d^1.5 + eta * d^0.25 * v";
  spec.parameters = {{"k", p[0]}, {"eta", eta}};
  auto expr = CreateLaw(spec, SteelScene());
  const double e = oracle::Integrate(*expr, expr->ParameterValues(), body, 2.0).restitution;
  EXPECT_LT(Rel(e, 0.5), kClosedTol);
}

// ------------------------------------------------------------------------ viscoelastic Hertz
TEST(HertzViscoelastic, MasterCurveMatchesIntegrationAndFallsWithSpeed) {
  const ContactBody body = BodyFromScene(SteelScene());
  for (double a : {1e-8, 1e-7, 1e-6}) {
    auto law = Make("hertz-viscoelastic", {{"A", a}});
    const auto p = law->ParameterValues();
    double previous = 1.0;
    for (double v : {0.01, 0.1, 1.0, 3.0, 10.0}) {
      ExpectClosedFormsMatch(*law, body, v);
      const double e = oracle::Integrate(*law, p, body, v).restitution;
      EXPECT_LT(e, previous) << "A " << a << " v " << v;  // e falls with speed
      previous = e;
    }
  }
}

TEST(HertzViscoelastic, RamirezSeriesAtLowSpeed) {
  // b = beta v^(1/5), beta = 1.5 A (k/m*)^(2/5); the two-term series must be accurate to a
  // small fraction of its own b^2 term, and the one-term series must not be.
  const ContactBody body = BodyFromScene(SteelScene());
  auto law = Make("hertz-viscoelastic", {{"A", 1e-8}});
  const auto p = law->ParameterValues();
  const double beta = 1.5 * p[1] * std::pow(p[0] / body.mass_kg, 0.4);
  for (double v : {1e-3, 1e-2, 0.1}) {
    const double b = beta * std::pow(v, 0.2);
    ASSERT_LT(b, 0.01);
    const double e = oracle::Integrate(*law, p, body, v).restitution;
    const double series = laws::ViscoelasticSeriesRestitution(b);
    const double c2_term = laws::kRamirezC2 * b * b;
    EXPECT_LT(std::abs(e - series), 0.05 * c2_term) << "v " << v << " b " << b;
    EXPECT_GT(std::abs(e - (1.0 - laws::kRamirezC1 * b)), 0.5 * c2_term);
  }
}

// ------------------------------------------------------------------------ Hunt-Crossley family
TEST(HuntCrossley, VariantsMissTheirTarget) {
  // docs/physics.md §3: for a target of 0.8, Lankarani-Nikravesh gives ~0.847, Flores ~0.789.
  const ContactBody body = BodyFromScene(SteelScene());
  const double v0 = 1.98;
  std::map<std::string, double> got;
  for (const char* name : {"hunt-crossley-hc", "hunt-crossley-ln", "hunt-crossley-flores"}) {
    auto law = Make(name, {{"e", 0.8}, {"v0", v0}});
    got[name] = oracle::Integrate(*law, law->ParameterValues(), body, v0).restitution;
    EXPECT_GT(std::abs(got[name] - 0.8), 0.01) << name << " reproduces its target";
  }
  EXPECT_NEAR(got["hunt-crossley-ln"], 0.847, 0.002);
  EXPECT_NEAR(got["hunt-crossley-flores"], 0.789, 0.002);
  EXPECT_NEAR(got["hunt-crossley-hc"], 0.833, 0.002);
  std::printf("[ measured ] Hunt-Crossley target 0.8: hc %.4f  ln %.4f  flores %.4f\n",
              got["hunt-crossley-hc"], got["hunt-crossley-ln"], got["hunt-crossley-flores"]);
}

// The integrator inlines the force of the Hunt-Crossley family at n = 1.5 (HertzDamper): the
// form it is given carries each variant's k and alpha (alpha from the variant's own formula,
// written out here), gives the law's force to the bit in double and in the sensitivity type
// (whose value is computed by the law's general code), at and around delta = 0 and where the
// damping factor turns negative; and no form is given at another exponent or by another law.
TEST(HuntCrossley, InlinedForceIsTheLawsForceAndOnlyAtHertzExponent) {
  const ContactBody body = BodyFromScene(SteelScene());
  const double e = 0.8, v0 = 1.5;
  const std::map<std::string, double> alpha_of = {
      {"hunt-crossley-hc", 3.0 * (1.0 - e) / (2.0 * v0)},
      {"hunt-crossley-ln", 3.0 * (1.0 - e * e) / (4.0 * v0)},
      {"hunt-crossley-flores", 8.0 * (1.0 - e) / (5.0 * e * v0)},
      {"hunt-crossley", 0.3}};
  for (const auto& [name, alpha] : alpha_of) {
    SCOPED_TRACE(name);
    auto law = name == "hunt-crossley" ? Make(name, {{"alpha", alpha}})
                                       : Make(name, {{"e", e}, {"v0", v0}});
    const std::vector<double> p = law->ParameterValues();
    const auto dyn = law->Dynamics(p, body);
    HertzDamper form;
    ASSERT_TRUE(dyn->InlineHertzDamper(&form));
    EXPECT_EQ(form.k, p[0]);
    EXPECT_NEAR(form.alpha, alpha, 1e-15 * alpha);
    for (double delta : {-1e-6, 0.0, 1e-12, 3e-7, 2e-5}) {
      for (double rate : {-2.0 / alpha, -1.0 / alpha, -0.5, 0.0, 1.98}) {
        const double f = form(delta, rate);
        EXPECT_EQ(f, dyn->Force(delta, rate, nullptr)) << delta << " " << rate;
        EXPECT_EQ(f,
                  dyn->ForceOnBranch(SensitivityJet(delta), SensitivityJet(rate), nullptr, true).a)
            << delta << " " << rate;
        const double expected =
            delta > 0.0 ? std::max(0.0, p[0] * std::pow(delta, 1.5) * (1.0 + alpha * rate)) : 0.0;
        EXPECT_NEAR(f, expected, 1e-15 * expected) << delta << " " << rate;
      }
    }
  }
  auto other_n = Make("hunt-crossley", {{"n", 1.2}});
  HertzDamper form;
  EXPECT_FALSE(other_n->Dynamics(other_n->ParameterValues(), body)->InlineHertzDamper(&form));
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression || info.name.rfind("hunt-crossley", 0) == 0) continue;
    auto law = Make(info.name, {});
    EXPECT_FALSE(law->Dynamics(law->ParameterValues(), body)->InlineHertzDamper(&form))
        << info.name;
  }
}

TEST(HuntCrossley, SmallDampingLimitAndSpeedDependence) {
  // e ~ 1 - (2/3) alpha v for small alpha v (Hunt & Crossley 1975); e depends on alpha v only.
  const ContactBody body = BodyFromScene(SteelScene());
  auto law = Make("hunt-crossley", {{"alpha", 0.01}});
  const auto p = law->ParameterValues();
  const double e = oracle::Integrate(*law, p, body, 1.0).restitution;
  EXPECT_NEAR(e, 1.0 - 2.0 / 3.0 * 0.01, 2e-4);
  auto scaled = Make("hunt-crossley", {{"alpha", 0.001}, {"k", p[0] * 7}});
  EXPECT_NEAR(oracle::Integrate(*scaled, scaled->ParameterValues(), body, 10.0).restitution, e,
              1e-8);
  EXPECT_LT(oracle::Integrate(*law, p, body, 10.0).restitution, e);  // falls with speed
}

TEST(HuntCrossley, LargeDampingNeverTurnsAttractive) {
  // During unloading F = k d^n (1 + alpha d') vanishes as d' -> -1/alpha, so the rebound speed
  // stays below 1/alpha and the force never turns attractive.
  const ContactBody body = BodyFromScene(SteelScene());
  for (double alpha : {1.0, 5.0, 50.0}) {
    auto law = Make("hunt-crossley", {{"alpha", alpha}});
    const auto p = law->ParameterValues();
    const auto r = oracle::Integrate(*law, p, body, 2.0);
    EXPECT_GT(r.restitution, 0.0) << alpha;
    EXPECT_LE(r.v_out_m_s, (1.0 + 1e-9) / alpha) << alpha;
    EXPECT_EQ(r.end_overlap_m, 0.0);
  }
}

// Hunt & Crossley (1975) first integral: m v dv/dd = -k d^n (1 + alpha v) separates into
// v dv / (1 + alpha v) = -(k/m) d^n dd, so G(v) = alpha v - ln(1 + alpha v) takes the same value
// at entry and exit (both at d = 0): with u = alpha v_in and w = -alpha v_out in (0, 1),
// u - ln(1 + u) = -w - ln(1 - w), e = w / u. Independent of k, n and m, and of any integrator
// (the oracle integrates the law's own force, so only this catches a wrong force or alpha).
double HuntCrossleyExactRestitution(double alpha, double v_in) {
  const double u = alpha * v_in;
  const double target = u - std::log1p(u);
  // -w - ln(1 - w) rises from 0 (w = 0) to +inf (w -> 1): bisection.
  double lo = 0.0, hi = 1.0;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (-mid - std::log1p(-mid) < target ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi) / u;
}

TEST(HuntCrossley, RestitutionMatchesTheExactFirstIntegral) {
  const ContactBody body = BodyFromScene(SteelScene());
  struct Case {
    const char* name;
    std::map<std::string, double> params;
    double alpha;  // from the paper's formula, written here independently of the law
  };
  const double v0 = 1.98;
  const Case cases[] = {
      {"hunt-crossley", {{"alpha", 0.01}}, 0.01},
      {"hunt-crossley", {{"alpha", 0.3}}, 0.3},
      {"hunt-crossley", {{"alpha", 0.3}, {"n", 1.2}}, 0.3},  // the general pow() path
      {"hunt-crossley", {{"alpha", 5.0}}, 5.0},
      {"hunt-crossley-hc", {{"e", 0.8}, {"v0", v0}}, 3.0 * (1.0 - 0.8) / (2.0 * v0)},
      {"hunt-crossley-ln", {{"e", 0.8}, {"v0", v0}}, 3.0 * (1.0 - 0.64) / (4.0 * v0)},
      {"hunt-crossley-flores", {{"e", 0.8}, {"v0", v0}}, 8.0 * (1.0 - 0.8) / (5.0 * 0.8 * v0)},
  };
  double worst_oracle = 0.0, worst_sim = 0.0;
  for (const Case& c : cases) {
    auto law = Make(c.name, c.params);
    const std::vector<double> p = law->ParameterValues();
    for (double v : {0.5, 1.98, 4.0}) {
      const double exact = HuntCrossleyExactRestitution(c.alpha, v);
      const double by_oracle = oracle::Integrate(*law, p, body, v).restitution;
      const double by_sim = SimulateContact(*law, p, body, v, 0.0).restitution;
      worst_oracle = std::max(worst_oracle, Rel(by_oracle, exact));
      worst_sim = std::max(worst_sim, Rel(by_sim, exact));
      // Measured worst 1.3e-11 (oracle at rtol 1e-12) and 3e-10 (the simulator at its default
      // rtol 1e-9); bounds 5e-11 and 1e-9. A 1 % change of alpha moves e by 1e-4 (alpha 0.01)
      // to 1e-2 relative.
      EXPECT_LT(Rel(by_oracle, exact), 5e-11)
          << c.name << " v " << v << ": " << by_oracle << " vs exact " << exact;
      EXPECT_LT(Rel(by_sim, exact), 1e-9)
          << c.name << " v " << v << ": " << by_sim << " vs exact " << exact;
    }
  }
  std::printf("[ measured ] Hunt-Crossley e vs the first integral: oracle %.2g, simulator %.2g\n",
              worst_oracle, worst_sim);
}

// ------------------------------------------------------------------------ expression law
TEST(Expression, ReproducesBuiltInLaw) {
  const ContactBody body = BodyFromScene(SteelScene());
  LawSpec spec;
  spec.name = "expression";
  spec.expression = "k * d + c * v";
  spec.parameters = {{"k", 1e7}, {"c", 20.0}};
  auto expr = CreateLaw(spec, SteelScene());
  auto linear = Make("linear-dashpot", {{"k", 1e7}, {"c", 20.0}});
  const auto pl = linear->ParameterValues();
  const double e_expected = *linear->Restitution(pl, body, 1.0);
  const auto r = oracle::Integrate(*expr, expr->ParameterValues(), body, 1.0);
  EXPECT_LT(Rel(r.restitution, e_expected), kClosedTol);
  EXPECT_NEAR(expr->Dynamics(expr->ParameterValues(), body)->ElasticEnergy(1e-4, nullptr),
              0.5 * 1e7 * 1e-8, 1e-12);
  EXPECT_EQ(expr->Name(), "expression");
  EXPECT_FALSE(expr->Parameters()[expr->ParameterIndex("k")].damping);
  EXPECT_TRUE(expr->Parameters()[expr->ParameterIndex("c")].damping);
}

TEST(Expression, ElasticEnergyIsWorkOfRateIndependentPart) {
  LawSpec spec;
  spec.name = "expression";
  spec.expression = "k * d^1.5 * (1 + alpha * v)";
  spec.parameters = {{"k", 1e10}, {"alpha", 0.3}};
  auto law = CreateLaw(spec, SteelScene());
  const ContactBody body = BodyFromScene(SteelScene());
  const double d = 2e-5;
  EXPECT_NEAR(law->Dynamics(law->ParameterValues(), body)->ElasticEnergy(d, nullptr),
              1e10 * std::pow(d, 2.5) / 2.5, 1e-9 * 1e10 * std::pow(d, 2.5));
}

// ------------------------------------------------------------------------ inverse maps
TEST(InverseMaps, RoundTrip) {
  const ContactBody body = BodyFromScene(SteelScene());
  const char* names[] = {"linear-dashpot", "linear-dashpot-force-zero",
                         "walton-braun",   "walton-braun-hysteretic",
                         "hertz-tsuji",    "hertz-viscoelastic"};
  for (const char* name : names) {
    auto law = Make(name, {});
    for (double e : {0.1, 0.5, 0.8, 0.99}) {
      for (double v : {0.3, 3.0}) {
        const auto q = law->DampingForRestitution(law->ParameterValues(), body, e, v);
        ASSERT_TRUE(q.has_value()) << name << " e " << e;
        std::string why;
        EXPECT_TRUE(law->IsValid(*q, body, &why)) << why;
        EXPECT_NEAR(*law->Restitution(*q, body, v), e, 1e-9) << name << " e " << e;
        EXPECT_LT(Rel(oracle::Integrate(*law, *q, body, v).restitution, e), kClosedTol)
            << name << " e " << e << " v " << v;
      }
    }
    EXPECT_FALSE(law->DampingForRestitution(law->ParameterValues(), body, 1.5, 1.0).has_value());
    EXPECT_FALSE(law->DampingForRestitution(law->ParameterValues(), body, -0.1, 1.0).has_value());
  }
}

// ------------------------------------------------------------------------ gradients
TEST(RestitutionGradient, MatchesFiniteDifferences) {
  const ContactBody body = BodyFromScene(SteelScene());
  struct Case {
    const char* name;
    std::map<std::string, double> params;
  };
  const Case cases[] = {
      {"linear-dashpot", {{"k", 1e7}, {"c", 20.0}}},
      {"linear-dashpot-force-zero", {{"k", 1e7}, {"c", 20.0}}},
      {"linear-dashpot-force-zero", {{"k", 1e7}, {"c", 900.0}}},  // over-damped branch
      {"walton-braun", {{"gamma", 0.4}}},
      {"walton-braun-hysteretic", {{"k1", 1e7}, {"k2", 2e7}}},
      {"hertz-tsuji", {{"e", 0.7}}},
      {"hertz-viscoelastic", {{"A", 3e-7}}},
  };
  for (const Case& c : cases) {
    auto law = Make(c.name, c.params);
    const std::vector<double> p = law->ParameterValues();
    const double v = 1.3;
    double e = 0.0;
    std::vector<double> grad(p.size());
    ASSERT_TRUE(law->RestitutionGradient(p, body, v, &e, grad.data())) << c.name;
    EXPECT_NEAR(e, *law->Restitution(p, body, v), 1e-12) << c.name;
    for (size_t i = 0; i < p.size(); ++i) {
      const double h = 1e-5 * std::abs(p[i]);
      std::vector<double> hi = p, lo = p;
      hi[i] += h;
      lo[i] -= h;
      const double fd = (*law->Restitution(hi, body, v) - *law->Restitution(lo, body, v)) / (2 * h);
      EXPECT_NEAR(grad[i], fd, 1e-6 * std::max(std::abs(fd), 1e-300) + 1e-9 / std::abs(p[i]))
          << c.name << " d e / d " << law->Parameters()[i].name;
    }
  }
}

// ------------------------------------------------------------------------ registry properties
// A law defined by an expression is created with this one (the row says which laws need one).
LawSpec ListingSpec(const std::string& name) {
  LawSpec spec;
  spec.name = name;
  if (FindLaw(name)->needs_expression) {
    spec.expression = "k * d^1.5 * (1 + alpha * v)";
    spec.parameters = {{"k", 1e10}, {"alpha", 0.3}};
  }
  return spec;
}

TEST(Registry, EveryLawIsCompleteAndConsistent) {
  const Scene scene = SteelScene();
  const ContactBody body = BodyFromScene(scene);
  ASSERT_GE(RegisteredLaws().size(), 8u);
  for (const LawInfo& info : RegisteredLaws()) {
    auto law = CreateLaw(ListingSpec(info.name), scene);
    EXPECT_EQ(law->Name(), info.name);
    EXPECT_FALSE(law->Formula().empty());
    EXPECT_FALSE(law->Source().empty());
    const auto p = law->ParameterValues();
    ASSERT_EQ(p.size(), law->Parameters().size());
    bool has_damping = false;
    for (size_t i = 0; i < p.size(); ++i) {
      const ParameterSpec& s = law->Parameters()[i];
      EXPECT_FALSE(s.unit.empty()) << info.name << " " << s.name;
      EXPECT_LE(s.lower, s.default_value) << info.name << " " << s.name;
      EXPECT_GE(s.upper, s.default_value) << info.name << " " << s.name;
      EXPECT_EQ(p[i], s.default_value);
      has_damping = has_damping || s.damping;
    }
    EXPECT_TRUE(has_damping) << info.name << " has nothing to fit";
    std::string why;
    EXPECT_TRUE(law->IsValid(p, body, &why)) << why;
    // The closed forms the row lists are exactly the closed forms the law provides.
    EXPECT_EQ(law->ClosedForms(), info.closed_forms);
    std::vector<double> g(p.size());
    double e = 0;
    EXPECT_EQ(law->Restitution(p, body, 1.0).has_value(), info.HasClosedForm("restitution"))
        << info.name;
    EXPECT_EQ(law->ContactTime(p, body, 1.0).has_value(), info.HasClosedForm("contact_time"))
        << info.name;
    EXPECT_EQ(law->SolveContact(p, body, 1.0).has_value(), info.HasClosedForm("solve_contact"))
        << info.name;
    EXPECT_EQ(law->DampingForRestitution(p, body, 0.7, 1.0).has_value(),
              info.HasClosedForm("damping_for_restitution"))
        << info.name;
    EXPECT_EQ(law->RestitutionGradient(p, body, 1.0, &e, g.data()),
              info.HasClosedForm("restitution_gradient"))
        << info.name;
    EXPECT_EQ(law->EndRule(), info.end_rule) << info.name;
    // The elastic energy is the potential of the rate-independent force (dE/dd = F(d, 0)) for
    // laws without internal state, and no law gains energy in a contact.
    // (Walton-Braun's elastic energy is what the unloading branch returns.)
    const auto dyn = law->Dynamics(p, body);
    if (law->StateSize() == 0 && !dyn->HasSwitch()) {
      const double d = 1e-5, h = 1e-9;
      const double dE =
          (dyn->ElasticEnergy(d + h, nullptr) - dyn->ElasticEnergy(d - h, nullptr)) / (2 * h);
      EXPECT_NEAR(dE, dyn->Force(d, 0.0, nullptr), 1e-5 * std::abs(dyn->Force(d, 0.0, nullptr)))
          << info.name;
    }
    const auto r = oracle::Integrate(*law, p, body, 1.0);
    EXPECT_LE(r.restitution, 1.0 + 1e-9) << info.name;
    EXPECT_GT(r.restitution, 0.0) << info.name;
  }
}

// ------------------------------------------------------------------------ hard cases
// Every law at the extremes of issue 3 (stiffness 1e3 and 1e12 in the law's units, masses 1 mg
// and 10 kg, impact speeds 1 mm/s and 10 m/s, e 0.01 and 0.999 where an inverse map exists):
// the oracle must finish in a bounded number of steps with a finite e in [0, 1] (no energy
// gained), and the closed forms must stay finite.
TEST(HardCases, ExtremeParametersStayFiniteAndDissipative) {
  for (const LawInfo& info : RegisteredLaws()) {
    for (double k : {1e3, 1e12}) {
      for (double mass : {1e-6, 10.0}) {
        for (double v : {1e-3, 10.0}) {
          LawSpec spec = ListingSpec(info.name);
          const std::string stiffness = info.name == "walton-braun-hysteretic" ? "k1" : "k";
          spec.parameters[stiffness] = k;
          if (info.name == "walton-braun-hysteretic") spec.parameters["k2"] = 1.5 * k;
          Scene scene = SteelScene();
          scene.ball.mass_kg = mass;
          scene.ball.density_kg_m3.reset();
          auto law = CreateLaw(spec, scene);
          const ContactBody body = BodyFromScene(scene);
          std::vector<std::vector<double>> params = {law->ParameterValues()};
          for (double e : {0.01, 0.999}) {
            if (auto q = law->DampingForRestitution(law->ParameterValues(), body, e, v)) {
              params.push_back(*q);
            }
          }
          for (const auto& p : params) {
            std::string why;
            if (!law->IsValid(p, body, &why)) continue;  // e.g. e = 0.01 below a law's bound
            const auto r = oracle::Integrate(*law, p, body, v);
            const std::string where = info.name + " k " + std::to_string(k) + " m " +
                                      std::to_string(mass) + " v " + std::to_string(v);
            ASSERT_FALSE(r.stuck) << where;
            EXPECT_TRUE(std::isfinite(r.restitution)) << where;
            EXPECT_GE(r.restitution, 0.0) << where;
            EXPECT_LE(r.restitution, 1.0 + 1e-9) << where;
            EXPECT_LT(r.steps, 20000) << where;
            if (auto e = law->Restitution(p, body, v)) {
              EXPECT_LT(std::abs(*e - r.restitution), 1e-6) << where;
            }
          }
        }
      }
    }
  }
}

// ------------------------------------------------------------------------ invalid input
void ExpectBadParameter(const LawSpec& spec, const std::vector<std::string>& fragments,
                        const Scene& scene = SteelScene()) {
  try {
    CreateLaw(spec, scene);
    ADD_FAILURE() << "no error for law " << spec.name;
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter) << e.what();
    const std::string msg = e.what();
    for (const std::string& f : fragments) {
      EXPECT_NE(msg.find(f), std::string::npos) << "'" << f << "' missing in: " << msg;
    }
    EXPECT_EQ(msg.find('\n'), std::string::npos) << "message must be one line: " << msg;
  }
}

TEST(InvalidInput, RegistryRejectsBadNamesAndValues) {
  ExpectBadParameter({"no-such-law", {}, ""}, {"no-such-law", "linear-dashpot", "jiang-liu"});
  ExpectBadParameter({"linear-dashpot", {{"kk", 1.0}}, ""}, {"linear-dashpot", "kk", "k, c"});
  ExpectBadParameter({"linear-dashpot", {{"k", -5.0}}, ""}, {"linear-dashpot", "k", "-5"});
  ExpectBadParameter({"linear-dashpot", {{"k", 0.0}}, ""}, {"linear-dashpot", "k"});
  ExpectBadParameter({"linear-dashpot", {{"c", -1.0}}, ""}, {"c", "-1"});
  ExpectBadParameter({"linear-dashpot", {{"c", std::nan("")}}, ""}, {"c", "nan", "finite"});
  ExpectBadParameter({"linear-dashpot", {{"k", INFINITY}}, ""}, {"k", "inf"});
  ExpectBadParameter({"walton-braun", {{"gamma", 1.0}}, ""}, {"walton-braun", "gamma", "1"});
  ExpectBadParameter({"walton-braun", {{"gamma", -0.1}}, ""}, {"gamma", "-0.1"});
  ExpectBadParameter({"walton-braun-hysteretic", {{"k1", 2e7}, {"k2", 1e7}}, ""},
                     {"walton-braun-hysteretic", "k2", "k1"});
  ExpectBadParameter({"hertz-tsuji", {{"e", 1.2}}, ""}, {"hertz-tsuji", "e", "1.2"});
  ExpectBadParameter({"hertz-tsuji", {{"e", 0.0}}, ""}, {"hertz-tsuji", "e"});
  ExpectBadParameter({"hertz-viscoelastic", {{"A", -1e-7}}, ""}, {"A", "-1e-07"});
  ExpectBadParameter({"hunt-crossley", {{"n", 0.5}}, ""}, {"hunt-crossley", "n", "0.5"});
  ExpectBadParameter({"hunt-crossley-ln", {{"v0", 0.0}}, ""}, {"v0"});
  ExpectBadParameter({"hunt-crossley-flores", {{"e", 0.0}}, ""}, {"e"});
  ExpectBadParameter({"jiang-liu", {{"tau", 0.0}}, ""}, {"jiang-liu", "tau"});
  ExpectBadParameter({"jiang-liu", {{"eta", -0.1}}, ""}, {"jiang-liu", "eta"});
}

TEST(InvalidInput, HertzStiffnessNeedsMaterialsOrAValue) {
  Scene scene = SteelScene();
  scene.ball.material = "unobtainium";
  scene.ball.youngs_modulus_pa.reset();
  scene.ball.poisson_ratio.reset();
  ExpectBadParameter({"hertz-tsuji", {}, ""}, {"hertz-tsuji", "k", "required", "unobtainium"},
                     scene);
  LawSpec given{"hertz-tsuji", {{"k", 1e9}}, ""};
  EXPECT_NO_THROW(CreateLaw(given, scene));
}

TEST(InvalidInput, BadBodyIsRejected) {
  auto law = Make("linear-dashpot", {});
  std::string why;
  EXPECT_FALSE(
      law->IsValid(law->ParameterValues(), ContactBody::BallOnRigidWall(-1.0, 0.005), &why));
  EXPECT_NE(why.find("mass"), std::string::npos) << why;
  EXPECT_FALSE(law->IsValid(law->ParameterValues(), ContactBody::BallOnRigidWall(0.01, 0.0), &why));
  EXPECT_NE(why.find("radius"), std::string::npos) << why;
  EXPECT_FALSE(law->IsValid(std::vector<double>{1e7}, BodyFromScene(SteelScene()), &why));
  EXPECT_NE(why.find("expected 2 parameters"), std::string::npos) << why;
}

TEST(InvalidInput, ExpressionErrorsNameTheExpression) {
  ExpectBadParameter({"expression", {}, ""}, {"expression", "no force expression"});
  ExpectBadParameter({"expression", {{"k", 1.0}}, "k * d^1.5 +"}, {"k * d^1.5 +", "position"});
  ExpectBadParameter({"expression", {{"k", 1.0}}, "k * d + zeta * v"}, {"zeta"});
  ExpectBadParameter({"expression", {{"d", 1.0}}, "d"}, {"'d'", "reserved"});
  ExpectBadParameter({"expression", {{"k", std::nan("")}}, "k * d"}, {"k", "finite"});
  ExpectBadParameter({"expression", {{"k", 1.0}}, "k * d * (1 + v"}, {"k * d * (1 + v"});
}

// ------------------------------------------------------------------------ CLI: bouncecal laws
struct CommandResult {
  int exit_code;
  std::string out, err;
};

CommandResult RunCli(const std::string& args) {
  const testing_util::CommandResult r = testing_util::RunCommand(BOUNCECAL_BINARY, args);
  return {r.exit_code, r.out, r.err};
}

TEST(LawsCli, JsonListsEveryRegisteredLawWithStableKeys) {
  const CommandResult r = RunCli("laws --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = nlohmann::json::parse(r.out);
  ASSERT_EQ(j.at("laws").size(), RegisteredLaws().size());
  size_t i = 0;
  for (const LawInfo& info : RegisteredLaws()) {
    const nlohmann::json& law = j["laws"][i++];
    EXPECT_EQ(law.at("name"), info.name);
    for (const char* key : {"formula", "source", "end_rule", "parameters", "closed_forms"}) {
      EXPECT_TRUE(law.contains(key)) << info.name << " lacks " << key;
    }
    for (const nlohmann::json& p : law.at("parameters")) {
      for (const char* key : {"value", "unit", "lower", "upper", "damping", "description"}) {
        EXPECT_TRUE(p.contains(key)) << info.name << " parameter lacks " << key;
      }
    }
  }
  EXPECT_EQ(j["laws"][0]["closed_forms"][0], "restitution");
}

TEST(LawsCli, OneLawHumanAndUnknownLaw) {
  const CommandResult one = RunCli("laws walton-braun");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_NE(one.out.find("gamma"), std::string::npos);
  EXPECT_EQ(one.out.find("hertz-tsuji"), std::string::npos);
  const CommandResult bad = RunCli("laws no-such-law");
  EXPECT_EQ(bad.exit_code, static_cast<int>(ErrorCode::kBadParameter));
  EXPECT_TRUE(bad.out.empty());
  EXPECT_NE(bad.err.find("no-such-law"), std::string::npos);
}

// Printed last: the measured agreement of closed forms with the oracle (for the report).
TEST(Summary, ZZPrintWorstAgreement) {
  for (const auto& [name, w] : Worst()) {
    std::printf("[ measured ] %-28s max rel. error vs oracle: e %.2e  t_c %.2e\n", name.c_str(),
                w.first, w.second);
  }
}

}  // namespace
}  // namespace bouncecal
