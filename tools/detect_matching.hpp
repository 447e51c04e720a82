// The rule that pairs detected impact times with exact truth onsets, shared by the detection
// benchmarks (tools/bench_detect.cpp, tools/scoreboard.cpp) so that their numbers mean the same.
//
// One constant offset per file is allowed (no detector knows the microphone distance, and a real
// sound's onset convention is its hand mark's): the offset is the median of (nearest detection -
// truth onset) over the eligible impacts, within +-20 ms. After removing it, truth and detections
// are matched one-to-one, nearest pairs first, within +-1 ms. Which impacts are eligible (count
// for recall) is the caller's rule; every truth onset takes part in the matching, so a detection
// of an ineligible impact is not a false one.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace bouncecal::bench {

inline constexpr double kOffsetSearch_s = 0.02;  // the constant offset is looked for within this
inline constexpr double kMatchWindow_s = 1e-3;   // a detection matches a truth onset within this

struct TruthOnset {
  double t = 0.0;  // onset, s on the file's clock (in the channel the detector listened to)
  int drop = 0;
  int index = 0;
  bool eligible = false;
  double amplitude = 0.0;
};

struct OnsetMatch {
  double offset_s = 0.0;
  std::vector<int> truth_to_det;  // -1: unmatched
  std::vector<int> det_to_truth;  // -1: unmatched (a false detection)
};

inline double Quantile(std::vector<double> v, double q) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const double pos = q * static_cast<double>(v.size() - 1);
  const auto i = static_cast<std::size_t>(pos);
  const double f = pos - static_cast<double>(i);
  return i + 1 < v.size() ? v[i] * (1 - f) + v[i + 1] * f : v[i];
}

// The rule above; det in any order. O((T + D) log D).
inline OnsetMatch MatchOnsets(const std::vector<TruthOnset>& truth,
                              const std::vector<double>& det) {
  OnsetMatch m;
  std::vector<std::size_t> order(det.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](std::size_t a, std::size_t b) { return det[a] < det[b]; });
  std::vector<double> sorted;
  for (std::size_t i : order) sorted.push_back(det[i]);
  auto nearest = [&](double t) {
    auto it = std::lower_bound(sorted.begin(), sorted.end(), t);
    double best = 1e9;
    if (it != sorted.end()) best = *it - t;
    if (it != sorted.begin() && std::fabs(*(it - 1) - t) < std::fabs(best)) best = *(it - 1) - t;
    return best;
  };
  std::vector<double> offs;
  for (const TruthOnset& tr : truth)
    if (tr.eligible) {
      const double d = nearest(tr.t);
      if (std::fabs(d) < kOffsetSearch_s) offs.push_back(d);
    }
  m.offset_s = offs.empty() ? 0.0 : Quantile(offs, 0.5);
  struct Pair {
    double dist;
    int ti, di;
  };
  std::vector<Pair> pairs;
  for (std::size_t ti = 0; ti < truth.size(); ++ti) {
    const double t = truth[ti].t + m.offset_s;
    for (auto it = std::lower_bound(sorted.begin(), sorted.end(), t - kMatchWindow_s);
         it != sorted.end() && *it <= t + kMatchWindow_s; ++it) {
      const std::size_t k = static_cast<std::size_t>(it - sorted.begin());
      pairs.push_back({std::fabs(*it - t), static_cast<int>(ti), static_cast<int>(order[k])});
    }
  }
  std::sort(pairs.begin(), pairs.end(),
            [](const Pair& a, const Pair& b) { return a.dist < b.dist; });
  m.truth_to_det.assign(truth.size(), -1);
  m.det_to_truth.assign(det.size(), -1);
  for (const Pair& p : pairs) {
    if (m.truth_to_det[static_cast<std::size_t>(p.ti)] >= 0 ||
        m.det_to_truth[static_cast<std::size_t>(p.di)] >= 0)
      continue;
    m.truth_to_det[static_cast<std::size_t>(p.ti)] = p.di;
    m.det_to_truth[static_cast<std::size_t>(p.di)] = p.ti;
  }
  return m;
}

}  // namespace bouncecal::bench
