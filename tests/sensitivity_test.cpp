// SimulateWithSensitivities: the derivatives of every impact's time and arrival speed with
// respect to the law's parameters and the first impact speed, checked against central
// differences of Simulate (tight tolerance, so the differences are accurate), with every scene
// effect on: quadratic drag, buoyancy, a compliant plate (surface compliance), and the contact
// durations (always part of the simulated impact times). The fast path must give the same
// impacts as Simulate.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {
namespace {

Scene EveryEffect(const std::string& law) {
  Scene s;  // 1 cm steel ball, 0.2 m
  s.law.name = law;
  s.effects.drag = DragModel::kQuadratic;
  s.effects.buoyancy = true;
  s.effects.contact_duration = true;
  s.effects.surface_compliance = true;
  s.surface.kind = Surface::Kind::kSpringMass;
  s.surface.mass_kg = 0.5;
  s.surface.stiffness_n_m = 1e7;
  s.surface.damping_n_s_m = 20.0;
  s.drop.height_m.reset();
  s.drop.impact_speed_m_s = 1.5;
  s.limits.max_impacts = 8;
  return s;
}

struct Case {
  std::string law;
  std::map<std::string, double> params;
};

// Central differences of Simulate in theta_j (a parameter, or the first impact speed).
std::vector<std::vector<double>> Differences(const Scene& scene, const ContactLaw& law,
                                             const std::vector<double>& p,
                                             const SimulatorOptions& o, size_t j, bool times) {
  const double x = j < p.size() ? p[j] : *scene.drop.impact_speed_m_s;
  const double h = 1e-5 * std::abs(x);
  auto run = [&](double sign) {
    Scene s = scene;
    std::vector<double> q = p;
    if (j < p.size()) {
      q[j] += sign * h;
    } else {
      s.drop.impact_speed_m_s = x + sign * h;
    }
    return Simulate(s, law, q, o);
  };
  const Simulation hi = run(+1.0), lo = run(-1.0);
  std::vector<std::vector<double>> out;
  for (size_t k = 0; k < std::min(hi.impacts.size(), lo.impacts.size()); ++k) {
    const double a = times ? hi.impacts[k].time_s : hi.impacts[k].v_in_m_s;
    const double b = times ? lo.impacts[k].time_s : lo.impacts[k].v_in_m_s;
    out.push_back({(a - b) / (2 * h)});
  }
  return out;
}

TEST(Sensitivities, MatchCentralDifferencesWithEveryEffect) {
  const Case cases[] = {
      {"hertz-tsuji", {{"e", 0.8}}},
      {"hertz-viscoelastic", {{"A", 3e-7}}},
      {"linear-dashpot", {}},
      {"linear-dashpot-force-zero", {}},
      {"walton-braun", {{"gamma", 0.3}}},
      {"walton-braun-hysteretic", {}},
      {"hunt-crossley-ln", {}},
      {"jiang-liu", {{"eta", 20.0}}},
  };
  SimulatorOptions o;
  o.rel_tolerance = 1e-12;  // the differences then carry ~1e-7 relative error (h = 1e-5)
  o.abs_tolerance = 1e-14;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.law);
    Scene scene = EveryEffect(c.law);
    scene.law.parameters = c.params;
    const auto law = CreateLaw(scene.law, scene);
    const std::vector<double> p = law->ParameterValues();
    SimulationSensitivities sens;
    const Simulation sim = SimulateWithSensitivities(scene, *law, p, o, &sens);
    ASSERT_EQ(sens.time_s.size(), sim.impacts.size());
    ASSERT_EQ(sens.names.size(), p.size() + 1);
    EXPECT_EQ(sens.names.back(), "v_first_m_s");
    for (size_t j = 0; j <= p.size(); ++j) {
      SCOPED_TRACE("d / d " + sens.names[j]);
      const double x = j < p.size() ? p[j] : *scene.drop.impact_speed_m_s;
      if (x == 0.0) continue;
      for (bool times : {true, false}) {
        const auto fd = Differences(scene, *law, p, o, j, times);
        ASSERT_GE(fd.size(), 4u);
        for (size_t k = 1; k < std::min(fd.size(), sim.impacts.size()); ++k) {
          const double analytic = times ? sens.time_s[k][j] : sens.v_in_m_s[k][j];
          // Scale of the derivative: the quantity's own size over theta's (relative units).
          const double scale =
              (times ? sim.impacts[k].time_s : sim.impacts[k].v_in_m_s) / std::abs(x);
          // Measured agreement ~1e-7 of scale (central differences, h = 1e-5 relative, on a
          // simulator at rtol 1e-12); bound 1e-5.
          EXPECT_NEAR(analytic, fd[k][0], 1e-5 * scale + 1e-4 * std::abs(fd[k][0]))
              << (times ? "time" : "v_in") << " of impact " << k;
        }
      }
    }
  }
}

TEST(Sensitivities, GiveTheImpactsOfSimulate) {
  for (const LawInfo& info : RegisteredLaws()) {
    if (info.needs_expression) continue;
    SCOPED_TRACE(info.name);
    Scene scene = EveryEffect(info.name);
    scene.effects.surface_compliance = false;
    scene.surface.kind = Surface::Kind::kRigid;
    scene.limits.max_impacts = 20;
    const auto law = CreateLaw(scene.law, scene);
    const std::vector<double> p = law->ParameterValues();
    SimulationSensitivities sens;
    const Simulation a = Simulate(scene, *law, p, {});
    const Simulation b = SimulateWithSensitivities(scene, *law, p, {}, &sens);
    ASSERT_EQ(a.impacts.size(), b.impacts.size());
    EXPECT_EQ(a.stop_reason, b.stop_reason);
    for (size_t k = 0; k < a.impacts.size(); ++k) {
      // The same step sequence (error control on the values only): the same numbers.
      EXPECT_EQ(a.impacts[k].time_s, b.impacts[k].time_s) << k;
      EXPECT_EQ(a.impacts[k].v_out_m_s, b.impacts[k].v_out_m_s) << k;
      EXPECT_EQ(a.impacts[k].steps, b.impacts[k].steps) << k;
    }
  }
}

TEST(Sensitivities, FirstImpactHasTheTrivialDerivatives) {
  Scene scene = EveryEffect("hertz-tsuji");
  const auto law = CreateLaw(scene.law, scene);
  SimulationSensitivities sens;
  SimulateWithSensitivities(scene, *law, law->ParameterValues(), {}, &sens);
  ASSERT_FALSE(sens.time_s.empty());
  const size_t v = sens.names.size() - 1;
  for (size_t j = 0; j <= v; ++j) EXPECT_EQ(sens.time_s[0][j], 0.0);  // first_impact_time_s held
  EXPECT_EQ(sens.v_in_m_s[0][v], 1.0);
  EXPECT_EQ(sens.v_in_m_s[0][0], 0.0);
}

TEST(Sensitivities, TooManyParametersIsAClearError) {
  Scene scene;
  scene.law.name = "expression";
  scene.law.expression = "k * d + a + b + c + e + f + g + h";
  scene.law.parameters = {{"k", 1e7}, {"a", 0}, {"b", 0}, {"c", 0},
                          {"e", 0},   {"f", 0}, {"g", 0}, {"h", 0}};
  const auto law = CreateLaw(scene.law, scene);
  try {
    SimulationSensitivities sens;
    SimulateWithSensitivities(scene, *law, law->ParameterValues(), {}, &sens);
    FAIL() << "8 parameters accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    EXPECT_NE(std::string(e.what()).find("at most 7 parameters"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace bouncecal
