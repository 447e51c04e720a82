// Rules of the detection of one signal (src/acoustic/detect_signal.cpp) pinned to within a
// factor of 2 (issue 29; tools/mutations.txt a102-a107): an impact's energy rise (Impact::rise_db,
// what the tracker weighs a candidate's attack by) compares the millisecond after its onset with
// the few milliseconds before it.
//
// The signals are synthetic: a white noise floor, a steady tone that stops before an impact, and
// the impact's click (a decaying 3-kHz sine), so every energy is known.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "acoustic/detect_signal.hpp"

namespace bouncecal {
namespace {

constexpr double kRateHz = 48000.0;
constexpr double kPi = 3.14159265358979323846;

// 0.6 s of noise (RMS 1e-4), a 1.5-kHz tone of amplitude `tone` from 0.1 s until `tone_end_s`
// (faded out over the last `fade_s` with a raised cosine),
// and a click of amplitude 0.5 decaying with 0.3 ms at 0.5 s (its mean square over the
// millisecond after it: 0.5^2 / 2 * 0.3 ms / 2 / 1 ms = 0.01875; 99.9 % of its energy).
constexpr double kClickS = 0.5, kClickTauS = 3e-4;
constexpr double kClickMeanSquare = 0.25 / 2.0 * kClickTauS / 2.0 / 1e-3;
std::vector<float> Signal(double tone, double tone_end_s, double fade_s = 0.0) {
  std::mt19937 rng(7);
  std::normal_distribution<double> noise(0.0, 1e-4);
  std::vector<float> x(static_cast<std::size_t>(0.6 * kRateHz));
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double t = static_cast<double>(i) / kRateHz;
    double v = noise(rng);
    if (t >= 0.1 && t < tone_end_s) {
      const double u =
          fade_s > 0.0 ? std::clamp((t - (tone_end_s - fade_s)) / fade_s, 0.0, 1.0) : 0.0;
      v += tone * 0.5 * (1.0 + std::cos(kPi * u)) * std::sin(2.0 * kPi * 1500.0 * t);
    }
    if (t >= kClickS)
      v += 0.5 * std::exp(-(t - kClickS) / kClickTauS) *
           std::sin(2.0 * kPi * 3000.0 * (t - kClickS));
    x[i] = static_cast<float>(v);
  }
  return x;
}

// The rise of the candidate at the click (NaN when the detector found none within 0.5 ms).
double ClickRiseDb(const std::vector<float>& x) {
  const SignalDetection d = DetectInSignal(x, kRateHz, DetectOptions{});
  double best = NAN, dist = 5e-4;
  for (const Impact& c : d.candidates)
    if (std::fabs(c.time_s - kClickS) < dist)
      dist = std::fabs(c.time_s - kClickS), best = c.rise_db;
  return best;
}

// The sound before an onset is what rang in the 3.5 ms before it (up to 0.5 ms before it): a tone
// as loud as the click's millisecond (faded out over 0.3 ms: an abrupt stop is an onset of its
// own) that stopped 2.5 ms before the click rang through a quarter of that window, and leaves the
// click a rise of a few dB; one that stopped 5 ms before has rung out, and the click rises ~60 dB
// above the noise floor. (A window of 1.75 ms would miss the first tone, one of 7 ms would hear
// the second.)
TEST(SignalRules, TheRiseComparesWithTheThreeAndAHalfMillisecondsBefore) {
  const double tone = std::sqrt(2.0 * kClickMeanSquare);
  const double late = ClickRiseDb(Signal(tone, kClickS - 0.0025, 3e-4));
  const double early = ClickRiseDb(Signal(tone, kClickS - 0.005, 3e-4));
  ASSERT_FALSE(std::isnan(late));
  ASSERT_FALSE(std::isnan(early));
  EXPECT_LT(late, 10.0) << "a tone that stopped 2.5 ms before the click";
  EXPECT_GT(early, 30.0) << "a tone that stopped 5 ms before the click";
}

// The attack is the millisecond after the onset: over a steady tone that goes on through the
// click, the rise is the ratio of the click's mean square over that millisecond plus the tone's
// (C + P) to the tone's P: 10 log10(1 + C / P). With P = C / 3, 6.0 dB (a window of 2 ms would
// give 4.0 dB, of 0.5 ms 8.3 dB).
TEST(SignalRules, TheAttackIsTheMillisecondAfterTheOnset) {
  const double p = kClickMeanSquare / 3.0;
  const double rise = ClickRiseDb(Signal(std::sqrt(2.0 * p), 1.0));
  ASSERT_FALSE(std::isnan(rise));
  EXPECT_NEAR(rise, 10.0 * std::log10(1.0 + kClickMeanSquare / p), 1.0);
}

// The sound before an onset ends 0.5 ms before it (a guard for the onset's own timing error): a
// burst 0.9-0.6 ms before the click is in it (the click rises ~0 dB over it; a 1-ms guard would
// leave it out), one 0.45-0.3 ms before is not (the click rises ~60 dB over the noise; a 0.25-ms
// guard would count it). The burst's amplitude makes its mean square over the 3-ms window equal
// to the click's over its millisecond.
TEST(SignalRules, TheRiseIgnoresTheHalfMillisecondBeforeTheOnset) {
  const double amplitude = std::sqrt(2.0 * kClickMeanSquare * 3.0 / 0.3);
  auto rise_with_burst = [&](double from_ms, double to_ms) {
    std::vector<float> x = Signal(0.0, 0.0);  // the noise and the click
    for (std::size_t i = 0; i < x.size(); ++i) {
      const double t = static_cast<double>(i) / kRateHz;
      const double before_ms = (kClickS - t) * 1e3;
      if (before_ms <= from_ms && before_ms > to_ms)
        x[i] += static_cast<float>(amplitude * std::sin(2.0 * kPi * 8000.0 * t));
    }
    return RawRiseDb(x, kRateHz, kClickS);
  };
  EXPECT_LT(rise_with_burst(0.9, 0.6), 10.0) << "a burst 0.9-0.6 ms before the click";
  EXPECT_GT(rise_with_burst(0.45, 0.3), 30.0) << "a burst 0.45-0.3 ms before the click";
}

// ---- a member inside an attack's sound is moved to the attack (MoveMembersToTheirAttacks) -------
// A member at 1.0 s of a sequence with flights of ~0.2 s; a candidate before it whose rise and
// level are set; the member does not rise (-2 dB). Rules: the attack began within 3.5 ms before
// the member (the rise's window), rises by >= 6 dB, and is at most 6 dB quieter than the member.
double MovedTo(double attack_before_s, double attack_rise_db, double attack_level_db,
               double member_rise_db = -2.0) {
  std::vector<Impact> cands;
  auto impact = [](double t, double rise_db, double amplitude) {
    Impact i;
    i.time_s = t;
    i.rise_db = rise_db;
    i.amplitude = amplitude;
    return i;
  };
  Sequence q;
  q.impacts = {impact(0.6, 20.0, 0.2), impact(0.81, 20.0, 0.18), impact(1.0, member_rise_db, 0.16),
               impact(1.17, 20.0, 0.15)};
  cands = q.impacts;
  cands.push_back(
      impact(1.0 - attack_before_s, attack_rise_db, 0.16 * std::pow(10.0, attack_level_db / 20.0)));
  std::sort(cands.begin(), cands.end(),
            [](const Impact& a, const Impact& b) { return a.time_s < b.time_s; });
  std::vector<Sequence> seqs{q};
  MoveMembersToTheirAttacks(cands, TrackOptions{}, &seqs);
  return seqs[0].impacts[2].time_s;
}
bool Moved(double before_s, double rise_db, double level_db, double member_rise_db = -2.0) {
  return std::fabs(MovedTo(before_s, rise_db, level_db, member_rise_db) - (1.0 - before_s)) < 1e-12;
}

TEST(SignalRules, AMemberInsideAnAttacksSoundIsMovedToTheAttack) {
  EXPECT_TRUE(Moved(0.003, 8.0, -3.0)) << "the real rubber ball: 3.06 ms, 21 dB, -2.8 dB";
  EXPECT_FALSE(Moved(0.003, 8.0, -3.0, 1.0)) << "a member that rises is its own attack";
}
// kAttackReachS = 3.5 ms: 3.0 ms moves, 4.5 ms does not (x2: 7 ms; x1/2: 1.75 ms).
TEST(SignalRules, TheAttackReachIsTheRiseWindow) {
  EXPECT_TRUE(Moved(0.0030, 8.0, -3.0));
  EXPECT_FALSE(Moved(0.0045, 8.0, -3.0));
}
// kAttackRiseDb = 6 dB: an attack rising 8 dB moves the member, one rising 4.5 dB does not.
TEST(SignalRules, TheAttackMustRiseBySixDecibels) {
  EXPECT_TRUE(Moved(0.003, 8.0, -3.0));
  EXPECT_FALSE(Moved(0.003, 4.5, -3.0));
}
// kAttackLevelDb = 6 dB: an attack 4 dB below the member moves it, one 8 dB below is a precursor
// (the real basketball's cut: 19 dB below its attack) and does not.
TEST(SignalRules, APrecursorFarQuieterThanTheMemberIsNotItsAttack) {
  EXPECT_TRUE(Moved(0.003, 8.0, -4.0));
  EXPECT_FALSE(Moved(0.003, 8.0, -8.0));
}

}  // namespace
}  // namespace bouncecal
