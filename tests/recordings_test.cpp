// Real recordings made by other people (../shared/recordings, see its README): every
// confidently (H) annotated impact is found and the main sequence's precision is >= 0.95.
// Skips cleanly when the folder is absent (as on a user's machine). Nothing here is tuned to
// these files: the detector runs with its defaults.
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

class Recordings : public ::testing::TestWithParam<std::string> {};

TEST_P(Recordings, EveryConfidentImpactFoundAndPrecise) {
  const std::filesystem::path dir = BOUNCECAL_SHARED_RECORDINGS;
  const std::filesystem::path wav = dir / (GetParam() + ".wav");
  if (!std::filesystem::exists(wav)) GTEST_SKIP() << "no " << wav << " (folder absent)";
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

}  // namespace
}  // namespace bouncecal
