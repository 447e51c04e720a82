// ContactLaw::PrepareParameters: the integrator passes [p..., prepared...] to the dynamics
// functions; a law must give the same force (and switch, state rate) for the extended vector as
// for plain p, and the prepared constants must follow p and the body (no stale values).
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

std::vector<double> Extended(const ContactLaw& law, const std::vector<double>& p,
                             const ContactBody& body) {
  std::vector<double> ext = p;
  ext.resize(p.size() + static_cast<size_t>(law.PreparedSize()));
  law.PrepareParameters(p, body, ext.data() + p.size());
  return ext;
}

TEST(PreparedParameters, EveryLawGivesTheSameDynamicsWithPreparedConstants) {
  const Scene scene;  // seed 002: 1 cm steel ball on copper
  const ContactBody body = BodyFromScene(scene);
  int prepared_laws = 0;
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.name == "expression") continue;  // needs a user expression
    LawSpec spec;
    spec.name = info.name;
    const auto law = CreateLaw(spec, scene);
    if (law->PreparedSize() > 0) ++prepared_laws;
    const std::vector<double> p = law->ParameterValues();
    const std::vector<double> ext = Extended(*law, p, body);
    std::vector<double> state(static_cast<size_t>(law->StateSize()) + 1, 0.0);
    law->InitialState(p, body, 1.0, state.data());
    for (double delta : {1e-9, 1e-6, 2e-5}) {
      for (double rate : {1.5, 0.0, -0.7}) {
        const double f = law->Force(p, body, delta, rate, state.data());
        EXPECT_EQ(law->Force(ext, body, delta, rate, state.data()), f)
            << info.name << " delta " << delta << " rate " << rate;
        for (bool branch : {true, false}) {
          EXPECT_EQ(law->ForceOnBranch(ext, body, delta, rate, state.data(), branch),
                    law->ForceOnBranch(p, body, delta, rate, state.data(), branch))
              << info.name;
        }
        EXPECT_EQ(law->SwitchFunction(ext, body, delta, rate, state.data()),
                  law->SwitchFunction(p, body, delta, rate, state.data()))
            << info.name;
      }
    }
  }
  EXPECT_GE(prepared_laws, 1);  // hertz-tsuji prepares eta = alpha(e) sqrt(m* k)
}

TEST(PreparedParameters, HertzTsujiPreparedDampingFollowsEAndBody) {
  const Scene scene;
  const ContactBody body = BodyFromScene(scene);
  LawSpec spec;
  spec.name = "hertz-tsuji";
  const auto law = CreateLaw(spec, scene);
  ASSERT_EQ(law->PreparedSize(), 1);
  std::vector<double> p = law->ParameterValues();
  const int ie = law->ParameterIndex("e");
  ASSERT_GE(ie, 0);
  p[static_cast<size_t>(ie)] = 0.8;
  const double eta_08 = Extended(*law, p, body).back();
  p[static_cast<size_t>(ie)] = 0.3;
  const std::vector<double> ext_03 = Extended(*law, p, body);
  EXPECT_GT(ext_03.back(), eta_08);  // lower e: more damping
  // The damping force alone (delta' only) scales with eta: F(ext) == F(p) for the new e.
  EXPECT_EQ(law->Force(ext_03, body, 1e-6, 1.0, nullptr), law->Force(p, body, 1e-6, 1.0, nullptr));
  // eta = alpha sqrt(m* k): four times the mass, twice eta.
  ContactBody heavy = body;
  heavy.mass_kg *= 4.0;
  EXPECT_NEAR(Extended(*law, p, heavy).back() / ext_03.back(), 2.0, 1e-12);
}

TEST(PreparedParameters, OneHertzTsujiLawSimulatesSuccessiveParameterVectorsExactly) {
  // The fitter varies p between simulations with the same law object: each simulation must use
  // its own e (the first impact's restitution equals e up to gravity during the ~50 us contact).
  Scene scene;
  scene.law.name = "hertz-tsuji";
  scene.limits.max_impacts = 3;
  const auto law = CreateLaw(scene.law, scene);
  std::vector<double> p = law->ParameterValues();
  const size_t ie = static_cast<size_t>(law->ParameterIndex("e"));
  SimulatorOptions o;
  o.use_closed_form = false;
  for (double e : {0.9, 0.4, 0.9, 0.6}) {
    p[ie] = e;
    const Simulation sim = Simulate(scene, *law, p, o);
    ASSERT_FALSE(sim.impacts.empty());
    const SimImpact& first = sim.impacts.front();
    EXPECT_NEAR(first.v_out_m_s / first.v_in_m_s, e, 1e-3) << "e = " << e;
  }
}

}  // namespace
}  // namespace bouncecal
