// Real recordings made by other people (../shared/recordings, see its README): every
// confidently (H) annotated impact is found and the main sequence's precision is >= 0.95.
// Skips cleanly when the folder is absent (as on a user's machine), but not under CI=true: CI has
// ../shared, and the recording tests must not vanish. Nothing here is tuned to these files: the
// detector runs with its defaults.
//
// Rule: no microphone distance is known, so one constant offset per file is allowed: the
// median of (nearest detection - annotation) over the H impacts. After removing it, every H
// impact must have a detection of the main sequence within +-3 ms. Precision: detections of
// the main sequence inside the annotated span (first - 50 ms .. last + half the last annotated
// interval) that lie within +-3 ms of an H annotation or +-5 ms of an M/L one (the README gives
// M/L as +-1-3 ms themselves), over all detections in that span. Detections past the annotated
// span are not judged: the annotators stopped where they were unsure (e.g. "irregular events
// after ~10.6 s"), and the impacts that follow are not marked either way.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"

namespace bouncecal {
namespace {

struct Annotation {
  double t = 0.0;
  char confidence = 'L';
};

// k,t_impact_s,confidence,... (header line first).
std::vector<Annotation> ReadAnnotations(const std::string& path) {
  std::ifstream f(path);
  std::vector<Annotation> out;
  std::string line;
  std::getline(f, line);
  while (std::getline(f, line)) {
    std::stringstream ss(line);
    std::string k, t, c;
    if (!std::getline(ss, k, ',') || !std::getline(ss, t, ',') || !std::getline(ss, c, ','))
      continue;
    out.push_back({std::stod(t), c.empty() ? 'L' : c[0]});
  }
  return out;
}

bool UnderCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

// The recording's path; skips (or, under CI=true, fails) when it is absent.
#define REQUIRE_RECORDING(wav)                                            \
  do {                                                                    \
    if (!std::filesystem::exists(wav)) {                                  \
      if (UnderCi()) FAIL() << "CI=true but " << (wav) << " is missing";  \
      GTEST_SKIP() << "no " << (wav) << " (../shared/recordings absent)"; \
    }                                                                     \
  } while (0)

class Recordings : public ::testing::TestWithParam<std::string> {};

TEST_P(Recordings, EveryConfidentImpactFoundAndPrecise) {
  const std::filesystem::path dir = BOUNCECAL_SHARED_RECORDINGS;
  const std::filesystem::path wav = dir / (GetParam() + ".wav");
  REQUIRE_RECORDING(wav);
  const std::vector<Annotation> ann =
      ReadAnnotations((dir / (GetParam() + ".impacts.csv")).string());
  ASSERT_GE(ann.size(), 3u);
  const DetectionResult r = DetectImpacts(ReadAudio(wav.string()), DetectOptions{});
  std::vector<double> det;
  for (const Impact& i : r.main().impacts) det.push_back(i.time_s);
  auto nearest = [&](double t) {
    double best = 1e9;
    for (double d : det)
      if (std::fabs(d - t) < std::fabs(best)) best = d - t;
    return best;
  };
  std::vector<double> offs;
  for (const Annotation& a : ann)
    if (a.confidence == 'H') offs.push_back(nearest(a.t));
  std::sort(offs.begin(), offs.end());
  const double offset = offs[offs.size() / 2];
  EXPECT_LT(std::fabs(offset), 0.01) << "constant offset";
  int h_total = 0, h_found = 0;
  for (const Annotation& a : ann) {
    if (a.confidence != 'H') continue;
    ++h_total;
    const bool found = std::fabs(nearest(a.t + offset)) <= 0.003;
    h_found += found;
    EXPECT_TRUE(found) << "H impact at " << a.t << " s not found";
  }
  const double lo = ann.front().t - 0.05;
  const double hi = ann.back().t + 0.5 * (ann.back().t - ann[ann.size() - 2].t);
  int in_span = 0, correct = 0;
  for (double d : det) {
    if (d < lo + offset || d > hi + offset) continue;
    ++in_span;
    bool ok = false;
    for (const Annotation& a : ann)
      ok = ok || std::fabs(d - offset - a.t) <= (a.confidence == 'H' ? 0.003 : 0.005);
    correct += ok;
  }
  ASSERT_GT(in_span, 0);
  const double precision = static_cast<double>(correct) / in_span;
  EXPECT_GE(precision, 0.95) << correct << " of " << in_span;
  std::printf("%s: H found %d/%d, precision %.3f (%d/%d), offset %.2f ms, %zu sequences\n",
              GetParam().c_str(), h_found, h_total, precision, correct, in_span, offset * 1e3,
              r.sequences.size());
}

INSTANTIATE_TEST_SUITE_P(Shared, Recordings,
                         ::testing::Values("eeps_pingpong", "pfe_bouncyball_h0.9m_stereo48k",
                                           "pisa_fr4nci_tennis_h2.50m", "mth337_basketball_24k",
                                           "mth337_rubberball"),
                         [](const ::testing::TestParamInfo<std::string>& i) {
                           std::string n = i.param;
                           for (char& c : n)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

const std::filesystem::path kPfe =
    std::filesystem::path(BOUNCECAL_SHARED_RECORDINGS) / "pfe_bouncyball_h0.9m_stereo48k.wav";

// The superball from 0.9 m after handling noise: before the drop (first impact 3.1367 s) the file
// holds taps that form a geometric-looking chain 40 dB below the ball at the same speeds. No
// sequence may start there, and the main sequence starts at the drop. (The tracker no longer
// forms that chain at all; before, the plausibility stage removed it as a phantom.)
TEST(RealRecordings, HandlingNoiseBeforeTheDropIsNoSequence) {
  REQUIRE_RECORDING(kPfe);
  const DetectionResult r = DetectImpacts(ReadAudio(kPfe.string()), DetectOptions{});
  for (const Sequence& q : r.sequences)
    EXPECT_GT(q.impacts.front().time_s, 3.1) << q.impacts.size();
  EXPECT_NEAR(r.main().impacts.front().time_s, 3.1367, 0.003);
  EXPECT_EQ(r.channel_scores.size(), 3u);  // both channels and the mix were scored
}

// Matched impacts of two runs, `full` and `part` (part's times + shift = full's times), and
// how many disagree: the two times are two estimates, each with its sigma, so their difference
// has sigma sqrt(sa^2 + sb^2), and 3 of those (or 2 us) is the bound. A sequence's constant
// offset (its onset convention, from the members' AIC picks) is not in sigma_s (timing.hpp: it
// cancels in intervals), so each sequence's median move is taken out first. `worst_s`: the
// largest move of a matched impact (within 5 ms), offset included.
struct Agreement {
  int matched = 0, outside = 0;
  double worst_s = 0.0;
};
Agreement CompareRuns(const DetectionResult& full, const DetectionResult& part, double shift,
                      const std::string& label) {
  Agreement g;
  for (const Sequence& qa : full.sequences) {
    std::vector<std::pair<const Impact*, const Impact*>> pairs;
    for (const Impact& a : qa.impacts) {
      const Impact* best = nullptr;
      for (const Sequence& qb : part.sequences)
        for (const Impact& b : qb.impacts)
          if (!best ||
              std::fabs(b.time_s + shift - a.time_s) < std::fabs(best->time_s + shift - a.time_s))
            best = &b;
      if (!best || std::fabs(best->time_s + shift - a.time_s) > 0.005) continue;
      pairs.push_back({&a, best});
    }
    if (pairs.empty()) continue;
    std::vector<double> moves;
    for (const auto& [a, b] : pairs) moves.push_back(b->time_s + shift - a->time_s);
    std::nth_element(moves.begin(), moves.begin() + static_cast<std::ptrdiff_t>(moves.size() / 2),
                     moves.end());
    const double offset = moves[moves.size() / 2];
    for (const auto& [a, b] : pairs) {
      ++g.matched;
      g.worst_s = std::max(g.worst_s, std::fabs(b->time_s + shift - a->time_s));
      const double d = std::fabs(b->time_s + shift - a->time_s - offset);
      if (d > std::max(3.0 * std::hypot(a->sigma_s, b->sigma_s), 2e-6)) {
        ++g.outside;
        std::printf("%s: impact at %.6f s moves %.1f us (sigmas %.1f, %.1f us)\n", label.c_str(),
                    a->time_s, 1e6 * d, 1e6 * a->sigma_s, 1e6 * b->sigma_s);
      }
    }
  }
  return g;
}

Audio CutStart(const Audio& full, std::size_t samples) {
  Audio part = full;
  for (auto& c : part.channels)
    c.erase(c.begin(), c.begin() + static_cast<std::ptrdiff_t>(samples));
  part.info.frames -= static_cast<std::int64_t>(samples);
  return part;
}

// Start invariance on a real file: the same samples with 0.5 to 2.7 s (all before the drop, in
// the handling noise) cut off give the same impact times, within max(3 sigma of the difference,
// 2 us), for every impact both runs find.
// Measured: 0 of 239 comparisons outside with the absolute sigma (5-25x too large for
// intervals); with the interval sigma 5 of 255, all one impact (10.729 s) timed 52 us (2.5
// samples, 3.1 sigma) apart in the full file and in every cut: the detection anchor moves the
// correlation search window (open, issue 29 note). Bound: the every-recording test's 2 %.
TEST(RealRecordings, StartInvarianceAtFiveOffsets) {
  REQUIRE_RECORDING(kPfe);
  const Audio full = ReadAudio(kPfe.string());
  const DetectionResult ref = DetectImpacts(full, DetectOptions{});
  const double rate = full.info.sample_rate_hz;
  int outside = 0, total = 0;
  for (double cut_s : {0.5, 1.0, 1.3, 2.0, 2.7}) {
    const std::size_t cut = static_cast<std::size_t>(std::lround(cut_s * rate));
    const DetectionResult r = DetectImpacts(CutStart(full, cut), DetectOptions{});
    const Agreement g =
        CompareRuns(ref, r, static_cast<double>(cut) / rate, "cut " + std::to_string(cut_s));
    EXPECT_GE(g.matched, 40) << "cut " << cut_s;
    EXPECT_LT(g.worst_s, 1.5e-3) << "cut " << cut_s;  // no impact moves by two ringing cycles
    outside += g.outside;
    total += g.matched;
  }
  std::printf("%d of %d matched impacts outside 3 sigma of the difference\n", outside, total);
  EXPECT_LE(outside, total / 50) << outside << " of " << total;
}

// Every real recording, cut at 10, 25, 40, 60 and 85 % of the time before its first annotated
// impact (the last leaves 20-470 ms before it). Measured with the interval sigma (each
// sequence's median move taken out, CompareRuns): 12 of 662 comparisons outside 3 sigma of the
// difference (1.8 %): the superball's impact at 10.73 s by 52 us (sigmas 14.5, 8.5 us) in every
// cut, one basketball tail impact a bounce-shape apart (2.5 ms, sigma 0.15 ms) and another by
// 0.7 ms, and on the rubber ball one member the sequence assigns differently (2.4 ms) in every
// cut. (With the former sigma, 5-25x larger, and no offset taken out: 11 of 648.) The bound: at
// most 2 % of all comparisons.
TEST(RealRecordings, StartInvarianceOnEveryRecording) {
  int outside = 0, total = 0;
  for (const char* name :
       {"eeps_pingpong", "pfe_bouncyball_h0.9m_stereo48k", "pisa_fr4nci_tennis_h2.50m",
        "mth337_basketball_24k", "mth337_rubberball"}) {
    const std::filesystem::path wav =
        std::filesystem::path(BOUNCECAL_SHARED_RECORDINGS) / (std::string(name) + ".wav");
    REQUIRE_RECORDING(wav);
    const std::vector<Annotation> ann = ReadAnnotations(
        (std::filesystem::path(BOUNCECAL_SHARED_RECORDINGS) / (std::string(name) + ".impacts.csv"))
            .string());
    ASSERT_FALSE(ann.empty()) << name;
    const Audio full = ReadAudio(wav.string());
    const DetectionResult ref = DetectImpacts(full, DetectOptions{});
    const double rate = full.info.sample_rate_hz;
    for (double frac : {0.1, 0.25, 0.4, 0.6, 0.85}) {
      const std::size_t cut = static_cast<std::size_t>(std::floor(frac * ann.front().t * rate));
      const DetectionResult r = DetectImpacts(CutStart(full, cut), DetectOptions{});
      const Agreement g = CompareRuns(ref, r, static_cast<double>(cut) / rate,
                                      std::string(name) + " cut " + std::to_string(frac));
      EXPECT_GE(g.matched, 0.8 * static_cast<double>(ref.main().impacts.size()))
          << name << " cut " << frac;
      outside += g.outside;
      total += g.matched;
    }
  }
  std::printf("%d of %d matched impacts outside 3 sigma of the difference\n", outside, total);
  EXPECT_LE(outside, total / 50) << outside << " of " << total;
}

}  // namespace
}  // namespace bouncecal
