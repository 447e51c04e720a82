// Onset detection: whitening, AIC picker, sub-sample timing of rendered clicks, level
// independence.
#include "bouncecal/acoustic/onsets.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <fstream>
#include <functional>
#include <random>
#include <string>
#include <thread>

#include "acoustic/avx2_clones.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {
namespace {

TEST(Onsets, LevinsonDurbinRecoversAnAr1Predictor) {
  // AR(1) x[n] = phi x[n-1] + e[n]: r[k] = phi^k, prediction-error filter a = {1, -phi, 0, ...}.
  const double phi = 0.7;
  std::vector<double> r(5);
  for (int k = 0; k < 5; ++k) r[static_cast<std::size_t>(k)] = std::pow(phi, k);
  const std::vector<double> a = LevinsonDurbin(r, 4);
  ASSERT_EQ(a.size(), 5u);
  EXPECT_DOUBLE_EQ(a[0], 1.0);
  EXPECT_NEAR(a[1], -phi, 1e-12);
  for (int k = 2; k < 5; ++k) EXPECT_NEAR(a[static_cast<std::size_t>(k)], 0.0, 1e-12);
}

TEST(Onsets, WhiteningReturnsTheDrivingNoiseOfAnArProcess) {
  // A resonance (AR(2), pole radius 0.99 at 0.1 fs) driven by white noise: the residual of the
  // fitted predictor is the driving noise.
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
  const std::vector<float> w = Whiten(x, 8);
  double xy = 0, xx = 0, yy = 0;
  for (std::size_t i = 100; i < n; ++i) {
    xy += w[i] * e[i];
    xx += static_cast<double>(w[i]) * w[i];
    yy += e[i] * e[i];
  }
  EXPECT_GT(xy / std::sqrt(xx * yy), 0.995);
  EXPECT_NEAR(std::sqrt(xx / yy), 1.0, 0.02);  // same power as the driving noise
}

// The whitening as it is defined (Whiten's comments): per 4096-sample block and lag, eight float
// partial sums (lane k mod 8) then their sum in double after the block's tail products; the
// blocks' sums added in block order; the prediction error filter one tap at a time in float.
// Whiten computes the same operations in another order of independent work (several lags, and
// outputs, per pass): it must give the same floats.
std::vector<float> ReferenceWhiten(const std::vector<float>& x, int order) {
  const std::size_t n = x.size(), lags = static_cast<std::size_t>(order) + 1, block = 4096;
  std::vector<double> r(lags, 0.0);
  for (std::size_t s = 0; s < n; s += block) {
    const std::size_t e = std::min(n, s + block);
    for (std::size_t l = 0; l < lags; ++l) {
      const std::size_t i0 = std::max(s, l);
      if (i0 >= e) continue;
      const std::size_t m = e - i0, m8 = m & ~std::size_t{7};
      float acc[8] = {0, 0, 0, 0, 0, 0, 0, 0};
      for (std::size_t k = 0; k < m8; ++k) acc[k % 8] += x[i0 + k] * x[i0 + k - l];
      double total = 0.0;
      for (std::size_t k = m8; k < m; ++k) total += static_cast<double>(x[i0 + k]) * x[i0 + k - l];
      for (float v : acc) total += v;
      r[l] += total;
    }
  }
  r[0] *= 1.0 + 1e-6;
  const std::vector<double> a = LevinsonDurbin(r, order);
  std::vector<float> out(x);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = 1; j < a.size() && j <= i; ++j)
      out[i] += static_cast<float>(a[j]) * x[i - j];
  return out;
}

TEST(Onsets, WhitenIsTheDefinedFilterToTheBit) {
  // A ringing resonance plus clicks and noise, lengths that leave partial blocks, any threads.
  std::mt19937 rng(11);
  std::normal_distribution<double> g(0.0, 1.0);
  for (std::size_t n : {std::size_t{300}, std::size_t{4096 * 3 + 77}, std::size_t{50001}}) {
    std::vector<float> x(n);
    double y1 = 0, y2 = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const double kick = i % 7919 == 100 ? 0.5 : 0.0;
      const double y = 1.9 * y1 - 0.95 * y2 + 0.01 * g(rng) + kick;
      x[i] = static_cast<float>(y);
      y2 = y1;
      y1 = y;
    }
    for (int order : {8, 48, 51}) {
      const std::vector<float> ref = ReferenceWhiten(x, order);
      for (int threads : {1, 2}) {
        const std::vector<float> w = Whiten(x, order, threads);
        ASSERT_EQ(w.size(), ref.size());
        std::size_t differ = 0;
        for (std::size_t i = 0; i < n; ++i) differ += w[i] != ref[i];
        EXPECT_EQ(differ, 0u) << "n " << n << " order " << order << " threads " << threads;
      }
    }
  }
}

TEST(Onsets, SlidingSampleSelectsWhatNthElementSelects) {
  // Windows sliding by a multiple of the stride (kept sorted, values in and out), by other
  // steps (selected anew), shrinking at the end, with many equal values: the median and the
  // median absolute deviation equal nth_element's on the window's values.
  std::mt19937 rng(17);
  std::uniform_int_distribution<int> level(0, 40);
  std::vector<double> v(5000);
  for (double& x : v) x = 0.25 * level(rng);  // many ties
  auto nth = [](std::vector<double> a) {
    if (a.empty()) return 0.0;
    const auto mid = a.begin() + static_cast<std::ptrdiff_t>(a.size() / 2);
    std::nth_element(a.begin(), mid, a.end());
    return *mid;
  };
  for (std::size_t stride : {std::size_t{1}, std::size_t{4}}) {
    for (std::size_t win : {std::size_t{16}, std::size_t{900}, std::size_t{901}}) {
      SlidingSample s;
      std::size_t checked = 0;
      for (std::size_t lo = 0; lo < v.size(); lo += (lo % 3 == 0 ? 112 : 37)) {
        const std::size_t hi = std::min(v.size(), lo + win);
        s.Set(v, lo, hi, stride);
        std::vector<double> ref;
        for (std::size_t q = lo; q < hi; q += stride) ref.push_back(v[q]);
        ASSERT_EQ(s.size(), ref.size());
        const double med = nth(ref);
        EXPECT_EQ(s.Median(), med) << lo;
        for (double& x : ref) x = std::fabs(x - med);
        EXPECT_EQ(s.Mad(med), nth(ref)) << lo;
        ++checked;
      }
      EXPECT_GT(checked, 40u);
    }
  }
  SlidingSample empty;
  empty.Set(v, 10, 10, 4);
  EXPECT_EQ(empty.Median(), 0.0);
  EXPECT_EQ(empty.Mad(0.0), 0.0);
}

TEST(Onsets, AicFindsAVarianceStep) {
  std::mt19937 rng(5);
  std::normal_distribution<double> g(0.0, 1.0);
  std::vector<float> x(600);
  for (std::size_t i = 0; i < x.size(); ++i)
    x[i] = static_cast<float>(g(rng) * (i >= 400 ? 20.0 : 1.0));
  const AicPick p = PickAic(x, 100, 600);
  ASSERT_TRUE(p.valid);
  // The new regime starts at sample 400, i.e. between 399 and 400 on the AIC's convention.
  EXPECT_NEAR(p.index, 399.5, 1.0);
  EXPECT_GT(p.sigma, 0.0);
  EXPECT_LT(p.sigma, 1.0);
  EXPECT_FALSE(PickAic(x, 0, 10).valid);  // too short
}

// Impacts of equal shape at fractional-sample times, rendered by the synth (exact onsets).
struct Rendered {
  std::vector<float> x;
  std::vector<double> onset_s;
  std::vector<double> v;
  double rate_hz;
};

Rendered RenderClicks(const std::vector<double>& v_in, double spacing_s, double snr_db,
                      const std::string& plate) {
  RenderOptions ro;
  ro.sample_rate_hz = 48000;
  ro.plate_modes = PlateModes(plate);
  ro.snr_db = snr_db;
  ro.tail_s = 0.3;
  ro.seed = 11;
  std::vector<TruthImpact> imps;
  for (std::size_t k = 0; k < v_in.size(); ++k) {
    TruthImpact t;
    // Fractional sample positions spread over [0, 1): 0.3 s + k spacing + k * 0.37 samples.
    t.time_s = 0.3 + static_cast<double>(k) * spacing_s + 0.37 * static_cast<double>(k) / 48000.0;
    t.v_in_m_s = v_in[k];
    t.v_out_m_s = 0.9 * v_in[k];
    t.contact_s = 5e-5;
    imps.push_back(t);
  }
  const Recording rec = RenderRecording(imps, ro);
  Rendered r;
  r.x = rec.channels[0];
  r.rate_hz = rec.sample_rate_hz;
  for (const RenderedImpact& i : rec.drops[0]) {
    r.onset_s.push_back(i.onset_s);
    r.v.push_back(i.truth.v_in_m_s);
  }
  return r;
}

// Error of the detected onset nearest each true onset (NaN if none within 1 ms).
std::vector<double> Errors(const OnsetResult& res, const std::vector<double>& truth) {
  std::vector<double> err;
  for (double t : truth) {
    double best = NAN;
    for (const Impact& i : res.onsets)
      if (std::fabs(i.time_s - t) < 1e-3 && !(std::fabs(i.time_s - t) >= std::fabs(best)))
        best = i.time_s - t;
    err.push_back(best);
  }
  return err;
}

TEST(Onsets, SubSampleTimingOfRenderedClicks) {
  const std::vector<double> v(10, 1.0);
  const Rendered r = RenderClicks(v, 0.21, 60.0, "copper-dish");
  const OnsetDetector det(OnsetOptions{}, r.rate_hz);
  const OnsetResult res = det.Detect(r.x);
  const std::vector<double> err = Errors(res, r.onset_s);
  std::vector<double> interval_err;
  for (std::size_t k = 0; k < err.size(); ++k) {
    ASSERT_TRUE(std::isfinite(err[k])) << "impact " << k << " not found";
    // A sample is 20.8 us. Measured: the AIC pick keeps a bias of up to ~0.4 sample that
    // depends on where the onset falls between samples (0.37-sample steps here).
    EXPECT_LT(std::fabs(err[k]), 10.4e-6) << "impact " << k;
    if (k > 0) interval_err.push_back(std::fabs(err[k] - err[k - 1]));
  }
  std::sort(interval_err.begin(), interval_err.end());
  EXPECT_LT(interval_err[interval_err.size() / 2], 8e-6);
  EXPECT_LT(interval_err.back(), 15e-6);
  // Without refinement the frame grid (~0.33 ms hop) is all there is: much worse.
  OnsetOptions coarse;
  coarse.refine = false;
  const std::vector<double> err_coarse =
      Errors(OnsetDetector(coarse, r.rate_hz).Detect(r.x), r.onset_s);
  double worst = 0.0;
  for (double e : err_coarse)
    if (std::isfinite(e)) worst = std::max(worst, std::fabs(e));
  EXPECT_GT(worst, 30e-6);
}

TEST(Onsets, TemplateMatchAcrossTheNccChunks) {
  // The template's NCC is computed in chunks of 65536 starts (1.37 s at 48 kHz, onsets.cpp
  // kNccChunk). 50 clicks over 10.6 s, click 25 a few samples after the fourth chunk boundary
  // (262144: 0.3 + 25 x 0.206453 s = 5.4613 s, plus 25 x 0.37 samples): every click is found,
  // matched and timed as well as within one chunk (SubSampleTimingOfRenderedClicks), and the result
  // does not depend on the threads that computed the chunks.
  const std::vector<double> v(50, 1.0);
  const Rendered r = RenderClicks(v, 0.206453, 60.0, "copper-dish");
  ASSERT_GT(r.x.size(), 262144u + 48000u);  // the boundary a second inside
  ASSERT_NEAR(r.onset_s[25] * r.rate_hz, 262144.0, 40.0);
  const OnsetResult res = OnsetDetector(OnsetOptions{}, r.rate_hz).Detect(r.x);
  const std::vector<double> err = Errors(res, r.onset_s);
  for (std::size_t k = 0; k < err.size(); ++k) {
    ASSERT_TRUE(std::isfinite(err[k])) << "impact " << k << " not found";
    EXPECT_LT(std::fabs(err[k]), 10.4e-6) << "impact " << k;
  }
  // The onset nearest each click matches the template. Measured 0.73-1.00 (periodic in the
  // clicks' 0.37-sample steps between samples; click 25: 0.97), bound 0.7.
  for (double t : r.onset_s) {
    const Impact* best = nullptr;
    for (const Impact& im : res.onsets)
      if (!best || std::fabs(im.time_s - t) < std::fabs(best->time_s - t)) best = &im;
    EXPECT_GE(best->score, 0.7) << t;
  }
  OnsetOptions two;
  two.threads = 2;
  const OnsetResult res2 = OnsetDetector(two, r.rate_hz).Detect(r.x);
  ASSERT_EQ(res2.onsets.size(), res.onsets.size());
  for (std::size_t k = 0; k < res.onsets.size(); ++k) {
    EXPECT_EQ(res2.onsets[k].time_s, res.onsets[k].time_s);
    EXPECT_EQ(res2.onsets[k].score, res.onsets[k].score);
    EXPECT_EQ(res2.onsets[k].sigma_s, res.onsets[k].sigma_s);
  }
}

// The relative spectral flux written out: every frame's periodic-Hann power spectrum (a direct
// DFT), its reference the mean of the kRefFrames = 8 frames ending `lag` frames before it
// (those that exist), num = sum max(0, P - R), den = sum R (the median reference where the
// reference is not yet full), 10 log10(1 + num / (den + floor)), then a 3-frame mean.
std::vector<double> ReferenceNovelty(const std::vector<float>& w, std::size_t hop, std::size_t nw) {
  const std::size_t frames = (w.size() - nw) / hop + 1, bins = nw / 2 + 1;
  const std::size_t lag = (nw + hop - 1) / hop, kRef = 8;
  std::vector<std::vector<double>> p(frames, std::vector<double>(bins));
  const double n = static_cast<double>(nw);
  std::vector<double> hann(nw), c(bins * nw), sn(bins * nw);
  for (std::size_t i = 0; i < nw; ++i) {
    hann[i] = 0.5 - 0.5 * std::cos(2.0 * M_PI * static_cast<double>(i) / n);
    for (std::size_t k = 0; k < bins; ++k) {
      const double phase = 2.0 * M_PI * static_cast<double>(k * i % nw) / n;
      c[k * nw + i] = std::cos(phase);
      sn[k * nw + i] = std::sin(phase);
    }
  }
  for (std::size_t t = 0; t < frames; ++t)
    for (std::size_t k = 0; k < bins; ++k) {
      double re = 0.0, im = 0.0;
      for (std::size_t i = 0; i < nw; ++i) {
        const double x = w[t * hop + i] * hann[i];
        re += x * c[k * nw + i];
        im -= x * sn[k * nw + i];
      }
      p[t][k] = re * re + im * im;
    }
  std::vector<double> num(frames), den(frames), valid;
  for (std::size_t t = 0; t < frames; ++t) {
    std::vector<double> r(bins, 0.0);
    if (t >= lag)
      for (std::size_t f = t - lag + 1 >= kRef ? t - lag + 1 - kRef : 0; f <= t - lag; ++f)
        for (std::size_t k = 0; k < bins; ++k) r[k] += p[f][k] / static_cast<double>(kRef);
    for (std::size_t k = 0; k < bins; ++k) {
      num[t] += std::max(0.0, p[t][k] - r[k]);
      den[t] += r[k];
    }
    if (t >= lag + kRef) valid.push_back(den[t]);
  }
  std::nth_element(valid.begin(), valid.begin() + static_cast<long>(valid.size() / 2), valid.end());
  const double floor = valid[valid.size() / 2];
  std::vector<double> db(frames), nov(frames, 0.0);
  for (std::size_t t = 0; t < frames; ++t)
    db[t] = 10.0 * std::log10(1.0 + num[t] / ((t >= lag + kRef ? den[t] : floor) + floor));
  for (std::size_t t = 1; t + 1 < frames; ++t) nov[t] = (db[t - 1] + db[t] + db[t + 1]) / 3.0;
  return nov;
}

TEST(Onsets, NoveltyIsTheRelativeSpectralFluxAtEveryFrameForAnyThreadCount) {
  // The novelty is computed in chunks of 4096 frames (65536 samples at 48 kHz), each starting
  // its running reference anew from the power rows before it, on any thread: 30 clicks over
  // 6.5 s span five chunks. Every frame, the first ones of each chunk included, is the flux
  // written out (ReferenceNovelty) to 1e-9 dB (measured: 4e-13; a chunk that started its
  // reference one row short would be off by ~0.1 dB at its first frames), and the values are
  // the same to the bit on one, two and three threads.
  const std::vector<double> v(30, 1.0);
  const Rendered r = RenderClicks(v, 0.2, 60.0, "copper-dish");
  ASSERT_GT(r.x.size(), 4u * 65536u);
  const OnsetDetector one(OnsetOptions{}, r.rate_hz);
  const OnsetResult res = one.Detect(r.x);
  const std::vector<double> ref =
      ReferenceNovelty(res.whitened, static_cast<std::size_t>(one.hop_samples()),
                       static_cast<std::size_t>(one.window_samples()));
  ASSERT_EQ(res.novelty_db.size(), ref.size());
  double worst = 0.0;
  for (std::size_t t = 0; t < ref.size(); ++t) {
    ASSERT_NEAR(res.novelty_db[t], ref[t], 1e-9) << "frame " << t;
    worst = std::max(worst, std::fabs(res.novelty_db[t] - ref[t]));
  }
  RecordProperty("worst_db", std::to_string(worst));
  EXPECT_GT(*std::max_element(ref.begin(), ref.end()), 10.0);  // the clicks stand out
  for (int threads : {2, 3}) {
    OnsetOptions o;
    o.threads = threads;
    EXPECT_EQ(OnsetDetector(o, r.rate_hz).Detect(r.x).novelty_db, res.novelty_db) << threads;
  }
  // A longer hop (64 samples, 129 bins): chunks of 2032 frames (their power rows held to 2 MB),
  // three of them here.
  OnsetOptions longer;
  longer.hop_s = 64.0 / r.rate_hz;
  const OnsetDetector coarse(longer, r.rate_hz);
  ASSERT_EQ(coarse.hop_samples(), 64);
  const OnsetResult cr = coarse.Detect(r.x);
  const std::vector<double> cref = ReferenceNovelty(cr.whitened, 64, 256);
  ASSERT_EQ(cr.novelty_db.size(), cref.size());
  ASSERT_GT(cref.size(), 2u * 2032u);
  for (std::size_t t = 0; t < cref.size(); ++t)
    ASSERT_NEAR(cr.novelty_db[t], cref[t], 1e-9) << "frame " << t << " at the 64-sample hop";
  longer.threads = 3;
  EXPECT_EQ(OnsetDetector(longer, r.rate_hz).Detect(r.x).novelty_db, cr.novelty_db);
}

TEST(Onsets, TimingDoesNotDependOnLevel) {
  // Loud (v = 1) and quiet (v = 0.01: -40 dB) impacts of the same shape, alternating, on a
  // ringing plate: no level-dependent bias (an energy threshold would time the quiet ones late).
  std::vector<double> v;
  for (int k = 0; k < 12; ++k) v.push_back(k % 2 == 0 ? 1.0 : 0.01);
  for (const std::string plate : {"copper-dish", "wood-table"}) {
    const Rendered r = RenderClicks(v, 0.2, 85.0, plate);
    const OnsetDetector det(OnsetOptions{}, r.rate_hz);
    const OnsetResult res = det.Detect(r.x);
    const std::vector<double> err = Errors(res, r.onset_s);
    double loud = 0, quiet = 0;
    for (std::size_t k = 0; k < err.size(); ++k) {
      ASSERT_TRUE(std::isfinite(err[k]))
          << plate << ": impact " << k << " (v = " << v[k] << ") not found";
      EXPECT_LT(std::fabs(err[k]), 20e-6) << plate << ": impact " << k << " v = " << v[k];
      (v[k] > 0.5 ? loud : quiet) += err[k] / 6.0;
    }
    EXPECT_LT(std::fabs(loud), 10.4e-6) << plate;
    // Measured: 2 us (copper) and 6.4 us (wood); the loud picks carry the sample-phase bias of
    // the AIC (up to ~0.4 sample), so 0.4 sample is the bound.
    EXPECT_LT(std::fabs(quiet - loud), 8.3e-6) << plate << ": loud " << loud << " quiet " << quiet;
  }
}

TEST(Onsets, SigmaIsPositiveAndGrowsWithNoise) {
  const std::vector<double> v(6, 1.0);
  // Median sigma of the onsets that time a true impact (within 0.1 ms).
  auto median_sigma = [&](double snr_db) {
    const Rendered r = RenderClicks(v, 0.2, snr_db, "wood-table");
    const OnsetResult res = OnsetDetector(OnsetOptions{}, r.rate_hz).Detect(r.x);
    std::vector<double> s;
    for (const Impact& i : res.onsets)
      for (double t : r.onset_s)
        if (std::fabs(i.time_s - t) < 1e-4) s.push_back(i.sigma_s);
    EXPECT_EQ(s.size(), v.size()) << "snr " << snr_db;
    std::sort(s.begin(), s.end());
    return s.empty() ? NAN : s[s.size() / 2];
  };
  const double quiet_room = median_sigma(70.0), noisy_room = median_sigma(30.0);
  EXPECT_GT(quiet_room, 0.0);
  EXPECT_GT(noisy_room, quiet_room);
}

TEST(Onsets, InvalidOptionsAndRate) {
  OnsetOptions o;
  std::string why;
  EXPECT_TRUE(o.IsValid(&why));
  o.lpc_order = -1;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("lpc_order"), std::string::npos);
  EXPECT_THROW(OnsetDetector(o, 48000), Error);
  EXPECT_THROW(OnsetDetector(OnsetOptions{}, 0.0), Error);
  EXPECT_THROW(OnsetDetector(OnsetOptions{}, NAN), Error);
}

TEST(Onsets, ShortAndEmptyInputGiveNoOnsets) {
  const OnsetDetector det(OnsetOptions{}, 48000);
  EXPECT_TRUE(det.Detect({}).onsets.empty());
  EXPECT_TRUE(det.Detect(std::vector<float>(10, 0.1f)).onsets.empty());
  EXPECT_TRUE(det.Detect(std::vector<float>(48000, 0.0f)).onsets.empty());
}

// ---- the rise onsets (OnsetOptions::min_rise_db) ---------------------------------------------

// `seconds` of white noise (RMS noise_rms, from `seed`) at rate_hz plus sound(t).
std::vector<float> NoiseAnd(double rate_hz, double seconds, unsigned seed, double noise_rms,
                            const std::function<double(double)>& sound) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> g(0.0, noise_rms);
  std::vector<float> x(static_cast<std::size_t>(seconds * rate_hz));
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double t = static_cast<double>(i) / rate_hz;
    x[i] = static_cast<float>(g(rng) + sound(t));
  }
  return x;
}

// A soft ball's impacts excite little but the plate's low modes, which the whole recording's
// whitening predicts away: on synth's rubber ball on wood (1.4-ms contact) the flux and the
// template find half of the impacts 20 dB or more above the room (measured, seeds 1-8: 0.47-0.53
// of 19 each), with the energy rise 0.63-0.74.
TEST(RiseOnsets, FindTheSoftImpactsTheWhiteningHides) {
  int n = 0, with = 0, without = 0;
  for (std::uint64_t seed = 1; seed <= 4; ++seed) {
    SynthSpec spec = SynthPreset("rubber-wood");
    spec.render.seed = seed;
    const SynthResult s = Synthesize(spec);
    const std::vector<float>& x = s.recording.channels[0];
    OnsetOptions off;
    off.min_rise_db = 0.0;
    const OnsetResult on_r = OnsetDetector(OnsetOptions{}, s.recording.sample_rate_hz).Detect(x);
    const OnsetResult off_r = OnsetDetector(off, s.recording.sample_rate_hz).Detect(x);
    auto has = [](const OnsetResult& r, double t) {
      return std::any_of(r.onsets.begin(), r.onsets.end(),
                         [&](const Impact& im) { return std::fabs(im.time_s - t) < 1e-3; });
    };
    for (const auto& drop : s.recording.drops)
      for (const RenderedImpact& t : drop) {
        if (t.snr_db < 20.0) continue;
        ++n;
        with += has(on_r, t.onset_s);
        without += has(off_r, t.onset_s);
      }
  }
  ASSERT_GT(n, 40);
  EXPECT_GE(with, 0.6 * n) << without << " without the rise, of " << n;
  EXPECT_LE(without, 0.55 * n) << with << " with the rise, of " << n;
}

// min_rise_db = 6 dB pinned to a factor of 2: white noise (its rise spreads by ~1 dB, so the MAD
// rule asks for less than the floor) and soft 2-kHz bursts whose rise over the room (the floored
// rise: (after + background) / (before + background)) is ~4.5 or ~7.5 dB. The flux is turned off
// (min_novelty_db out of reach) so that only the rise finds them: at 6 dB the loud ones and not the
// quiet ones; at 3 dB the quiet ones too; at 12 dB neither.
TEST(RiseOnsets, TheFloorIsPinnedToAFactorOfTwo) {
  constexpr double kRate = 48000.0, kNoise = 1e-3, kLen = 0.002;
  // Burst amplitudes (x noise RMS): 2.5 -> raw rise ~6.5 dB (floored ~4.4), 5 -> ~10 dB (~7.4).
  const std::vector<double> quiet(6, 2.5), loud(6, 5.0);
  std::vector<double> starts, gains;
  for (std::size_t k = 0; k < 12; ++k) {
    starts.push_back(0.2 + 0.25 * static_cast<double>(k));
    gains.push_back(k % 2 ? loud[k / 2] : quiet[k / 2]);
  }
  const std::vector<float> x = NoiseAnd(kRate, 3.3, 5, kNoise, [&](double t) {
    double v = 0.0;
    for (std::size_t k = 0; k < starts.size(); ++k) {
      const double u = (t - starts[k]) / kLen;
      if (u >= 0.0 && u < 1.0)
        v += gains[k] * kNoise * std::sin(M_PI * u) * std::sin(2.0 * M_PI * 2000.0 * t);
    }
    return v;
  });
  auto count = [&](double min_rise_db, double gain) {
    OnsetOptions o;
    o.min_rise_db = min_rise_db;
    o.min_novelty_db = 1e6;      // no flux onsets
    o.template_threshold = 2.0;  // no template search
    const OnsetResult r = OnsetDetector(o, kRate).Detect(x);
    int n = 0;
    for (std::size_t k = 0; k < starts.size(); ++k) {
      if (gains[k] != gain) continue;
      for (const Impact& im : r.onsets)
        if (std::fabs(im.time_s - starts[k]) < 2e-3) {
          ++n;
          break;
        }
    }
    return n;
  };
  const double floor = OnsetOptions{}.min_rise_db;
  EXPECT_GE(count(floor, 5.0), 5) << "the loud bursts at the default floor";
  EXPECT_LE(count(floor, 2.5), 1) << "the quiet bursts at the default floor";
  EXPECT_GE(count(floor / 2.0, 2.5), 5) << "the quiet bursts at half the floor";
  EXPECT_LE(count(floor * 2.0, 5.0), 1) << "the loud bursts at twice the floor";
}

// A rise onset is timed where the recording rises: when the AIC pick on the whitened signal lands
// where it does not (a soft attack is not in the whitened signal), the pick on the recording
// itself is used; its onsets all sit on a rise of at least min_rise_db.
TEST(RiseOnsets, AreTimedWhereTheRecordingRises) {
  SynthSpec spec = SynthPreset("rubber-wood");
  spec.render.seed = 12;
  const SynthResult s = Synthesize(spec);
  const std::vector<float>& x = s.recording.channels[0];
  OnsetOptions on, off;
  off.min_rise_db = 0.0;
  const OnsetResult with = OnsetDetector(on, s.recording.sample_rate_hz).Detect(x);
  const OnsetResult without = OnsetDetector(off, s.recording.sample_rate_hz).Detect(x);
  int added = 0;
  for (const Impact& im : with.onsets) {
    const bool flux =
        std::any_of(without.onsets.begin(), without.onsets.end(),
                    [&](const Impact& o) { return std::fabs(o.time_s - im.time_s) < 1e-9; });
    if (flux) continue;
    ++added;
    EXPECT_GE(RawRiseDb(x, s.recording.sample_rate_hz, im.time_s), 0.0) << "onset at " << im.time_s;
    double nearest = 1.0;
    for (const auto& drop : s.recording.drops)
      for (const RenderedImpact& t : drop)
        nearest = std::min(nearest, std::fabs(im.time_s - t.onset_s));
    EXPECT_LT(nearest, 1e-3) << "onset at " << im.time_s << ": no impact within 1 ms";
  }
  EXPECT_GE(added, 5);
}

// A rise onset must rise above the loudest millisecond of the 20 ms before it (kRingingS), not
// only above the 3 ms before it: a loud burst (decaying with 3 ms) and a bump -10 dB below it
// 15 ms later (a beat of its ringing) is no onset; the same bump 30 ms after its burst is one.
// 10 ms would take the first bump, 40 ms would lose the second. Flux and template off, as above.
TEST(RiseOnsets, RiseAboveTheRingingsEnvelopeOverTwentyMilliseconds) {
  constexpr double kRate = 48000.0, kNoise = 1e-4;
  const std::vector<double> bursts = {0.3, 0.7, 1.1, 1.5}, delays = {0.015, 0.030, 0.015, 0.030};
  const std::vector<float> x = NoiseAnd(kRate, 1.9, 9, kNoise, [&](double t) {
    double v = 0.0;
    for (std::size_t k = 0; k < bursts.size(); ++k) {
      if (t >= bursts[k])
        v += 0.3 * std::exp(-(t - bursts[k]) / 0.003) * std::sin(2.0 * M_PI * 2000.0 * t);
      const double u = (t - bursts[k] - delays[k]) / 0.002;
      if (u >= 0.0 && u < 1.0)
        v += 0.3 * 0.316 * std::sin(M_PI * u) * std::sin(2.0 * M_PI * 2000.0 * t);
    }
    return v;
  });
  OnsetOptions o;
  o.min_novelty_db = 1e6;
  o.template_threshold = 2.0;
  const OnsetResult r = OnsetDetector(o, kRate).Detect(x);
  for (std::size_t k = 0; k < bursts.size(); ++k) {
    const double at = bursts[k] + delays[k];
    const bool found = std::any_of(r.onsets.begin(), r.onsets.end(), [&](const Impact& im) {
      return std::fabs(im.time_s - at) < 2e-3;
    });
    EXPECT_EQ(found, delays[k] > 0.02) << "bump " << delays[k] * 1e3 << " ms after its burst";
    EXPECT_TRUE(
        std::any_of(r.onsets.begin(), r.onsets.end(),
                    [&](const Impact& im) { return std::fabs(im.time_s - bursts[k]) < 1e-3; }))
        << "burst at " << bursts[k];
  }
}

}  // namespace
}  // namespace bouncecal
