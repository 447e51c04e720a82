// Calibration tests: round trips (simulate with known parameters -> impact times -> fit),
// noisy pulls over fixed seeds, cross-law e(v) recovery, the audio round trip (render ->
// detect -> fit), joint fits, identifiability, and every failure path.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {
namespace {

bool Registered(const std::string& name) {
  for (const auto& l : RegisteredLaws()) {
    if (l.name == name) return true;
  }
  return false;
}

Scene SteelScene(const std::string& law, std::map<std::string, double> params) {
  Scene s;  // seed 002: 1 cm steel ball, 0.2 m, copper dish
  s.law.name = law;
  s.law.parameters = std::move(params);
  return s;
}

// Simulated truth of a scene: the first n impacts, shifted to start at t_offset, with Gaussian
// timing noise of sigma_s (seeded) and that sigma reported.
Sequence MeasuredFromSimulation(const Scene& scene, int n, double sigma_s, std::uint64_t seed,
                                double t_offset = 1.0, Simulation* sim_out = nullptr) {
  auto law = CreateLaw(scene.law, scene);
  Scene s = scene;
  s.limits.max_impacts = n;
  SimulatorOptions so;
  so.rel_tolerance = 1e-11;
  Simulation sim = Simulate(s, *law, law->ParameterValues(), so);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> noise(0.0, 1.0);
  Sequence seq;
  for (const auto& i : sim.impacts) {
    Impact imp;
    imp.time_s = t_offset + i.time_s + (seed ? sigma_s * noise(rng) : 0.0);
    imp.sigma_s = sigma_s;
    seq.impacts.push_back(imp);
  }
  if (sim_out) *sim_out = sim;
  return seq;
}

double FittedValue(const Calibration& c, const std::string& name) {
  for (const auto& p : c.parameters) {
    if (p.name == name) return p.value;
  }
  ADD_FAILURE() << "no parameter " << name;
  return std::nan("");
}

const FittedParameter& Param(const Calibration& c, const std::string& name) {
  for (const auto& p : c.parameters) {
    if (p.name == name) return p;
  }
  throw std::runtime_error("no parameter " + name);
}

// Start the fit away from the truth: the scene handed to Calibrate holds other damping values
// and the inverse-map seed is switched off, so the optimiser must do the work.
struct RoundTripCase {
  std::string law;
  std::map<std::string, double> truth;  // damping parameters (+ held ones)
  std::map<std::string, double> start;  // start values of the damping parameters
  std::string damping;                  // the parameter checked
};

std::vector<RoundTripCase> Cases() {
  return {
      {"walton-braun", {{"gamma", 0.408}}, {{"gamma", 0.2}}, "gamma"},
      {"linear-dashpot", {{"c", 0.0}}, {}, "c"},  // c filled in below from e = 0.75
      {"hertz-tsuji", {}, {}, ""},
      {"hertz-viscoelastic", {}, {}, ""},
  };
}

// Damping parameter values for laws whose natural scale depends on the body: from the law's
// own inverse map at e = 0.75 (truth) and 0.9 (start) at 1 m/s.
void FillFromInverseMap(RoundTripCase* c, const Scene& scene) {
  auto law = CreateLaw(scene.law, scene);
  const ContactBody body = BodyFromScene(scene);
  auto truth = law->DampingForRestitution(law->ParameterValues(), body, 0.75, 1.0);
  auto start = law->DampingForRestitution(law->ParameterValues(), body, 0.9, 1.0);
  ASSERT_TRUE(truth && start) << c->law << " has no inverse map";
  const auto& specs = law->Parameters();
  for (size_t i = 0; i < specs.size(); ++i) {
    if (!specs[i].damping) continue;
    c->truth[specs[i].name] = (*truth)[i];
    c->start[specs[i].name] = (*start)[i];
    if (c->damping.empty()) c->damping = specs[i].name;
  }
}

class RoundTrip : public ::testing::TestWithParam<int> {};

TEST_P(RoundTrip, CleanImpactTimesRecoverDampingWithinOnePercent) {
  RoundTripCase rc = Cases()[static_cast<size_t>(GetParam())];
  if (!Registered(rc.law)) GTEST_SKIP() << rc.law << " is not registered yet";
  Scene truth = SteelScene(rc.law, {});
  if (rc.law != "walton-braun") {
    FillFromInverseMap(&rc, truth);
    if (HasFatalFailure()) return;
  }
  truth.law.parameters = rc.truth;
  const Sequence seq = MeasuredFromSimulation(truth, 14, 2e-6, 0);
  ASSERT_GE(seq.impacts.size(), 10u);
  for (FitStrategy strategy : {FitStrategy::kTrajectory, FitStrategy::kRestitution}) {
    Scene start = truth;
    start.law.parameters = rc.start;
    CalibrationOptions o;
    o.strategy = strategy;
    o.seed_from_inverse_map = false;
    const Calibration c = Calibrate({{"sim", seq}}, start, o);
    const double want = rc.truth.at(rc.damping);
    const double got = FittedValue(c, rc.damping);
    SCOPED_TRACE(rc.law + " " + FitStrategyName(strategy) + ": " + c.BriefReport());
    EXPECT_EQ(c.outcome, FitOutcome::kConverged) << c.message;
    EXPECT_NEAR(got, want, 0.01 * std::abs(want));
    EXPECT_TRUE(std::isfinite(Param(c, rc.damping).sigma));
    if (strategy == FitStrategy::kTrajectory) {
      // Clean times: residuals at the simulator's own precision (well under a microsecond).
      EXPECT_LT(c.rms_residual, 1e-6);
      EXPECT_NEAR(c.recordings[0].time_origin_s, 1.0, 1e-6);
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Laws, RoundTrip, ::testing::Range(0, 4));

TEST(Calibrate, NoisyTimesGivePullsConsistentWithReportedSigma) {
  // walton-braun, gamma = 0.408, 20 us Gaussian timing noise, 10 fixed seeds.
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.408}});
  std::vector<double> pulls;
  for (std::uint64_t seed = 1; seed <= 10; ++seed) {
    const Sequence seq = MeasuredFromSimulation(truth, 14, 20e-6, seed);
    CalibrationOptions o;
    o.loss = RobustLoss::kNone;  // Gaussian noise: plain least squares
    const Calibration c = Calibrate({{"noisy", seq}}, SteelScene("walton-braun", {}), o);
    const auto& g = Param(c, "gamma");
    ASSERT_TRUE(std::isfinite(g.sigma) && g.sigma > 0.0) << c.FullReport();
    pulls.push_back((g.value - 0.408) / g.sigma);
    EXPECT_LT(std::abs(pulls.back()), 3.0) << "seed " << seed << ": " << c.BriefReport();
  }
  double ss = 0.0;
  for (double p : pulls) ss += p * p;
  const double rms = std::sqrt(ss / static_cast<double>(pulls.size()));
  // With 10 draws the RMS of unit-normal pulls lies in [0.55, 1.45] with > 99 % probability.
  EXPECT_GT(rms, 0.55);
  EXPECT_LT(rms, 1.45);
}

TEST(Calibrate, AutomaticAndNumericDerivativesReachTheSameOptimum) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.3}});
  const Sequence seq = MeasuredFromSimulation(truth, 12, 10e-6, 7);
  CalibrationOptions a, n;
  n.derivatives = DerivativeMode::kNumeric;
  const Calibration ca = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), a);
  const Calibration cn = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), n);
  EXPECT_TRUE(ca.analytic_jacobian);
  EXPECT_FALSE(cn.analytic_jacobian);
  const auto& ga = Param(ca, "gamma");
  const auto& gn = Param(cn, "gamma");
  EXPECT_NEAR(ga.value, gn.value, 0.05 * ga.sigma);
  EXPECT_NEAR(ga.sigma, gn.sigma, 0.05 * ga.sigma);
}

TEST(Calibrate, JointFitSharesTheLawAndKeepsPerFileNuisances) {
  Scene a = SteelScene("walton-braun", {{"gamma", 0.25}});
  Scene b = a;
  b.drop.height_m = 0.05;
  const Sequence sa = MeasuredFromSimulation(a, 12, 5e-6, 3, 0.7);
  const Sequence sb = MeasuredFromSimulation(b, 10, 5e-6, 4, 2.3);
  const Calibration c = Calibrate({{"a", sa}, {"b", sb}}, SteelScene("walton-braun", {}), {});
  ASSERT_EQ(c.recordings.size(), 2u);
  const auto& g = Param(c, "gamma");
  EXPECT_NEAR(g.value, 0.25, 3 * g.sigma + 1e-4);
  const double g0 = 9.8;
  EXPECT_NEAR(c.recordings[0].impact_speed_m_s, std::sqrt(2 * g0 * 0.2), 1e-3);
  EXPECT_NEAR(c.recordings[1].impact_speed_m_s, std::sqrt(2 * g0 * 0.05), 1e-3);
  EXPECT_NEAR(c.recordings[0].time_origin_s, 0.7, 2e-5);
  EXPECT_NEAR(c.recordings[1].time_origin_s, 2.3, 2e-5);
  // The joint speed range covers both drops.
  EXPECT_LT(c.v_min_m_s, 0.3);
  EXPECT_GT(c.v_max_m_s, 1.9);
  // A joint fit pins gamma better than either file alone.
  const Calibration ca = Calibrate({{"a", sa}}, SteelScene("walton-braun", {}), {});
  EXPECT_LT(g.sigma, Param(ca, "gamma").sigma);
}

TEST(Calibrate, EOfVRecoveredWhenTheTruthIsAnotherLaw) {
  // Truth: linear spring-dashpot (constant e); fitted: seed 002's walton-braun.
  Scene truth = SteelScene("linear-dashpot", {});
  {
    auto law = CreateLaw(truth.law, truth);
    auto p = law->DampingForRestitution(law->ParameterValues(), BodyFromScene(truth), 0.8, 1.0);
    ASSERT_TRUE(p.has_value());
    truth.law.parameters["c"] = (*p)[static_cast<size_t>(law->ParameterIndex("c"))];
  }
  const Sequence seq = MeasuredFromSimulation(truth, 14, 5e-6, 11);
  auto truth_law = CreateLaw(truth.law, truth);
  for (FitStrategy st : {FitStrategy::kTrajectory, FitStrategy::kRestitution}) {
    CalibrationOptions o;
    o.strategy = st;
    const Calibration c = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), o);
    ASSERT_GE(c.e_of_v.size(), 2u);
    for (const auto& pt : c.e_of_v) {
      const double e_true = SimulateContact(*truth_law, truth_law->ParameterValues(),
                                            BodyFromScene(truth), pt.v_m_s, 9.8)
                                .restitution;
      EXPECT_NEAR(pt.e, e_true, 0.005) << FitStrategyName(st) << " v = " << pt.v_m_s;
    }
  }
  if (Registered("hertz-viscoelastic") && Registered("hertz-tsuji")) {
    // Velocity-dependent truth, velocity-dependent fitted law of another family.
    Scene vt = SteelScene("hertz-viscoelastic", {});
    auto law = CreateLaw(vt.law, vt);
    auto p = law->DampingForRestitution(law->ParameterValues(), BodyFromScene(vt), 0.8, 1.0);
    ASSERT_TRUE(p.has_value());
    for (size_t i = 0; i < law->Parameters().size(); ++i) {
      if (law->Parameters()[i].damping) vt.law.parameters[law->Parameters()[i].name] = (*p)[i];
    }
    const Sequence s2 = MeasuredFromSimulation(vt, 14, 5e-6, 12);
    auto tl = CreateLaw(vt.law, vt);
    for (const std::string fitted : {"hertz-viscoelastic"}) {
      const Calibration c = Calibrate({{"x", s2}}, SteelScene(fitted, {}), {});
      for (const auto& pt : c.e_of_v) {
        const double e_true =
            SimulateContact(*tl, tl->ParameterValues(), BodyFromScene(vt), pt.v_m_s, 9.8)
                .restitution;
        EXPECT_NEAR(pt.e, e_true, 0.005) << fitted << " v = " << pt.v_m_s;
      }
    }
  }
}

TEST(Calibrate, StiffnessFreedIsReportedWithItsDeterminability) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.4}});
  const Sequence seq = MeasuredFromSimulation(truth, 14, 5e-6, 5);
  // Restitution points: e of a constant-e law does not depend on k at all.
  CalibrationOptions ro;
  ro.strategy = FitStrategy::kRestitution;
  ro.free_parameters = {"k"};
  const Calibration cr = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), ro);
  EXPECT_FALSE(Param(cr, "k").fixed);
  EXPECT_FALSE(Param(cr, "k").determined) << cr.FullReport();
  const auto und = cr.Undetermined();
  EXPECT_NE(std::find(und.begin(), und.end(), "k"), und.end());
  EXPECT_EQ(cr.outcome, FitOutcome::kConverged);  // gamma is still determined
  EXPECT_TRUE(Param(cr, "gamma").determined);
  EXPECT_NEAR(Param(cr, "gamma").value, 0.4, 3 * Param(cr, "gamma").sigma);
  ro.free_parameters.clear();
  const Calibration crh = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), ro);
  EXPECT_TRUE(Param(crh, "k").fixed);
  EXPECT_FALSE(Param(crh, "k").determined);

  // Impact times: each interval includes the ~60 us contact, whose duration scales as
  // k^-1/2, so with 5 us timing noise the sound does pin k (to a few per cent).
  CalibrationOptions to;
  to.free_parameters = {"k"};
  const Calibration ct = Calibrate({{"x", seq}}, SteelScene("walton-braun", {{"k", 3e6}}), to);
  const auto& k = Param(ct, "k");
  ASSERT_TRUE(k.determined) << ct.FullReport();
  EXPECT_LT(k.sigma, 0.2 * k.value);
  EXPECT_NEAR(k.value, 1e7, 3 * k.sigma) << ct.FullReport();
  EXPECT_NEAR(Param(ct, "gamma").value, 0.4, 3 * Param(ct, "gamma").sigma);
  const Calibration cth = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), {});
  EXPECT_TRUE(Param(cth, "k").fixed);
  EXPECT_TRUE(Param(cth, "k").determined);  // "the data could fit it"
}

TEST(Calibrate, ReportsNameParametersUnitsAndStatistics) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.408}});
  const Sequence seq = MeasuredFromSimulation(truth, 12, 5e-6, 9);
  const Calibration c = Calibrate({{"drop.wav", seq}}, SteelScene("walton-braun", {}), {});
  const std::string full = c.FullReport();
  for (const char* want :
       {"gamma", "N/m", "chi2/dof", "drop.wav", "determined by the sound", "e(v)", "us"}) {
    EXPECT_NE(full.find(want), std::string::npos) << want << "\n" << full;
  }
  EXPECT_NE(c.BriefReport().find("gamma = 0.40"), std::string::npos) << c.BriefReport();
  EXPECT_EQ(c.dof, c.num_residuals - c.num_free);
  EXPECT_GT(c.chi2_dof, 0.2);
  EXPECT_LT(c.chi2_dof, 3.0);
  EXPECT_NEAR(c.aic, c.chi2 + 2 * c.num_free, 1e-9);
  // The scene that comes back carries the fitted value.
  EXPECT_DOUBLE_EQ(c.scene.law.parameters.at("gamma"), Param(c, "gamma").value);
}

TEST(Calibrate, OneImpactAndTooFewImpactsFailClearly) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.3}});
  Sequence seq = MeasuredFromSimulation(truth, 12, 5e-6, 0);
  for (int n : {1, 2, 3}) {
    Sequence s = seq;
    s.impacts.resize(static_cast<size_t>(n));
    try {
      Calibrate({{"short.wav", s}}, truth, {});
      ADD_FAILURE() << n << " impacts: expected kFitFailed";
    } catch (const Error& e) {
      EXPECT_EQ(e.code(), ErrorCode::kFitFailed) << e.what();
      EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos);
      if (n == 1) {
        EXPECT_NE(std::string(e.what()).find("short.wav"), std::string::npos);
      }
    }
  }
  // Four impacts: 3 intervals for gamma, v0 and t0 -> one degree of freedom: it works.
  Sequence s4 = seq;
  s4.impacts.resize(4);
  EXPECT_NO_THROW(Calibrate({{"four", s4}}, truth, {}));
}

TEST(Calibrate, StickingLawFailsWithAClearMessage) {
  // A linear dashpot started overdamped (zeta >> 1): no rebound at the first impact.
  Scene start = SteelScene("linear-dashpot", {});
  auto law = CreateLaw(start.law, start);
  const double m = start.ball.Mass();
  const double k = law->ParameterValues()[static_cast<size_t>(law->ParameterIndex("k"))];
  start.law.parameters["c"] = 20.0 * 2.0 * std::sqrt(m * k);
  const Sequence seq =
      MeasuredFromSimulation(SteelScene("walton-braun", {{"gamma", 0.3}}), 12, 5e-6, 0);
  CalibrationOptions o;
  o.seed_from_inverse_map = false;
  try {
    Calibrate({{"x", seq}}, start, o);
    ADD_FAILURE() << "expected kFitFailed";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kFitFailed);
    EXPECT_NE(std::string(e.what()).find("sticks"), std::string::npos) << e.what();
  }
}

TEST(Calibrate, BadOptionsAndNamesAreRejected) {
  CalibrationOptions o;
  std::string err;
  EXPECT_TRUE(o.IsValid(&err));
  o.rel_tolerance = 0.5;
  EXPECT_FALSE(o.IsValid(&err));
  EXPECT_NE(err.find("rel_tolerance"), std::string::npos);
  o = {};
  o.free_parameters = {"k"};
  o.fixed_parameters = {"k"};
  EXPECT_FALSE(o.IsValid(&err));
  o = {};
  o.loss_scale_sigma = -1;
  EXPECT_FALSE(o.IsValid(&err));
  EXPECT_THROW(ParseFitStrategy("bogus"), Error);
  EXPECT_THROW(ParseDerivativeMode("analytic"), Error);
  EXPECT_THROW(ParseRobustLoss("l1"), Error);
  EXPECT_EQ(ParseFitStrategy("restitution"), FitStrategy::kRestitution);

  const Sequence seq =
      MeasuredFromSimulation(SteelScene("walton-braun", {{"gamma", 0.3}}), 10, 5e-6, 0);
  CalibrationOptions bad;
  bad.free_parameters = {"stiffness"};
  try {
    Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), bad);
    ADD_FAILURE();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    EXPECT_NE(std::string(e.what()).find("stiffness"), std::string::npos);
  }
  EXPECT_THROW(Calibrate({{"x", seq}}, SteelScene("no-such-law", {}), {}), Error);
}

TEST(Calibrate, ImpactsFlaggedMissedByTheDetectorKeepTheSimulatedIndex) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.2}});
  Sequence seq = MeasuredFromSimulation(truth, 16, 5e-6, 17);
  // Drop impacts 6 and 11; the tracker flags each gap (missed_after = measured index).
  seq.impacts.erase(seq.impacts.begin() + 11);
  seq.impacts.erase(seq.impacts.begin() + 6);
  seq.missed_after = {5, 9};
  const Calibration c = Calibrate({{"gaps", seq}}, SteelScene("walton-braun", {}), {});
  const auto& g = Param(c, "gamma");
  EXPECT_NEAR(g.value, 0.2, 3 * g.sigma);
  EXPECT_LT(c.rms_residual, 20e-6);
  EXPECT_EQ(c.recordings[0].impacts, 14);
  EXPECT_EQ(c.recordings[0].simulated_impacts, 16);
  // Without the flags the same times cannot be fitted.
  seq.missed_after.clear();
  const Calibration bad = Calibrate({{"gaps", seq}}, SteelScene("walton-braun", {}), {});
  EXPECT_GT(bad.chi2_dof, 100.0);
}

TEST(Calibrate, QuadraticDragIsFittedWhenTheSceneTurnsItOn) {
  // A ping-pong ball (40 mm, 2.7 g) from 0.5 m: drag changes every flight by percents.
  Scene truth = SteelScene("walton-braun", {{"gamma", 0.15}, {"k", 2e4}});
  truth.ball.diameter_m = 0.04;
  truth.ball.mass_kg = 0.0027;
  truth.ball.density_kg_m3.reset();
  truth.effects.drag = DragModel::kQuadratic;
  truth.drop.height_m = 0.5;
  const Sequence seq = MeasuredFromSimulation(truth, 15, 5e-6, 3);
  Scene start = truth;
  start.law.parameters = {{"k", 2e4}};
  const Calibration c = Calibrate({{"pingpong", seq}}, start, {});
  EXPECT_TRUE(c.analytic_jacobian);
  EXPECT_NEAR(Param(c, "gamma").value, 0.15, 3 * Param(c, "gamma").sigma + 1e-6);
  EXPECT_LT(c.chi2_dof, 3.0);
  // The same data fitted without drag: biased, and chi2 says so.
  start.effects.drag = DragModel::kNone;
  const Calibration nd = Calibrate({{"pingpong", seq}}, start, {});
  EXPECT_GT(std::abs(Param(nd, "gamma").value - 0.15), 0.005);
  EXPECT_GT(nd.chi2_dof, 1000.0);
  EXPECT_NE(nd.message.find("does not describe"), std::string::npos);
}

TEST(Calibrate, RobustLossKeepsOneBadImpactFromDraggingTheFit) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.35}});
  Sequence seq = MeasuredFromSimulation(truth, 14, 5e-6, 21);
  seq.impacts[6].time_s += 300e-6;  // one onset 60 sigma off (e.g. a distractor merged in)
  CalibrationOptions huber, plain;
  plain.loss = RobustLoss::kNone;
  const Calibration ch = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), huber);
  const Calibration cp = Calibrate({{"x", seq}}, SteelScene("walton-braun", {}), plain);
  const double eh = std::abs(Param(ch, "gamma").value - 0.35);
  const double ep = std::abs(Param(cp, "gamma").value - 0.35);
  EXPECT_LT(eh, ep);
}

TEST(Calibrate, LawComparisonRanksEveryRegisteredLaw) {
  const Scene truth = SteelScene("walton-braun", {{"gamma", 0.3}});
  const Sequence seq = MeasuredFromSimulation(truth, 12, 5e-6, 13);
  const auto rows = CompareLaws({{"x", seq}}, SteelScene("walton-braun", {}), {});
  size_t expected = 0;
  for (const auto& l : RegisteredLaws()) expected += l.needs_expression ? 0 : 1;
  ASSERT_EQ(rows.size(), expected);
  for (size_t i = 1; i < rows.size(); ++i) {
    if (rows[i].fit.outcome == FitOutcome::kFailed) continue;
    EXPECT_GE(rows[i].fit.aic, rows[i - 1].fit.aic);
  }
  EXPECT_DOUBLE_EQ(rows.front().delta_aic, 0.0);
  // The truth's law fits at the noise level.
  for (const auto& r : rows) {
    if (r.fit.law == "walton-braun") {
      EXPECT_LT(r.fit.chi2_dof, 3.0);
    }
  }
  const std::string table = LawComparisonTable(rows, {0.5, 1.0});
  EXPECT_NE(table.find("walton-braun"), std::string::npos);
  EXPECT_NE(table.find("e(0.5 m/s)"), std::string::npos);
}

TEST(Calibrate, AudioRoundTripRenderDetectFit) {
  // Simulated walton-braun impacts (gamma = 0.1, e = 0.905 as for steel on copper) rendered as
  // a 48 kHz recording with the steel-copper preset's plate, noise and hum, detected, fitted.
  const double gamma = 0.1;
  const Scene truth = SteelScene("walton-braun", {{"gamma", gamma}});
  auto law = CreateLaw(truth.law, truth);
  Scene s = truth;
  s.drop.first_impact_time_s = 0.5;
  s.limits.max_impacts = 30;
  const Simulation sim = Simulate(s, *law, law->ParameterValues());
  std::vector<TruthImpact> impacts;
  for (const auto& i : sim.impacts) {
    if (!impacts.empty() && i.time_s - impacts.back().time_s < 0.02) break;
    impacts.push_back({i.time_s, i.v_in_m_s, i.v_out_m_s, i.contact_s});
  }
  ASSERT_GE(impacts.size(), 15u);
  RenderOptions ro = SynthPreset("steel-copper").render;
  ro.latency_s = 0.0;
  ro.seed = 5;
  const auto rec = RenderRecording(impacts, ro);
  Audio audio;
  audio.info.path = "rendered.wav";
  audio.info.sample_rate_hz = rec.sample_rate_hz;
  audio.info.channels = 1;
  audio.info.frames = static_cast<std::int64_t>(rec.channels[0].size());
  audio.channels = rec.channels;
  audio.clipping.resize(1);
  const DetectionResult det = DetectImpacts(audio, DetectOptions{});
  Sequence seq = det.main();
  ASSERT_GE(seq.impacts.size(), 12u);
  ASSERT_NEAR(seq.impacts[0].time_s, 0.5, 1e-4);  // the sequence starts at the first impact
  // The rendered truth stops where flights get short; keep the detected impacts it covers.
  if (seq.impacts.size() > impacts.size()) seq.impacts.resize(impacts.size());
  const Calibration c = Calibrate({{"rendered.wav", seq}}, SteelScene("walton-braun", {}), {});
  const auto& g = Param(c, "gamma");
  EXPECT_EQ(c.outcome, FitOutcome::kConverged) << c.FullReport();
  EXPECT_NEAR(g.value, gamma, 0.01 * gamma) << c.FullReport();
  EXPECT_NEAR(g.value, gamma, 4 * g.sigma) << c.FullReport();
  EXPECT_NEAR(c.recordings[0].time_origin_s, 0.5, 20e-6);
}

}  // namespace
}  // namespace bouncecal
