// The Jiang-Liu thermodynamic contact law (seed 000, docs/physics.md §4): energy balance of eq. 17
// (mechanical + relaxation + heat conserved), e falling with speed (paper Fig. 4), the
// near-elastic 1 cm steel ball of the paper's prefactors, and the dissipative branch leaving
// w_r = 0 without a seed. The heat integral is computed here, independently of the law.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/contact_dynamics.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "law_oracle.hpp"
#include "physics/laws/jiang_liu.hpp"

namespace bouncecal {
namespace {

std::unique_ptr<ContactLaw> MakeJL(std::map<std::string, double> params,
                                   const Scene& scene = Scene{}) {
  LawSpec spec;
  spec.name = "jiang-liu";
  spec.parameters = std::move(params);
  return CreateLaw(spec, scene);
}

struct Balance {
  oracle::Result r;
  double initial_j, kinetic_out_j, relaxation_j, heat_j;
};

// One contact with the heat of eq. 33 integrated alongside: R = w_r / tau, w_r = s^(4/3).
Balance RunWithHeat(const ContactLaw& law, const std::vector<double>& p, const ContactBody& body,
                    double v) {
  const double tau = laws::JiangLiuTau(p, body);
  oracle::Options opt;
  opt.extra_rate = [tau](double, double, const double* state) {
    return std::pow(std::max(state[0], 0.0), 4.0 / 3.0) / tau;
  };
  Balance b;
  b.r = oracle::Integrate(law, p, body, v, opt);
  b.initial_j = 0.5 * body.mass_kg * v * v;
  b.kinetic_out_j = 0.5 * body.mass_kg * b.r.v_out_m_s * b.r.v_out_m_s;
  b.relaxation_j = law.Dynamics(p, body)->InternalEnergy(b.r.end_state.data());
  b.heat_j = b.r.extra;
  return b;
}

TEST(JiangLiu, EnergyBalanceOfEq17) {
  const ContactBody body = BodyFromScene(Scene{});
  for (double eta : {0.1, 1.0, 10.0}) {
    auto law = MakeJL({{"eta", eta}});
    const auto p = law->ParameterValues();
    for (double v : {0.1, 1.0, 10.0}) {
      const Balance b = RunWithHeat(*law, p, body, v);
      ASSERT_FALSE(b.r.stuck);
      const double total = b.kinetic_out_j + b.relaxation_j + b.heat_j;  // elastic = 0 at d = 0
      EXPECT_NEAR(total, b.initial_j, 1e-8 * b.initial_j) << "eta " << eta << " v " << v;
      EXPECT_GT(b.heat_j, 0.0);
      EXPECT_GT(b.relaxation_j, 0.0);  // left the w_r = 0 branch without a seed
      if (eta == 0.1 && v == 1.0) {
        std::printf(
            "[ measured ] jiang-liu eta 0.1, v 1 m/s: e = %.6f, energy balance error "
            "%.2e of w0 (w_r left %.2e, heat %.2e of w0)\n",
            b.r.restitution, (total - b.initial_j) / b.initial_j, b.relaxation_j / b.initial_j,
            b.heat_j / b.initial_j);
      }
    }
  }
}

TEST(JiangLiu, ViscousForceOnlyDissipates) {
  // d(KE + W_e)/dt = -F d' + (dW_e/dd) d' = -eta_relax d'^2 <= 0 at every state (eq. 17):
  // checked with the law's own force and elastic energy, loading and unloading.
  const ContactBody body = BodyFromScene(Scene{});
  auto law = MakeJL({{"eta", 3.0}});
  const auto dyn = law->Dynamics(law->ParameterValues(), body);
  for (double d : {1e-7, 1e-6, 5e-6}) {
    for (double rate : {-2.0, -0.5, 0.5, 2.0}) {
      const double s = 1e-6;
      const double f = dyn->Force(d, rate, &s);
      const double h = 1e-12;
      const double dwe = (dyn->ElasticEnergy(d + h, &s) - dyn->ElasticEnergy(d - h, &s)) / (2 * h);
      // power into the ball: -F rate; power into the spring: dwe * rate; the difference is the
      // viscous power -eta rate^2 <= 0.
      EXPECT_LT(-f * rate + dwe * rate, 0.0) << d << " " << rate;
    }
  }
}

TEST(JiangLiu, RestitutionFallsWithSpeedAsInFig4) {
  const ContactBody body = BodyFromScene(Scene{});
  for (double eta : {0.1, 1.0}) {
    auto law = MakeJL({{"eta", eta}});
    const auto p = law->ParameterValues();
    double previous = 1.0;
    for (double v : {0.03, 0.1, 0.3, 1.0, 3.0, 10.0}) {
      const double e = oracle::Integrate(*law, p, body, v).restitution;
      EXPECT_LT(e, previous) << "eta " << eta << " v " << v;
      previous = e;
    }
  }
}

TEST(JiangLiu, PaperPrefactorsGiveANearlyElasticSteelBall) {
  // docs/physics.md §4: with the example prefactor 0.1 a 1 cm steel ball has e ~ 0.999 at 1 m/s.
  const ContactBody body = BodyFromScene(Scene{});
  auto law = MakeJL({});
  const auto p = law->ParameterValues();
  EXPECT_EQ(p[1], 0.1);
  EXPECT_EQ(p[2], 0.06);
  const double e = oracle::Integrate(*law, p, body, 1.0).restitution;
  EXPECT_GT(e, 0.998);
  EXPECT_LT(e, 0.9999);
  // More damping prefactor, less restitution (what a calibration exploits).
  double previous = e;
  for (double eta : {1.0, 10.0, 100.0}) {
    auto damped = MakeJL({{"eta", eta}});
    const double ed = oracle::Integrate(*damped, damped->ParameterValues(), body, 1.0).restitution;
    EXPECT_LT(ed, previous) << eta;
    previous = ed;
  }
}

TEST(JiangLiu, RelaxationTimeIsTinyComparedWithContact) {
  // docs/physics.md §4: tau ~ t_c / 190 for steel (stiff relaxation) with the paper's prefactor.
  const ContactBody body = BodyFromScene(Scene{});
  auto law = MakeJL({});
  const auto p = law->ParameterValues();
  const double tc = oracle::Integrate(*law, p, body, 1.0).contact_time_s;
  const double tau = laws::JiangLiuTau(p, body);
  EXPECT_GT(tc / tau, 50.0);
  EXPECT_LT(tc / tau, 1000.0);
  std::printf(
      "[ measured ] jiang-liu 1 cm steel, 1 m/s: t_c = %.3g s, tau = %.3g s, t_c/tau = %.0f\n", tc,
      tau, tc / tau);
}

TEST(JiangLiu, InvalidInput) {
  for (auto [key, value] : std::vector<std::pair<std::string, double>>{
           {"tau", 0.0}, {"tau", -1.0}, {"eta", -0.1}, {"k", -1e9}, {"k", NAN}, {"w_r", 1.0}}) {
    try {
      MakeJL({{key, value}});
      ADD_FAILURE() << key << " = " << value << " accepted";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
      EXPECT_NE(std::string(e.what()).find(key), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace bouncecal
