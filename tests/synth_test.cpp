// Tests of the test-recording renderer (synth.hpp): truth against closed-form flights, the
// rendered sound against a numerical convolution, timing/causality, determinism, SNR, clipping,
// channels, presets, the truth JSON and the `bouncecal synth` command.
#include "bouncecal/synth/synth.hpp"

#include <gtest/gtest.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/physics/bundled_scenes.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {
namespace fs = std::filesystem;

constexpr double kG = 9.8;

Scene SteelScene(double height_m = 0.2) {
  Scene s;
  s.ball.material = "steel";
  s.surface.material = "copper";
  s.drop.height_m = height_m;
  s.environment.g_m_s2 = kG;
  return s;
}

// ---- truth -----------------------------------------------------------------------------------

TEST(Truth, VacuumTimesAreTheClosedForm) {
  Scene s = SteelScene(0.2);
  s.drop.first_impact_time_s = 0.75;
  const double e = 0.8;
  const auto imp = ImpactsFromRestitution(s, RestitutionModel::Constant(e));
  ASSERT_GT(imp.size(), 20u);
  double v = std::sqrt(2 * kG * 0.2);  // release from rest, silent
  double t = 0.75;
  for (std::size_t k = 0; k < imp.size(); ++k) {
    EXPECT_NEAR(imp[k].time_s, t, 1e-12 * (1 + t)) << k;
    EXPECT_NEAR(imp[k].v_in_m_s, v, 1e-12) << k;
    EXPECT_NEAR(imp[k].v_out_m_s, e * v, 1e-12) << k;
    EXPECT_NEAR(imp[k].e(), e, 1e-12);
    t += 2 * e * v / kG;  // vacuum: interval = 2 v_out / g
    v *= e;
  }
  // Stopped exactly where the next interval would fall below the threshold (2 ms default).
  const double last_interval = 2 * imp.back().v_out_m_s / kG;
  EXPECT_LT(last_interval, TruthOptions{}.min_interval_s);
  EXPECT_GE(imp[imp.size() - 1].time_s - imp[imp.size() - 2].time_s, TruthOptions{}.min_interval_s);
}

TEST(Truth, PowerLawRestitutionUsesTheArrivalSpeed) {
  const auto model = RestitutionModel::PowerLaw(0.95, 0.02, 0.5);
  EXPECT_NEAR(model(4.0), 0.95 - 0.02 * 2.0, 1e-15);
  const auto imp = ImpactsFromRestitution(SteelScene(0.5), model);
  ASSERT_GT(imp.size(), 10u);
  for (std::size_t k = 0; k < imp.size(); ++k) {
    EXPECT_NEAR(imp[k].e(), 0.95 - 0.02 * std::sqrt(imp[k].v_in_m_s), 1e-12);
    if (k > 0) {
      EXPECT_NEAR(imp[k].v_in_m_s, imp[k - 1].v_out_m_s, 1e-12);  // no drag
    }
    if (k > 1) {  // e rises as the ball slows down: intervals shrink more slowly
      const double r1 =
          (imp[k].time_s - imp[k - 1].time_s) / (imp[k - 1].time_s - imp[k - 2].time_s);
      EXPECT_NEAR(r1, imp[k - 1].e(), 1e-9);
    }
  }
}

TEST(Truth, QuadraticDragMatchesTheExactFlightFormulas) {
  // Ping-pong ball: drag matters (docs/physics.md §2 closed forms, evaluated here independently).
  Scene s;
  s.ball.diameter_m = 0.04;
  s.ball.mass_kg = 0.0027;
  s.ball.density_kg_m3.reset();
  s.ball.material = "pingpong";
  s.surface.material = "wood";
  s.drop.height_m = 0.3;
  s.effects.drag = DragModel::kQuadratic;
  TruthOptions o;
  o.contact_s = 0.0;
  const double e = 0.9;
  const auto imp = ImpactsFromRestitution(s, RestitutionModel::Constant(e), o);
  ASSERT_GT(imp.size(), 10u);
  const double rho_a = s.environment.air_density_kg_m3, cd = s.environment.drag_coefficient;
  const double area = M_PI * 0.02 * 0.02;
  const double vt = std::sqrt(2 * 0.0027 * kG / (rho_a * cd * area));
  // Fall from 0.3 m.
  const double v_first = vt * std::sqrt(1 - std::exp(-2 * kG * 0.3 / (vt * vt)));
  EXPECT_NEAR(imp[0].v_in_m_s, v_first, 1e-9);
  EXPECT_LT(v_first, std::sqrt(2 * kG * 0.3) * 0.99);  // drag is visible
  for (std::size_t k = 0; k + 1 < imp.size(); ++k) {
    const double v0 = imp[k].v_out_m_s;
    const double t_up = vt / kG * std::atan(v0 / vt);
    const double h = vt * vt / (2 * kG) * std::log(1 + v0 * v0 / (vt * vt));
    const double t_down = vt / kG * std::acosh(std::exp(kG * h / (vt * vt)));
    const double v_arr = vt * std::sqrt(1 - std::exp(-2 * kG * h / (vt * vt)));
    EXPECT_NEAR(imp[k + 1].time_s - imp[k].time_s, t_up + t_down, 1e-10) << k;
    EXPECT_NEAR(imp[k + 1].v_in_m_s, v_arr, 1e-9) << k;
    EXPECT_LT(imp[k + 1].v_in_m_s, v0);  // drag takes energy in flight
  }
}

TEST(Truth, ContactDurationIsAddedOnlyWhenTheSceneAsks) {
  TruthOptions o;
  o.contact_s = 1.4e-3;
  Scene off = SteelScene(0.3);
  Scene on = off;
  on.effects.contact_duration = true;
  const auto a = ImpactsFromRestitution(off, RestitutionModel::Constant(0.85), o);
  const auto b = ImpactsFromRestitution(on, RestitutionModel::Constant(0.85), o);
  ASSERT_GT(a.size(), 5u);
  for (std::size_t k = 0; k + 1 < 5; ++k) {
    const double flight = 2 * a[k].v_out_m_s / kG;
    EXPECT_NEAR(a[k + 1].time_s - a[k].time_s, flight, 1e-12);
    EXPECT_NEAR(b[k + 1].time_s - b[k].time_s, flight + 1.4e-3, 1e-12);
    EXPECT_EQ(a[k].contact_s, 1.4e-3);  // reported either way: it shapes the click
  }
}

TEST(Truth, HertzContactDuration) {
  const Scene s = SteelScene();
  // Independent evaluation: steel (E 200 GPa, nu 0.29) on copper (120 GPa, 0.34), 1 cm ball.
  const double m = 7800.0 * M_PI / 6.0 * 1e-6;
  const double e_star = 1.0 / ((1 - 0.29 * 0.29) / 2.0e11 + (1 - 0.34 * 0.34) / 1.2e11);
  const double tau = 2.87 * std::pow(m * m / (0.005 * e_star * e_star * 1.0), 0.2);
  EXPECT_NEAR(HertzContactDuration(s, 1.0), tau, 1e-9 * tau);
  EXPECT_GT(tau, 20e-6);  // tens of microseconds for steel (docs/physics.md §2)
  EXPECT_LT(tau, 60e-6);
  EXPECT_NEAR(HertzContactDuration(s, 2.0) / HertzContactDuration(s, 1.0), std::pow(2.0, -0.2),
              1e-12);
  // The truth uses it per impact when no duration is given.
  const auto imp = ImpactsFromRestitution(s, RestitutionModel::Constant(0.9));
  EXPECT_NEAR(imp[3].contact_s, HertzContactDuration(s, imp[3].v_in_m_s), 1e-15);
}

TEST(Truth, StopsAtRestSpeedAndRejectsBadInput) {
  TruthOptions o;
  o.rest_speed_m_s = 0.5;
  const auto imp = ImpactsFromRestitution(SteelScene(), RestitutionModel::Constant(0.7), o);
  ASSERT_FALSE(imp.empty());
  EXPECT_LT(imp.back().v_out_m_s, 0.5);
  for (std::size_t k = 0; k + 1 < imp.size(); ++k) EXPECT_GE(imp[k].v_out_m_s, 0.5);

  auto code = [](auto&& f) {
    try {
      f();
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kOk;
  };
  EXPECT_EQ(code([] { ImpactsFromRestitution(SteelScene(), RestitutionModel::Constant(1.2)); }),
            ErrorCode::kBadParameter);
  EXPECT_EQ(code([] {
              ImpactsFromRestitution(SteelScene(), RestitutionModel::Function(
                                                       [](double v) { return 1.0 + v; }, "bad"));
            }),
            ErrorCode::kBadParameter);
  EXPECT_EQ(code([] { ImpactsFromRestitution(SteelScene(-1.0), RestitutionModel::Constant(0.9)); }),
            ErrorCode::kBadScene);
  TruthOptions bad;
  bad.min_interval_s = 0.0;
  EXPECT_EQ(
      code([&] { ImpactsFromRestitution(SteelScene(), RestitutionModel::Constant(0.9), bad); }),
      ErrorCode::kBadParameter);
}

// ---- truth from a contact law -----------------------------------------------------------------

RenderOptions Quiet(double rate_hz);  // below

Scene ViscoScene(double a_s) {
  Scene s = SteelScene(0.2);
  s.law.name = "hertz-viscoelastic";
  s.law.parameters["A"] = a_s;
  return s;
}

ErrorCode CodeOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const Error& e) {
    return e.code();
  }
  return ErrorCode::kOk;
}

// The list is the simulator's, cut where the restitution truth would cut it; in vacuum every
// interval is the contact plus the closed-form flight 2 v_out / g.
TEST(TruthFromLaw, IsTheSimulatorsImpactListCutAtTheMinimumInterval) {
  Scene s = ViscoScene(5e-7);
  s.drop.first_impact_time_s = 0.25;
  const auto imp = ImpactsFromLaw(s);
  const auto law = CreateLaw(s.law, s);
  const Simulation sim = Simulate(s, *law, law->ParameterValues());
  ASSERT_GT(imp.size(), 50u);
  ASSERT_GT(sim.impacts.size(), imp.size());  // cut before the ball comes to rest
  EXPECT_DOUBLE_EQ(imp[0].time_s, 0.25);
  EXPECT_NEAR(imp[0].v_in_m_s, std::sqrt(2 * kG * 0.2), 1e-12);
  for (std::size_t k = 0; k < imp.size(); ++k) {
    EXPECT_EQ(imp[k].time_s, sim.impacts[k].time_s);
    EXPECT_EQ(imp[k].v_in_m_s, sim.impacts[k].v_in_m_s);
    EXPECT_EQ(imp[k].v_out_m_s, sim.impacts[k].v_out_m_s);
    EXPECT_EQ(imp[k].contact_s, sim.impacts[k].contact_s);
    EXPECT_GT(imp[k].contact_s, 2e-5);
    if (k + 1 < imp.size()) {
      const double interval = imp[k + 1].time_s - imp[k].time_s;
      EXPECT_GE(interval, 0.002);
      EXPECT_NEAR(interval, imp[k].contact_s + 2 * imp[k].v_out_m_s / kG, 1e-9 * interval);
      EXPECT_GT(imp[k + 1].e(), imp[k].e());  // viscoelastic: e rises as the ball slows
    }
  }
  const std::size_t last = imp.size() - 1;
  EXPECT_LT(sim.impacts[last + 1].time_s - sim.impacts[last].time_s, 0.002);

  // A longer minimum interval gives a prefix of the same list.
  TruthOptions o;
  o.min_interval_s = 0.05;
  const auto short_list = ImpactsFromLaw(s, o);
  ASSERT_LT(short_list.size(), imp.size());
  for (std::size_t k = 0; k < short_list.size(); ++k) {
    EXPECT_EQ(short_list[k].time_s, imp[k].time_s);
  }
  EXPECT_LT(imp[short_list.size()].time_s - short_list.back().time_s, 0.05);
  // The law's closed-form e(v) (which neglects gravity during the ~35 us contact) at the first
  // impact.
  const auto e0 = law->Restitution(law->ParameterValues(), BodyFromScene(s), imp[0].v_in_m_s);
  ASSERT_TRUE(e0.has_value());
  EXPECT_NEAR(imp[0].e(), *e0, 2e-4);
}

TEST(TruthFromLaw, StuckLawGivesOneImpactAndBadInputIsRejected) {
  Scene stuck = SteelScene(0.2);
  stuck.law.name = "linear-dashpot";
  stuck.law.parameters = {{"k", 1e6}, {"c", 1e5}};  // far past critical damping
  const auto one = ImpactsFromLaw(stuck);
  ASSERT_EQ(one.size(), 1u);
  EXPECT_LT(one[0].v_out_m_s, 1e-3);
  // The simulator ends a slow contact as stuck (v_out = 0) once the ball creeps below the rest
  // speed: that impact is kept (it is heard) but is no restitution, so e_range leaves it out.
  SynthSpec spec = SynthPreset("steel-copper");
  spec.scene = SteelScene(0.2);
  spec.scene.law.name = "hertz-tsuji";
  spec.scene.law.parameters["e"] = 0.92;
  spec.scene.limits.rest_speed_m_s = 0.01;
  spec.truth.min_interval_s = 1e-4;
  spec.truth_source = TruthSource::kLaw;
  spec.render = Quiet(16000);
  const SynthResult sr = Synthesize(spec);
  ASSERT_GE(sr.truth[0].size(), 10u);
  EXPECT_EQ(sr.truth[0].back().v_out_m_s, 0.0);
  const nlohmann::json sj = TruthJson(spec, sr);
  EXPECT_NEAR(sj.at("e_range")[0].get<double>(), 0.92, 0.01);
  EXPECT_NEAR(sj.at("e_range")[1].get<double>(), 0.92, 0.01);

  TruthOptions fixed;
  fixed.contact_s = 1e-4;
  EXPECT_EQ(CodeOf([&] { ImpactsFromLaw(ViscoScene(5e-7), fixed); }), ErrorCode::kBadParameter);
  Scene unknown = SteelScene();
  unknown.law.name = "no-such-law";
  EXPECT_EQ(CodeOf([&] { ImpactsFromLaw(unknown); }), ErrorCode::kBadParameter);
  EXPECT_EQ(CodeOf([&] { ImpactsFromLaw(ViscoScene(-1.0)); }), ErrorCode::kBadParameter);
  Scene bad = ViscoScene(5e-7);
  bad.drop.height_m = -1.0;
  EXPECT_EQ(CodeOf([&] { ImpactsFromLaw(bad); }), ErrorCode::kBadScene);
}

TEST(TruthFromLaw, SynthesizeAndTruthJsonSayWhereTheImpactsCameFrom) {
  SynthSpec spec = SynthPreset("steel-copper");
  spec.scene = ViscoScene(5e-7);
  spec.truth_source = TruthSource::kLaw;
  spec.render = Quiet(48000);
  const SynthResult r = Synthesize(spec);
  Scene at = spec.scene;
  at.drop.first_impact_time_s = spec.drops[0].first_impact_s;
  const auto direct = ImpactsFromLaw(at, spec.truth);
  ASSERT_EQ(r.truth.size(), 1u);
  ASSERT_EQ(r.truth[0].size(), direct.size());
  for (std::size_t k = 0; k < direct.size(); ++k) EXPECT_EQ(r.truth[0][k].time_s, direct[k].time_s);
  const nlohmann::json j = TruthJson(spec, r);
  EXPECT_EQ(j.at("truth_source"), "law");
  EXPECT_FALSE(j.contains("restitution"));
  EXPECT_EQ(j.at("law").at("name"), "hertz-viscoelastic");
  EXPECT_EQ(j.at("law").at("parameters").at("A").get<double>(), 5e-7);
  EXPECT_GT(j.at("law").at("parameters").at("k").get<double>(), 1e9);  // the materials' default
  EXPECT_EQ(j.at("e_range")[0].get<double>(), direct.front().e());
  EXPECT_EQ(j.at("e_range")[1].get<double>(), direct.back().e());
  // The restitution source is unchanged and says so.
  spec.truth_source = TruthSource::kRestitution;
  const nlohmann::json jr = TruthJson(spec, Synthesize(spec));
  EXPECT_EQ(jr.at("truth_source"), "restitution");
  EXPECT_TRUE(jr.contains("restitution"));
  EXPECT_FALSE(jr.contains("law"));
}

// ---- rendering -------------------------------------------------------------------------------

RenderOptions Quiet(double rate_hz) {
  RenderOptions o;
  o.sample_rate_hz = rate_hz;
  o.snr_db.reset();
  o.hum_hz = 0;
  o.distractors = 0;
  o.tail_s = 0.3;
  return o;
}

TruthImpact Imp(double t, double v, double contact_s) {
  return TruthImpact{t, v, 0.8 * v, contact_s};
}

// The modal response to the half-sine pulse is computed in closed form; check it against a
// brute-force convolution integral (midpoint rule, 4000 steps over the pulse).
TEST(Render, ModeResponseMatchesNumericalConvolution) {
  // Two modes: their relative level checks the pulse normalisation, not only the shape.
  const double rate = 48000, tau = 3.1e-4, onset = 0.0100123;
  const std::vector<Mode> modes{{1730.0, 0.02, 1.0}, {5210.0, 0.005, 0.6}};
  RenderOptions o = Quiet(rate);
  o.plate_modes = modes;
  o.click_gain = 0.0;
  o.duration_s = 0.05;
  const Recording r = RenderRecording(std::vector<TruthImpact>{Imp(onset, 1.0, tau)}, o);
  const auto& x = r.channels[0];
  std::vector<double> ref(x.size(), 0.0);
  const int steps = 4000;
  for (std::size_t n = 0; n < x.size(); ++n) {
    const double t = static_cast<double>(n) / rate - onset;
    if (t <= 0) continue;
    const double u = std::min(t, tau);
    double acc = 0;
    for (int j = 0; j < steps; ++j) {
      const double s = (j + 0.5) * u / steps;
      const double force = M_PI / (2 * tau) * std::sin(M_PI * s / tau);  // unit area
      for (const Mode& m : modes) {
        acc += force * m.gain * std::exp(-(t - s) / m.decay_s) *
               std::sin(2 * M_PI * m.freq_hz * (t - s));
      }
    }
    ref[n] = acc * u / steps;
  }
  double ref_peak = 0;
  for (double v : ref) ref_peak = std::max(ref_peak, std::fabs(v));
  const double scale = o.peak_level / ref_peak;  // the renderer normalises its peak
  for (std::size_t n = 0; n < x.size(); ++n) {
    ASSERT_NEAR(x[n], ref[n] * scale, 2e-6) << "sample " << n;
  }
}

std::size_t FirstNonZero(const std::vector<float>& x) {
  for (std::size_t n = 0; n < x.size(); ++n) {
    if (x[n] != 0.0f) return n;
  }
  return x.size();
}

TEST(Render, SoundStartsExactlyAtTheOnsetInEveryChannel) {
  for (double rate : {8000.0, 44100.0, 48000.0, 384000.0}) {
    RenderOptions o = Quiet(rate);
    o.latency_s = 7.3e-4;
    o.channels = {ChannelSpec{1.0, 0.0}, ChannelSpec{0.5, 3.1e-4}};
    const double t = 0.1234567;
    const Recording r = RenderRecording(std::vector<TruthImpact>{Imp(t, 2.0, 3e-5)}, o);
    ASSERT_EQ(r.channels.size(), 2u);
    for (std::size_t c = 0; c < 2; ++c) {
      const double onset = t + o.latency_s + o.channels[c].delay_s;
      // Causal: nothing before the onset, sound from the first sample after it.
      EXPECT_EQ(FirstNonZero(r.channels[c]), static_cast<std::size_t>(std::floor(onset * rate)) + 1)
          << rate << " Hz, channel " << c;
    }
    EXPECT_NEAR(r.drops[0][0].onset_s, t + o.latency_s, 1e-15);
  }
}

TEST(Render, EchoIsADelayedScaledCopy) {
  RenderOptions o = Quiet(48000);
  o.duration_s = 0.2;
  const std::vector<TruthImpact> one{Imp(0.05, 1.5, 4e-5)};
  const Recording dry = RenderRecording(one, o);
  o.echoes = {Echo{6e-3, 0.3}};
  const Recording wet = RenderRecording(one, o);
  const auto& a = dry.channels[0];
  const auto& b = wet.channels[0];
  // Both are normalised to the same peak; undo that with the ratio at the direct sound.
  const std::size_t echo_start = static_cast<std::size_t>(std::floor((0.05 + 6e-3) * 48000)) + 1;
  const double k = b[echo_start - 10] / a[echo_start - 10];
  for (std::size_t n = 0; n < echo_start; ++n) ASSERT_NEAR(b[n], k * a[n], 1e-6) << n;
  const auto shift = static_cast<std::size_t>(6e-3 * 48000);  // 288 samples: exact
  for (std::size_t n = echo_start; n < echo_start + 500; ++n) {
    ASSERT_NEAR(b[n], k * (a[n] + 0.3 * a[n - shift]), 1e-6) << n;
  }
}

TEST(Render, ChannelsHearTheModesDifferentlyWithModeSpread) {
  RenderOptions o = Quiet(48000);
  o.duration_s = 0.3;
  o.channels = {ChannelSpec{1.0, 0.0, 0.0}, ChannelSpec{0.5, 0.0, 0.0}};
  const std::vector<TruthImpact> one{Imp(0.05, 1.5, 4e-5)};
  const Recording same = RenderRecording(one, o);
  for (std::size_t n = 0; n < same.channels[0].size(); n += 37) {
    ASSERT_NEAR(same.channels[1][n], 0.5 * same.channels[0][n], 1e-7);
  }
  o.channels[1].mode_spread_db = 6.0;
  const Recording spread = RenderRecording(one, o);
  double worst = 0;
  for (std::size_t n = 0; n < spread.channels[0].size(); ++n) {
    worst = std::max(worst, std::fabs(spread.channels[1][n] - 0.5 * spread.channels[0][n]));
  }
  EXPECT_GT(worst, 0.02);                                        // not a scaled copy any more
  EXPECT_EQ(RenderRecording(one, o).channels, spread.channels);  // still deterministic
  // The truth reports each channel's own level.
  const auto& imp = spread.drops[0][0];
  ASSERT_EQ(imp.channel_amplitude.size(), 2u);
  double peak1 = 0;
  for (float v : spread.channels[1]) peak1 = std::max(peak1, std::fabs(double(v)));
  EXPECT_NEAR(imp.channel_amplitude[1], peak1, 1e-6);  // a single impact: its peak is the file's
  EXPECT_EQ(imp.channel_amplitude[0], imp.amplitude);
}

TEST(Render, NoImpactsGivesNoiseHumAndDistractorsOnly) {
  RenderOptions o = Quiet(16000);
  o.snr_db = 30.0;
  o.distractors = 3;
  try {
    RenderRecording(std::vector<TruthImpact>{}, o);
    FAIL() << "no impacts and no duration accepted";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  }
  o.duration_s = 2.0;
  const Recording r = RenderRecording(std::vector<TruthImpact>{}, o);
  ASSERT_EQ(r.channels[0].size(), 32000u);
  EXPECT_TRUE(r.drops.empty() || r.drops[0].empty());
  EXPECT_EQ(r.distractors.size(), 3u);
  double s2 = 0;
  for (float v : r.channels[0]) s2 += double(v) * v;
  // Noise (0.5 * 10^-1.5 RMS) plus three short bursts: the RMS is the noise's within 20 %.
  EXPECT_NEAR(std::sqrt(s2 / 32000.0), 0.5 * std::pow(10.0, -1.5),
              0.2 * 0.5 * std::pow(10.0, -1.5));
  o.snr_db.reset();
  o.distractors = 0;
  const Recording silent = RenderRecording(std::vector<TruthImpact>{}, o);
  for (float v : silent.channels[0]) ASSERT_EQ(v, 0.0f);
}

TEST(Render, TruthIsIndependentOfTheSampleRate) {
  std::vector<std::vector<TruthImpact>> truths;
  for (double rate : {16000.0, 48000.0, 96000.0}) {
    SynthSpec s = SynthPreset("steel-copper");
    s.render.sample_rate_hz = rate;
    const SynthResult r = Synthesize(s);
    EXPECT_EQ(r.recording.sample_rate_hz, rate);
    EXPECT_NEAR(r.recording.duration_s(),
                r.truth[0].back().time_s + s.render.latency_s + s.render.tail_s, 1.0 / rate);
    truths.push_back(r.truth[0]);
  }
  for (std::size_t i = 1; i < truths.size(); ++i) {
    ASSERT_EQ(truths[i].size(), truths[0].size());
    for (std::size_t k = 0; k < truths[0].size(); ++k) {
      EXPECT_EQ(truths[i][k].time_s, truths[0][k].time_s);
      EXPECT_EQ(truths[i][k].v_in_m_s, truths[0][k].v_in_m_s);
    }
  }
}

TEST(Render, SameSeedIsBitIdenticalOtherSeedDiffers) {
  SynthSpec s = SynthPreset("phone-16k");  // noise, hum, distractors, clipping: all random parts
  const SynthResult a = Synthesize(s);
  const SynthResult b = Synthesize(s);
  ASSERT_EQ(a.recording.channels, b.recording.channels);
  ASSERT_EQ(a.recording.distractors.size(), 6u);
  s.render.seed += 1;
  const SynthResult c = Synthesize(s);
  ASSERT_EQ(c.recording.channels[0].size(), a.recording.channels[0].size());
  std::size_t differ = 0;
  for (std::size_t n = 0; n < a.recording.channels[0].size(); ++n) {
    differ += a.recording.channels[0][n] != c.recording.channels[0][n];
  }
  EXPECT_GT(differ, a.recording.channels[0].size() / 2);
  EXPECT_NE(a.recording.distractors[0].time_s, c.recording.distractors[0].time_s);
  // The truth is physics, not chance.
  EXPECT_EQ(a.truth[0].size(), c.truth[0].size());
  EXPECT_EQ(a.truth[0].back().time_s, c.truth[0].back().time_s);
}

// SNR measured on the rendered samples: peak of the file over the RMS of the lead-in (noise
// only, before the first onset).
double MeasuredSnrDb(const std::vector<float>& x, double rate, double first_onset_s) {
  const auto n_lead = static_cast<std::size_t>((first_onset_s - 0.001) * rate);
  double s2 = 0, peak = 0;
  for (std::size_t n = 0; n < n_lead; ++n) s2 += double(x[n]) * x[n];
  for (float v : x) peak = std::max(peak, std::fabs(double(v)));
  return 20 * std::log10(peak / std::sqrt(s2 / static_cast<double>(n_lead)));
}

TEST(Render, SnrOfTheFileMatchesTheRequest) {
  // (Below ~25 dB the noise riding on the peak sample biases this simple peak measurement
  // upwards by > 0.5 dB; the noise RMS itself is exact at any SNR, checked first.)
  for (NoiseColor color : {NoiseColor::kWhite, NoiseColor::kPink}) {
    for (double snr : {10.0, 30.0, 40.0, 50.0}) {
      SynthSpec s = SynthPreset("steel-copper");
      s.render.hum_hz = 0;
      s.render.snr_db = snr;
      s.render.noise_color = color;
      s.render.channels = {ChannelSpec{1.0, 0.0}, ChannelSpec{0.7, 1e-4}};
      const SynthResult r = Synthesize(s);
      const double onset = r.recording.drops[0][0].onset_s;
      const auto& x0 = r.recording.channels[0];
      const auto n_lead = static_cast<std::size_t>((onset - 0.001) * 48000);
      double s2 = 0;
      for (std::size_t n = 0; n < n_lead; ++n) s2 += double(x0[n]) * x0[n];
      const double expected_rms = 0.5 * std::pow(10, -snr / 20);
      EXPECT_NEAR(r.recording.noise_rms, expected_rms, 1e-12);
      EXPECT_NEAR(std::sqrt(s2 / double(n_lead)) / expected_rms, 1.0, 0.03) << snr;
      if (snr < 25) continue;
      EXPECT_NEAR(MeasuredSnrDb(x0, 48000, onset), snr, 1.0)
          << "white=" << (color == NoiseColor::kWhite);
      // Same noise RMS in every channel: gain 0.7 gives 3.1 dB less SNR.
      EXPECT_NEAR(MeasuredSnrDb(r.recording.channels[1], 48000, onset), snr + 20 * std::log10(0.7),
                  1.0);
      // Per-impact SNRs in the truth are consistent with the global one.
      EXPECT_LE(r.recording.drops[0][0].snr_db, snr + 1e-9);
      EXPECT_GT(r.recording.drops[0][0].snr_db, snr - 3.0);
    }
  }
}

TEST(Render, LaterImpactsAreQuieterWithTheAmplitudeExponent) {
  SynthSpec s = SynthPreset("steel-copper");
  const SynthResult r = Synthesize(s);
  const auto& d = r.recording.drops[0];
  ASSERT_GT(d.size(), 40u);
  EXPECT_GT(d[0].amplitude, 10 * d[40].amplitude);
  // amplitude ~ v_in^1 for short pulses: ratio within 10 % of the speed ratio.
  EXPECT_NEAR(d[20].amplitude / d[0].amplitude, d[20].truth.v_in_m_s / d[0].truth.v_in_m_s,
              0.1 * d[20].truth.v_in_m_s / d[0].truth.v_in_m_s);
}

TEST(Render, ClippingWhenAskedAndOnlyThen) {
  const testing_util::ScratchDir scratch("bc_synth_clip");
  const fs::path& dir = scratch.path();
  for (bool clip : {false, true}) {
    SynthSpec s = SynthPreset("phone-16k");
    if (!clip) s.render.clip_level.reset();
    const SynthResult r = Synthesize(s);
    double peak = 0;
    for (float v : r.recording.channels[0]) peak = std::max(peak, std::fabs(double(v)));
    if (clip) {
      EXPECT_NEAR(peak, 0.25, 1e-6);
      EXPECT_TRUE(r.recording.drops[0][0].clipped);
    } else {
      EXPECT_GT(peak, 0.3);
      EXPECT_FALSE(r.recording.drops[0][0].clipped);
    }
    const std::string path = (dir / (clip ? "c.wav" : "n.wav")).string();
    WriteAudio(path, r.recording.channels, r.recording.sample_rate_hz, AudioWriteOptions{"FLOAT"});
    const Audio a = ReadAudio(path);
    EXPECT_EQ(a.clipping[0].clipped(), clip);
  }
}

TEST(Render, DistractorsKeepAwayFromImpactsAndAreHeard) {
  SynthSpec s = SynthPreset("steel-copper");
  s.render.snr_db.reset();
  s.render.hum_hz = 0;
  s.render.distractors = 5;
  s.render.distractor_db = -20;
  const SynthResult with = Synthesize(s);
  s.render.distractors = 0;
  const SynthResult without = Synthesize(s);
  ASSERT_EQ(with.recording.distractors.size(), 5u);
  for (const Distractor& d : with.recording.distractors) {
    for (const auto& i : with.recording.drops[0]) EXPECT_GT(std::fabs(i.onset_s - d.time_s), 0.010);
    EXPECT_LE(d.amplitude, 0.5 * std::pow(10, -20.0 / 20) + 1e-12);
    // The difference between the two renderings is there, right after the distractor time.
    const auto n = static_cast<std::size_t>(d.time_s * 48000);
    double diff = 0;
    for (std::size_t j = n; j < n + 480 && j < with.recording.channels[0].size(); ++j) {
      diff = std::max(diff, std::fabs(double(with.recording.channels[0][j]) -
                                      without.recording.channels[0][j]));
    }
    EXPECT_GT(diff, 0.3 * d.amplitude);
    EXPECT_LT(diff, 1.01 * d.amplitude + 1e-6);
  }
}

TEST(Render, RejectsBadOptionsAndImpacts) {
  auto code = [](const RenderOptions& o, std::vector<TruthImpact> imp) {
    try {
      RenderRecording(imp, o);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kOk;
  };
  const std::vector<TruthImpact> ok{Imp(0.1, 1.0, 3e-5)};
  RenderOptions o = Quiet(48000);
  EXPECT_EQ(code(o, ok), ErrorCode::kOk);
  for (auto mutate : std::vector<std::function<void(RenderOptions&)>>{
           [](RenderOptions& r) { r.sample_rate_hz = 4000; },
           [](RenderOptions& r) { r.sample_rate_hz = 44100.5; },
           [](RenderOptions& r) { r.channels.clear(); },
           [](RenderOptions& r) { r.channels[0].gain = 0; },
           [](RenderOptions& r) { r.snr_db = std::nan(""); },
           [](RenderOptions& r) { r.clip_level = 0.0; },
           [](RenderOptions& r) {
             r.plate_modes = {{30000, 0.1, 1}}, r.click_gain = 0;
           },
           [](RenderOptions& r) { r.duration_s = 0.05; },  // ends before the impact
       }) {
    RenderOptions bad = Quiet(48000);
    mutate(bad);
    EXPECT_EQ(code(bad, ok), ErrorCode::kBadParameter);
  }
  EXPECT_EQ(code(o, {Imp(-0.1, 1.0, 0)}), ErrorCode::kBadParameter);
  EXPECT_EQ(code(o, {Imp(0.1, std::nan(""), 0)}), ErrorCode::kBadParameter);
  EXPECT_EQ(code(o, {Imp(0.1, 1.0, -1e-3)}), ErrorCode::kBadParameter);
}

// ---- presets and truth JSON -----------------------------------------------------------------

TEST(Presets, AllRenderAndDescribeWhatTheySay) {
  for (const std::string& name : SynthPresetNames()) {
    const SynthSpec s = SynthPreset(name);
    std::string err;
    ASSERT_TRUE(s.IsValid(&err)) << name << ": " << err;
    const SynthResult r = Synthesize(s);
    ASSERT_EQ(r.truth.size(), s.drops.size()) << name;
    for (const auto& d : r.truth) {
      ASSERT_GT(d.size(), 10u) << name;
      for (std::size_t k = 2; k < d.size(); ++k) {  // intervals shrink
        EXPECT_LT(d[k].time_s - d[k - 1].time_s, d[k - 1].time_s - d[k - 2].time_s) << name;
      }
    }
  }
  EXPECT_EQ(SynthPreset("steel-copper").render.sample_rate_hz, 48000);
  EXPECT_EQ(SynthPreset("glass-glass").render.sample_rate_hz, 96000);
  EXPECT_EQ(SynthPreset("phone-16k").render.sample_rate_hz, 16000);
  EXPECT_EQ(SynthPreset("pingpong-wood").scene.effects.drag, DragModel::kQuadratic);
  EXPECT_EQ(SynthPreset("rubber-wood").truth.contact_s.value_or(0), 1.4e-3);
  EXPECT_EQ(SynthPreset("two-drops").drops.size(), 2u);
  const double e_steel = SynthPreset("steel-copper").restitution(std::sqrt(2 * kG * 0.2));
  EXPECT_NEAR(e_steel, 0.92, 0.005);
  try {
    SynthPreset("tuba");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  }
}

// The presets' scenes come from data/scenes/*.toml (the one source of their ball, surface, drop
// and effects): each preset's scene equals its file read from the source tree, the embedded copy
// is that file byte for byte, and every file in data/scenes is a preset's scene or an example
// that README.md names (no orphan scene that nothing uses or documents).
TEST(Presets, SceneIsItsBundledTomlFile) {
  const std::filesystem::path dir = std::filesystem::path(BOUNCECAL_SOURCE_DIR) / "data/scenes";
  std::set<std::string> preset_files;
  for (const std::string& name : SynthPresetNames()) {
    SCOPED_TRACE(name);
    const std::string file = SynthPresetSceneFile(name);
    preset_files.insert(file);
    Scene from_disk = LoadSceneFile((dir / (file + ".toml")).string());
    from_disk.source.clear();  // a preset's scene has no source (not a file the user gave)
    EXPECT_EQ(SynthPreset(name).scene, from_disk);
  }
  EXPECT_EQ(SynthPresetSceneFile("two-drops"), "steel-copper");
  EXPECT_EQ(SynthPreset("pingpong-wood").scene.drop.height_m, 0.30);  // a value from the file

  std::ifstream readme_in(std::string(BOUNCECAL_SOURCE_DIR) + "/README.md");
  const std::string readme((std::istreambuf_iterator<char>(readme_in)), {});
  std::set<std::string> on_disk;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".toml") continue;
    const std::string name = entry.path().stem().string();
    on_disk.insert(name);
    SCOPED_TRACE(name);
    std::ifstream in(entry.path(), std::ios::binary);
    const std::string text((std::istreambuf_iterator<char>(in)), {});
    EXPECT_EQ(BundledSceneText(name), text);
    EXPECT_TRUE(preset_files.count(name) > 0 ||
                readme.find("data/scenes/" + name + ".toml") != std::string::npos)
        << "data/scenes/" << name << ".toml is neither a preset's scene nor named in README.md";
  }
  const std::vector<std::string> bundled = BundledSceneNames();
  EXPECT_EQ(std::set<std::string>(bundled.begin(), bundled.end()), on_disk);
  try {
    BundledScene("tuba");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
    EXPECT_NE(std::string(e.what()).find("known: compliant-plate"), std::string::npos) << e.what();
  }
}

TEST(Presets, TwoDropsAreSeparateSequencesInOneFile) {
  const SynthResult r = Synthesize(SynthPreset("two-drops"));
  ASSERT_EQ(r.truth.size(), 2u);
  EXPECT_DOUBLE_EQ(r.truth[1].front().time_s, 6.5);
  EXPECT_LT(r.truth[0].back().time_s, r.truth[1].front().time_s - 0.5);
  EXPECT_LT(r.truth[1].front().v_in_m_s, r.truth[0].front().v_in_m_s);  // 0.12 m vs 0.2 m
  EXPECT_EQ(r.recording.channels.size(), 2u);
}

TEST(TruthJson, HasTheContractKeys) {
  const SynthSpec s = SynthPreset("two-drops");
  const SynthResult r = Synthesize(s);
  const nlohmann::json j = TruthJson(s, r);
  EXPECT_EQ(j["generator"].get<std::string>().rfind("bouncecal synth ", 0), 0u);
  EXPECT_EQ(j["sample_rate_hz"].get<double>(), 48000.0);
  EXPECT_EQ(j["channels"].get<int>(), 2);
  EXPECT_EQ(j["seed"].get<std::uint64_t>(), s.render.seed);
  ASSERT_EQ(j["drops"].size(), 2u);
  const auto& i0 = j["drops"][1]["impacts"][3];
  const auto& t0 = r.recording.drops[1][3];
  EXPECT_EQ(i0["time_s"].get<double>(), t0.truth.time_s);
  EXPECT_EQ(i0["onset_s"].get<double>(), t0.onset_s);
  EXPECT_DOUBLE_EQ(i0["e"].get<double>(), t0.truth.v_out_m_s / t0.truth.v_in_m_s);
  for (const char* key : {"v_in_m_s", "v_out_m_s", "contact_s", "amplitude", "snr_db", "clipped"}) {
    EXPECT_TRUE(i0.contains(key)) << key;
  }
  EXPECT_EQ(j["distractors"].size(), 4u);
  EXPECT_EQ(j["scene"]["ball"]["diameter_m"].get<double>(), 0.01);
  EXPECT_EQ(j["scene"]["drop"]["height_m"].get<double>(), 0.2);
  EXPECT_EQ(j["restitution"]["model"], "power-law");
  // The embedded scene reads back to the same scene.
  const Scene back = ParseScene(j["scene_toml"].get<std::string>(), "truth");
  EXPECT_EQ(back.ball, s.scene.ball);
  EXPECT_EQ(back.drop.height_m, s.scene.drop.height_m);
}

TEST(TruthJson, LoadTruthReadsBackWhatWasWritten) {
  const testing_util::ScratchDir scratch("bc_truth");
  const fs::path& dir = scratch.path();
  const SynthSpec s = SynthPreset("two-drops");
  const SynthResult r = Synthesize(s);
  const std::string path = (dir / "t.truth.json").string();
  std::ofstream(path) << TruthJson(s, r).dump(2);
  const TruthFile t = LoadTruth(path);
  EXPECT_EQ(t.sample_rate_hz, 48000.0);
  EXPECT_EQ(t.latency_s, s.render.latency_s);
  ASSERT_EQ(t.drops.size(), 2u);
  for (std::size_t d = 0; d < 2; ++d) {
    ASSERT_EQ(t.drops[d].size(), r.recording.drops[d].size());
    for (std::size_t k = 0; k < t.drops[d].size(); ++k) {
      EXPECT_EQ(t.drops[d][k].onset_s, r.recording.drops[d][k].onset_s);  // exact round trip
      EXPECT_EQ(t.drops[d][k].truth.v_out_m_s, r.recording.drops[d][k].truth.v_out_m_s);
      EXPECT_EQ(t.drops[d][k].snr_db, r.recording.drops[d][k].snr_db);
      EXPECT_EQ(t.drops[d][k].channel_snr_db, r.recording.drops[d][k].channel_snr_db);
    }
  }
  ASSERT_EQ(t.distractors.size(), r.recording.distractors.size());
  EXPECT_EQ(t.distractors[2].time_s, r.recording.distractors[2].time_s);

  auto code = [](const std::string& p) {
    try {
      LoadTruth(p);
    } catch (const Error& e) {
      return e.code();
    }
    return ErrorCode::kOk;
  };
  EXPECT_EQ(code((dir / "none.json").string()), ErrorCode::kInputMissing);
  std::ofstream(dir / "text.json") << "not json";
  EXPECT_EQ(code((dir / "text.json").string()), ErrorCode::kBadParameter);
  std::ofstream(dir / "other.json") << R"({"generator": "bouncecal synth 0.1.0", "drops": 3})";
  EXPECT_EQ(code((dir / "other.json").string()), ErrorCode::kBadParameter);
}

// The bundled default recording is what data/README.md says: impacts simulated with the contact
// law of data/default_steel_copper.toml (hertz-viscoelastic, A = 5.16e-7 s, e = 0.92 at the
// first impact), rendered with the steel-copper preset's sound and seed 1 (regenerate with
// tools/make_default_recording.sh after changing the renderer or the simulator).
TEST(DefaultRecording, IsTheDocumentedRenderingOfItsScene) {
  const std::string root = BOUNCECAL_SOURCE_DIR;
  const std::string flac = root + "/data/default_steel_copper.flac";
  const Audio a = ReadAudio(flac);
  EXPECT_EQ(a.info.format, "FLAC");
  EXPECT_EQ(a.info.sample_rate_hz, 48000);
  EXPECT_EQ(a.info.channels, 1);
  EXPECT_GE(a.info.duration_s(), 8.0);
  EXPECT_LE(a.info.duration_s(), 10.0);
  EXPECT_LT(fs::file_size(flac), 1000000u);

  SynthSpec spec = SynthPreset("steel-copper");
  spec.scene = LoadSceneFile(root + "/data/default_steel_copper.toml");
  EXPECT_EQ(spec.scene.law.name, "hertz-viscoelastic");
  EXPECT_EQ(spec.scene.law.parameters.at("A"), 5.16e-7);
  spec.truth_source = TruthSource::kLaw;
  spec.render.seed = 1;
  const SynthResult r = Synthesize(spec);
  // The documented numbers (data/README.md).
  ASSERT_EQ(r.truth.size(), 1u);
  EXPECT_EQ(r.truth[0].size(), 113u);
  EXPECT_DOUBLE_EQ(r.truth[0].front().time_s, 1.5);
  EXPECT_NEAR(r.truth[0].front().e(), 0.920, 5e-4);
  EXPECT_NEAR(r.truth[0].back().e(), 0.970, 5e-4);
  ASSERT_EQ(r.recording.channels[0].size(), a.channels[0].size());
  double worst = 0;
  for (std::size_t n = 0; n < a.channels[0].size(); ++n) {
    worst = std::max(worst, std::fabs(double(a.channels[0][n]) - r.recording.channels[0][n]));
  }
  EXPECT_LE(worst, 1.5 / 32768.0);  // 16-bit quantisation only

  const TruthFile t = LoadTruth(root + "/data/default_steel_copper.truth.json");
  EXPECT_EQ(t.document.at("truth_source"), "law");
  EXPECT_EQ(t.document.at("law").at("name"), "hertz-viscoelastic");
  ASSERT_EQ(t.drops.size(), 1u);
  ASSERT_EQ(t.drops[0].size(), r.truth[0].size());
  // The impacts come from the adaptive contact integrator (rel. tolerance 1e-9): a change in its
  // floating-point order moves them by ~1e-13 s, so the times agree to 1 ns (1/20000 sample).
  for (std::size_t k = 0; k < t.drops[0].size(); ++k) {
    EXPECT_NEAR(t.drops[0][k].truth.time_s, r.truth[0][k].time_s, 1e-9);
    EXPECT_NEAR(t.drops[0][k].onset_s, r.recording.drops[0][k].onset_s, 1e-9);
    EXPECT_NEAR(t.drops[0][k].truth.v_out_m_s, r.truth[0][k].v_out_m_s, 1e-9);
  }
}

// ---- the command -----------------------------------------------------------------------------

class SynthCli : public ::testing::Test {
 protected:
  testing_util::ScratchDir scratch_{"bc_synth_cli"};
  const fs::path& dir_ = scratch_.path();
  int Run(const std::string& args) {
    const std::string cmd = std::string(BOUNCECAL_BINARY) + " synth " + args + " >" +
                            (dir_ / "stdout").string() + " 2>" + (dir_ / "stderr").string();
    const int rc = std::system(cmd.c_str());
    return WIFEXITED(rc) ? WEXITSTATUS(rc) : -1;
  }
  std::string Slurp(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    std::stringstream s;
    s << in.rdbuf();
    return s.str();
  }
};

TEST_F(SynthCli, WritesAudioAndTruthAndRefusesToOverwrite) {
  const std::string out = (dir_ / "d.wav").string();
  ASSERT_EQ(Run("--preset rubber-wood --seed 9 --rate 22050 -o " + out), 0)
      << Slurp(dir_ / "stderr");
  ASSERT_TRUE(fs::exists(dir_ / "d.truth.json"));
  const Audio a = ReadAudio(out);
  EXPECT_EQ(a.info.sample_rate_hz, 22050);
  const auto truth = nlohmann::json::parse(Slurp(dir_ / "d.truth.json"));
  EXPECT_EQ(truth["seed"].get<int>(), 9);
  EXPECT_EQ(truth["sample_rate_hz"].get<double>(), 22050);
  EXPECT_NEAR(truth["duration_s"].get<double>(), a.info.duration_s(), 1e-9);
  const std::string before = Slurp(out);
  // Exists: refused with the output code, file untouched.
  EXPECT_EQ(Run("--preset rubber-wood --seed 10 --rate 22050 -o " + out), 11);
  EXPECT_NE(Slurp(dir_ / "stderr").find("exists"), std::string::npos);
  EXPECT_EQ(Slurp(out), before);
  // --force with the same seed: byte-identical file.
  EXPECT_EQ(Run("--preset rubber-wood --seed 9 --rate 22050 --force -o " + out), 0);
  EXPECT_EQ(Slurp(out), before);
}

TEST_F(SynthCli, SceneFlagsOverrideThePresetScene) {
  const std::string out = (dir_ / "h.flac").string();
  ASSERT_EQ(Run("--preset steel-copper --height 0.1 --restitution 0.8 --no-noise --channels 2 "
                "--json -o " +
                out),
            0)
      << Slurp(dir_ / "stderr");
  const auto summary = nlohmann::json::parse(Slurp(dir_ / "stdout"));
  EXPECT_EQ(summary["channels"].get<int>(), 2);
  const auto truth = nlohmann::json::parse(Slurp(dir_ / "h.truth.json"));
  const auto& imps = truth["drops"][0]["impacts"];
  EXPECT_NEAR(imps[0]["v_in_m_s"].get<double>(), std::sqrt(2 * kG * 0.1), 1e-12);
  EXPECT_NEAR(imps[1]["e"].get<double>(), 0.8, 1e-12);
  EXPECT_EQ(truth["scene"]["ball"]["material"], "steel");  // the rest of the preset kept
}

// --truth-from auto takes the law when the scene file or the flags name one.
TEST_F(SynthCli, TruthFromTheSceneLawWhenOneIsNamed) {
  const fs::path scene = dir_ / "visco.toml";
  std::ofstream(scene) << "[ball]\ndiameter_m = 0.01\nmaterial = \"steel\"\n[drop]\n"
                          "height_m = 0.1\n[law]\nname = \"hertz-viscoelastic\"\n"
                          "[law.parameters]\nA = 4e-7\n";
  auto source = [&](const std::string& args) {
    const std::string out = (dir_ / "t.wav").string();
    const int rc = Run(args + " --no-noise --tail 0.1 --force -o " + out);
    EXPECT_EQ(rc, 0) << args << ": " << Slurp(dir_ / "stderr");
    if (rc != 0) return nlohmann::json();
    return nlohmann::json::parse(Slurp(dir_ / "t.truth.json"));
  };
  const auto by_file = source("--scene " + scene.string());
  ASSERT_FALSE(by_file.is_null());
  EXPECT_EQ(by_file["truth_source"], "law");
  EXPECT_EQ(by_file["law"]["parameters"]["A"].get<double>(), 4e-7);
  Scene s = LoadSceneFile(scene.string());
  s.drop.first_impact_time_s = by_file["drops"][0]["impacts"][0]["time_s"].get<double>();
  const auto imp = ImpactsFromLaw(s);
  ASSERT_EQ(by_file["drops"][0]["impacts"].size(), imp.size());
  EXPECT_EQ(by_file["drops"][0]["impacts"][5]["time_s"].get<double>(), imp[5].time_s);

  const auto by_flags = source("--law hertz-viscoelastic --set A=3e-7");
  EXPECT_EQ(by_flags["truth_source"], "law");
  EXPECT_EQ(by_flags["law"]["parameters"]["A"].get<double>(), 3e-7);
  const auto forced = source("--scene " + scene.string() + " --truth-from restitution");
  EXPECT_EQ(forced["truth_source"], "restitution");
  EXPECT_FALSE(forced.contains("law"));
  EXPECT_EQ(source("")["truth_source"], "restitution");  // the preset alone: its e(v)

  const std::string out = (dir_ / "x.wav").string();
  EXPECT_EQ(Run("--truth-from banana -o " + out), 9);
  EXPECT_EQ(Run("--truth-from law --restitution 0.8 -o " + out), 9);
  EXPECT_EQ(Run("--law hertz-viscoelastic --contact-s 1e-4 -o " + out), 9);
  EXPECT_EQ(Run("--law no-such-law -o " + out), 9);
  EXPECT_FALSE(fs::exists(out));
}

// --drops with random gaps (an automated dropper) and varied drops: the drop plan (PlanDrops).
TEST_F(SynthCli, RandomGapsAndVariedDrops) {
  const std::string out = (dir_ / "rig.flac").string();
  ASSERT_EQ(Run("--preset steel-copper --height 0.03 --drops 6 --drop-gap 0.1 --drop-gap-max 1.3 "
                "--no-noise --tail 0.2 -o " +
                out),
            0)
      << Slurp(dir_ / "stderr");
  const auto rig = nlohmann::json::parse(Slurp(dir_ / "rig.truth.json"));
  ASSERT_EQ(rig["drops"].size(), 6u);
  std::set<double> gaps;
  for (std::size_t d = 1; d < 6; ++d) {
    const auto& prev = rig["drops"][d - 1]["impacts"];
    const auto& next = rig["drops"][d]["impacts"];
    const double gap =
        next[0]["time_s"].get<double>() - prev[prev.size() - 1]["time_s"].get<double>();
    EXPECT_GE(gap, 0.1 - 1e-12);
    EXPECT_LE(gap, 1.3 + 1e-12);
    gaps.insert(gap);
    // Identical drops: the same impacts, shifted.
    ASSERT_EQ(next.size(), prev.size());
    EXPECT_EQ(next[3]["v_in_m_s"], prev[3]["v_in_m_s"]);
    EXPECT_FALSE(rig["drops"][d].contains("e_shift"));  // an identical drop: the two-key form
  }
  EXPECT_EQ(gaps.size(), 5u);  // drawn, not fixed

  ASSERT_EQ(Run("--preset steel-copper --height 0.03 --drops 4 --vary-height 0.5 --vary-e 0.02 "
                "--scatter-e 0.004 --no-noise --tail 0.2 -o " +
                (dir_ / "varied.wav").string()),
            0)
      << Slurp(dir_ / "stderr");
  const auto varied = nlohmann::json::parse(Slurp(dir_ / "varied.truth.json"));
  std::set<double> heights, shifts, first_e;
  for (const auto& d : varied["drops"]) {
    const double h = d["height_m"].get<double>();
    EXPECT_GE(h, 0.015);
    EXPECT_LE(h, 0.045);
    EXPECT_LE(std::fabs(d["e_shift"].get<double>()), 0.02);
    heights.insert(h);
    shifts.insert(d["e_shift"].get<double>());
    first_e.insert(d["impacts"][0]["e"].get<double>());
    EXPECT_NEAR(d["impacts"][0]["v_in_m_s"].get<double>(), std::sqrt(2 * kG * h), 1e-9);
  }
  EXPECT_EQ(heights.size(), 4u);
  EXPECT_EQ(shifts.size(), 4u);
  EXPECT_EQ(first_e.size(), 4u);

  const std::string bad = (dir_ / "bad.wav").string();
  EXPECT_EQ(Run("--drops 3 --drop-gap 0.5 --drop-gap-max 0.2 -o " + bad), 9);
  EXPECT_NE(Slurp(dir_ / "stderr").find("--drop-gap-max"), std::string::npos)
      << Slurp(dir_ / "stderr");
  EXPECT_EQ(Run("--drops 3 --vary-height 1.5 -o " + bad), 9);
  EXPECT_NE(Slurp(dir_ / "stderr").find("--vary-height"), std::string::npos);
  EXPECT_EQ(Run("--drops 1001 -o " + bad), 9);
  EXPECT_FALSE(fs::exists(bad));
}

TEST(DropPlanTest, SameSeedSamePlanOtherSeedOtherGaps) {
  SynthSpec spec = SynthPreset("steel-copper");
  spec.scene.drop.height_m = 0.03;
  DropPlan plan;
  plan.drops = 5;
  plan.gap_min_s = 0.1;
  plan.gap_max_s = 1.3;
  plan.seed = 4;
  const auto a = PlanDrops(spec, plan), b = PlanDrops(spec, plan);
  plan.seed = 5;
  const auto c = PlanDrops(spec, plan);
  for (std::size_t i = 0; i < 5; ++i) EXPECT_EQ(a[i].first_impact_s, b[i].first_impact_s);
  EXPECT_NE(a[2].first_impact_s, c[2].first_impact_s);
  EXPECT_EQ(a[0].first_impact_s, plan.first_impact_s);
  // A fixed gap: the next drop starts exactly the gap after the last impact.
  plan.gap_max_s = plan.gap_min_s;
  const auto f = PlanDrops(spec, plan);
  EXPECT_EQ(f[1].first_impact_s, DropTruth(spec, f[0]).back().time_s + 0.1);
  plan.e_spread = 0.01;
  spec.truth_source = TruthSource::kLaw;
  EXPECT_THROW(PlanDrops(spec, plan), Error);
  plan.drops = 0;
  std::string why;
  EXPECT_FALSE(plan.IsValid(&why));
  EXPECT_NE(why.find("drops = 0"), std::string::npos) << why;
}

TEST_F(SynthCli, BadArgumentsFailCleanly) {
  const std::string out = (dir_ / "x.wav").string();
  EXPECT_EQ(Run("--preset tuba -o " + out), 9);
  EXPECT_EQ(Run("--rate 1000 -o " + out), 9);
  EXPECT_EQ(Run("--height -2 -o " + out), 9);
  EXPECT_EQ(Run("-o " + (dir_ / "x.mp3").string()), 11);
  EXPECT_EQ(Run("-o " + (dir_ / "missing" / "x.wav").string()), 11);
  EXPECT_EQ(Run("--scene " + (dir_ / "none.toml").string() + " -o " + out), 3);
  EXPECT_EQ(Run(""), 2);
  EXPECT_FALSE(fs::exists(out));
  EXPECT_FALSE(fs::exists(dir_ / "x.truth.json"));
}

}  // namespace
}  // namespace bouncecal

namespace bouncecal {
namespace {

TEST(TruthScatter, RestitutionScatterHasTheRequestedSigmaAndIsSeeded) {
  Scene s = SteelScene(1.0);
  TruthOptions o;
  o.scatter_e = 0.01;
  o.scatter_seed = 42;
  o.min_interval_s = 0.002;
  const RestitutionModel model = RestitutionModel::Constant(0.9);
  const auto a = ImpactsFromRestitution(s, model, o);
  const auto b = ImpactsFromRestitution(s, model, o);
  ASSERT_GT(a.size(), 40u);
  double s1 = 0, s2 = 0;
  for (size_t k = 0; k + 1 < a.size(); ++k) {
    EXPECT_EQ(a[k].time_s, b[k].time_s);  // same seed: the same bounces
    const double d = a[k].e() - 0.9;
    s1 += d, s2 += d * d;
  }
  const double n = static_cast<double>(a.size() - 1);
  const double sd = std::sqrt(s2 / n - (s1 / n) * (s1 / n));
  // ~45 draws: the sample sd is within 25 % of 0.01 with > 99 % probability.
  EXPECT_NEAR(sd, 0.01, 0.0025);
  o.scatter_seed = 43;
  EXPECT_NE(ImpactsFromRestitution(s, model, o)[3].time_s, a[3].time_s);
  o.scatter_e = 0.6;
  std::string err;
  EXPECT_FALSE(o.IsValid(&err));
  EXPECT_NE(err.find("scatter_e"), std::string::npos);
}

TEST(TruthScatter, LawTruthBounceByBounceAgreesWithTheSimulatorWithoutScatter) {
  // With a vanishing scatter the bounce-by-bounce path (one contact at a time, exact flights)
  // must give the simulator's sequence: measured agreement 4.6e-13 s and 5.5e-13 in e over 35
  // impacts; bound 1e-10.
  Scene s = SteelScene(0.3);
  s.law.name = "hertz-viscoelastic";
  s.law.parameters["A"] = 5e-7;
  TruthOptions plain, tiny;
  plain.min_interval_s = tiny.min_interval_s = 0.05;
  tiny.scatter_e = 1e-15;
  const auto a = ImpactsFromLaw(s, plain);
  const auto b = ImpactsFromLaw(s, tiny);
  ASSERT_EQ(a.size(), b.size());
  ASSERT_GT(a.size(), 10u);
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_NEAR(a[k].time_s, b[k].time_s, 1e-10) << k;
    EXPECT_NEAR(a[k].e(), b[k].e(), 1e-10) << k;
    EXPECT_NEAR(a[k].contact_s, b[k].contact_s, 1e-10) << k;
  }
  Scene compliant = s;
  compliant.surface.kind = Surface::Kind::kSpringMass;
  compliant.surface.mass_kg = 0.5;
  compliant.surface.stiffness_n_m = 1e6;
  compliant.effects.surface_compliance = true;
  tiny.scatter_e = 0.01;
  EXPECT_THROW(ImpactsFromLaw(compliant, tiny), Error);
}

}  // namespace
}  // namespace bouncecal
