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
// sequence may start there, and the main sequence starts at the drop.
TEST(RealRecordings, HandlingNoiseBeforeTheDropIsNoSequence) {
  REQUIRE_RECORDING(kPfe);
  const DetectionResult r = DetectImpacts(ReadAudio(kPfe.string()), DetectOptions{});
  for (const Sequence& q : r.sequences)
    EXPECT_GT(q.impacts.front().time_s, 3.1) << q.impacts.size();
  EXPECT_NEAR(r.main().impacts.front().time_s, 3.1367, 0.003);
  EXPECT_TRUE(HasWarning(r.warnings, "phantom_removed"));
  EXPECT_EQ(r.channel_scores.size(), 3u);  // both channels and the mix were scored
}

// Start invariance on a real file: the same samples with 0.5 to 2.7 s (all before the drop) cut
// off give the same impact times, within max(3 sigma of the difference, 2 us), for every impact
// both runs find.
// Measured: 45-47 impacts per cut agree, the rest are the sequence's weak tail (found in one run
// only); the offset-free agreement is 0.3-2 us where sigma is below 1 us... (tools/bench_detect
// "real recordings" prints the figure).
TEST(RealRecordings, StartInvarianceAtFiveOffsets) {
  REQUIRE_RECORDING(kPfe);
  const Audio full = ReadAudio(kPfe.string());
  const DetectionResult ref = DetectImpacts(full, DetectOptions{});
  const double rate = full.info.sample_rate_hz;
  int outside = 0, total = 0;
  for (double cut_s : {0.5, 1.0, 1.3, 2.0, 2.7}) {
    Audio part = full;
    const std::size_t cut = static_cast<std::size_t>(std::lround(cut_s * rate));
    for (auto& c : part.channels) c.erase(c.begin(), c.begin() + static_cast<std::ptrdiff_t>(cut));
    part.info.frames -= static_cast<std::int64_t>(cut);
    const DetectionResult r = DetectImpacts(part, DetectOptions{});
    const double shift = static_cast<double>(cut) / rate;
    int matched = 0;
    for (const Sequence& qa : ref.sequences)
      for (const Impact& a : qa.impacts) {
        const Impact* best = nullptr;
        for (const Sequence& qb : r.sequences)
          for (const Impact& b : qb.impacts)
            if (!best ||
                std::fabs(b.time_s + shift - a.time_s) < std::fabs(best->time_s + shift - a.time_s))
              best = &b;
        if (!best || std::fabs(best->time_s + shift - a.time_s) > 0.005) continue;
        ++matched;
        // The two runs' times are two estimates, each with its sigma: their difference has
        // sigma sqrt(sa^2 + sb^2), and 3 of those (or 2 us) is the bound.
        const double d = std::fabs(best->time_s + shift - a.time_s);
        if (d > std::max(3.0 * std::hypot(a.sigma_s, best->sigma_s), 2e-6)) {
          ++outside;
          std::printf("cut %.1f s: impact at %.6f s moves %.1f us (sigmas %.1f, %.1f us)\n", cut_s,
                      a.time_s, 1e6 * d, 1e6 * a.sigma_s, 1e6 * best->sigma_s);
        }
        EXPECT_LT(d, 1.5e-3) << "cut " << cut_s << " s: impact at " << a.time_s;
      }
    EXPECT_GE(matched, 40) << "cut " << cut_s;
    total += matched;
  }
  // Known open defect (issue 8): on this superball a few impacts are timed one ringing cycle
  // (~0.6 ms) apart depending on where the file starts (the detector's anchors depend on the
  // whole-file whitening, see timing.hpp), and the sigma of one of the two runs does not cover
  // it: measured 7 of 239 comparisons (8.7775 s at every cut, 9.672 s at cut 0.5 s, 10.5395 s
  // at cut 1.3 s). The test holds the line there: at most 3 % outside 3 sigma of the
  // difference, and no impact moves by 1.5 ms or more (more than two ringing cycles).
  std::printf("%d of %d matched impacts outside 3 sigma of the difference\n", outside, total);
  EXPECT_LE(outside, std::max(1, total * 3 / 100)) << outside << " of " << total;
}

}  // namespace
}  // namespace bouncecal
