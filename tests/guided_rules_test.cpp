// Every rule of the guided search (src/acoustic/guided_search.hpp) pinned to within a factor of 2
// (issue 29; tools/mutations.txt a90-a101, a108-a109; the rise's guard, a106-a107, is pinned in
// signal_rules_test.cpp). Each test puts one case just inside the rule and one just outside it; it
// also runs them with the option doubled and halved and expects the property to break there, so
// the cases demonstrably sit inside the factor-2 band.
//
// The signals are built to order: the "whitened signal" is white noise of RMS 1e-3 plus copies of
// a template h (a decaying noise burst, 1.5 ms) at chosen samples, each copy distorted by beta g
// (g orthogonal to h, |g| = |h|), so that its NCC with the template is 1 / sqrt(1 + beta^2) to
// 1e-3. The sequences the search extends are given (exact times, chosen timing sigma), so every
// number a case depends on is the documented rule's.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "acoustic/detect_signal.hpp"
#include "acoustic/guided_search.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

constexpr double kRate = 48000.0;
constexpr long kTemplateSamples = 72;  // 1.5 ms, the onset detector's template length
constexpr double kNoiseRms = 1e-3;
constexpr double kDuration = 4.0;

double OnSample(double t) { return std::round(t * kRate) / kRate; }

// Impact times from t0: first flight d0, then one ratio per later flight, each on a sample.
std::vector<double> Chain(double t0, double d0, const std::vector<double>& ratios) {
  std::vector<double> t{t0, t0 + d0};
  double d = d0;
  for (double r : ratios) t.push_back(t.back() + (d *= r));
  for (double& x : t) x = OnSample(x);
  return t;
}

std::vector<double> Repeat(double r, int n) {
  return std::vector<double>(static_cast<std::size_t>(n), r);
}

// The noise of a Scene: white, or not white in the way a ringing plate's whitened residual is
// not (the template does not share its spectrum): low-passed noise (three AR(1) stages of
// coefficient 0.95, scaled to the same RMS) under a high-passed template (a burst of differenced
// noise). The noise's NCC with the template spreads by 0.004-0.009 there, against white noise's
// 1 / sqrt(L) = 0.118.
enum class Noise { kWhite, kOtherSpectrum };

class Scene {
 public:
  explicit Scene(unsigned seed = 11, Noise noise = Noise::kWhite)
      : w_(static_cast<std::size_t>(kDuration * kRate)) {
    std::mt19937 rng(seed);
    std::normal_distribution<double> n01(0.0, 1.0);
    const bool white = noise == Noise::kWhite;
    std::vector<double> y(w_.size());
    for (double& v : y) v = n01(rng);
    for (int stage = 0; !white && stage < 3; ++stage)
      for (std::size_t i = 1; i < y.size(); ++i) y[i] += 0.95 * y[i - 1];
    double ss = 0.0;
    for (double v : y) ss += v * v;
    const double scale = kNoiseRms / std::sqrt(ss / static_cast<double>(y.size()));
    for (std::size_t i = 0; i < y.size(); ++i) w_[i] = static_cast<float>(scale * y[i]);
    h_.resize(kTemplateSamples);
    g_.resize(kTemplateSamples);
    double last_h = 0.0;
    for (long j = 0; j < kTemplateSamples; ++j) {
      const double envelope = std::exp(-static_cast<double>(j) / 60.0);
      const double nh = n01(rng);
      h_[static_cast<std::size_t>(j)] = envelope * (white ? nh : nh - last_h);
      g_[static_cast<std::size_t>(j)] = envelope * n01(rng);
      last_h = nh;
    }
    double hh = 0.0, hg = 0.0, gg = 0.0;
    for (std::size_t j = 0; j < h_.size(); ++j) hh += h_[j] * h_[j], hg += h_[j] * g_[j];
    for (std::size_t j = 0; j < h_.size(); ++j) g_[j] -= hg / hh * h_[j];
    for (double v : g_) gg += v * v;
    for (double& v : g_) v *= std::sqrt(hh / gg);
    // Another drop's sound: the same envelope, another burst, uncorrelated with h (|NCC| < 0.15).
    other_.resize(kTemplateSamples);
    for (long j = 0; j < kTemplateSamples; ++j)
      other_[static_cast<std::size_t>(j)] = std::exp(-static_cast<double>(j) / 60.0) * n01(rng);
  }

  // A copy of the template starting at t_s (on a sample), with NCC 1 / sqrt(1 + beta^2).
  void Put(double t_s, double beta = 0.0) {
    const long l = std::lround(t_s * kRate);
    for (long j = 0; j < kTemplateSamples; ++j) {
      const std::size_t i = static_cast<std::size_t>(l + j);
      w_[i] += static_cast<float>(h_[static_cast<std::size_t>(j)] +
                                  beta * g_[static_cast<std::size_t>(j)]);
    }
  }
  // A faint undistorted copy at t_s whose NCC with the template, over the noise there, is c.
  void PutFaint(double t_s, double c) {
    const long l = std::lround(t_s * kRate);
    double hh = 0.0, nn = 0.0;
    for (long j = 0; j < kTemplateSamples; ++j) {
      hh += h_[static_cast<std::size_t>(j)] * h_[static_cast<std::size_t>(j)];
      nn += static_cast<double>(w_[static_cast<std::size_t>(l + j)]) *
            w_[static_cast<std::size_t>(l + j)];
    }
    const double a = c * std::sqrt(nn / hh / (1.0 - c * c));
    for (long j = 0; j < kTemplateSamples; ++j)
      w_[static_cast<std::size_t>(l + j)] +=
          static_cast<float>(a * h_[static_cast<std::size_t>(j)]);
  }
  void PutAll(const std::vector<double>& t) {
    for (double x : t) Put(x);
  }
  // After each copy at t: a ringing of the same waveform every time (decaying noise, time
  // constant tau_s, 4 tau_s long), starting rms_over_noise times the noise's rms.
  void PutRinging(const std::vector<double>& t, double tau_s, double rms_over_noise) {
    std::mt19937 rng(7);
    std::normal_distribution<double> n01(0.0, 1.0);
    std::vector<double> ring(static_cast<std::size_t>(4.0 * tau_s * kRate));
    for (std::size_t j = 0; j < ring.size(); ++j)
      ring[j] = rms_over_noise * kNoiseRms * std::exp(-static_cast<double>(j) / (tau_s * kRate)) *
                n01(rng);
    for (double x : t) {
      const long l = std::lround(x * kRate) + kTemplateSamples;
      for (std::size_t j = 0;
           j < ring.size() && l + static_cast<long>(j) < static_cast<long>(w_.size()); ++j)
        w_[static_cast<std::size_t>(l) + j] += static_cast<float>(ring[j]);
    }
  }
  // An undistorted copy at t_s scaled so that its NCC with the template over white noise of the
  // scene's rms alone would be c.
  void PutScaled(double t_s, double c) {
    double hh = 0.0;
    for (double v : h_) hh += v * v;
    const double a = c * std::sqrt(static_cast<double>(kTemplateSamples) * kNoiseRms * kNoiseRms /
                                   hh / (1.0 - c * c));
    const long l = std::lround(t_s * kRate);
    for (long j = 0; j < kTemplateSamples; ++j)
      w_[static_cast<std::size_t>(l + j)] +=
          static_cast<float>(a * h_[static_cast<std::size_t>(j)]);
  }
  // A copy of the other sound at each of t.
  void PutOther(const std::vector<double>& t) {
    for (double x : t) {
      const long l = std::lround(x * kRate);
      for (long j = 0; j < kTemplateSamples; ++j)
        w_[static_cast<std::size_t>(l + j)] +=
            static_cast<float>(other_[static_cast<std::size_t>(j)]);
    }
  }

  // What the onset detector hands the guided search: the signal (already "whitened"), the
  // template (the copy at template_onset_s) and the timing floor.
  OnsetResult Onsets(double template_onset_s, double sigma_floor_s) const {
    OnsetResult r;
    r.whitened = w_;
    r.rate_hz = kRate;
    r.noise_rms = kNoiseRms;
    r.template_wave = h_;
    r.template_onset_s = template_onset_s;
    r.template_start = std::lround(template_onset_s * kRate);
    r.sigma_floor_s = sigma_floor_s;
    return r;
  }

  // The sequence `given` (the tracker's), extended by the guided search with options `go`.
  std::vector<double> Extend(const std::vector<double>& given, const GuidedOptions& go,
                             double sigma_s = 1e-6) const {
    return ExtendEach({given}, go, sigma_s)[0];
  }
  // As Extend, and the tail may also be searched in the noise-whitened signal with the members
  // cancelled (GuidedOptions::noise_signal; the rule tests above and below pin the look's rules
  // in the recording's whitened signal, and Extend turns it off).
  std::vector<double> ExtendWithNoiseSignal(const std::vector<double>& given, GuidedOptions go,
                                            double sigma_s = 1e-6) const {
    go.noise_signal = true;
    return Run({given}, go, sigma_s)[0];
  }
  // Several sequences (in time order) extended together; the template is the first one's.
  std::vector<std::vector<double>> ExtendEach(const std::vector<std::vector<double>>& given,
                                              GuidedOptions go, double sigma_s = 1e-6) const {
    go.noise_signal = false;
    return Run(given, go, sigma_s);
  }
  std::vector<std::vector<double>> Run(const std::vector<std::vector<double>>& given,
                                       const GuidedOptions& go, double sigma_s) const {
    std::vector<Sequence> seqs;
    for (const std::vector<double>& times : given) {
      Sequence q;
      for (double t : times) {
        Impact i;
        i.time_s = t;
        i.sigma_s = sigma_s;
        i.score = 1.0;
        q.impacts.push_back(i);
      }
      seqs.push_back(q);
    }
    const OnsetResult onsets = Onsets(given[0].front(), std::max(sigma_s, 2e-6));
    ExtendByTemplate(onsets, w_, kDuration, TrackOptions{}, go, &seqs);
    std::vector<std::vector<double>> out;
    for (const Sequence& q : seqs) {
      out.emplace_back();
      for (const Impact& i : q.impacts) out.back().push_back(i.time_s);
    }
    return out;
  }

  // Whether the template's best match within half_s of t_s, ranked as the search ranks, is at t_s.
  bool BestMatchAt(double t_s, double half_s, double template_onset_s) const {
    const OnsetResult onsets = Onsets(template_onset_s, 2e-6);
    Impact m;
    return FindByTemplate(onsets, TemplateOf(onsets), w_, t_s, half_s, -1.0, &m,
                          GuidedOptions{}.edge_penalty) &&
           std::fabs(m.time_s - t_s) < 1.5 / kRate;
  }

  // The spread of the noise's NCC where a look at t_c after a flight dn measures it (the middle
  // third of the flight before), as the search measures it (not floored at 1 / sqrt(L)).
  double NoiseNcc(const std::vector<double>& given, double t_c, double dn) const {
    const OnsetResult onsets = Onsets(given.front(), 2e-6);
    return NccNoiseSpread(onsets, TemplateOf(onsets), t_c - 2.0 * dn / 3.0, t_c - dn / 3.0, 256);
  }

 private:
  std::vector<float> w_;
  std::vector<double> h_, g_, other_;
};

// The documented p-value of a match of NCC c at the centre of a window of half width half_s:
// the chance that noise (NCC spread s) ranks as well at one of its positions, the ranking
// penalised by edge_penalty u^2 towards the edges.
double CentreP(double c, double s, double half_s, double edge_penalty) {
  const long positions = std::max(1L, std::lround(half_s * kRate));
  double p = 0.0;
  for (long l = -positions; l <= positions; ++l) {
    const double u = static_cast<double>(l) / static_cast<double>(positions);
    p += 0.5 * std::erfc((c + edge_penalty * u * u) / s / std::sqrt(2.0));
  }
  return std::min(1.0, p);
}

// beta for which a centred match has p-value p (bisection on its NCC).
double BetaForP(double p, double s, double half_s) {
  double lo = 0.0, hi = 1.0;  // NCC
  for (int i = 0; i < 80; ++i) {
    const double c = 0.5 * (lo + hi);
    (CentreP(c, s, half_s, GuidedOptions{}.edge_penalty) > p ? lo : hi) = c;
  }
  const double c = 0.5 * (lo + hi);
  return std::sqrt(1.0 / (c * c) - 1.0);
}

// A scene with the copies at `t` and a copy of p-value p at `at` (a look there after a flight dn):
// the first noise draw in which that copy is the window's best match. The rules below are about
// a match's p-value; a noise peak outranks a copy of p = 0.07 in 7 % of the draws (what the
// p-value says), and then the case is not the one the test means.
Scene WithCopyOfP(const std::vector<double>& t, double at, double dn, double p,
                  Noise noise = Noise::kWhite) {
  const double half_s = 4.0 * 0.005 * dn;
  for (unsigned seed = 11; seed < 41; ++seed) {
    Scene s(seed, noise);
    s.PutAll(t);
    s.Put(at, BetaForP(p, s.NoiseNcc(t, at, dn), half_s));
    if (s.BestMatchAt(at, half_s, t.front())) return s;
  }
  ADD_FAILURE() << "no noise draw in 30 leaves the copy of p " << p << " the best match";
  return Scene();
}

bool Holds(const std::vector<double>& t, double at) {
  return std::any_of(t.begin(), t.end(), [&](double x) { return std::fabs(x - at) < 1.5 / kRate; });
}

// Six flights of ratio 0.9 from 0.3 s: the trend predicts the next at ratio 0.9 with the floor
// spread 0.005 of log r (the ratios are exact).
struct Geometric {
  std::vector<double> t = Chain(0.2, 0.3, Repeat(0.9, 5));
  double last() const { return t.back() - t[t.size() - 2]; }
  double dn() const { return 0.9 * last(); }
  double next() const { return t.back() + dn(); }
};

// A look's p-value takes the noise's NCC spread as measured in the flight before, not floored at
// 1 / sqrt(L) (whitened white noise's): where the whitened signal is not white, as a ringing
// plate's residual under a template that does not share its spectrum, the spread is far smaller
// and the floor took real tail impacts for noise. A faint copy 6 measured spreads above the
// noise joins (p ~ 1e-7); with the floor it would be 0.5 floor spreads above it (p ~ 1).
TEST(GuidedRules, ALookMeasuresTheNoiseItIsIn) {
  const Geometric g;
  const double at = OnSample(g.next()), half_s = 4.0 * 0.005 * g.dn();
  const double floor = 1.0 / std::sqrt(static_cast<double>(kTemplateSamples));
  Scene s(11, Noise::kOtherSpectrum);
  s.PutAll(g.t);
  const double spread = s.NoiseNcc(g.t, at, g.dn());
  ASSERT_GT(spread, 0.0);
  ASSERT_LT(spread, floor / 10.0) << "the case needs noise the template does not match";
  s.PutFaint(at, 6.0 * spread);
  ASSERT_TRUE(s.BestMatchAt(at, half_s, g.t.front()));
  EXPECT_GT(CentreP(6.0 * spread, floor, half_s, GuidedOptions{}.edge_penalty), 0.5);
  EXPECT_TRUE(Holds(s.Extend(g.t, GuidedOptions{}), at));
}

// The window spans 4 spreads of the predicted flight on each side, the spread at least 0.005 of
// log r: a match 3 floor spreads off joins, one 6 spreads off does not; with half the reach or
// half the floor the first is outside, with twice either the second is inside.
TEST(GuidedRules, AMatchWithinFourSpreadsOfThePredictionJoins) {
  const Geometric g;
  const double spread_s = 0.005 * g.dn();
  for (double z : {3.0, 6.0}) {
    Scene s;
    s.PutAll(g.t);
    const double at = OnSample(g.next() + z * spread_s);
    s.Put(at);
    auto joins = [&](const GuidedOptions& go) { return Holds(s.Extend(g.t, go), at); };
    GuidedOptions reach_half, reach_twice, floor_half, floor_twice;
    reach_half.reach /= 2.0, reach_twice.reach *= 2.0;
    floor_half.min_ratio_spread /= 2.0, floor_twice.min_ratio_spread *= 2.0;
    if (z == 3.0) {
      EXPECT_TRUE(joins(GuidedOptions{})) << "3 spreads off";
      EXPECT_FALSE(joins(reach_half)) << "reach 2";
      EXPECT_FALSE(joins(floor_half)) << "floor 0.0025";
    } else {
      EXPECT_FALSE(joins(GuidedOptions{})) << "6 spreads off";
      EXPECT_TRUE(joins(reach_twice)) << "reach 8";
      EXPECT_TRUE(joins(floor_twice)) << "floor 0.01";
    }
  }
}

// Ranking is NCC - 0.15 u^2 (u: distance from the prediction in half windows): an impact at the
// prediction beats a perfect copy at u = 0.8 when its NCC is above 1 - 0.15 * 0.64 = 0.904.
// At NCC 0.928 it wins (with half the penalty it would need 0.952); at 0.856 it loses (with twice
// the penalty it would need only 0.808).
TEST(GuidedRules, TheEdgePenaltyPrefersTheMatchAtThePrediction) {
  const Geometric g;
  const double half_s = 4.0 * 0.005 * g.dn();
  const double centre = OnSample(g.next()), rival = OnSample(g.next() + 0.8 * half_s);
  for (double c : {0.928, 0.856}) {
    Scene s;
    s.PutAll(g.t);
    s.Put(centre, std::sqrt(1.0 / (c * c) - 1.0));
    s.Put(rival);
    auto centre_wins = [&](const GuidedOptions& go) {
      const std::vector<double> t = s.Extend(g.t, go);
      EXPECT_TRUE(Holds(t, centre) || Holds(t, rival)) << "one of the two joins";
      return Holds(t, centre);
    };
    GuidedOptions half, twice;
    half.edge_penalty /= 2.0, twice.edge_penalty *= 2.0;
    if (c > 0.9) {
      EXPECT_TRUE(centre_wins(GuidedOptions{}));
      EXPECT_FALSE(centre_wins(half));
    } else {
      EXPECT_FALSE(centre_wins(GuidedOptions{}));
      EXPECT_TRUE(centre_wins(twice));
    }
  }
}

// A look's match joins when its own p-value is at most 0.05, even inside a run that a strong
// next impact makes certain: at p = 0.035 both join (with 0.025 neither: the tail ends at its
// first unheard impact); at p = 0.07 neither (with 0.1 both).
TEST(GuidedRules, AMatchJoinsWhenNoiseMatchesAsWellInOneWindowOfTwenty) {
  const Geometric g;
  const double weak = OnSample(g.next()), strong = OnSample(g.next() + 0.9 * g.dn());
  for (double p : {0.035, 0.07}) {
    Scene s = WithCopyOfP(g.t, weak, g.dn(), p);
    s.Put(strong);
    auto both_join = [&](const GuidedOptions& go) {
      const std::vector<double> t = s.Extend(g.t, go);
      EXPECT_EQ(Holds(t, weak), Holds(t, strong)) << "the strong one joins only after the weak";
      return Holds(t, weak) && Holds(t, strong);
    };
    GuidedOptions half, twice;
    half.member_p /= 2.0, twice.member_p *= 2.0;
    if (p < 0.05) {
      EXPECT_TRUE(both_join(GuidedOptions{})) << "p " << p;
      EXPECT_FALSE(both_join(half)) << "p " << p << ", member_p 0.025";
    } else {
      EXPECT_FALSE(both_join(GuidedOptions{})) << "p " << p;
      EXPECT_TRUE(both_join(twice)) << "p " << p << ", member_p 0.1";
    }
  }
}

// A run of looks joins when noise alone explains it with probability at most 0.01 (Fisher's
// combination; one look: its own p-value). A lone match of p = 0.007 joins (not with 0.005); one
// of p = 0.014 does not (does with 0.02).
TEST(GuidedRules, ARunJoinsWhenNoiseExplainsItOnceInAHundred) {
  const Geometric g;
  const double at = OnSample(g.next());
  for (double p : {0.007, 0.014}) {
    const Scene s = WithCopyOfP(g.t, at, g.dn(), p);
    auto joins = [&](const GuidedOptions& go) { return Holds(s.Extend(g.t, go), at); };
    GuidedOptions half, twice;
    half.false_alarm /= 2.0, twice.false_alarm *= 2.0;
    if (p < 0.01) {
      EXPECT_TRUE(joins(GuidedOptions{})) << "p " << p;
      EXPECT_FALSE(joins(half)) << "p " << p << ", false alarm 0.005";
    } else {
      EXPECT_FALSE(joins(GuidedOptions{})) << "p " << p;
      EXPECT_TRUE(joins(twice)) << "p " << p << ", false alarm 0.02";
    }
  }
}

// The least-squares line through the last n log ratios, evaluated one flight on.
double LinePrediction(const std::vector<double>& t, std::size_t n) {
  std::vector<double> y;
  for (std::size_t k = t.size() - n; k < t.size(); ++k)
    y.push_back(std::log((t[k] - t[k - 1]) / (t[k - 1] - t[k - 2])));
  double mx = 0.0, my = 0.0;
  const double m = static_cast<double>(n);
  for (std::size_t j = 0; j < n; ++j) mx += static_cast<double>(j) / m, my += y[j] / m;
  double sxx = 0.0, sxy = 0.0;
  for (std::size_t j = 0; j < n; ++j)
    sxx += (static_cast<double>(j) - mx) * (static_cast<double>(j) - mx),
        sxy += (static_cast<double>(j) - mx) * (y[j] - my);
  return my + sxy / sxx * (m - mx);
}

// The trend of log r is a line through the last six ratios. Ratios flat, then rising by 0.04 per
// flight over the last three: the impact where the six-flight line puts it joins; a three-flight
// line predicts 6 of its spreads away and misses it.
TEST(GuidedRules, TheTrendIsALineThroughTheLastSixRatios) {
  std::vector<double> ratios = Repeat(0.80, 8);
  for (double k : {1.0, 2.0, 3.0}) ratios.push_back(0.80 * std::exp(0.04 * k));
  const std::vector<double> t = Chain(0.2, 0.35, ratios);
  const double last = t.back() - t[t.size() - 2];
  const double at = OnSample(t.back() + last * std::exp(LinePrediction(t, 6)));
  Scene s;
  s.PutAll(t);
  s.Put(at);
  GuidedOptions three;
  three.trend_flights = 3;
  EXPECT_TRUE(Holds(s.Extend(t, GuidedOptions{}), at));
  EXPECT_FALSE(Holds(s.Extend(t, three), at));
}

// ... and only the last six: ratios that scattered by +-0.03 before them do not widen the window
// (a line through twelve would take their scatter, 0.04 of log r, for the spread: a copy where
// the flight is 4 % longer than predicted, 8 floor spreads off, would join).
TEST(GuidedRules, OlderScatterDoesNotWidenTheWindow) {
  std::vector<double> ratios;
  for (int k = 0; k < 6; ++k) ratios.push_back(0.85 * std::exp(k % 2 ? 0.03 : -0.03));
  for (int k = 0; k < 6; ++k) ratios.push_back(0.85);
  const std::vector<double> t = Chain(0.2, 0.3, ratios);
  const double last = t.back() - t[t.size() - 2];
  const double at = OnSample(t.back() + 0.85 * last * 1.04);
  Scene s;
  s.PutAll(t);
  s.Put(at);
  GuidedOptions twelve;
  twelve.trend_flights = 12;
  EXPECT_FALSE(Holds(s.Extend(t, GuidedOptions{}), at));
  EXPECT_TRUE(Holds(s.Extend(t, twelve), at));
}

// After a member the next flight may be longer than the one before (e > 1) only within 3 sigma
// of the two impacts' timing noise (100 us each: 3 * 141 us / 0.3 s = 1.4e-3 of the flight).
// Nearly elastic flights (ratio 0.998): a flight longer by 0.75 of that slack joins (not with
// 1.5 sigma), one longer by 1.5 of it does not (does with 6 sigma).
TEST(GuidedRules, AFlightLongerThanTheOneBeforeOnlyWithinThreeSigmas) {
  constexpr double kSigma = 1e-4;
  const std::vector<double> t = Chain(0.2, 0.3, Repeat(0.998, 5));
  const double last = t.back() - t[t.size() - 2];
  const double slack = 3.0 * std::hypot(kSigma, kSigma) / last;
  for (double f : {0.75, 1.5}) {
    const double at = OnSample(t.back() + last * (1.0 + f * slack));
    Scene s;
    s.PutAll(t);
    s.Put(at);
    auto joins = [&](const GuidedOptions& go) { return Holds(s.Extend(t, go, kSigma), at); };
    GuidedOptions half, twice;
    half.ratio_slack_sigmas /= 2.0, twice.ratio_slack_sigmas *= 2.0;
    if (f < 1.0) {
      EXPECT_TRUE(joins(GuidedOptions{}));
      EXPECT_FALSE(joins(half));
    } else {
      EXPECT_FALSE(joins(GuidedOptions{}));
      EXPECT_TRUE(joins(twice));
    }
  }
}

// Each drop is looked for with its own sound (the whitened waveform of its strongest member): a
// drop whose impacts sound unlike the recording's strongest one (another impact point, another
// cut of a real ball: NCC 0.31-0.55 between drops) keeps its tail. The first drop sounds like the
// recording's template, the second like nothing in it: the second's next impact joins its tail.
TEST(GuidedRules, EachDropIsLookedForWithItsOwnSound) {
  const std::vector<double> a = Chain(0.2, 0.3, Repeat(0.9, 5));
  const std::vector<double> b = Chain(2.2, 0.3, Repeat(0.9, 5));
  const double last = b.back() - b[b.size() - 2];
  const double next_a = OnSample(a.back() + 0.9 * (a.back() - a[a.size() - 2]));
  const double next_b = OnSample(b.back() + 0.9 * last);
  Scene s;
  s.PutAll(a);
  s.Put(next_a);
  s.PutOther(b);
  s.PutOther({next_b});
  const std::vector<std::vector<double>> t = s.ExtendEach({a, b}, GuidedOptions{});
  EXPECT_TRUE(Holds(t[0], next_a));
  EXPECT_TRUE(Holds(t[1], next_b));
}

TEST(GuidedRules, InvalidOptionsAreRefused) {
  Scene s;
  const Geometric g;
  GuidedOptions bad;
  bad.member_p = 1.5;
  EXPECT_THROW(s.Extend(g.t, bad), Error);
  bad = GuidedOptions{};
  bad.trend_flights = 2;
  EXPECT_THROW(s.Extend(g.t, bad), Error);
  GuidedOptions order = GuidedOptions{};
  order.lpc_order = -1;
  EXPECT_THROW(s.ExtendWithNoiseSignal(g.t, order), Error);
  for (double share : {0.0, 1.5}) {
    GuidedOptions frames;
    frames.noise_frames = share;
    EXPECT_THROW(s.ExtendWithNoiseSignal(g.t, frames), Error) << share;
  }
}

// The tail's impacts ring (the same waveform after every impact, as a plate's or a ball's ringing
// after impacts of one drop): 10 times the noise at its start, decaying over 20 ms, flights of
// 60 ms shrinking by 0.9. A weak next impact (NCC 0.6 over the noise alone: p ~ 1e-4 where the
// noise is white) sits in the ringing of the ones before it. In the whitened signal that ringing
// is noise to the look (its spread mid-flight several times white noise's): it does not join. With
// the members' responses cancelled (the noise-whitened signal, GuidedOptions::noise_signal) the
// ringing is gone, the last member stands out more there, the tail is searched there, and it
// joins, at its time.
TEST(GuidedNoiseSignal, CancellingTheMembersRingingLetsAWeakImpactInItJoin) {
  const std::vector<double> t = Chain(0.2, 0.06, Repeat(0.9, 5));
  const double dn = 0.9 * (t.back() - t[t.size() - 2]);
  const double at = OnSample(t.back() + dn);
  Scene s;
  s.PutAll(t);
  s.PutRinging(t, 0.02, 10.0);
  s.PutScaled(at, 0.6);
  EXPECT_FALSE(Holds(s.Extend(t, GuidedOptions{}), at));
  const std::vector<double> with = s.ExtendWithNoiseSignal(t, GuidedOptions{});
  EXPECT_TRUE(Holds(with, at));
  // Nothing else joins: the ringing is not taken for impacts.
  EXPECT_EQ(with.size(), t.size() + 1);
}

// Where nothing rings (white noise, the copies alone) the two signals are the same, and the
// noise-whitened one changes nothing: the same impacts join, at the same times to a sample.
TEST(GuidedNoiseSignal, WithoutRingingTheTailIsTheSame) {
  const Geometric g;
  Scene s;
  s.PutAll(g.t);
  const std::vector<double> more = Chain(g.next(), 0.9 * g.dn(), Repeat(0.9, 3));
  std::vector<double> tail{g.next()};
  tail.insert(tail.end(), more.begin(), more.end());
  s.PutAll(tail);
  const std::vector<double> a = s.Extend(g.t, GuidedOptions{});
  const std::vector<double> b = s.ExtendWithNoiseSignal(g.t, GuidedOptions{});
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_NEAR(a[i], b[i], 1.0 / kRate) << i;
  for (double x : tail) EXPECT_TRUE(Holds(b, x)) << x;
}

}  // namespace
}  // namespace bouncecal
