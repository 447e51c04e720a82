// Tests for kinematics (kinematics.hpp): the vacuum oracle e = dt_k / dt_{k-1}, the seed's
// numbers, exact round trips with drag/buoyancy/contact duration, and the propagated sigmas
// against a Monte Carlo simulation.
#include "bouncecal/fit/kinematics.hpp"

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/flight.hpp"

namespace bouncecal {
namespace {

Sequence FromTimes(const std::vector<double>& t, double sigma_s = 0.0) {
  Sequence s;
  for (double x : t) {
    Impact i;
    i.time_s = x;
    i.sigma_s = sigma_s;
    s.impacts.push_back(i);
  }
  return s;
}

// Exact onsets of a bouncing ball with restitution e[k] at impact k: the forward model written
// with FlightModel only (independent of AnalyzeBounces' inversion).
std::vector<double> ExactTimes(const Scene& scene, const std::vector<double>& e, double t0,
                               double fixed_contact_s, bool hertz) {
  const FlightModel f = FlightModel::FromScene(scene);
  double v_in =
      scene.drop.height_m ? f.FallArrivalSpeed(*scene.drop.height_m) : *scene.drop.impact_speed_m_s;
  std::vector<double> t{t0};
  for (double ek : e) {
    double tau = 0.0;
    if (scene.effects.contact_duration)
      tau = hertz ? HertzContactTime(scene, v_in) : fixed_contact_s;
    const double v_out = ek * v_in;
    t.push_back(t.back() + tau + f.FlightTime(v_out));
    v_in = f.ArrivalSpeed(v_out);
  }
  return t;
}

TEST(KinematicsTest, VacuumOracleIsTheIntervalRatio) {
  Scene scene;  // seed 002: h = 0.2 m, g = 9.8, no drag
  const std::vector<double> t = {0.1, 0.43, 0.70, 0.91, 1.08, 1.21};
  const Analysis a = AnalyzeBounces(FromTimes(t, 1e-5), scene);
  ASSERT_EQ(a.bounces.size(), t.size());
  for (size_t k = 1; k + 1 < t.size(); ++k) {
    const double expect = (t[k + 1] - t[k]) / (t[k] - t[k - 1]);  // seed 002 eq. 11
    EXPECT_NEAR(a.bounces[k].e, expect, 2e-15) << k;
    EXPECT_NEAR(a.bounces[k].eta, 1 - expect * expect, 4e-15);
    EXPECT_NEAR(a.bounces[k].v_out_m_s, 9.8 * (t[k + 1] - t[k]) / 2, 1e-14);
    EXPECT_NEAR(a.bounces[k].v_in_m_s, 9.8 * (t[k] - t[k - 1]) / 2, 1e-14);
    EXPECT_DOUBLE_EQ(a.bounces[k].interval_s, t[k + 1] - t[k]);
  }
  // The first impact: the unheard interval is 2 sqrt(2h/g) = 0.40406 s (seed: 0.4040 s).
  const double dt0 = 2 * std::sqrt(2 * 0.2 / 9.8);
  EXPECT_NEAR(dt0, 0.4040, 1e-4);
  ASSERT_TRUE(a.first_e.has_value());
  EXPECT_NEAR(*a.first_e, (t[1] - t[0]) / dt0, 1e-14);
  EXPECT_NEAR(a.bounces[0].v_in_m_s, std::sqrt(2 * 9.8 * 0.2), 1e-14);
  // The last impact has no rebound.
  EXPECT_TRUE(std::isnan(a.bounces.back().e));
  EXPECT_TRUE(std::isnan(a.bounces.back().interval_s));
  EXPECT_TRUE(std::isnan(a.bounces.back().v_out_m_s));
  EXPECT_TRUE(std::isfinite(a.bounces.back().v_in_m_s));
  // Mean eta of the first three: impacts 0, 1, 2 (the first from the drop height).
  ASSERT_TRUE(a.mean_eta_first3.has_value());
  EXPECT_EQ(a.mean_eta_indices, (std::vector<int>{0, 1, 2}));
  EXPECT_NEAR(*a.mean_eta_first3, (a.bounces[0].eta + a.bounces[1].eta + a.bounces[2].eta) / 3,
              1e-15);
}

TEST(KinematicsTest, SeedMeanEtaRoundTrip) {
  // Seed 002 reports mean eta 0.58 over the first three impacts: a ball with constant
  // e = sqrt(0.42) gives exactly that back.
  Scene scene;
  const double e = std::sqrt(1 - 0.58);
  const std::vector<double> t = ExactTimes(scene, std::vector<double>(8, e), 0.0, 0, false);
  EXPECT_NEAR(t[1] - t[0], e * 2 * std::sqrt(2 * 0.2 / 9.8), 1e-15);
  const Analysis a = AnalyzeBounces(FromTimes(t), scene);
  EXPECT_NEAR(*a.mean_eta_first3, 0.58, 1e-13);
  EXPECT_NEAR(*a.first_e, e, 1e-14);
  // Without the drop height the first e is unknown and the mean starts at impact 1.
  AnalysisOptions no_drop;
  no_drop.use_drop = false;
  const Analysis b = AnalyzeBounces(FromTimes(t), scene, no_drop);
  EXPECT_FALSE(b.first_e.has_value());
  EXPECT_TRUE(std::isnan(b.bounces[0].e));
  EXPECT_EQ(b.mean_eta_indices, (std::vector<int>{1, 2, 3}));
  EXPECT_NEAR(*b.mean_eta_first3, 0.58, 1e-13);
}

TEST(KinematicsTest, DragRoundTripRecoversRestitution) {
  const std::vector<double> e = {0.93, 0.91, 0.9, 0.88, 0.85, 0.83, 0.8, 0.78, 0.75, 0.7};
  struct Case {
    const char* name;
    DragModel drag;
    bool buoyancy;
    bool contact;
    bool hertz;
    std::string material;
    double diameter_m;
  };
  const std::vector<Case> cases = {
      {"pingpong quadratic", DragModel::kQuadratic, false, false, false, "pingpong", 0.04},
      {"pingpong quadratic+buoyancy+contact", DragModel::kQuadratic, true, true, false, "pingpong",
       0.04},
      {"steel linear+buoyancy", DragModel::kLinear, true, false, false, "steel", 0.01},
      {"rubber quadratic+hertz contact", DragModel::kQuadratic, false, true, true, "rubber", 0.03},
      {"steel vacuum+hertz contact", DragModel::kNone, false, true, true, "steel", 0.01},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    Scene scene;
    scene.ball.material = c.material;
    scene.ball.density_kg_m3 = FindMaterial(c.material)->density_kg_m3;
    scene.ball.diameter_m = c.diameter_m;
    scene.drop.height_m = 0.5;
    scene.effects.drag = c.drag;
    scene.effects.buoyancy = c.buoyancy;
    scene.effects.contact_duration = c.contact;
    AnalysisOptions options;
    options.contact_time_s = c.hertz ? 0.0 : 1.5e-3;
    const std::vector<double> t = ExactTimes(scene, e, 0.37, options.contact_time_s, c.hertz);
    const Analysis a = AnalyzeBounces(FromTimes(t, 1e-5), scene, options);
    ASSERT_EQ(a.bounces.size(), e.size() + 1);
    for (size_t k = 0; k < e.size(); ++k) EXPECT_NEAR(a.bounces[k].e, e[k], 1e-12) << k;
    if (c.drag != DragModel::kNone) {
      // With drag the interval ratio is NOT the restitution (docs/physics.md §2).
      const double ratio = (t[3] - t[2]) / (t[2] - t[1]);
      EXPECT_GT(std::abs(ratio - e[2]), 1e-6);
      // Arrival speed after each flight is below the rebound speed that started it.
      for (size_t k = 0; k + 1 < e.size(); ++k) {
        EXPECT_LT(a.bounces[k + 1].v_in_m_s, a.bounces[k].v_out_m_s);
      }
    }
    if (c.contact) {
      EXPECT_GT(a.bounces[0].contact_s, 0.0);
    } else {
      EXPECT_EQ(a.bounces[0].contact_s, 0.0);
    }
  }
}

TEST(KinematicsTest, HertzContactTime) {
  Scene scene;  // 1 cm steel ball on copper
  // tau = 2.87 (m^2 / (R E*^2 v))^(1/5), written out with the preset values.
  const double m = 7800 * M_PI / 6 * 1e-6, r = 0.005;
  const double e_star = 1 / ((1 - 0.29 * 0.29) / 2.0e11 + (1 - 0.34 * 0.34) / 1.2e11);
  const double expect = 2.87 * std::pow(m * m / (r * e_star * e_star * 2.0), 0.2);
  EXPECT_NEAR(HertzContactTime(scene, 2.0), expect, 1e-15);
  EXPECT_GT(expect, 20e-6);  // "tens of microseconds for steel" (docs/physics.md §2)
  EXPECT_LT(expect, 60e-6);
  EXPECT_NEAR(HertzContactTime(scene, 1.0) / HertzContactTime(scene, 32.0), 2.0, 1e-12);
  scene.ball.material = "rubber";
  scene.ball.density_kg_m3 = 1150;
  scene.ball.diameter_m = 0.05;
  scene.surface.material = "wood";
  EXPECT_GT(HertzContactTime(scene, 2.0), 1e-3);  // milliseconds for rubber
  scene.ball.material = "my-resin";
  EXPECT_THROW(HertzContactTime(scene, 2.0), Error);
}

// Monte Carlo check of the propagated timing sigmas (and of the correlation of successive e's).
// The screen is off: these six e's are arbitrary, and their spread would count as scatter.
void CheckSigmasAgainstMonteCarlo(const Scene& scene, AnalysisOptions options) {
  options.screen = false;
  const std::vector<double> e = {0.9, 0.85, 0.8, 0.78, 0.75, 0.7};
  const std::vector<double> t = ExactTimes(scene, e, 0.2, 0.0, false);
  std::vector<double> sig(t.size());
  for (size_t k = 0; k < t.size(); ++k) sig[k] = 2e-5 * (1.0 + 0.5 * static_cast<double>(k));
  Sequence exact = FromTimes(t);
  for (size_t k = 0; k < t.size(); ++k) exact.impacts[k].sigma_s = sig[k];
  const Analysis ref = AnalyzeBounces(exact, scene, options);

  std::mt19937_64 rng(12345);
  std::normal_distribution<double> normal(0.0, 1.0);
  const int trials = 4000;
  const size_t nb = e.size();
  std::vector<double> sum(nb, 0), sum2(nb, 0), cross(nb, 0);
  // Speeds: v_out,k from interval k, v_in,k+1 = A(v_out,k) through the flight (drag factor).
  std::vector<double> vin_sum(nb, 0), vin_sum2(nb, 0), vout_sum(nb, 0), vout_sum2(nb, 0);
  std::vector<double> eta_sum(nb, 0), eta_sum2(nb, 0);
  double mean_sum = 0, mean_sum2 = 0;
  for (int trial = 0; trial < trials; ++trial) {
    Sequence noisy = exact;
    for (size_t k = 0; k < t.size(); ++k) noisy.impacts[k].time_s += sig[k] * normal(rng);
    const Analysis a = AnalyzeBounces(noisy, scene, options);
    for (size_t k = 0; k < nb; ++k) {
      const double d = a.bounces[k].e - ref.bounces[k].e;
      sum[k] += d;
      sum2[k] += d * d;
      if (k + 1 < nb) cross[k] += d * (a.bounces[k + 1].e - ref.bounces[k + 1].e);
      const double dvi = a.bounces[k].v_in_m_s - ref.bounces[k].v_in_m_s;
      const double dvo = a.bounces[k].v_out_m_s - ref.bounces[k].v_out_m_s;
      vin_sum[k] += dvi, vin_sum2[k] += dvi * dvi;
      vout_sum[k] += dvo, vout_sum2[k] += dvo * dvo;
      const double deta = a.bounces[k].eta - ref.bounces[k].eta;
      eta_sum[k] += deta, eta_sum2[k] += deta * deta;
    }
    const double dm = *a.mean_eta_first3 - *ref.mean_eta_first3;
    mean_sum += dm;
    mean_sum2 += dm * dm;
  }
  std::vector<double> sd(nb);
  for (size_t k = 0; k < nb; ++k) {
    if (!std::isfinite(ref.bounces[k].e)) continue;  // first e unknown without the drop
    const double mean = sum[k] / trials;
    sd[k] = std::sqrt(sum2[k] / trials - mean * mean);
    EXPECT_NEAR(ref.bounces[k].e_sigma / sd[k], 1.0, 0.10) << "bounce " << k;
  }
  // The speeds' sigmas (the first v_in comes from the scene, not from an interval).
  auto sd_of = [&](const std::vector<double>& s1, const std::vector<double>& s2, size_t k) {
    const double mean = s1[k] / trials;
    return std::sqrt(s2[k] / trials - mean * mean);
  };
  for (size_t k = 0; k < nb; ++k) {
    if (k > 0 && std::isfinite(ref.bounces[k].v_in_m_s)) {
      EXPECT_NEAR(ref.bounces[k].v_in_sigma_m_s / sd_of(vin_sum, vin_sum2, k), 1.0, 0.10)
          << "v_in of bounce " << k;
    }
    if (std::isfinite(ref.bounces[k].eta)) {
      EXPECT_NEAR(ref.bounces[k].eta_sigma / sd_of(eta_sum, eta_sum2, k), 1.0, 0.10)
          << "eta of bounce " << k;
    }
    if (k + 1 < nb && std::isfinite(ref.bounces[k].v_out_m_s)) {
      EXPECT_NEAR(ref.bounces[k].v_out_sigma_m_s / sd_of(vout_sum, vout_sum2, k), 1.0, 0.10)
          << "v_out of bounce " << k;
    }
  }
  for (size_t k = 0; k + 1 < nb; ++k) {
    if (!std::isfinite(ref.bounces[k].e)) continue;
    const double mc_corr =
        (cross[k] / trials - sum[k] / trials * sum[k + 1] / trials) / (sd[k] * sd[k + 1]);
    EXPECT_NEAR(ref.bounces[k].e_next_correlation, mc_corr, 0.06) << "bounce " << k;
  }
  // Successive e's share onsets: e_k goes up when t_{k+1} is late, e_{k+1} goes down.
  EXPECT_LT(ref.bounces[2].e_next_correlation, -0.3);
  const double mm = mean_sum / trials;
  const double mean_sd = std::sqrt(mean_sum2 / trials - mm * mm);
  EXPECT_NEAR(*ref.mean_eta_first3_sigma / mean_sd, 1.0, 0.10);
  // Ignoring the correlations would give a visibly different sigma for the mean.
  double naive = 0;
  for (int k : ref.mean_eta_indices) naive += std::pow(ref.bounces[k].eta_sigma / 3, 2);
  EXPECT_GT(std::abs(std::sqrt(naive) / mean_sd - 1.0), 0.15);
}

TEST(KinematicsTest, SigmasMatchMonteCarloVacuum) {
  Scene scene;
  CheckSigmasAgainstMonteCarlo(scene, {});
}

TEST(KinematicsTest, SigmasMatchMonteCarloQuadraticDragNoDrop) {
  Scene scene;
  scene.ball.material = "pingpong";
  scene.ball.density_kg_m3 = FindMaterial("pingpong")->density_kg_m3;
  scene.ball.diameter_m = 0.04;
  scene.drop.height_m = 1.0;
  scene.effects.drag = DragModel::kQuadratic;
  AnalysisOptions options;
  options.use_drop = false;  // the times come from h = 1 m; the analysis does not know it
  CheckSigmasAgainstMonteCarlo(scene, options);
}

TEST(KinematicsTest, MissedImpactAndBadIntervals) {
  Scene scene;
  Sequence seq = FromTimes({0.0, 0.3, 0.55, 0.75, 0.9, 1.0});
  seq.missed_after = {2};
  const Analysis a = AnalyzeBounces(seq, scene);
  EXPECT_TRUE(std::isnan(a.bounces[2].v_out_m_s));
  EXPECT_TRUE(std::isnan(a.bounces[2].e));
  EXPECT_TRUE(std::isnan(a.bounces[3].v_in_m_s));
  EXPECT_TRUE(std::isnan(a.bounces[3].e));
  EXPECT_TRUE(std::isfinite(a.bounces[1].e));
  EXPECT_TRUE(std::isfinite(a.bounces[4].e));
  EXPECT_FALSE(a.warnings.empty());
  // A growing interval gives e > 1 and a warning, not an error.
  const Analysis g = AnalyzeBounces(FromTimes({0.0, 0.3, 0.31, 0.5}), scene);
  EXPECT_GT(g.bounces[2].e, 1.0);
  bool warned = false;
  for (const Warning& w : g.warnings)
    warned |= w.code == "e_above_one" && w.message.find("e = ") != std::string::npos;
  EXPECT_TRUE(warned);
  // A contact duration longer than the interval: that interval is dropped with a warning.
  scene.effects.contact_duration = true;
  AnalysisOptions long_contact;
  long_contact.contact_time_s = 0.2;
  const Analysis c = AnalyzeBounces(FromTimes({0.0, 0.3, 0.45, 0.6}), scene, long_contact);
  EXPECT_TRUE(std::isnan(c.bounces[1].v_out_m_s));
  EXPECT_TRUE(std::isfinite(c.bounces[0].v_out_m_s));
}

TEST(KinematicsTest, InvalidInputs) {
  Scene scene;
  auto code = [&](const Sequence& s, const Scene& sc, const AnalysisOptions& o) {
    try {
      AnalyzeBounces(s, sc, o);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kOk;
  };
  EXPECT_EQ(code(FromTimes({0.5}), scene, {}), ErrorCode::kNoBounces);
  EXPECT_EQ(code(FromTimes({}), scene, {}), ErrorCode::kNoBounces);
  EXPECT_EQ(code(FromTimes({0.5, 0.4, 0.6}), scene, {}), ErrorCode::kBadParameter);
  EXPECT_EQ(code(FromTimes({0.5, NAN, 0.6}), scene, {}), ErrorCode::kBadParameter);
  AnalysisOptions bad;
  bad.contact_time_s = -1;
  EXPECT_EQ(code(FromTimes({0.1, 0.5, 0.8}), scene, bad), ErrorCode::kBadParameter);
  Scene broken;
  broken.ball.diameter_m = 0;
  EXPECT_EQ(code(FromTimes({0.1, 0.5, 0.8}), broken, {}), ErrorCode::kBadScene);
  EXPECT_EQ(code(FromTimes({0.1, 0.5, 0.8}), scene, {}), ErrorCode::kOk);
}

}  // namespace
}  // namespace bouncecal

namespace bouncecal {
namespace {

// The derivatives the fitter's covariance uses, against finite differences of AnalyzeBounces.
TEST(KinematicsTest, SpeedAndHeightDerivativesMatchFiniteDifferences) {
  Scene scene;
  scene.drop.height_m = 0.5;
  scene.effects.drag = DragModel::kQuadratic;
  const std::vector<double> e = {0.9, 0.88, 0.87, 0.86, 0.85};
  const std::vector<double> t = ExactTimes(scene, e, 0.2, 0.0, false);
  AnalysisOptions o;
  o.screen = false;
  const Analysis ref = AnalyzeBounces(FromTimes(t, 1e-5), scene, o);
  const double h = 1e-7;
  for (size_t k = 1; k + 1 < t.size(); ++k) {
    for (int which : {-1, 0}) {
      std::vector<double> tp = t, tm = t;
      tp[k + which] += h;
      tm[k + which] -= h;
      const Analysis ap = AnalyzeBounces(FromTimes(tp, 1e-5), scene, o);
      const Analysis am = AnalyzeBounces(FromTimes(tm, 1e-5), scene, o);
      const double fd = (ap.bounces[k].v_in_m_s - am.bounces[k].v_in_m_s) / (2 * h);
      const double an = which < 0 ? ref.bounces[k].dv_in_dt_prev : ref.bounces[k].dv_in_dt_this;
      EXPECT_NEAR(an, fd, 1e-5 * std::abs(fd)) << "bounce " << k << " onset " << k + which;
    }
  }
  // The first impact: v_in and e against the drop height.
  Scene up = scene, down = scene;
  const double dh = 1e-6;
  up.drop.height_m = 0.5 + dh;
  down.drop.height_m = 0.5 - dh;
  const Analysis au = AnalyzeBounces(FromTimes(t, 1e-5), up, o);
  const Analysis ad = AnalyzeBounces(FromTimes(t, 1e-5), down, o);
  EXPECT_NEAR(ref.bounces[0].dv_in_dh, (au.bounces[0].v_in_m_s - ad.bounces[0].v_in_m_s) / (2 * dh),
              1e-6);
  EXPECT_NEAR(ref.bounces[0].de_dh, (au.bounces[0].e - ad.bounces[0].e) / (2 * dh), 1e-6);
  // A height sigma enters the first impact's speed and e sigmas (and nothing later).
  Scene sig = scene;
  sig.drop.height_sigma_m = 0.01;
  const Analysis as = AnalyzeBounces(FromTimes(t, 1e-5), sig, o);
  EXPECT_NEAR(as.bounces[0].v_in_sigma_m_s, std::abs(ref.bounces[0].dv_in_dh) * 0.01, 1e-12);
  EXPECT_NEAR(as.bounces[0].e_sigma,
              std::hypot(ref.bounces[0].e_sigma, ref.bounces[0].de_dh * 0.01), 1e-12);
  EXPECT_DOUBLE_EQ(as.bounces[2].e_sigma, ref.bounces[2].e_sigma);
  EXPECT_EQ(as.height_sigma_m, 0.01);
}

}  // namespace
}  // namespace bouncecal
