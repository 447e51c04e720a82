// The adaptive threshold (running median + k MAD) of the novelty and the peaks above it. See
// include/bouncecal/acoustic/onsets.hpp.
#include <algorithm>
#include <cmath>
#include <vector>

#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/core/parallel.hpp"
#include "onset_constants.hpp"

namespace bouncecal {
namespace {

// Threshold blocks (their medians) per task.
constexpr std::size_t kThresholdPart = 64;

}  // namespace

void SlidingSample::Set(const std::vector<double>& v, std::size_t lo, std::size_t hi,
                        std::size_t stride) {
  stride = std::max<std::size_t>(1, stride);
  hi = std::max(hi, lo);
  // The first sampled index at or after `from` on the grid lo + k stride.
  auto on_grid = [&](std::size_t from) {
    return from <= lo ? lo : lo + (from - lo + stride - 1) / stride * stride;
  };
  bool slide =
      valid_ && stride == stride_ && lo >= lo_ && hi >= hi_ && lo < hi_ && (lo - lo_) % stride == 0;
  if (slide) {
    // One merge pass: the kept values in order, minus the ones that left, plus the ones that
    // came (both sorted). A value that left must be among the kept ones (NaN is not).
    leaving_.clear();
    for (std::size_t q = lo_; q < lo; q += stride) leaving_.push_back(v[q]);
    coming_.clear();
    for (std::size_t q = on_grid(hi_); q < hi; q += stride) coming_.push_back(v[q]);
    std::sort(leaving_.begin(), leaving_.end());
    std::sort(coming_.begin(), coming_.end());
    merged_.clear();
    std::size_t a = 0, l = 0, c = 0;
    const std::size_t na = sorted_.size(), nl = leaving_.size(), nc = coming_.size();
    while (a < na) {
      const double x = sorted_[a];
      if (l < nl && leaving_[l] == x) {  // one copy leaves
        ++l;
        ++a;
      } else if (l < nl && !(leaving_[l] > x)) {
        break;  // a leaving value not among the kept ones (NaN): select anew
      } else if (c < nc && coming_[c] < x) {
        merged_.push_back(coming_[c++]);
      } else {
        merged_.push_back(x);
        ++a;
      }
    }
    slide = a == na && l == nl;
    if (slide) {
      merged_.insert(merged_.end(), coming_.begin() + static_cast<std::ptrdiff_t>(c),
                     coming_.end());
      sorted_.swap(merged_);
    }
  }
  if (!slide) {
    sorted_.clear();
    for (std::size_t q = lo; q < hi; q += stride) sorted_.push_back(v[q]);
    std::sort(sorted_.begin(), sorted_.end());
  }
  lo_ = lo;
  hi_ = hi;
  stride_ = stride;
  valid_ = true;
}

double SlidingSample::Median() const { return sorted_.empty() ? 0.0 : sorted_[sorted_.size() / 2]; }

double SlidingSample::Mad(double centre) const {
  if (sorted_.empty()) return 0.0;
  // |value - centre| grows away from centre on both sides of the sorted values: merge the two
  // runs (left of the first value >= centre going down, the rest going up) up to the rank.
  const std::size_t n = sorted_.size(), rank = n / 2;
  std::size_t right = static_cast<std::size_t>(
      std::lower_bound(sorted_.begin(), sorted_.end(), centre) - sorted_.begin());
  std::size_t left = right;  // values [0, left) not taken yet, taken from left - 1 down
  double d = 0.0;
  for (std::size_t taken = 0; taken <= rank; ++taken) {
    const bool has_l = left > 0, has_r = right < n;
    const double dl = has_l ? std::fabs(sorted_[left - 1] - centre) : 0.0;
    const double dr = has_r ? std::fabs(sorted_[right] - centre) : 0.0;
    if (has_l && (!has_r || dl <= dr)) {
      d = dl;
      --left;
    } else {
      d = dr;
      ++right;
    }
  }
  return d;
}

// The threshold at frame c: median + max(threshold_mads MAD, min_novelty_db) of the novelty
// over the `win` frames around c (every fourth frame). `window` slides from the previous
// block's frames (SlidingSample: the same median and MAD as selecting from all of them).
double OnsetDetector::BlockThreshold(const std::vector<double>& nov, std::size_t c, std::size_t win,
                                     SlidingSample* window) const {
  const std::size_t frames = nov.size();
  const std::size_t lo = c > win / 2 ? c - win / 2 : 0;
  const std::size_t hi = std::min(frames, lo + win);
  // Every fourth frame of the window (~225 values at the default hop): the median and MAD of
  // the background are as good and a quarter of the work.
  window->Set(nov, lo, hi, 4);
  const double med = window->Median();
  const double mad = 1.4826 * window->Mad(med);
  return med + std::max(options_.threshold_mads * mad, options_.min_novelty_db);
}

std::vector<double> OnsetDetector::Threshold(const std::vector<double>& nov) const {
  // Running median + k * MAD, evaluated on blocks and interpolated.
  const std::size_t frames = nov.size();
  const std::size_t hop = static_cast<std::size_t>(hop_);
  const std::size_t win = std::max<std::size_t>(
      16, static_cast<std::size_t>(options_.median_window_s * rate_hz_ / static_cast<double>(hop)));
  const std::size_t blk = std::max<std::size_t>(1, win / 8);
  const std::size_t nblk = (frames + blk - 1) / blk;
  std::vector<double> blk_thr(nblk);
  // Each block's median and MAD are independent: groups of kThresholdPart blocks per thread task.
  ParallelForGroups(Threads(), nblk, kThresholdPart, [&](std::size_t b0, std::size_t b1) {
    SlidingSample window;
    for (std::size_t b = b0; b < b1; ++b)
      blk_thr[b] = BlockThreshold(nov, b * blk + blk / 2, win, &window);
  });
  std::vector<double> thr(frames);
  ParallelForGroups(Threads(), frames, kSpectraChunk, [&](std::size_t t0, std::size_t t1) {
    for (std::size_t t = t0; t < t1; ++t) {
      const double pos =
          (static_cast<double>(t) - static_cast<double>(blk) / 2.0) / static_cast<double>(blk);
      const double cl = std::clamp(pos, 0.0, static_cast<double>(nblk - 1));
      const std::size_t b0 = static_cast<std::size_t>(cl);
      const std::size_t b1 = std::min(nblk - 1, b0 + 1);
      const double fr = cl - static_cast<double>(b0);
      thr[t] = blk_thr[b0] * (1.0 - fr) + blk_thr[b1] * fr;
    }
  });
  return thr;
}

std::vector<std::size_t> OnsetDetector::Peaks(const std::vector<double>& nov,
                                              const std::vector<double>& thr) const {
  // Local maxima above threshold; within min_gap keep the stronger.
  std::vector<std::size_t> peaks;
  const std::size_t gap =
      static_cast<std::size_t>(options_.min_gap_s * rate_hz_ / static_cast<double>(hop_));
  for (std::size_t t = 1; t + 1 < nov.size(); ++t) {
    if (nov[t] <= thr[t] || nov[t] < nov[t - 1] || nov[t] <= nov[t + 1]) continue;
    if (!peaks.empty() && t - peaks.back() <= gap) {
      if (nov[t] > nov[peaks.back()]) peaks.back() = t;
      continue;
    }
    peaks.push_back(t);
  }
  return peaks;
}

}  // namespace bouncecal
