// Contact-law tests: closed forms against the independent integrator (tests/law_oracle.hpp),
// the seed paper's relation, inverse maps, gradients, and every invalid-input case.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bouncecal/error.hpp"
#include "bouncecal/law_registry.hpp"
#include "law_oracle.hpp"

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
  EXPECT_NEAR(e_force, 0.808, 0.001);  // PHYSICS.md §3
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
  // PHYSICS.md §1: the exact inverse of eta = 0.58 is gamma = eta/(2 - eta) = 0.408.
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

}  // namespace
}  // namespace bouncecal
