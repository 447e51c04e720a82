// Bounce-sequence tracker: physically possible chains from onset candidates.
#include "bouncecal/acoustic/sequence.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <set>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

// A candidate at t whose level is its SNR above a noise floor of 1e-3 (full scale = 1).
Impact Cand(double t, double snr_db = 30.0, double score = 0.8) {
  Impact i;
  i.time_s = t;
  i.snr_db = snr_db;
  i.score = score;
  i.amplitude = 1e-3 * std::pow(10.0, snr_db / 20.0);
  return i;
}

// A geometric bouncing sequence: first impact at t0, first interval dt0, ratio e, until the
// interval drops below min_dt.
std::vector<double> Bounces(double t0, double dt0, double e, double min_dt, int max_n = 200) {
  std::vector<double> t{t0};
  double dt = dt0;
  while (dt >= min_dt && static_cast<int>(t.size()) < max_n) {
    t.push_back(t.back() + dt);
    dt *= e;
  }
  return t;
}

std::vector<Impact> Sorted(std::vector<Impact> c) {
  std::sort(c.begin(), c.end(),
            [](const Impact& a, const Impact& b) { return a.time_s < b.time_s; });
  return c;
}

std::vector<double> Times(const Sequence& s) {
  std::vector<double> t;
  for (const Impact& i : s.impacts) t.push_back(i.time_s);
  return t;
}

TEST(Sequence, CleanGeometricSequenceIsKeptWhole) {
  const std::vector<double> t = Bounces(1.0, 0.4, 0.9, 0.02, 25);
  std::vector<Impact> c;
  for (double x : t) c.push_back(Cand(x));
  const auto seqs = TrackSequences(c, 10.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
  EXPECT_TRUE(seqs[0].missed_after.empty());
}

TEST(Sequence, RejectsDistractorClicksAndEchoes) {
  const std::vector<double> t = Bounces(1.0, 0.5, 0.85, 0.03);
  std::vector<Impact> c;
  for (double x : t) {
    c.push_back(Cand(x));
    c.push_back(Cand(x + 0.004, 8.0, 0.3));  // echo / double trigger 4 ms later, weaker
  }
  // Distractor clicks at random times, as loud as the impacts.
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 6.0);
  for (int k = 0; k < 8; ++k) c.push_back(Cand(u(rng), 30.0, 0.2));
  const auto seqs = TrackSequences(Sorted(c), 6.0, TrackOptions{});
  ASSERT_GE(seqs.size(), 1u);
  std::size_t main = 0;
  for (std::size_t s = 1; s < seqs.size(); ++s)
    if (seqs[s].impacts.size() > seqs[main].impacts.size()) main = s;
  const std::vector<double> got = Times(seqs[main]);
  // Every true impact found, nothing else in the main sequence.
  ASSERT_EQ(got.size(), t.size());
  for (std::size_t k = 0; k < t.size(); ++k) EXPECT_DOUBLE_EQ(got[k], t[k]) << "k=" << k;
}

TEST(Sequence, RingingRetriggersAtConstantSpacingAreNotASequence) {
  // Re-triggers every 51 ms on the ringing (tennis-ball recording): constant intervals, weak.
  const std::vector<double> t = Bounces(0.2, 1.0, 0.8, 0.1);
  std::vector<Impact> c;
  for (double x : t) {
    c.push_back(Cand(x, 30.0, 0.9));
    for (int r = 1; r <= 5; ++r) c.push_back(Cand(x + 0.051 * r, 6.0, 0.25));
  }
  const auto seqs = TrackSequences(Sorted(c), 8.0, TrackOptions{});
  ASSERT_GE(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
}

TEST(Sequence, FlagsAMissingImpact) {
  std::vector<double> t = Bounces(0.5, 0.5, 0.9, 0.05);
  ASSERT_GT(t.size(), 10u);
  std::vector<Impact> c;
  for (std::size_t k = 0; k < t.size(); ++k)
    if (k != 6) c.push_back(Cand(t[k]));  // impact 6 not detected
  const auto seqs = TrackSequences(c, 10.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(seqs[0].impacts.size(), t.size() - 1);
  ASSERT_EQ(seqs[0].missed_after.size(), 1u);
  EXPECT_EQ(seqs[0].missed_after[0], 5);  // between sequence impacts 5 and 6
}

TEST(Sequence, SplitsTwoDropsInOneFile) {
  const std::vector<double> a = Bounces(0.5, 0.4, 0.9, 0.02);
  const std::vector<double> b = Bounces(a.back() + 1.5, 0.3, 0.8, 0.02);
  std::vector<Impact> c;
  for (double x : a) c.push_back(Cand(x));
  for (double x : b) c.push_back(Cand(x));
  const auto seqs = TrackSequences(c, 20.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 2u);
  EXPECT_EQ(Times(seqs[0]), a);
  EXPECT_EQ(Times(seqs[1]), b);
  // The first drop's next impact (18 ms later) would have been resolvable: it was not heard.
  EXPECT_EQ(seqs[0].end_reason, "snr_limit");
}

TEST(Sequence, StopsWhereImpactsAreNoLongerResolvable) {
  // Candidates continue to 1 ms intervals; below min_interval_s (3 ms) nothing is invented
  // or kept.
  const std::vector<double> t = Bounces(0.5, 0.3, 0.8, 0.001);
  std::vector<Impact> c;
  for (double x : t) c.push_back(Cand(x));
  TrackOptions o;
  const auto seqs = TrackSequences(c, 5.0, o);
  ASSERT_GE(seqs.size(), 1u);
  const std::vector<double> got = Times(seqs[0]);
  for (std::size_t k = 1; k < got.size(); ++k) EXPECT_GE(got[k] - got[k - 1], o.min_interval_s);
  // The sequence reaches the resolvable limit: its last interval is within 1/e of it.
  ASSERT_GE(got.size(), 3u);
  EXPECT_LT(got.back() - got[got.size() - 2], o.min_interval_s / 0.8 / 0.8);
  EXPECT_EQ(seqs[0].end_reason, "resolved_limit");
}

TEST(Sequence, EndReasonEndOfFile) {
  const std::vector<double> t = Bounces(0.5, 0.5, 0.9, 0.2);
  std::vector<Impact> c;
  for (double x : t) c.push_back(Cand(x));
  const auto seqs = TrackSequences(c, t.back() + 0.05, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(seqs[0].end_reason, "end_of_file");
}

TEST(Sequence, OneOrTwoImpactsOrGrowingIntervalsAreNotASequence) {
  EXPECT_TRUE(TrackSequences({}, 1.0, TrackOptions{}).empty());
  EXPECT_TRUE(TrackSequences({Cand(0.5)}, 1.0, TrackOptions{}).empty());
  EXPECT_TRUE(TrackSequences({Cand(0.5), Cand(0.9)}, 1.0, TrackOptions{}).empty());
  // Three impacts with a growing interval: restitution 1.3 > 1, impossible.
  EXPECT_TRUE(TrackSequences({Cand(0.1), Cand(0.15), Cand(0.215)}, 5.0, TrackOptions{}).empty());
}

// Bounces of a ball with restitution e from rest at height h (m), first impact at t0: flights
// of 2 v / g, v_(k+1) = e v_k, until the flight is shorter than min_dt.
std::vector<double> Drop(double t0, double h, double e, double min_dt = 0.003, int max_n = 400) {
  const double g = 9.81;
  double v = std::sqrt(2.0 * g * h) * e;
  std::vector<double> t{t0};
  while (2.0 * v / g >= min_dt && static_cast<int>(t.size()) < max_n) {
    t.push_back(t.back() + 2.0 * v / g);
    v *= e;
  }
  return t;
}

// A drop's impacts with falling SNR (level ~ v: 20 log10 e per bounce from snr0).
void AddDrop(const std::vector<double>& t, double snr0, double e, std::vector<Impact>* c) {
  for (std::size_t k = 0; k < t.size(); ++k) {
    c->push_back(Cand(t[k], snr0 + 20.0 * std::log10(e) * static_cast<double>(k), 0.8));
  }
}

// Which drop each member of each sequence belongs to (-1: none): a time equal to a truth time.
std::vector<std::set<int>> DropsOf(const std::vector<Sequence>& seqs,
                                   const std::vector<std::vector<double>>& drops) {
  std::vector<std::set<int>> out;
  for (const Sequence& q : seqs) {
    std::set<int> ds;
    for (const Impact& i : q.impacts) {
      int which = -1;
      for (std::size_t d = 0; d < drops.size(); ++d)
        if (std::find(drops[d].begin(), drops[d].end(), i.time_s) != drops[d].end())
          which = static_cast<int>(d);
      ds.insert(which);
    }
    out.push_back(ds);
  }
  return out;
}

// A dropper rig: one drop repeated 100 times with 0.1-1.3 s between the copies. Every copy is
// its own whole sequence (before the joint tracker: 3-15 sequences, several spanning copies).
TEST(Sequence, EveryCopyOfARepeatedDropIsItsOwnSequence) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> gap(0.1, 1.3);
  const std::vector<double> one = Drop(0.0, 0.1, 0.9, 0.01);
  std::vector<std::vector<double>> drops;
  std::vector<Impact> c;
  double t = 0.5;
  for (int d = 0; d < 100; ++d) {
    std::vector<double> copy;
    for (double x : one) copy.push_back(t + x);
    AddDrop(copy, 30.0, 0.9, &c);
    drops.push_back(copy);
    t = copy.back() + 0.05 + gap(rng);  // the recording of a drop ends 50 ms after its last impact
  }
  const auto seqs = TrackSequences(Sorted(c), t + 1.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), drops.size());
  const auto of = DropsOf(seqs, drops);
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    ASSERT_EQ(of[s].size(), 1u) << "sequence " << s << " spans drops";
    EXPECT_EQ(Times(seqs[s]), drops[static_cast<std::size_t>(*of[s].begin())]) << s;
  }
}

// Drops of different heights and balls one after another: each drop one sequence, none spanning
// two, whatever the heights (a later drop may start lower than an earlier one ended).
TEST(Sequence, DropsOfDifferentHeightsAreSeparated) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> height(0.02, 0.5), e(0.6, 0.95), pause(0.3, 2.0);
  std::vector<std::vector<double>> drops;
  std::vector<Impact> c;
  double t = 0.4;
  for (int d = 0; d < 30; ++d) {
    const double ed = e(rng);
    const std::vector<double> x = Drop(t, height(rng), ed, 0.02);
    AddDrop(x, 35.0, ed, &c);
    drops.push_back(x);
    t = x.back() + pause(rng);
  }
  const auto seqs = TrackSequences(Sorted(c), t, TrackOptions{});
  EXPECT_EQ(seqs.size(), drops.size());
  for (const auto& ds : DropsOf(seqs, drops)) EXPECT_EQ(ds.size(), 1u);
}

// A recording that starts in the middle of a sequence is still a sequence: 3 impacts with
// plausible ratios suffice (the ball was bouncing before t = 0).
TEST(Sequence, AClipThatStartsMidSequenceIsASequence) {
  const std::vector<double> full = Drop(-0.4, 0.3, 0.7, 0.004);
  std::vector<double> t;
  for (double x : full)
    if (x >= 0.02) t.push_back(x);
  ASSERT_GE(t.size(), 4u);
  std::vector<Impact> c;
  AddDrop(t, 30.0, 0.7, &c);
  const auto seqs = TrackSequences(c, 0.9, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
}

// The same tiny intervals later in a file, with nothing before them, are not a drop: a ball
// released from rest falls at least min_drop_height_m, so its first flight is not 5 ms (a
// cluster of echoes or a plate's buzz). At the start of the file they could be a tail.
TEST(Sequence, ATinyFirstFlightAwayFromTheStartIsNotADrop) {
  std::vector<Impact> c;
  for (double x : {2.0, 2.005, 2.0085, 2.011}) c.push_back(Cand(x));
  EXPECT_TRUE(TrackSequences(c, 5.0, TrackOptions{}).empty());
  std::vector<Impact> early;
  for (double x : {0.002, 0.007, 0.0105, 0.013}) early.push_back(Cand(x));
  EXPECT_EQ(TrackSequences(early, 5.0, TrackOptions{}).size(), 1u);
}

// Restitution near one: 81 impacts from 176 ms down to 45 ms intervals (e 0.983) found whole.
TEST(Sequence, ALivelyBallIsFollowedToItsEnd) {
  std::vector<double> t{1.0};
  double d = 0.176;
  for (int k = 0; k < 80; ++k) {
    t.push_back(t.back() + d);
    d *= 0.983;
  }
  std::vector<Impact> c;
  AddDrop(t, 25.0, 0.983, &c);
  const auto seqs = TrackSequences(c, t.back() + 0.5, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
}

// A real ball's restitution scatters from bounce to bounce (sigma_e 0.02): the sequence stays
// one, its members all found, none flagged irregular.
TEST(Sequence, ScatterOfARealBallIsFollowed) {
  std::mt19937 rng(11);
  std::normal_distribution<double> scatter(0.0, 0.02);
  std::vector<double> t{0.5};
  double v = 3.0;
  while (2.0 * v / 9.81 > 0.02) {
    t.push_back(t.back() + 2.0 * v / 9.81);
    v *= std::clamp(0.85 + scatter(rng), 0.0, 0.99);
  }
  std::vector<Impact> c;
  AddDrop(t, 30.0, 0.85, &c);
  const auto seqs = TrackSequences(c, t.back() + 1.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_TRUE(seqs[0].irregular_after.empty());
  // Every bounce a member, or inside a gap flagged as unheard (guided search looks there,
  // detect.hpp); nothing else.
  const std::vector<double> got = Times(seqs[0]);
  EXPECT_EQ(got.front(), t.front());
  EXPECT_EQ(got.back(), t.back());
  for (double x : got) EXPECT_NE(std::find(t.begin(), t.end(), x), t.end());
  std::size_t inside_gaps = 0;
  for (int k : seqs[0].missed_after) {
    const auto a = std::find(t.begin(), t.end(), got[static_cast<std::size_t>(k)]);
    const auto b = std::find(t.begin(), t.end(), got[static_cast<std::size_t>(k) + 1]);
    inside_gaps += static_cast<std::size_t>(b - a - 1);
  }
  EXPECT_EQ(got.size() + inside_gaps, t.size());
}

// A ratio above one is no bounce (e <= 1): intervals growing by 1 % a step, timed to a
// microsecond, are not one sequence.
TEST(Sequence, GrowingIntervalsAreNotOneSequence) {
  std::vector<Impact> c;
  double t = 1.0, d = 0.1;
  for (int k = 0; k < 12; ++k) {
    Impact i = Cand(t);
    i.sigma_s = 1e-6;
    c.push_back(i);
    t += d;
    d *= 1.01;
  }
  const auto seqs = TrackSequences(c, 5.0, TrackOptions{});
  for (const Sequence& q : seqs) EXPECT_LT(q.impacts.size(), 6u);
}

// Restitution 0.3 (a dead ball) is tracked; 0.15 is below min_ratio.
TEST(Sequence, LowRestitutionDownToMinRatio) {
  std::vector<Impact> c;
  for (double x : Bounces(1.0, 0.4, 0.3, 0.003)) c.push_back(Cand(x));
  ASSERT_EQ(TrackSequences(c, 5.0, TrackOptions{}).size(), 1u);
  std::vector<Impact> dead;
  for (double x : Bounces(1.0, 0.4, 0.15, 0.003)) dead.push_back(Cand(x));
  EXPECT_TRUE(TrackSequences(dead, 5.0, TrackOptions{}).empty());
}

// An irregular bounce (spin: one interval 8 % longer than the one before) does not end the
// sequence and is flagged; a step of 1.3 is no bounce of this ball (max_irregular_ratio).
TEST(Sequence, OneIrregularBounceIsFlaggedNotAnEnd) {
  std::vector<double> t{0.5};
  double d = 0.5;
  for (int k = 1; k < 18; ++k) {
    t.push_back(t.back() + d);
    d *= k == 8 ? 1.08 : 0.88;  // interval 8 -> 9 is 8 % longer than interval 7 -> 8
  }
  std::vector<Impact> c;
  for (double x : t) c.push_back(Cand(x));
  auto seqs = TrackSequences(c, 20.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
  EXPECT_EQ(seqs[0].irregular_after, std::vector<int>{8});
}

// Two unheard impacts in a row (a quiet stretch) are bridged and flagged when the gap is
// exactly three flights; a gap that three flights do not explain ends the sequence.
TEST(Sequence, UnheardImpactsAreBridgedOnlyWhenTheGapFits) {
  const std::vector<double> t = Bounces(0.5, 0.4, 0.9, 0.05);
  std::vector<Impact> c;
  for (std::size_t k = 0; k < t.size(); ++k)
    if (k != 7 && k != 8) {
      Impact i = Cand(t[k], 8.0);  // quiet: an unheard impact is plausible
      c.push_back(i);
    }
  auto seqs = TrackSequences(c, 10.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(seqs[0].impacts.size(), t.size() - 2);
  EXPECT_EQ(seqs[0].missed_after, std::vector<int>{6});
}

// A loud ball does not go unheard: between two members 30 dB above the noise, a gap of two
// flights is less likely than the candidate that is there, 1.5 % off the pattern (a real ball's
// scatter).
TEST(Sequence, ALoudImpactIsNotAssumedUnheard) {
  std::vector<double> t = Bounces(0.5, 0.4, 0.9, 0.05);
  t[8] += 0.015 * (t[8] - t[7]);
  std::vector<Impact> c;
  for (double x : t) c.push_back(Cand(x, 30.0));
  auto seqs = TrackSequences(c, 10.0, TrackOptions{});
  ASSERT_EQ(seqs.size(), 1u);
  EXPECT_EQ(Times(seqs[0]), t);
}

// No caps: 500 drops (9 500 impacts) among 25 000 clutter candidates (24 per second, as loud as
// the drops' tails) are all tracked: no sequence spans two drops, every drop has a sequence that
// holds at least 90 % of its impacts, and clutter is at most 1 % of the members. (Before, the
// strongest 300 candidates per block entered tracking and at most 16 sequences came out.)
TEST(Sequence, ManyDropsInHeavyClutterAreAllFound) {
  std::mt19937 rng(17);
  std::uniform_real_distribution<double> pause(0.5, 1.5);
  std::vector<std::vector<double>> drops;
  std::vector<Impact> c;
  double t = 0.5;
  for (int d = 0; d < 500; ++d) {
    const std::vector<double> x = Drop(t, 0.05, 0.85, 0.01);
    AddDrop(x, 35.0, 0.85, &c);
    drops.push_back(x);
    t = x.back() + pause(rng);
  }
  std::uniform_real_distribution<double> when(0.0, t), snr(-3.0, 12.0), ncc(0.1, 0.5);
  for (int k = 0; k < 25000; ++k) c.push_back(Cand(when(rng), snr(rng), ncc(rng)));
  const auto seqs = TrackSequences(Sorted(c), t, TrackOptions{});
  const auto of = DropsOf(seqs, drops);
  std::vector<std::size_t> held(drops.size(), 0);
  std::size_t members = 0, clutter = 0;
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    std::set<int> real = of[s];
    real.erase(-1);
    EXPECT_LE(real.size(), 1u) << "sequence " << s << " spans drops";
    members += seqs[s].impacts.size();
    for (const Impact& i : seqs[s].impacts) {
      bool found = false;
      for (int d : real) {
        const auto& x = drops[static_cast<std::size_t>(d)];
        if (std::find(x.begin(), x.end(), i.time_s) != x.end())
          found = true, ++held[static_cast<std::size_t>(d)];
      }
      clutter += !found;
    }
  }
  std::size_t whole = 0;
  for (std::size_t d = 0; d < drops.size(); ++d) whole += 10 * held[d] >= 9 * drops[d].size();
  EXPECT_EQ(whole, drops.size());
  EXPECT_LE(clutter, members / 100) << clutter << " of " << members;
}

TEST(Sequence, OptionsValidation) {
  std::string why;
  TrackOptions o;
  EXPECT_TRUE(o.IsValid(&why));
  o.min_sequence_impacts = 2;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("min_sequence_impacts"), std::string::npos);
  o = TrackOptions{};
  o.max_ratio = 0.1;
  EXPECT_FALSE(o.IsValid(&why));
  o = TrackOptions{};
  o.beam = 0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("beam"), std::string::npos);
  o = TrackOptions{};
  o.drop_rate_hz = 0.0;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_THROW(TrackSequences({}, 1.0, o), Error);
}

}  // namespace
}  // namespace bouncecal
