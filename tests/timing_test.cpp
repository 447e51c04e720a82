// The local timing stage (timing.hpp): its parts, the honesty of its sigma on intervals (every
// synthetic preset, real impact sounds, exact copies of a known sound in white noise), and start
// invariance.
#include "bouncecal/acoustic/timing.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <random>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/realsound.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {
namespace {

Audio InMemory(std::vector<std::vector<float>> ch, double rate, const std::string& name) {
  Audio a;
  a.info.path = name;
  a.info.sample_rate_hz = rate;
  a.info.channels = static_cast<int>(ch.size());
  a.info.frames = static_cast<std::int64_t>(ch[0].size());
  for (std::size_t c = 0; c < ch.size(); ++c)
    a.clipping.push_back(AnalyzeClipping(ch[c], static_cast<int>(c)));
  a.channels = std::move(ch);
  return a;
}

TEST(Timing, NeighbourhoodPredictorWhitensAnArProcess) {
  // AR(2) resonance driven by white noise: the predictor fitted on a few windows returns the
  // driving noise (same check as the whole-file Whiten test in onsets_test).
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 1.0);
  const double rad = 0.99, th = 2.0 * M_PI * 0.1;
  const double a1 = 2 * rad * std::cos(th), a2 = -rad * rad;
  const std::size_t n = 60000;
  std::vector<float> x(n);
  std::vector<double> e(n);
  double y1 = 0, y2 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    e[i] = 0.01 * g(rng);
    const double y = a1 * y1 + a2 * y2 + e[i];
    x[i] = static_cast<float>(y);
    y2 = y1;
    y1 = y;
  }
  const std::vector<double> a = NeighbourhoodPredictor(x, {10000, 30000, 50000}, 8, 2000, 1000);
  ASSERT_EQ(a.size(), 9u);
  EXPECT_NEAR(a[1], -a1, 0.03);
  EXPECT_NEAR(a[2], -a2, 0.03);
  // WhitenSegment is the same filter on any segment.
  const std::vector<float> w = WhitenSegment(x, a, 20000, 21000);
  double xy = 0, xx = 0, yy = 0;
  for (std::size_t i = 0; i < w.size(); ++i) {
    xy += w[i] * e[20000 + i];
    xx += static_cast<double>(w[i]) * w[i];
    yy += e[20000 + i] * e[20000 + i];
  }
  EXPECT_GT(xy / std::sqrt(xx * yy), 0.99);
  // Both are the defined sums to the bit (they run several lags, and outputs, side by side):
  // double products in four partial sums by index mod 4, the tail into the first, then
  // (s0 + s1) + (s2 + s3).
  auto dot = [](auto pa, const float* b, std::size_t len) {
    double s4[4] = {0, 0, 0, 0};
    std::size_t k = 0;
    for (; k < (len & ~std::size_t{3}); ++k)
      s4[k % 4] += static_cast<double>(pa[k]) * static_cast<double>(b[k]);
    for (; k < len; ++k) s4[0] += static_cast<double>(pa[k]) * static_cast<double>(b[k]);
    return (s4[0] + s4[1]) + (s4[2] + s4[3]);
  };
  {
    std::vector<double> r(9, 0.0);
    for (long c : {10000L, 30000L, 50000L}) {
      const long lo = c - 2000, len = 3000;
      std::vector<double> rw(9);
      for (std::size_t lag = 0; lag < 9; ++lag)
        rw[lag] = dot(x.data() + lo + static_cast<long>(lag), x.data() + lo,
                      static_cast<std::size_t>(len) - lag);
      for (std::size_t k = 0; k < 9; ++k) r[k] += rw[k] / rw[0];
    }
    r[0] *= 1.0 + 1e-6;
    EXPECT_EQ(a, LevinsonDurbin(r, 8));
    std::vector<double> rev(a.rbegin(), a.rend());
    std::size_t differ = 0;
    for (std::size_t i = 0; i < w.size(); ++i)
      differ += w[i] != static_cast<float>(dot(rev.data(), x.data() + 20000 + i - 8, 9));
    EXPECT_EQ(differ, 0u);
  }
  // Windows of digital silence carry nothing: no whitening at all.
  EXPECT_EQ(NeighbourhoodPredictor(std::vector<float>(5000, 0.0f), {2500}, 8, 1000, 1000).size(),
            1u);
}

TEST(Timing, InterpolatedPeakIsBandLimited) {
  // Samples of a band-limited peak (sinc) centred between samples: the peak is found to a
  // hundredth of a sample (parabolic interpolation alone is off by ~0.05 here).
  for (double centre : {8.0, 8.13, 8.37, 8.5, 7.71}) {
    std::vector<double> c(17);
    for (std::size_t i = 0; i < c.size(); ++i) {
      const double d = static_cast<double>(i) - centre;
      c[i] = std::fabs(d) < 1e-12 ? 1.0 : std::sin(M_PI * d * 0.8) / (M_PI * d * 0.8);
    }
    const std::size_t at = static_cast<std::size_t>(std::lround(centre));
    double peak = 0.0;
    EXPECT_NEAR(InterpolatedPeak(c, at, &peak), centre, 0.01) << centre;
    EXPECT_NEAR(peak, 1.0, 0.01);
  }
}

TEST(Timing, OptionsValidation) {
  TimingOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why));
  o.template_s = 0.0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("template_s"), std::string::npos);
  o = TimingOptions{};
  o.noise_gain = -1.0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("noise_gain"), std::string::npos);
  Sequence s;
  EXPECT_THROW(TimeSequence({0.0f}, 0.0, &s), Error);
}

// ---- sigma_s on intervals ----------------------------------------------------------------------
// sigma_s is the part of an impact's timing error that is independent from impact to impact
// (timing.hpp): it is judged on intervals, pull = interval error / hypot(sigma_k, sigma_k+1),
// as the scoreboard does (eligible truth impacts: SNR >= 6 dB in the channel detected, >= 3 ms
// from their neighbours; one constant offset per file, the median; matched within 1 ms). The
// band [0.7, 1.4] is a factor 2 wide: sigma scaled x2 or x1/2 leaves it from anywhere inside.

struct TruthImpactAt {
  double t = 0.0;
  int drop = 0;
  bool eligible = false;
};

// The truth onsets of `rec` in channel `channel` (delays: every channel's arrival delay).
std::vector<TruthImpactAt> TruthIn(const Recording& rec, int channel,
                                   const std::vector<double>& delays) {
  const std::size_t c = static_cast<std::size_t>(std::max(channel, 0));
  const double shift = c < delays.size() ? delays[c] - delays[0] : 0.0;
  std::vector<TruthImpactAt> out;
  for (std::size_t d = 0; d < rec.drops.size(); ++d) {
    const auto& q = rec.drops[d];
    for (std::size_t k = 0; k < q.size(); ++k) {
      const double snr = c < q[k].channel_snr_db.size() ? q[k].channel_snr_db[c] : q[k].snr_db;
      const double prev = k > 0 ? q[k].onset_s - q[k - 1].onset_s : 1e9;
      const double next = k + 1 < q.size() ? q[k + 1].onset_s - q[k].onset_s : 1e9;
      out.push_back({q[k].onset_s + shift, static_cast<int>(d),
                     snr >= 6.0 && prev >= 0.003 && next >= 0.003});
    }
  }
  return out;
}

// Appends the interval pulls of one detection against its truth to *pulls.
void AppendIntervalPulls(const std::vector<TruthImpactAt>& truth, const DetectionResult& r,
                         std::vector<double>* pulls) {
  std::vector<Impact> det;
  for (const Sequence& q : r.sequences) det.insert(det.end(), q.impacts.begin(), q.impacts.end());
  if (det.empty()) return;
  auto nearest = [&](double t) {
    const Impact* best = &det.front();
    for (const Impact& i : det)
      if (std::fabs(i.time_s - t) < std::fabs(best->time_s - t)) best = &i;
    return best;
  };
  std::vector<double> offs;  // within 20 ms: a truth impact far from every detection says nothing
  for (const TruthImpactAt& t : truth)
    if (t.eligible && std::fabs(nearest(t.t)->time_s - t.t) < 0.02)
      offs.push_back(nearest(t.t)->time_s - t.t);
  if (offs.empty()) return;
  std::nth_element(offs.begin(), offs.begin() + static_cast<std::ptrdiff_t>(offs.size() / 2),
                   offs.end());
  const double offset = offs[offs.size() / 2];
  std::vector<const Impact*> match(truth.size(), nullptr);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const Impact* b = nearest(truth[i].t + offset);
    if (truth[i].eligible && std::fabs(b->time_s - truth[i].t - offset) < 1e-3) match[i] = b;
  }
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) {
    if (!match[i] || !match[i + 1] || match[i] == match[i + 1]) continue;
    if (truth[i].drop != truth[i + 1].drop) continue;
    const double err = (match[i + 1]->time_s - match[i]->time_s) - (truth[i + 1].t - truth[i].t);
    pulls->push_back(err / std::hypot(match[i]->sigma_s, match[i + 1]->sigma_s));
  }
}

double Rms(const std::vector<double>& v) {
  double ss = 0.0;
  for (double x : v) ss += x * x;
  return v.empty() ? NAN : std::sqrt(ss / static_cast<double>(v.size()));
}

void ExpectHonest(const std::vector<double>& pulls, const std::string& what) {
  const double rms = Rms(pulls);
  std::printf("%s: interval pull RMS %.2f over %zu intervals\n", what.c_str(), rms, pulls.size());
  EXPECT_GE(rms, 0.7) << what << ": sigma too large (" << pulls.size() << " intervals)";
  EXPECT_LE(rms, 1.4) << what << ": sigma too small (" << pulls.size() << " intervals)";
}

// Every synthetic preset, seeds 1, 2, ... until 40 intervals are in (at most 8 seeds; the soft
// rubber ball gives few: at least the scoreboard's 8). Measured (tools/bench_sigma, seeds 1-4):
// steel-copper 1.18-1.32, glass-glass 1.22-1.39, pingpong-wood 1.24-1.29, rubber-wood 1.10 (this
// test: 1.06 over 46 intervals with the rise onsets, 0.90 over 45 before),
// phone-16k 0.37-1.18 (9-12 intervals a file), two-drops 1.00-1.27.
class SigmaCoverage : public ::testing::TestWithParam<std::string> {};

TEST_P(SigmaCoverage, IntervalPullsAreNearOne) {
  std::vector<double> pulls;
  for (int seed = 1; seed <= 8 && pulls.size() < 40; ++seed) {
    SynthSpec spec = SynthPreset(GetParam());
    spec.render.seed = static_cast<std::uint64_t>(seed);
    const SynthResult s = Synthesize(spec);
    const Audio a = InMemory(s.recording.channels, s.recording.sample_rate_hz, GetParam());
    DetectionResult r;
    try {
      r = DetectImpacts(a, DetectOptions{});
    } catch (const Error& e) {
      // Recall is the scoreboard's business (rubber-wood: some seeds give no sequence); this
      // test judges the sigma of what is found.
      EXPECT_EQ(e.code(), ErrorCode::kNoBounces) << e.what();
      continue;
    }
    std::vector<double> delays;
    for (const ChannelSpec& c : spec.render.channels) delays.push_back(c.delay_s);
    AppendIntervalPulls(TruthIn(s.recording, r.channel, delays), r, &pulls);
  }
  ASSERT_GE(pulls.size(), 8u);
  ExpectHonest(pulls, GetParam());
}

INSTANTIATE_TEST_SUITE_P(Presets, SigmaCoverage, ::testing::ValuesIn(SynthPresetNames()),
                         [](const ::testing::TestParamInfo<std::string>& i) {
                           std::string n = i.param;
                           for (char& c : n)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

// The second source, which does not share synth's sound model (tools/realsound.cpp): a real
// impact sound of each shared recording at every impact of one drop, over that room's noise,
// at exact times (seeds 1 and 2). Measured (tools/bench_sigma, seeds 1-4): ping-pong 0.79,
// superball 0.72-0.73, tennis 0.89-1.21, basketball 0.73-1.01, rubber ball 0.71-0.91.
class RealSoundSigmaCoverage : public ::testing::TestWithParam<std::string> {};

TEST_P(RealSoundSigmaCoverage, IntervalPullsAreNearOne) {
  const std::filesystem::path wav =
      std::filesystem::path(BOUNCECAL_SHARED_RECORDINGS) / (GetParam() + ".wav");
  if (!std::filesystem::exists(wav)) {
    const char* ci = std::getenv("CI");
    if (ci != nullptr && std::string(ci) == "true")
      FAIL() << "CI=true but " << wav << " is missing";
    GTEST_SKIP() << "no " << wav << " (../shared/recordings absent)";
  }
  const SoundSource src = LoadSoundSource(wav.string());
  std::vector<double> pulls;
  for (std::uint64_t seed : {1u, 2u}) {
    RealSoundSpec spec = RealSoundSpecFor(src);
    spec.seed = spec.drops.seed = spec.truth.scatter_seed = seed;
    const RealSoundResult rs = RenderRealSound(src, spec);
    const Audio a =
        InMemory(rs.recording.channels, rs.recording.sample_rate_hz, GetParam() + ".wav");
    const DetectionResult r = DetectImpacts(a, DetectOptions{});
    AppendIntervalPulls(TruthIn(rs.recording, r.channel, {0.0}), r, &pulls);
  }
  ASSERT_GE(pulls.size(), 8u);
  ExpectHonest(pulls, GetParam());
}

INSTANTIATE_TEST_SUITE_P(Shared, RealSoundSigmaCoverage,
                         ::testing::Values("eeps_pingpong", "pfe_bouncyball_h0.9m_stereo48k",
                                           "pisa_fr4nci_tennis_h2.50m", "mth337_basketball_24k",
                                           "mth337_rubberball"),
                         [](const ::testing::TestParamInfo<std::string>& i) {
                           std::string n = i.param;
                           for (char& c : n)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

// ---- the model's parts on a sound whose truth is known to the last bit --------------------------
// A band-limited impact sound (four damped modes below 0.75 Nyquist, a raised-cosine attack of
// 0.2 ms) evaluated at exact, random sub-sample onsets; `levels` gives each copy's amplitude.
std::vector<float> ExactCopies(const std::vector<double>& onsets_s,
                               const std::vector<double>& levels, double rate, double duration_s,
                               double noise_rms, std::uint32_t seed) {
  const double f[4] = {2900.0, 7300.0, 11900.0, 17600.0}, tau[4] = {0.02, 0.012, 0.008, 0.005};
  const double amp[4] = {1.0, 0.7, 0.5, 0.35}, attack_s = 2e-4;
  std::vector<float> x(static_cast<std::size_t>(duration_s * rate), 0.0f);
  for (std::size_t k = 0; k < onsets_s.size(); ++k)
    for (std::size_t n = static_cast<std::size_t>(onsets_s[k] * rate);
         n < x.size() && n < static_cast<std::size_t>((onsets_s[k] + 0.1) * rate); ++n) {
      const double t = static_cast<double>(n) / rate - onsets_s[k];
      if (t < 0.0) continue;
      const double ramp = t < attack_s ? 0.5 - 0.5 * std::cos(M_PI * t / attack_s) : 1.0;
      double v = 0.0;
      for (int m = 0; m < 4; ++m)
        v += amp[m] * std::exp(-t / tau[m]) * std::sin(2.0 * M_PI * f[m] * t);
      x[n] += static_cast<float>(levels[k] * ramp * v);
    }
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, noise_rms);
  for (float& v : x) v += static_cast<float>(g(rng));
  return x;
}

// Twenty copies, the first the loudest, each 12 % quieter than the one before; anchors 0.1 ms
// after the true onsets (a detector's times are late by about that).
struct CopyRun {
  std::vector<double> t_true;
  Sequence seq;
  TimingResult res;
};
CopyRun TimeCopies(double noise_rms, std::uint32_t seed) {
  const double rate = 48000.0;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  CopyRun run;
  std::vector<double> levels;
  for (int k = 0; k < 20; ++k) {
    run.t_true.push_back(0.1 + 0.15 * k + u(rng) / rate);
    levels.push_back(0.5 * std::pow(0.88, k));
  }
  const std::vector<float> x = ExactCopies(run.t_true, levels, rate, 3.3, noise_rms, seed);
  for (double t : run.t_true) {
    Impact im;
    im.time_s = t + 1e-4;
    run.seq.impacts.push_back(im);
  }
  run.res = TimeSequence(x, rate, &run.seq);
  return run;
}

TEST(Timing, ExactCopiesAreTimedToAFiftiethOfASample) {
  // No noise: every interval, the template member's too, is right to 0.02 samples (0.4 us; the
  // copies are samples of a continuous sound at different phases, not band-limited shifts of one
  // another: the attack's kink aliases, measured worst 0.011 samples, RMS 0.006), the fitted levels
  // are the copies' (a member taken one sample off the peak read 0.3 for 0.93), and the measured
  // resolution floor is small.
  const CopyRun run = TimeCopies(1e-7, 1);
  double worst = 0.0;
  for (std::size_t k = 1; k < run.t_true.size(); ++k) {
    const double err = (run.seq.impacts[k].time_s - run.seq.impacts[k - 1].time_s) -
                       (run.t_true[k] - run.t_true[k - 1]);
    worst = std::max(worst, std::fabs(err));
  }
  std::printf("exact copies: worst interval error %.4f samples, measured floor %.4f\n",
              worst * 48000.0, run.res.resolution_samples);
  EXPECT_LT(worst, 0.02 / 48000.0);
  const double a0 = run.res.detail[static_cast<std::size_t>(run.res.template_member)].level_ratio;
  for (std::size_t k = 0; k < run.t_true.size(); ++k)
    EXPECT_NEAR(run.res.detail[k].level_ratio / a0,
                std::pow(0.88, static_cast<double>(k) - run.res.template_member), 0.01)
        << "member " << k;
  EXPECT_LT(run.res.resolution_samples, 0.01);
  for (const Impact& im : run.seq.impacts) EXPECT_LT(im.sigma_s, 0.05 / 48000.0);
}

TEST(Timing, NoiseTermIsTheErrorOfExactCopiesInWhiteNoise) {
  // White noise at two levels (the quietest copies at ~10 dB), four seeds each: the interval
  // pulls' RMS is near 1 (measured 0.9-1.1); a noise term off by 2x either way leaves [0.75, 1.33].
  std::vector<double> pulls;
  for (double noise : {3e-4, 1e-3})
    for (std::uint32_t seed = 1; seed <= 4; ++seed) {
      const CopyRun run = TimeCopies(noise, seed);
      for (std::size_t k = 1; k < run.t_true.size(); ++k) {
        const Impact& a = run.seq.impacts[k - 1];
        const Impact& b = run.seq.impacts[k];
        const double err = (b.time_s - a.time_s) - (run.t_true[k] - run.t_true[k - 1]);
        pulls.push_back(err / std::hypot(a.sigma_s, b.sigma_s));
      }
    }
  const double rms = Rms(pulls);
  std::printf("exact copies in white noise: interval pull RMS %.2f over %zu\n", rms, pulls.size());
  EXPECT_GE(rms, 0.75);
  EXPECT_LE(rms, 1.33);
}

// The same samples with different amounts of audio before them (cut at 5 offsets, all before
// the drop) give the same impacts: matched times agree within max(3 sigma, 2 us).
TEST(Timing, StartInvarianceAtFiveOffsets) {
  const SynthResult s = Synthesize(SynthPreset("steel-copper"));
  const double rate = s.recording.sample_rate_hz;
  const std::vector<float>& x = s.recording.channels[0];
  const DetectionResult full = DetectImpacts(InMemory({x}, rate, "full.wav"), DetectOptions{});
  int compared = 0;
  for (double cut_s : {0.1, 0.37, 0.6, 0.93, 1.2}) {
    const std::size_t cut = static_cast<std::size_t>(std::lround(cut_s * rate));
    std::vector<float> y(x.begin() + static_cast<std::ptrdiff_t>(cut), x.end());
    const DetectionResult part = DetectImpacts(InMemory({y}, rate, "cut.wav"), DetectOptions{});
    const double shift = static_cast<double>(cut) / rate;
    // The nearest member of `in` to time t (in the full recording's time), or null.
    auto nearest = [](const std::vector<Impact>& in, double t, double offset) {
      const Impact* best = nullptr;
      for (const Impact& b : in)
        if (!best || std::fabs(b.time_s + offset - t) < std::fabs(best->time_s + offset - t))
          best = &b;
      return best != nullptr && std::fabs(best->time_s + offset - t) <= 1e-3 ? best : nullptr;
    };
    for (const Impact& a : full.main().impacts) {
      const Impact* best = nearest(part.main().impacts, a.time_s, shift);
      // Members at the noise floor (SNR below 3 dB: the tail of this recording ends at 0 dB)
      // may come and go with the onset detector's frame grid; every other member is in both.
      if (!best) {
        EXPECT_LT(a.snr_db, 3.0) << "cut " << cut_s << " s: impact at " << a.time_s << " lost";
        continue;
      }
      ++compared;
      const double tol = std::max(3.0 * std::max(a.sigma_s, best->sigma_s), 2e-6);
      EXPECT_LE(std::fabs(best->time_s + shift - a.time_s), tol)
          << "cut " << cut_s << " s, impact at " << a.time_s;
    }
    for (const Impact& b : part.main().impacts) {
      if (nearest(full.main().impacts, b.time_s + shift, 0.0)) continue;
      EXPECT_LT(b.snr_db, 3.0) << "cut " << cut_s << " s: new impact at " << b.time_s + shift;
    }
  }
  EXPECT_GE(compared, 5 * 30);
}

// A member is timed by the template down to NCC min_template_ncc = 0.1, by its own AIC pick only
// below (measured on 42 files that are not the scoreboard's: members of NCC 0.10-0.20 timed by
// AIC were 480-530 us off in the median, 6 of 24 beyond 1 ms; by the template 32-97 us, none;
// at 0.2 the AIC took every one of them). Quiet copies in loud noise give members of NCC
// 0.1-0.2: they are timed by the template, and within 3 sigma. (Below 0.1 no member occurs,
// here or in that corpus: the best lag of the +-0.3 ms search reaches 0.15-0.25 on noise alone.)
TEST(Timing, WeakMembersAreTimedByTheTemplateDownToNccOneTenth) {
  int weak = 0;
  for (double noise : {0.1, 0.2, 0.4})
    for (std::uint32_t seed = 1; seed <= 3; ++seed) {
      const CopyRun run = TimeCopies(noise, seed);
      for (std::size_t k = 0; k < run.t_true.size(); ++k) {
        const TimingDetail& d = run.res.detail[k];
        const Impact& im = run.seq.impacts[k];
        EXPECT_EQ(d.by_template, d.ncc >= 0.1) << "member " << k << " ncc " << d.ncc;
        if (d.ncc < 0.1 || d.ncc >= 0.2) continue;
        ++weak;
        EXPECT_TRUE(d.by_template) << "member " << k << " ncc " << d.ncc;
        EXPECT_LE(std::fabs(im.time_s - run.t_true[k]), 3.0 * im.sigma_s)
            << "noise " << noise << " seed " << seed << " member " << k;
      }
    }
  EXPECT_GE(weak, 5) << "the case needs members of NCC 0.1-0.2";
}
}  // namespace
}  // namespace bouncecal
