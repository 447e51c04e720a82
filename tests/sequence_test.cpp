// Bounce-sequence tracker: physically possible chains from onset candidates.
#include "bouncecal/acoustic/sequence.hpp"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

Impact Cand(double t, double snr_db = 30.0, double score = 0.8) {
  Impact i;
  i.time_s = t;
  i.snr_db = snr_db;
  i.score = score;
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
  EXPECT_THROW(TrackSequences({}, 1.0, o), Error);
}

}  // namespace
}  // namespace bouncecal
