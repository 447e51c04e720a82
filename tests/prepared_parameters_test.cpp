// ContactLaw::Dynamics prepares a law for one parameter vector and body (per-contact constants
// computed once: Hertz-Tsuji's eta = alpha(e) sqrt(m* k), Jiang-Liu's a and tau). The prepared
// dynamics must follow p and the body (no stale constants), give the law's formula, and carry
// exact derivatives in forward-sensitivity arithmetic (the Jacobians the simulator's
// sensitivities are built from): checked against central differences for every law.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "physics/laws/jiang_liu.hpp"

namespace bouncecal {
namespace {

LawSpec SpecFor(const LawInfo& info) {
  LawSpec spec;
  spec.name = info.name;
  if (info.needs_expression) {
    spec.expression = "k * d^1.5 * (1 + alpha * v)";
    spec.parameters = {{"k", 1e10}, {"alpha", 0.3}};
  }
  return spec;
}

// The sensitivity-arithmetic force and state rate have the double values and the derivatives
// of central differences, in delta, delta', the state and every parameter.
TEST(PreparedParameters, EveryLawsJetDerivativesMatchCentralDifferences) {
  const Scene scene;  // seed 002: 1 cm steel ball on copper
  const ContactBody body = BodyFromScene(scene);
  for (const LawInfo& info : RegisteredLaws()) {
    SCOPED_TRACE(info.name);
    const auto law = CreateLaw(SpecFor(info), scene);
    const std::vector<double> p = law->ParameterValues();
    const auto dyn = law->Dynamics(p, body);
    const int ns = dyn->StateSize(), np = static_cast<int>(p.size());
    ASSERT_LE(np + 2 + ns, kSensitivityDirections + 2);
    // Inputs: a loading state of a 1 m/s contact (overlap ~1e-5 m), law state at a typical size.
    const double delta = 4e-6, rate = 0.6;
    std::vector<double> state(static_cast<size_t>(ns), 0.0);
    for (int i = 0; i < ns; ++i) state[i] = 0.5 * dyn->StateScale(i, 3e-5, 2e-3) * 1e-3;
    if (info.name == "walton-braun-hysteretic") state[0] = 5e-6;  // delta_max > delta
    for (bool branch : {true, false}) {
      // Seeds: delta -> direction np, rate -> np + 1 when room, else checked separately.
      using Jet = SensitivityJet;
      const int id = np, ir = np + 1;
      ASSERT_LT(ir, kSensitivityDirections);
      Jet dj(delta), rj(rate);
      dj.v[id] = 1.0;
      rj.v[ir] = 1.0;
      std::vector<Jet> sj(static_cast<size_t>(ns));
      for (int i = 0; i < ns; ++i) sj[i] = Jet(state[i]);
      const Jet f = dyn->ForceOnBranch(dj, rj, sj.data(), branch);
      const double f0 = dyn->ForceOnBranch(delta, rate, state.data(), branch);
      EXPECT_EQ(f.a, f0);
      auto expect_near = [&](double analytic, double fd, const std::string& what) {
        EXPECT_NEAR(analytic, fd, 1e-6 * std::abs(fd) + 1e-9 * std::abs(f0) / delta) << what;
      };
      const double hd = 1e-6 * delta, hr = 1e-6 * rate;
      expect_near(f.v[id],
                  (dyn->ForceOnBranch(delta + hd, rate, state.data(), branch) -
                   dyn->ForceOnBranch(delta - hd, rate, state.data(), branch)) /
                      (2 * hd),
                  "dF/d delta");
      expect_near(f.v[ir] * rate,
                  (dyn->ForceOnBranch(delta, rate + hr, state.data(), branch) -
                   dyn->ForceOnBranch(delta, rate - hr, state.data(), branch)) /
                      (2 * hr) * rate,
                  "dF/d rate");
      for (int j = 0; j < np; ++j) {
        std::vector<double> hi = p, lo = p;
        const double h = 1e-6 * std::abs(p[j]);
        if (h == 0.0) continue;
        hi[j] += h;
        lo[j] -= h;
        const double fd =
            (law->Dynamics(hi, body)->ForceOnBranch(delta, rate, state.data(), branch) -
             law->Dynamics(lo, body)->ForceOnBranch(delta, rate, state.data(), branch)) /
            (2 * h);
        expect_near(f.v[j] * p[j], fd * p[j], "dF/dp_" + law->Parameters()[j].name);
      }
      if (ns > 0) {
        std::vector<Jet> out(static_cast<size_t>(ns));
        dyn->StateRate(dj, rj, sj.data(), out.data());
        std::vector<double> r0(static_cast<size_t>(ns)), r1(r0), r2(r0);
        dyn->StateRate(delta, rate, state.data(), r0.data());
        EXPECT_EQ(out[0].a, r0[0]);
        dyn->StateRate(delta, rate + hr, state.data(), r1.data());
        dyn->StateRate(delta, rate - hr, state.data(), r2.data());
        EXPECT_NEAR(out[0].v[ir], (r1[0] - r2[0]) / (2 * hr),
                    1e-6 * std::abs(r1[0] - r2[0]) / (2 * hr) + 1e-12)
            << "d rate / d delta'";
      }
    }
  }
}

TEST(PreparedParameters, HertzTsujiDampingFollowsEAndBody) {
  const Scene scene;
  const ContactBody body = BodyFromScene(scene);
  LawSpec spec;
  spec.name = "hertz-tsuji";
  const auto law = CreateLaw(spec, scene);
  std::vector<double> p = law->ParameterValues();
  const int ie = law->ParameterIndex("e");
  ASSERT_GE(ie, 0);
  // The damping force alone: F(delta, v) - F(delta, 0) = eta delta^(1/4) v.
  auto eta = [&](const std::vector<double>& q, const ContactBody& b) {
    const auto dyn = law->Dynamics(q, b);
    const double d = 1e-6;
    return (dyn->Force(d, 1.0, nullptr) - dyn->Force(d, 0.0, nullptr)) / std::pow(d, 0.25);
  };
  p[static_cast<size_t>(ie)] = 0.8;
  const double eta_08 = eta(p, body);
  p[static_cast<size_t>(ie)] = 0.3;
  const double eta_03 = eta(p, body);
  EXPECT_GT(eta_03, eta_08);  // lower e: more damping
  // eta = alpha sqrt(m* k): four times the mass, twice eta.
  ContactBody heavy = body;
  heavy.mass_kg *= 4.0;
  EXPECT_NEAR(eta(p, heavy) / eta_03, 2.0, 1e-9);
}

TEST(PreparedParameters, JiangLiuConstantsAreThoseOfEqs37And39) {
  const Scene scene;
  const ContactBody body = BodyFromScene(scene);
  LawSpec spec;
  spec.name = "jiang-liu";
  spec.parameters = {{"eta", 2.0}, {"tau", 0.1}};
  const auto law = CreateLaw(spec, scene);
  const std::vector<double> p = law->ParameterValues();
  const auto dyn = law->Dynamics(p, body);
  const double a = laws::JiangLiuA(p, body), tau = laws::JiangLiuTau(p, body);
  const double d = 3e-6, v = -0.4, s = 2e-4;
  const double theta = laws::JiangLiuTheta(d / body.ball_diameter_m);
  // F = k d^1.5 + a s^(1/3) Theta v;  ds/dt = 3/4 (a Theta v^2 - s / tau)   (law's header)
  EXPECT_NEAR(dyn->Force(d, v, &s), p[0] * std::pow(d, 1.5) + a * std::cbrt(s) * theta * v,
              1e-12 * p[0] * std::pow(d, 1.5));
  double rate = 0.0;
  dyn->StateRate(d, v, &s, &rate);
  EXPECT_NEAR(rate, 0.75 * (a * theta * v * v - s / tau), 1e-12 * s / tau);
}

}  // namespace
}  // namespace bouncecal
