// The detect pipeline: channel selection -> onsets -> bounce-sequence tracking.
// See include/bouncecal/acoustic/detect.hpp.
#include "bouncecal/acoustic/detect.hpp"

#include <algorithm>
#include <atomic>
#include <cctype>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <functional>
#include <future>
#include <limits>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>

#include <boost/math/distributions/chi_squared.hpp>

#include "../core/huge_pages.hpp"
#include "avx2_clones.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/acoustic/plausibility.hpp"
#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/acoustic/timing.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/parallel.hpp"

namespace bouncecal {
namespace {

// One step of 16-bit PCM: a recording whose peak stays at or below it carries no impacts.
constexpr double kSilencePeak = 1.0 / 32768.0;
// Guided search: the window spans kGuidedReach spreads of the predicted time on each side
// (TrackOptions::max_z), the spread of log r the sequence's own (RatioSpread) but at least
// kMinRatioSpread (a quarter of TrackOptions::scatter_sigma: real balls scatter by >= 0.005 in e).
constexpr double kGuidedReach = 4.0;
constexpr double kMinRatioSpread = 0.005;
// Ranking penalty at the window edge (NCC units): near the noise level a noise peak 0.4 ms from
// the prediction matched as well as the impact (corpus: NCC 0.37 vs 0.36, a 433 us error).
constexpr double kGuidedEdgePenalty = 0.15;
// Channel choice (auto): a later candidate signal must score this much more (relative) to be
// chosen. The scores of the real stereo recording's channels and mix differ by 7-20 %; with the
// first 0.5-2.7 s cut off, the mix and channel 0 came within 3 % of each other.
constexpr double kChannelScoreMargin = 0.1;

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

// Median of the last (up to) three interval ratios of impacts [0, end).
double RecentRatio(const std::vector<Impact>& q, std::size_t end) {
  std::vector<double> r;
  for (std::size_t k = end - 1; k >= 2 && r.size() < 3; --k)
    r.push_back((q[k].time_s - q[k - 1].time_s) / (q[k - 1].time_s - q[k - 2].time_s));
  std::sort(r.begin(), r.end());
  return r[r.size() / 2];
}

// One look where a sequence predicts an impact: the best template match in a window
// kGuidedReach spreads wide around the prediction (FindByTemplate, ranked by NCC - edge
// penalty towards the window's edges) and its p-value, the chance that noise alone ranks as well
// somewhere in the window: the NCC where the template meets no impact spreads by
// s = max(1 / sqrt(L), the window's robust spread) (whitened white noise: 1 / sqrt(L) for a
// template of L samples).
struct Look {
  Impact match;
  bool any = false;
  double p = 1.0;
};
Look LookAt(const OnsetResult& onsets, const std::vector<float>& x, double t_c, double dn,
            double ratio_spread) {
  Look look;
  // At least two samples either side (the interpolated peak needs its neighbours).
  const double half = std::max(kGuidedReach * ratio_spread * dn, 2.0 / onsets.rate_hz);
  double spread = 0.0;
  look.any = FindByTemplate(onsets, x, t_c, half, -1.0, &look.match, kGuidedEdgePenalty, &spread);
  if (!look.any) return look;
  const double s =
      std::max(spread, 1.0 / std::sqrt(static_cast<double>(onsets.template_wave.size())));
  // The match was ranked by NCC - edge_penalty u^2 (u: distance from the centre in half
  // windows); noise alone ranks as well at position u with probability Q((rank + pen u^2) / s).
  const double u_match = (look.match.time_s - t_c) / half;
  const double rank = look.match.score - kGuidedEdgePenalty * u_match * u_match;
  const long positions = std::max(1L, std::lround(half * onsets.rate_hz));
  double p = 0.0;
  for (long l = -positions; l <= positions; ++l) {
    const double u = static_cast<double>(l) / static_cast<double>(positions);
    p += 0.5 * std::erfc((rank + kGuidedEdgePenalty * u * u) / s / std::sqrt(2.0));
  }
  look.p = std::min(1.0, p);
  if (std::getenv("BC_LOOK"))
    std::fprintf(stderr, "LOOK t_c %.4f dn %.4f -> %.4f ncc %.3f spread %.3f p %.3g snr %.1f\n",
                 t_c, dn, look.match.time_s, look.match.score, s, look.p, look.match.snr_db);
  return look;
}

// A match joins a sequence when noise alone would match as well in at most one window of twenty
// (its own p-value), inside a run of looks that noise alone explains with probability at most
// kGuidedFalseAlarm (Fisher's combination of their p-values).
constexpr double kGuidedMemberP = 0.05;
constexpr double kGuidedFalseAlarm = 0.01;

// The spread of log r about the sequence's trend over impacts [0, end): 1.4826 MAD of the
// changes of log r between successive flights over the last kSpreadFlights regular ones (flights
// across a flagged gap or after an irregular step left out), / sqrt 2 (each change holds two
// flights' scatter), with the last flight's timing noise, at least kMinRatioSpread.
constexpr std::size_t kSpreadFlights = 8;
double RatioSpread(const Sequence& seq, std::size_t end) {
  const std::vector<Impact>& q = seq.impacts;
  auto flagged = [&](std::size_t j) {  // interval j -> j + 1
    const int k = static_cast<int>(j);
    return std::find(seq.missed_after.begin(), seq.missed_after.end(), k) !=
               seq.missed_after.end() ||
           std::find(seq.irregular_after.begin(), seq.irregular_after.end(), k) !=
               seq.irregular_after.end();
  };
  std::vector<double> change;
  for (std::size_t k = end - 1; k >= 3 && change.size() < kSpreadFlights; --k) {
    if (flagged(k - 1) || flagged(k - 2) || flagged(k - 3)) continue;
    const double r1 = (q[k].time_s - q[k - 1].time_s) / (q[k - 1].time_s - q[k - 2].time_s);
    const double r0 = (q[k - 1].time_s - q[k - 2].time_s) / (q[k - 2].time_s - q[k - 3].time_s);
    change.push_back(std::fabs(std::log(r1 / r0)));
  }
  double spread = kMinRatioSpread;
  if (change.size() >= 2) {
    const auto mid = change.begin() + static_cast<std::ptrdiff_t>(change.size() / 2);
    std::nth_element(change.begin(), mid, change.end());
    spread = std::max(spread, 1.4826 * *mid / std::sqrt(2.0));
  }
  const double d = q[end - 1].time_s - q[end - 2].time_s;
  const double timing = std::sqrt(2.0) * q[end - 1].sigma_s / d;
  return std::hypot(spread, timing);
}

// Gaps the tracker flagged: m unheard impacts (the m that makes the gap closest to d (r + ... +
// r^(m+1)) with the ratio r of the flights before it), looked for at their places once the
// ratio is scaled so that the m + 1 flights fill the gap exactly.
void FillGaps(const OnsetResult& onsets, const std::vector<float>& x, const TrackOptions& to,
              Sequence* q) {
  std::vector<int> still_missed;
  int inserted = 0;
  for (int k0 : q->missed_after) {
    const std::size_t k = static_cast<std::size_t>(k0 + inserted);
    const double gap = q->impacts[k + 1].time_s - q->impacts[k].time_s;
    if (k < 2) {
      still_missed.push_back(k0 + inserted);
      continue;
    }
    const double d = q->impacts[k].time_s - q->impacts[k - 1].time_s;
    const double r0 = std::clamp(RecentRatio(q->impacts, k + 1), to.min_ratio, to.max_ratio);
    auto flights = [](double r, int n) {  // r + r^2 + ... + r^n
      double sum = 0.0, p = 1.0;
      for (int j = 1; j <= n; ++j) sum += (p *= r);
      return sum;
    };
    int m = 1;
    for (int mm = 2; mm <= to.max_missed; ++mm)
      if (std::fabs(std::log(gap / (d * flights(r0, mm + 1)))) <
          std::fabs(std::log(gap / (d * flights(r0, m + 1)))))
        m = mm;
    // r with d (r + ... + r^(m+1)) = gap, by bisection (the sum grows with r).
    double lo = 0.01, hi = 1.5;
    for (int it = 0; it < 60; ++it)
      (d * flights(0.5 * (lo + hi), m + 1) < gap ? lo : hi) = 0.5 * (lo + hi);
    const double r = 0.5 * (lo + hi);
    std::vector<Impact> found;
    double t = q->impacts[k].time_s, dn = d;
    for (int j = 1; j <= m; ++j) {
      dn *= r;
      t += dn;
      const Look look = LookAt(onsets, x, t, dn, RatioSpread(*q, k + 1));
      if (look.any && look.p <= kGuidedMemberP) found.push_back(look.match);
    }
    q->impacts.insert(q->impacts.begin() + static_cast<std::ptrdiff_t>(k + 1), found.begin(),
                      found.end());
    if (static_cast<int>(found.size()) < m) {
      // Flag the widest interval left in the gap (the unheard impacts are there).
      std::size_t widest = k;
      for (std::size_t j = k; j <= k + found.size(); ++j)
        if (q->impacts[j + 1].time_s - q->impacts[j].time_s >
            q->impacts[widest + 1].time_s - q->impacts[widest].time_s)
          widest = j;
      still_missed.push_back(static_cast<int>(widest));
    }
    inserted += static_cast<int>(found.size());
  }
  q->missed_after = still_missed;
}

// The tail: up to max_missed + 1 looks ahead at the trend's predictions (each from the match of
// the look before when it is better than noise's), as long as the interval stays resolvable and
// inside [.., limit_s). The longest run of looks that noise alone explains with probability below
// kGuidedFalseAlarm joins the sequence: its matches with p <= kGuidedMemberP as members, the
// others as unheard impacts (missed_after). It stops where no run is significant: the noise won
// or the ball stopped. Returns whether the sequence grew.
bool ExtendTail(const OnsetResult& onsets, const std::vector<float>& x, double limit_s,
                const TrackOptions& to, Sequence* q) {
  bool extended = false;
  while (q->impacts.size() >= 3) {
    const double r =
        std::clamp(RecentRatio(q->impacts, q->impacts.size()), to.min_ratio, to.max_ratio);
    double t = q->impacts.back().time_s;
    double d = t - q->impacts[q->impacts.size() - 2].time_s;
    const double spread = RatioSpread(*q, q->impacts.size());
    std::vector<Look> looks;
    for (int j = 0; j <= to.max_missed; ++j) {
      const double dn = d * r;
      if (dn < to.min_interval_s || t + dn > limit_s) break;
      looks.push_back(LookAt(onsets, x, t + dn, dn,
                             spread * std::sqrt(1.0 + static_cast<double>(looks.size()))));
      const Look& l = looks.back();
      const double next = l.any && l.p <= kGuidedMemberP ? l.match.time_s : t + dn;
      d = next - t;
      t = next;
    }
    // The run whose Fisher combination is the least probable under noise alone.
    std::size_t best_n = 0;
    double best_p = 1.0, chi2 = 0.0;
    for (std::size_t n = 1; n <= looks.size(); ++n) {
      chi2 -= 2.0 * std::log(std::max(looks[n - 1].p, 1e-300));
      const double p = boost::math::cdf(
          boost::math::complement(boost::math::chi_squared(2.0 * static_cast<double>(n)), chi2));
      if (p < best_p && looks[n - 1].any && looks[n - 1].p <= kGuidedMemberP)
        best_p = p, best_n = n;
    }
    if (best_n == 0 || best_p > kGuidedFalseAlarm) break;
    bool unheard = false;
    for (std::size_t n = 0; n < best_n; ++n) {
      if (!looks[n].any || looks[n].p > kGuidedMemberP) {
        unheard = true;
        continue;
      }
      if (unheard) q->missed_after.push_back(static_cast<int>(q->impacts.size()) - 1);
      q->impacts.push_back(looks[n].match);
      unheard = false;
    }
    extended = true;
  }
  return extended;
}

// The tracker knows where the impacts of a sequence should be: search there with the template,
// for the impacts the blind pass missed: flagged gaps and the tail.
void ExtendByTemplate(const OnsetResult& onsets, const std::vector<float>& x, double duration_s,
                      const TrackOptions& to, std::vector<Sequence>* sequences) {
  if (onsets.template_wave.empty()) return;
  for (std::size_t s = 0; s < sequences->size(); ++s) {
    Sequence& q = (*sequences)[s];
    FillGaps(onsets, x, to, &q);
    const double limit = s + 1 < sequences->size()
                             ? (*sequences)[s + 1].impacts.front().time_s - to.min_interval_s
                             : duration_s - 0.002;
    if (!ExtendTail(onsets, x, limit, to, &q)) continue;
    const double d = q.impacts.back().time_s - q.impacts[q.impacts.size() - 2].time_s;
    const double next_dt = d * RecentRatio(q.impacts, q.impacts.size());
    const double next_t = q.impacts.back().time_s + next_dt;
    if (next_dt < 1.5 * to.min_interval_s)
      q.end_reason = "resolved_limit";
    else if (next_t > duration_s)
      q.end_reason = "end_of_file";
    else if (s + 1 < sequences->size() &&
             (*sequences)[s + 1].impacts.front().time_s < next_t + next_dt)
      q.end_reason = "next_drop";
    else
      q.end_reason = "snr_limit";
  }
}

// The energy rise of x at t_s (Impact::rise_db): mean square over [t, t + kRiseAfterS) against
// [t - kRiseBeforeS, t - kRiseGuardS). One millisecond holds a hard impact's attack (contact
// 20-150 us) and its first response; 3 ms before (beyond a guard for the onset's own timing
// error) holds the decaying sound of what came earlier, even at a low plate mode's period.
constexpr double kRiseAfterS = 0.001, kRiseBeforeS = 0.0035, kRiseGuardS = 0.0005;
double RawRiseDb(const std::vector<float>& x, double rate_hz, double t_s) {
  const long n = static_cast<long>(x.size());
  const long i = std::lround(t_s * rate_hz);
  auto mean_square = [&](long a, long b) {
    a = std::clamp(a, 0L, n), b = std::clamp(b, 0L, n);
    double e = 0.0;
    for (long k = a; k < b; ++k)
      e += static_cast<double>(x[static_cast<std::size_t>(k)]) * x[static_cast<std::size_t>(k)];
    return b > a ? e / static_cast<double>(b - a) : 0.0;
  };
  const double post = mean_square(i, i + std::lround(kRiseAfterS * rate_hz) + 1);
  const double pre =
      mean_square(i - std::lround(kRiseBeforeS * rate_hz), i - std::lround(kRiseGuardS * rate_hz));
  return 10.0 * std::log10((post + 1e-30) / (pre + 1e-30));
}

// When auto had a real choice and the signals disagree on the main sequence, say which was
// used and why (the scores of all are in DetectionResult::channel_scores).
void ChannelChoiceWarning(const DetectionResult& r, std::vector<Warning>* out) {
  if (r.channel_scores.size() < 2) return;
  auto name = [](int c) {
    return c >= 0 ? "channel " + std::to_string(c) : std::string("the mix");
  };
  const ChannelScore* used = nullptr;
  for (const ChannelScore& c : r.channel_scores)
    if (c.channel == r.channel) used = &c;
  if (!used) return;
  bool disagree = false;
  std::string others;
  for (const ChannelScore& c : r.channel_scores) {
    if (&c == used) continue;
    others += (others.empty() ? "" : ", ") + name(c.channel) + " " + Fmt("%.1f", c.score) + " (" +
              std::to_string(c.impacts) + " impacts)";
    disagree = disagree || c.impacts == 0 ||
               std::fabs(c.first_impact_s - used->first_impact_s) > 0.005 ||
               std::abs(c.impacts - used->impacts) > std::max(2, used->impacts / 10);
  }
  if (!disagree) return;
  out->push_back({"channel_choice",
                  "the channels disagree; " + name(r.channel) +
                      " was used: its main sequence scores " + Fmt("%.1f", used->score) + " (" +
                      std::to_string(used->impacts) + " impacts from " +
                      Fmt("%.4f", used->first_impact_s) + " s), " + others +
                      " (score = sum of the members' tracker weights)",
                  -1});
}

// Warnings of one sequence's flags (missed and irregular intervals).
void FlagWarnings(const std::vector<Sequence>& seqs, std::vector<Warning>* out) {
  for (std::size_t s = 0; s < seqs.size(); ++s) {
    const Sequence& q = seqs[s];
    for (int k : q.missed_after)
      out->push_back({"missed_impact",
                      "sequence " + std::to_string(s) + ": an impact seems missing after impact " +
                          std::to_string(k) +
                          " (t = " + Fmt("%.4f", q.impacts[static_cast<std::size_t>(k)].time_s) +
                          " s); its interval is about two expected ones",
                      k});
    for (int k : q.irregular_after) {
      const auto& im = q.impacts;
      const std::size_t j = static_cast<std::size_t>(k);
      const double d = im[j + 1].time_s - im[j].time_s;
      const double d0 = j > 0 ? im[j].time_s - im[j - 1].time_s : 0.0;
      out->push_back({"irregular_interval",
                      "sequence " + std::to_string(s) + ": the interval after impact " +
                          std::to_string(k) + " (t = " + Fmt("%.4f", im[j].time_s) +
                          " s: " + Fmt("%.4f", d) + " s" +
                          (j > 0 ? " after " + Fmt("%.4f", d0) + " s" : std::string()) +
                          ") breaks the smooth ratio pattern (spin or an uneven spot?); the "
                          "sequence continues through it",
                      k});
    }
  }
}

// Everything one candidate signal yields.
struct SignalDetection {
  std::vector<Impact> candidates;
  std::vector<Sequence> sequences;
  std::vector<Warning> warnings;
  int hop_samples = 0;
  double score = 0.0;
  std::string failure;  // why no sequence (empty when there is one)
};

double SequenceScore(const Sequence& q) {
  double s = 0.0;
  for (const Impact& i : q.impacts) s += CandidateWeight(i);
  return s;
}

int LongestSequence(const std::vector<Sequence>& seqs) {
  int best = seqs.empty() ? -1 : 0;
  for (std::size_t s = 1; s < seqs.size(); ++s)
    if (seqs[s].impacts.size() > seqs[static_cast<std::size_t>(best)].impacts.size())
      best = static_cast<int>(s);
  return best;
}

// Stage list for one signal: onsets -> tracking -> guided search -> timing -> plausibility ->
// re-timing. (The clipped flags are set once the whole recording was read: MarkClipped.)
// The onset detector's options in a detection with `options`.
OnsetOptions OnsetOptionsOf(const DetectOptions& options) {
  OnsetOptions oo;
  oo.hop_s = options.hop_s;
  oo.refine = true;  // locate at full resolution; refine = false coarsens the times at the end
  oo.lpc_order = options.lpc_order;
  oo.threads = options.threads;
  oo.available_threads = options.available_threads;
  oo.pool = options.pool;
  return oo;
}

SignalDetection DetectInSignal(const std::vector<float>& x, double rate_hz,
                               const DetectOptions& options) {
  SignalDetection out;
  const double duration_s = static_cast<double>(x.size()) / rate_hz;
  const OnsetDetector detector(OnsetOptionsOf(options), rate_hz);
  const OnsetResult onsets = detector.Detect(x);
  out.hop_samples = detector.hop_samples();
  out.candidates = onsets.onsets;
  for (Impact& c : out.candidates) c.rise_db = RawRiseDb(x, rate_hz, c.time_s);

  TrackOptions to;
  to.min_interval_s = options.min_interval_s;
  to.min_sequence_impacts = options.min_sequence_impacts;
  out.sequences = TrackSequences(out.candidates, duration_s, to);
  if (options.guided_search) ExtendByTemplate(onsets, x, duration_s, to, &out.sequences);
  if (std::getenv("BC_GUIDED"))
    for (const Sequence& q : out.sequences) {
      for (std::size_t k = 0; k < q.impacts.size(); ++k)
        std::fprintf(stderr, "%.4f(%.1f,%.2f) ", q.impacts[k].time_s, q.impacts[k].snr_db,
                     q.impacts[k].score);
      std::fprintf(stderr, "\n");
    }

  TimingOptions tim;
  tim.lpc_order = options.lpc_order;
  tim.available_threads = options.available_threads;
  tim.pool = options.pool;
  // Every timing round starts from the detector's own times (the anchors), not from the previous
  // round's output: a round that began there would move the AIC windows and the lag searches by
  // the previous round's result, and a member whose own AIC pick pointed a ringing cycle away
  // (its slip sigma) would agree with itself in the next round and lose that sigma (measured:
  // a superball impact timed 0.66 ms early kept sigma 7.8 us instead of 494 us).
  // `detected` maps each timed time (exact value) to the detector time it came from.
  std::map<double, double> detected;
  auto anchors_of = [&](const Sequence& q) {
    std::vector<double> anchor_s(q.impacts.size());
    for (std::size_t k = 0; k < q.impacts.size(); ++k) {
      const auto it = detected.find(q.impacts[k].time_s);
      anchor_s[k] = it != detected.end() ? it->second : q.impacts[k].time_s;
    }
    return anchor_s;
  };
  auto time_at = [&](const std::vector<double>& anchor_s, int n_threads, Sequence* q) {
    for (std::size_t k = 0; k < q->impacts.size(); ++k) q->impacts[k].time_s = anchor_s[k];
    TimingOptions t = tim;
    t.threads = n_threads;
    TimeSequence(x, rate_hz, q, t);
  };
  // The sequences `which` are timed on the threads (one sequence alone: its members). Each reads
  // `detected` as it was before the round; one whose anchors a sequence before it in the round
  // changed (a detector time equal to another's timed time: never seen) is timed again here,
  // so the result is the serial one.
  auto time_from_anchors = [&](const std::vector<Sequence*>& which) {
    const int threads = StageThreads(options.threads, options.available_threads);
    std::vector<std::vector<double>> anchors(which.size());
    std::vector<Sequence> timed(which.size());
    for (std::size_t i = 0; i < which.size(); ++i) anchors[i] = anchors_of(*which[i]);
    const int inner = which.size() == 1 ? threads : 1;
    ParallelFor(
        threads, which.size(),
        [&](std::size_t i) {
          timed[i] = *which[i];
          time_at(anchors[i], inner, &timed[i]);
        },
        options.pool);
    for (std::size_t i = 0; i < which.size(); ++i) {
      std::vector<double> now = anchors_of(*which[i]);
      if (now != anchors[i]) {
        timed[i] = *which[i];
        time_at(now, threads, &timed[i]);
        anchors[i] = std::move(now);
      }
      *which[i] = std::move(timed[i]);
      for (std::size_t k = 0; k < which[i]->impacts.size(); ++k)
        detected[which[i]->impacts[k].time_s] = anchors[i][k];
    }
  };
  {
    std::vector<Sequence*> all;
    for (Sequence& q : out.sequences) all.push_back(&q);
    time_from_anchors(all);
  }
  PlausibilityOptions po;
  po.min_snr_db = options.min_snr_db;
  po.min_sequence_impacts = options.min_sequence_impacts;
  // The predictor and template of a sequence that lost members included them: time it again,
  // and check again (its members' SNR and sigma moved a little), until nothing is removed.
  // A sequence is known by its earliest member ever (removals keep it in `removed`).
  auto key = [](const Sequence& q) {
    double t = q.impacts.empty() ? 1e300 : q.impacts.front().time_s;
    for (const RemovedImpact& r : q.removed) t = std::min(t, r.impact.time_s);
    return t;
  };
  for (int round = 0; round < 4; ++round) {
    std::map<double, std::size_t> removed_before;
    for (const Sequence& q : out.sequences) removed_before[key(q)] = q.removed.size();
    const std::vector<Warning> w = EnforcePlausibility(&out.sequences, po);
    out.warnings.insert(out.warnings.end(), w.begin(), w.end());
    if (w.empty()) break;
    std::vector<Sequence*> lost;
    for (Sequence& q : out.sequences)
      if (q.removed.size() != removed_before[key(q)]) lost.push_back(&q);
    time_from_anchors(lost);
  }
  if (out.sequences.empty()) {
    std::string why = std::to_string(out.candidates.size()) + " onset candidates; ";
    if (out.warnings.empty())
      why += "none form " + std::to_string(options.min_sequence_impacts) +
             " or more impacts with shrinking intervals";
    else
      why += "the sequences they formed are not a bouncing ball: " + out.warnings.back().message;
    out.failure = why;
  } else {
    out.score =
        SequenceScore(out.sequences[static_cast<std::size_t>(LongestSequence(out.sequences))]);
  }
  return out;
}

// The signal of one choice (a channel or the mix) over frames [from, to) of a block.
void SignalOf(const std::vector<std::vector<float>>& block, int channel, std::size_t from,
              std::size_t to, std::vector<float>* x) {
  if (channel >= 0) {
    const std::vector<float>& c = block[static_cast<std::size_t>(channel)];
    x->assign(c.begin() + static_cast<std::ptrdiff_t>(from),
              c.begin() + static_cast<std::ptrdiff_t>(to));
    return;
  }
  // The mix: the mean of the channels (SelectChannel's kMix).
  const double nch = static_cast<double>(block.size());
  x->resize(to - from);
  for (std::size_t i = from; i < to; ++i) {
    double acc = 0.0;
    for (const std::vector<float>& c : block) acc += c[i];
    (*x)[i - from] = static_cast<float>(acc / nch);
  }
}

// The level from which an impact of `channel` (-1: the mix) counts as clipped (0: none).
double ClipPeak(const std::vector<ClippingReport>& clipping, int channel, std::size_t channels) {
  double clip_peak = 0.0;
  for (const ClippingReport& c : clipping)
    if (c.clipped() && (channel < 0 || c.channel == channel))
      clip_peak = channel < 0 ? 0.999 * c.peak / static_cast<double>(channels) : c.peak;
  return clip_peak;
}

void MarkClipped(double clip_peak, SignalDetection* d) {
  auto mark = [&](Impact& imp) {
    imp.clipped = clip_peak > 0.0 && imp.amplitude >= 0.999 * clip_peak;
  };
  for (Impact& imp : d->candidates) mark(imp);
  for (Sequence& q : d->sequences)
    for (Impact& imp : q.impacts) mark(imp);
}

// Detection runs at most at kMaxAnalysisRateHz: a recording at a higher rate (88.2 to 384 kHz)
// is low-passed and decimated by an integer factor first. The impact sound a microphone records
// lies below ~20 kHz; above it there is only noise, which the whitening (it flattens the whole
// band) then weighs like the clicks. Measured on a rendered steel drop before: recall 0.70 at
// 44.1 kHz, 0.59 at 96 kHz, 0.24 at 192 kHz, and no sequence at 384 kHz.
constexpr double kMaxAnalysisRateHz = 64000.0;

int DecimationFactor(double rate_hz) {
  return std::max(1, static_cast<int>(std::ceil(rate_hz / kMaxAnalysisRateHz)));
}

// y[k] = sum_j h[j] x[k f + j], |j| <= 12 f: a Blackman-windowed sinc low-pass with its cutoff at
// 0.45 of the new rate, centred (zero phase: no delay to correct), x taken as 0 beyond its ends.
void Decimate(const std::vector<float>& x, int factor, std::vector<float>* y) {
  const long f = factor, half = 12 * f, n = static_cast<long>(x.size());
  const double fc = 0.45 / static_cast<double>(f);  // cycles per input sample
  std::vector<float> h(static_cast<std::size_t>(2 * half + 1));
  double sum = 0.0;
  for (long j = -half; j <= half; ++j) {
    const double t = static_cast<double>(j);
    const double sinc = j == 0 ? 2.0 * fc : std::sin(2.0 * M_PI * fc * t) / (M_PI * t);
    const double u = static_cast<double>(j + half) / static_cast<double>(2 * half);
    const double w = 0.42 - 0.5 * std::cos(2.0 * M_PI * u) + 0.08 * std::cos(4.0 * M_PI * u);
    h[static_cast<std::size_t>(j + half)] = static_cast<float>(sinc * w);
    sum += sinc * w;
  }
  for (float& v : h) v = static_cast<float>(v / sum);  // unit gain at 0 Hz
  const long m = (n + f - 1) / f;
  y->assign(static_cast<std::size_t>(m), 0.0f);
  for (long k = 0; k < m; ++k) {
    const long c = k * f;
    const long j0 = std::max(-half, -c), j1 = std::min(half, n - 1 - c);
    const float* xp = x.data() + c;
    const float* hp = h.data() + half;
    float a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, a3 = 0.0f;
    long j = j0;
    for (; j + 3 <= j1; j += 4) {
      a0 += hp[j] * xp[j];
      a1 += hp[j + 1] * xp[j + 1];
      a2 += hp[j + 2] * xp[j + 2];
      a3 += hp[j + 3] * xp[j + 3];
    }
    for (; j <= j1; ++j) a0 += hp[j] * xp[j];
    (*y)[static_cast<std::size_t>(k)] = (a0 + a1) + (a2 + a3);
  }
}

// After detection at a decimated rate: each impact's amplitude is the peak |x| of the signal at
// the file's rate over the same 3 ms (the low-pass lowers peaks, and `clipped` compares
// amplitudes with the channel's full-rate peak).
void FullRateAmplitudes(const std::vector<float>& x, double rate_hz, SignalDetection* d) {
  const long n = static_cast<long>(x.size());
  const long len = static_cast<long>(0.003 * rate_hz) + 1;
  auto peak = [&](Impact& imp) {
    const long i0 = std::clamp(static_cast<long>(std::floor(imp.time_s * rate_hz)), 0L, n);
    double a = 0.0;
    for (long i = i0; i < std::min(n, i0 + len); ++i)
      a = std::max(a, static_cast<double>(std::fabs(x[static_cast<std::size_t>(i)])));
    imp.amplitude = a;
  };
  for (Impact& imp : d->candidates) peak(imp);
  for (Sequence& q : d->sequences) {
    for (Impact& imp : q.impacts) peak(imp);
    for (RemovedImpact& r : q.removed) peak(r.impact);
  }
}

void ShiftTimes(double dt, SignalDetection* d) {
  for (Impact& i : d->candidates) i.time_s += dt;
  for (Sequence& q : d->sequences) {
    for (Impact& i : q.impacts) i.time_s += dt;
    for (RemovedImpact& r : q.removed) r.impact.time_s += dt;
  }
}

}  // namespace

bool DetectOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(hop_s >= 0.0) || hop_s > 0.05)
    return fail("DetectOptions::hop_s = " + std::to_string(hop_s) + ": must be in [0, 0.05] s");
  if (min_sequence_impacts < 3)
    return fail("DetectOptions::min_sequence_impacts = " + std::to_string(min_sequence_impacts) +
                ": must be >= 3");
  if (!(min_interval_s > 0.0) || min_interval_s > 1.0)
    return fail("DetectOptions::min_interval_s = " + std::to_string(min_interval_s) +
                ": must be in (0, 1] s");
  if (lpc_order < 0 || lpc_order > 256)
    return fail("DetectOptions::lpc_order = " + std::to_string(lpc_order) + ": must be 0..256");
  if (channel.kind == ChannelSelection::Kind::kIndex && channel.index < 0)
    return fail("DetectOptions::channel.index must be >= 0");
  if (!(start_s >= 0.0) || !std::isfinite(start_s))
    return fail("DetectOptions::start_s = " + Fmt("%g", start_s) +
                ": must be a finite time >= 0 s");
  if (end_s && (!std::isfinite(*end_s) || !(*end_s > start_s)))
    return fail("DetectOptions::end_s = " + Fmt("%g", *end_s) +
                ": must be a finite time after start_s = " + Fmt("%g", start_s) + " s");
  if (!(max_block_s >= 4.0) || !std::isfinite(max_block_s))
    return fail("DetectOptions::max_block_s = " + Fmt("%g", max_block_s) +
                ": must be a finite time >= 4 s");
  if (threads < 0 || threads > 256)
    return fail("DetectOptions::threads = " + std::to_string(threads) +
                ": must be 0 (automatic) to 256");
  if (!std::isfinite(min_snr_db) || min_snr_db < -120.0 || min_snr_db > 120.0)
    return fail("DetectOptions::min_snr_db = " + Fmt("%g", min_snr_db) +
                ": must be in [-120, 120] dB");
  return true;
}

namespace {

// Long recordings are detected in blocks of at most DetectOptions::max_block_s (and
// kMaxBlockFrames frames: 44 s at 384 kHz), so that memory does not grow with the length. A
// block ends at the quietest moment of its last quarter (at most kMaxCutSearchS): between two
// drops, not inside a sequence, whose impacts come at most about a second apart. Each block
// keeps kBlockMarginS of audio on both sides of its cuts as context (whitening fit, running
// medians); a sequence belongs to the block its first impact is in.
constexpr std::int64_t kMaxBlockFrames = std::int64_t{1} << 24;
constexpr double kBlockMarginS = 0.5;
constexpr double kMaxCutSearchS = 30.0;
// The quiet measure of a cut: the largest energy of the signal's first difference (a high-pass
// that keeps impact attacks) in 10 ms frames within +-kCutQuietS of it.
constexpr double kCutFrameS = 0.01;
constexpr double kCutQuietS = 0.5;

// The frame (block index) of the quietest moment in [lo, hi) of the block.
std::size_t QuietestCut(const std::vector<std::vector<float>>& block, std::size_t lo,
                        std::size_t hi, double rate_hz) {
  const std::size_t fl = std::max<std::size_t>(1, static_cast<std::size_t>(kCutFrameS * rate_hz));
  const std::size_t reach = static_cast<std::size_t>(kCutQuietS / kCutFrameS);
  const std::size_t n = block.front().size();
  // Frames over [lo - reach frames, hi + reach frames), clipped to the block.
  const std::size_t f0 = lo > reach * fl ? lo - reach * fl : 1;
  const std::size_t f1 = std::min(n, hi + reach * fl);
  const std::size_t nf = (f1 - f0) / fl;
  if (nf == 0) return lo;
  std::vector<double> energy(nf, 0.0);
  for (const std::vector<float>& c : block)
    for (std::size_t f = 0; f < nf; ++f) {
      double e = 0.0;
      for (std::size_t i = f0 + f * fl; i < f0 + (f + 1) * fl; ++i) {
        const double d = static_cast<double>(c[i]) - c[i - 1];
        e += d * d;
      }
      energy[f] += e;
    }
  // The latest frame whose +-reach neighbourhood has the smallest peak energy.
  std::size_t best = lo;
  double best_score = std::numeric_limits<double>::infinity();
  for (std::size_t f = 0; f < nf; ++f) {
    const std::size_t centre = f0 + f * fl + fl / 2;
    if (centre < lo || centre >= hi) continue;
    double score = 0.0;
    for (std::size_t g = f > reach ? f - reach : 0; g < std::min(nf, f + reach + 1); ++g)
      score = std::max(score, energy[g]);
    if (score <= best_score) {
      best_score = score;
      best = centre;
    }
  }
  return best;
}

// One candidate signal's detections over the blocks read so far.
struct SignalAcrossBlocks {
  SignalDetection merged;
  bool sound = false;   // a block was not silent
  double peak = 0.0;    // max |x| over the blocks
  std::string failure;  // the last block's reason for finding no sequence
};

// Adds what one block found (times already in file seconds) to `into`: the candidates in
// [own_lo_s, own_hi_s) and the sequences that start there. A sequence with impacts past
// own_hi_s was cut by the block's end: block_split.
void MergeBlock(SignalDetection d, double own_lo_s, double own_hi_s, bool last_block,
                SignalAcrossBlocks* into) {
  SignalDetection& m = into->merged;
  m.hop_samples = d.hop_samples;
  if (!d.failure.empty()) into->failure = d.failure;
  for (const Impact& i : d.candidates)
    if (i.time_s >= own_lo_s && i.time_s < own_hi_s) m.candidates.push_back(i);
  for (Sequence& q : d.sequences) {
    const double t0 = q.impacts.front().time_s;
    if (t0 < own_lo_s || t0 >= own_hi_s) continue;
    if (!last_block && q.impacts.back().time_s >= own_hi_s) {
      char msg[300];
      std::snprintf(msg, sizeof msg,
                    "the sequence from %.4f s runs past %.4f s, where the recording was cut "
                    "into analysis blocks (DetectOptions::max_block_s): its impacts after the "
                    "cut may be missing or reported as a separate sequence",
                    t0, own_hi_s);
      d.warnings.push_back({"block_split", msg, -1});
    }
    m.sequences.push_back(std::move(q));
  }
  for (Warning& w : d.warnings) {
    const bool seen = std::any_of(m.warnings.begin(), m.warnings.end(), [&](const Warning& o) {
      return o.code == w.code && o.message == w.message;
    });
    if (!seen) m.warnings.push_back(std::move(w));
  }
}

// One block of the recording as read and cut, handed to a detection worker.
struct Block {
  std::vector<std::vector<float>> channels;  // its frames, every channel
  std::int64_t start = 0;                    // its first frame in the file
  double own_lo_s = 0.0, own_hi_s = 0.0;     // the sequences that start in here are its own
  bool last = false;
};

// What one block yields for each candidate signal: its peak and, when it is not silent there,
// what DetectInSignal found (times in file seconds).
struct BlockResult {
  std::vector<double> peak;
  std::vector<std::optional<SignalDetection>> found;
};

// max |x[i]| over x[0, n) (0 when empty) = max(-min, max), from the reader's vectorised MinMax:
// the same value as the largest of the doubles (the conversion is exact and keeps the order).
double MaxAbs(const float* x, std::size_t n) {
  if (n == 0) return 0.0;
  float lo, hi;
  MinMax(x, n, &lo, &hi);
  return static_cast<double>(std::max(0.0f, std::max(-lo, hi)));  // +0 for an all-zero block
}

// The bytes of the arrays of one signal's detection in a block of n frames (the signals are
// detected one after another and share them): the mix, the decimated signal, the detector's
// working set.
std::size_t BlockArrayBytes(std::size_t n, double rate, const std::vector<int>& choices,
                            const DetectOptions& options) {
  const int factor = DecimationFactor(rate);
  const std::size_t analysed = n / static_cast<std::size_t>(factor) + 1;
  const bool mixes = std::any_of(choices.begin(), choices.end(), [](int c) { return c < 0; });
  return (mixes ? n * sizeof(float) : 0) + (factor > 1 ? analysed * sizeof(float) : 0) +
         OnsetDetector::WorkingBytes(OnsetOptionsOf(options), rate / factor, analysed);
}

// Every candidate signal of one block through DetectInSignal (at most at kMaxAnalysisRateHz).
// `prefault`: map the memory of its arrays first, on this thread's heap, in huge pages
// (BlockArrayBytes, core/huge_pages.hpp).
BlockResult DetectBlock(const Block& b, double rate, const std::vector<int>& choices,
                        const DetectOptions& options, bool prefault) {
  BlockResult r;
  const int factor = DecimationFactor(rate);
  const double offset_s = static_cast<double>(b.start) / rate;
  if (prefault) PrefaultHeap(BlockArrayBytes(b.channels.front().size(), rate, choices, options));
  std::vector<float> mix, xd;
  for (int choice : choices) {
    // A channel is detected on the block's own samples; the mix is made one signal at a time.
    const std::vector<float>* x = &mix;
    if (choice >= 0)
      x = &b.channels[static_cast<std::size_t>(choice)];
    else
      SignalOf(b.channels, choice, 0, b.channels.front().size(), &mix);
    const double peak = MaxAbs(x->data(), x->size());
    r.peak.push_back(peak);
    r.found.emplace_back();
    if (!(peak > kSilencePeak)) continue;
    SignalDetection d;
    if (factor > 1) {
      Decimate(*x, factor, &xd);
      d = DetectInSignal(xd, rate / factor, options);
      FullRateAmplitudes(*x, rate, &d);
      d.hop_samples *= factor;  // in samples of the file's rate (CoarsenToHop)
    } else {
      d = DetectInSignal(*x, rate, options);
    }
    ShiftTimes(offset_s, &d);
    r.found.back() = std::move(d);
  }
  return r;
}

// Adds one block's results to the signals' (in block order: the merged result is the serial one).
void MergeBlockResult(BlockResult r, double own_lo_s, double own_hi_s, bool last,
                      std::vector<SignalAcrossBlocks>* signals) {
  for (std::size_t ci = 0; ci < signals->size(); ++ci) {
    SignalAcrossBlocks& sig = (*signals)[ci];
    sig.peak = std::max(sig.peak, r.peak[ci]);
    if (!r.found[ci]) continue;
    sig.sound = true;
    MergeBlock(std::move(*r.found[ci]), own_lo_s, own_hi_s, last, &sig);
  }
}

// Threads that detect the blocks handed to them, in the order handed, each result a future; the
// same threads for every block of the recording. Each thread's allocations come from an arena of
// the allocator of its own, which a thread started per block (std::async, before) could get
// anew, its memory first written again; here each thread's first block maps its arena's memory
// at once (DetectBlock's prefault) and the later ones reuse it. Measured (10 minutes, two
// threads, 21 alternating runs): 0.663 -> 0.597 s, page faults 11 700 -> 6 700; bench_long in
// one loop: 10, 30 and 60 minutes 1.09, 1.13 and 1.02 times faster.
class BlockWorkers {
 public:
  // A thread that cannot be started (std::system_error) ends the ones started, then rethrows.
  BlockWorkers(int n, std::function<BlockResult(const Block&, bool first)> detect)
      : detect_(std::move(detect)) {
    try {
      for (int i = 0; i < n; ++i) threads_.emplace_back([this] { Run(); });
    } catch (...) {
      Close();
      throw;
    }
  }
  // Finishes the blocks being detected, drops those not started (an error ended the reading),
  // and joins.
  ~BlockWorkers() { Close(); }
  BlockWorkers(const BlockWorkers&) = delete;
  BlockWorkers& operator=(const BlockWorkers&) = delete;

  // Threads waiting for a block while none is queued.
  int Idle() {
    std::lock_guard<std::mutex> lock(m_);
    return queue_.empty() ? waiting_ : 0;
  }

  std::future<BlockResult> Submit(Block b) {
    std::future<BlockResult> f;
    {
      std::lock_guard<std::mutex> lock(m_);
      queue_.push_back({std::move(b), {}});
      f = queue_.back().result.get_future();
    }
    cv_.notify_one();
    return f;
  }

 private:
  struct Job {
    Block block;
    std::promise<BlockResult> result;
  };
  void Close() {
    {
      std::lock_guard<std::mutex> lock(m_);
      closing_ = true;
    }
    cv_.notify_all();
    for (std::thread& t : threads_) t.join();
  }
  void Run() {
    for (bool first = true;; first = false) {
      Job job;
      {
        std::unique_lock<std::mutex> lock(m_);
        ++waiting_;
        cv_.wait(lock, [this] { return closing_ || !queue_.empty(); });
        --waiting_;
        if (closing_) return;
        job = std::move(queue_.front());
        queue_.pop_front();
      }
      try {
        job.result.set_value(detect_(job.block, first));
      } catch (...) {
        job.result.set_exception(std::current_exception());
      }
    }
  }
  std::function<BlockResult(const Block&, bool)> detect_;
  std::mutex m_;
  std::condition_variable cv_;
  std::deque<Job> queue_;
  int waiting_ = 0;
  bool closing_ = false;
  std::vector<std::thread> threads_;
};

// Reads frames [i0, i1) of the recording block by block and runs every candidate signal on
// each block (DetectBlock), merging what each finds in block order (MergeBlock); then reads the
// rest of the file, so that every sample is checked and the clipping reports are complete.
// A recording of one block is detected on this thread, its stages split among
// DetectOptions::threads; several blocks are detected concurrently on that many BlockWorkers
// (each block single-threaded), while this thread reads ahead. One block more than the workers
// is handed out, so that a worker that finishes finds the next block queued instead of waiting
// for this thread to merge the oldest and read: at most threads + 2 blocks in memory (10
// minutes, two threads, 15 alternating runs: 630 -> 614 ms median). The last blocks' stages
// take the workers left idle (DetectOptions::available_threads; 681 -> 630 ms). The cuts depend
// only on the audio, and the merge is in order, so the result is the serial one. (Giving the
// last blocks' stages all the threads from their start, whether or not a worker was idle, was
// slower on the 2-core machine: 0.79-1.06 s against 0.69-0.76 s for a 10-minute file.)
void DetectBlocks(AudioReader* reader, std::int64_t i0, std::int64_t i1,
                  const std::vector<int>& choices, const DetectOptions& options,
                  std::vector<SignalAcrossBlocks>* signals) {
  const double rate = reader->info().sample_rate_hz;
  const std::int64_t cap = std::max<std::int64_t>(
      16, std::min(kMaxBlockFrames, static_cast<std::int64_t>(options.max_block_s * rate)));
  const std::int64_t margin = static_cast<std::int64_t>(kBlockMarginS * rate);
  const std::int64_t search = std::min(cap / 4, static_cast<std::int64_t>(kMaxCutSearchS * rate));
  const int threads = ResolveThreads(options.threads);
  // A block's stages run on its worker alone while blocks are still to come; once the last
  // block is handed out, each stage that starts also takes the workers left without a block
  // (StageThreads): the recording's last blocks, which would otherwise finish on one core each
  // while the others wait, end sooner. The values do not depend on it.
  // `pool` is the workers' (set before the first block is handed out, read only after the last
  // one is); the workers themselves are declared after per_block, so that an error that ends
  // the reading joins their threads while the options they use still exist.
  std::atomic<bool> all_handed_out{false};
  BlockWorkers* pool = nullptr;
  DetectOptions per_block = options;
  per_block.threads = threads;
  per_block.available_threads = [&pool, &all_handed_out] {
    return 1 + (all_handed_out.load() ? pool->Idle() : 0);
  };
  // The threads those stages take are a WorkerPool's, kept running from one stage to the next
  // (its workers sleep until then; a block whose stages find it busy starts threads of its
  // own). 10 minutes, two threads: the fifth of five full blocks runs alone after the short
  // last one (measured below).
  std::optional<WorkerPool> last_blocks_pool;
  if (i1 - i0 > cap && threads > 1 && options.pool == nullptr) {
    last_blocks_pool.emplace(threads);
    per_block.pool = &*last_blocks_pool;
  }

  struct InFlight {
    double own_lo_s, own_hi_s;
    bool last;
    std::future<BlockResult> result;
  };
  std::deque<InFlight> in_flight;
  std::unique_ptr<BlockWorkers> workers;
  auto merge_oldest = [&] {
    InFlight& f = in_flight.front();
    MergeBlockResult(f.result.get(), f.own_lo_s, f.own_hi_s, f.last, signals);
    in_flight.pop_front();
  };
  reader->Skip(i0);
  // Where the blocks are detected on this thread (one block, or one thread), the memory for a
  // block's samples and arrays is mapped at once in huge pages (core/huge_pages.hpp), once: freed,
  // it serves the next block. Where they are detected concurrently (BlockWorkers), each worker
  // maps its arrays at its first block; mapping the samples of the blocks read ahead too changed
  // nothing measurable (10 minutes, two threads: 0.596-0.602 s with 0 to 4 blocks mapped).
  //
  // A recording of one block detected with several threads has that memory (its samples' and
  // its arrays') mapped on another thread while this one reads it, and the detector's FFTW plans
  // made there too: FFTW keeps a plan's solution, so that the detector this thread constructs
  // after the reading plans again in microseconds (~3 ms of planning for a first detector).
  const std::size_t channels = static_cast<std::size_t>(reader->info().channels);
  const bool one_block = i1 - i0 <= cap;
  const bool here = one_block || threads == 1;
  const std::size_t block_bytes =
      static_cast<std::size_t>(std::min(cap, i1 - i0)) * channels * sizeof(float);
  std::optional<HeapPrefault> ahead;
  if (one_block && threads > 1) {
    OnsetOptions oo = OnsetOptionsOf(options);
    oo.available_threads = nullptr;
    oo.pool = nullptr;
    const double analysis_rate = rate / DecimationFactor(rate);
    ahead.emplace(block_bytes,
                  BlockArrayBytes(static_cast<std::size_t>(i1 - i0), rate, choices, options),
                  [oo, analysis_rate] {
                    try {
                      const OnsetDetector plans(oo, analysis_rate);
                    } catch (...) {  // the detection itself reports what is wrong
                    }
                  });
  } else if (here) {
    PrefaultHeap(block_bytes);
  }
  std::vector<std::vector<float>> buf(channels);
  std::int64_t buf_start = i0;
  double own_lo_s = -std::numeric_limits<double>::infinity();
  for (bool first = true;; first = false) {
    // Fill the block up to `cap` frames (or the window's end).
    for (;;) {
      const std::int64_t have = static_cast<std::int64_t>(buf.front().size());
      const std::int64_t want = std::min(cap - have, i1 - (buf_start + have));
      if (want <= 0 || reader->Read(want, &buf) == 0) break;
    }
    const std::int64_t buf_end = buf_start + static_cast<std::int64_t>(buf.front().size());
    Block b;
    b.start = buf_start;
    b.own_lo_s = own_lo_s;
    b.last = buf_end >= i1 || buf_end - buf_start < cap;
    std::int64_t cut = buf_end, block_end = buf_end;
    if (!b.last) {
      const std::size_t lo = static_cast<std::size_t>(buf_end - search - buf_start);
      const std::size_t hi = static_cast<std::size_t>(buf_end - margin - buf_start);
      cut = buf_start + static_cast<std::int64_t>(QuietestCut(buf, lo, hi, rate));
      block_end = std::min(buf_end, cut + margin);
    }
    b.own_hi_s = b.last ? std::numeric_limits<double>::infinity() : static_cast<double>(cut) / rate;
    // The block takes frames [buf_start, block_end); the next starts kBlockMarginS before the cut.
    const std::int64_t next = b.last ? buf_end : std::max(buf_start, cut - margin);
    for (std::vector<float>& c : buf) {
      std::vector<float> rest(c.begin() + static_cast<std::ptrdiff_t>(next - buf_start), c.end());
      c.resize(static_cast<std::size_t>(block_end - buf_start));
      b.channels.push_back(std::move(c));
      c = std::move(rest);
    }
    buf_start = next;
    own_lo_s = b.own_hi_s;
    if (first && b.last) {  // one block: on this thread, with all the threads for its stages
      // The stages' threads kept running from one stage to the next (WorkerPool).
      DetectOptions stages = options;
      std::optional<WorkerPool> stage_pool;
      if (threads > 1 && stages.pool == nullptr) {
        stage_pool.emplace(threads);
        stages.pool = &*stage_pool;
      }
      MergeBlockResult(DetectBlock(b, rate, choices, stages, !ahead), b.own_lo_s, b.own_hi_s, true,
                       signals);
      break;
    }
    const double lo_s = b.own_lo_s, hi_s = b.own_hi_s;
    const bool last = b.last;
    if (threads > 1) {
      if (!workers) {
        workers = std::make_unique<BlockWorkers>(threads, [&](const Block& blk, bool first_here) {
          return DetectBlock(blk, rate, choices, per_block, first_here);
        });
        pool = workers.get();
      }
      in_flight.push_back({lo_s, hi_s, last, workers->Submit(std::move(b))});
      if (last) all_handed_out = true;
      while (static_cast<int>(in_flight.size()) > threads) merge_oldest();
    } else {
      MergeBlockResult(DetectBlock(b, rate, choices, per_block, here), lo_s, hi_s, last, signals);
    }
    if (last) break;
  }
  reader->Skip(std::numeric_limits<std::int64_t>::max());
  while (!in_flight.empty()) merge_oldest();
}

}  // namespace

DetectionResult DetectImpacts(const Audio& audio, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (audio.channels.empty() || audio.channels.front().empty())
    throw Error(ErrorCode::kNotAudio, audio.info.path + ": no samples");
  AudioReader reader(audio);
  return DetectImpacts(reader, options);
}

DetectionResult DetectImpactsInFile(const std::string& path, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  AudioReader reader(path);
  return DetectImpacts(reader, options);
}

DetectionResult DetectImpacts(AudioReader& reader, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  const AudioInfo& info = reader.info();
  const std::string& path = info.path;
  DetectionResult res;
  res.audio = info;
  if (info.channels < 1 || info.frames <= 0)
    throw Error(ErrorCode::kNotAudio, path + ": no samples");
  const double rate = info.sample_rate_hz;
  const std::int64_t frames = info.frames;
  const double duration_s = static_cast<double>(frames) / rate;

  // 1. Window.
  const std::string window = "[" + Fmt("%g", options.start_s) + ", " +
                             (options.end_s ? Fmt("%g", *options.end_s) : std::string("end")) +
                             ") s";
  if (options.start_s >= duration_s)
    throw Error(ErrorCode::kNoBounces, path + ": the window " + window +
                                           " starts after the recording ends (" +
                                           Fmt("%.3f", duration_s) + " s)");
  const std::int64_t i0 = static_cast<std::int64_t>(std::ceil(options.start_s * rate));
  const std::int64_t i1 =
      options.end_s ? std::min(frames, static_cast<std::int64_t>(std::ceil(*options.end_s * rate)))
                    : frames;
  res.start_s = static_cast<double>(i0) / rate;
  res.end_s = static_cast<double>(i1) / rate;

  // 2. Which signals to try.
  std::vector<int> choices;
  const int nch = info.channels;
  switch (options.channel.kind) {
    case ChannelSelection::Kind::kIndex:
      if (options.channel.index >= nch)
        throw Error(ErrorCode::kUsage, path + ": channel " + std::to_string(options.channel.index) +
                                           " out of range (" + std::to_string(nch) + " channel" +
                                           (nch == 1 ? "" : "s") + ", 0-based)");
      choices = {options.channel.index};
      break;
    case ChannelSelection::Kind::kMix:
      choices = {-1};
      break;
    case ChannelSelection::Kind::kAuto:
      for (int c = 0; c < nch; ++c) choices.push_back(c);
      if (nch > 1) choices.push_back(-1);
      break;
  }

  // 3. Detect in each signal, block by block.
  std::vector<SignalAcrossBlocks> signals(choices.size());
  DetectBlocks(&reader, i0, i1, choices, options, &signals);
  res.clipping = reader.clipping();

  // 4. Keep the best-scoring signal.
  int best = -1;
  SignalDetection chosen;
  std::string failures;
  bool any_sound = false;
  for (std::size_t ci = 0; ci < choices.size(); ++ci) {
    SignalAcrossBlocks& sig = signals[ci];
    SignalDetection& d = sig.merged;
    MarkClipped(ClipPeak(res.clipping, choices[ci], static_cast<std::size_t>(nch)), &d);
    ChannelScore cs;
    cs.channel = choices[ci];
    if (!sig.sound) {
      cs.failure = "silent (peak |x| = " + Fmt("%.3g", sig.peak) + ")";
    } else {
      any_sound = true;
      if (d.sequences.empty()) {
        d.failure = sig.failure.empty() ? std::string("no bounce sequence") : sig.failure;
      } else {
        d.score =
            SequenceScore(d.sequences[static_cast<std::size_t>(LongestSequence(d.sequences))]);
        const Sequence& m = d.sequences[static_cast<std::size_t>(LongestSequence(d.sequences))];
        cs.impacts = static_cast<int>(m.impacts.size());
        cs.first_impact_s = m.impacts.front().time_s;
      }
      cs.failure = d.failure;
      cs.score = d.score;
      // A later signal (channel 1, ..., then the mix) replaces the one chosen so far only when it
      // is clearly better (kChannelScoreMargin): near ties would otherwise flip with the weak
      // tail of a sequence, i.e. with how much audio surrounds it.
      if (best < 0 || (chosen.sequences.empty() && !d.sequences.empty()) ||
          d.score > (1.0 + kChannelScoreMargin) * chosen.score) {
        best = static_cast<int>(ci);
        chosen = std::move(d);
      }
    }
    if (!cs.failure.empty())
      failures += std::string(failures.empty() ? "" : "; ") +
                  (choices.size() > 1 ? (cs.channel >= 0 ? "channel " + std::to_string(cs.channel)
                                                         : std::string("mix")) +
                                            ": "
                                      : std::string()) +
                  cs.failure;
    res.channel_scores.push_back(cs);
  }
  const bool windowed = options.start_s > 0.0 || options.end_s.has_value();
  if (!any_sound)
    throw Error(ErrorCode::kSilence, path + ": recording" + (windowed ? " window " + window : "") +
                                         " is silent (peak |x| at or below one 16-bit step)");
  if (best < 0 || chosen.sequences.empty())
    throw Error(ErrorCode::kNoBounces, path + ": no bounce sequence found" +
                                           (windowed ? " in the window " + window : "") + " (" +
                                           failures + ")");
  res.channel = choices[static_cast<std::size_t>(best)];
  if (res.channel_scores.size() == 1) res.channel_scores.clear();  // nothing was chosen

  // 4. Result and warnings.
  res.candidates = std::move(chosen.candidates);
  res.sequences = std::move(chosen.sequences);
  if (!options.refine) {
    for (Impact& im : res.candidates) CoarsenToHop(&im, chosen.hop_samples, rate);
    for (Sequence& q : res.sequences)
      for (Impact& im : q.impacts) CoarsenToHop(&im, chosen.hop_samples, rate);
  }
  res.main_sequence = LongestSequence(res.sequences);
  for (const ClippingReport& c : res.clipping)
    if (c.clipped())
      res.warnings.push_back({"clipped",
                              "channel " + std::to_string(c.channel) + " is clipped (" +
                                  std::to_string(c.clipped_samples) +
                                  " samples at its extreme value); onsets are still usable, "
                                  "amplitudes are not",
                              -1});
  if (info.lossy) {
    const double delay_ms = 1e3 * static_cast<double>(info.codec_delay_samples) / rate;
    res.warnings.push_back(
        {"codec_delay",
         "decoded from lossy " + info.subtype + " (" + info.format + "): " +
             (info.codec_delay_samples > 0
                  ? std::to_string(info.codec_delay_samples) + " priming samples (" +
                        Fmt("%.2f", delay_ms) + " ms) " +
                        (info.codec_delay_trimmed
                             ? "were trimmed as the file says"
                             : "are declared but were not trimmed: times are late by that much")
                  : std::string("no codec delay stated")) +
             "; lossy coding smears onsets (pre-echo), so a constant offset of up to a few ms "
             "is possible (intervals are not)",
         -1});
  }
  ChannelChoiceWarning(res, &res.warnings);
  res.warnings.insert(res.warnings.end(), chosen.warnings.begin(), chosen.warnings.end());
  FlagWarnings(res.sequences, &res.warnings);
  return res;
}

SequenceChoice ParseSequenceChoice(const std::string& text) {
  SequenceChoice c;
  if (text == "main") return c;
  if (text == "all") {
    c.kind = SequenceChoice::Kind::kAll;
    return c;
  }
  if (!text.empty() && text.size() < 7 &&
      std::all_of(text.begin(), text.end(), [](unsigned char ch) { return std::isdigit(ch); })) {
    c.kind = SequenceChoice::Kind::kIndex;
    c.index = std::stoi(text);
    return c;
  }
  throw Error(ErrorCode::kUsage,
              "sequence choice '" + text + "': expected main, all or a 0-based sequence index");
}

std::vector<int> ChooseSequences(const std::vector<Sequence>& sequences,
                                 const SequenceChoice& choice, const std::string& name) {
  const int n = static_cast<int>(sequences.size());
  switch (choice.kind) {
    case SequenceChoice::Kind::kMain:
      return n > 0 ? std::vector<int>{LongestSequence(sequences)} : std::vector<int>{};
    case SequenceChoice::Kind::kAll: {
      std::vector<int> all(static_cast<std::size_t>(n));
      for (int s = 0; s < n; ++s) all[static_cast<std::size_t>(s)] = s;
      return all;
    }
    case SequenceChoice::Kind::kIndex:
      if (choice.index >= n)
        throw Error(ErrorCode::kUsage, name + ": sequence " + std::to_string(choice.index) +
                                           " requested, but there " + (n == 1 ? "is " : "are ") +
                                           std::to_string(n) + " sequence" + (n == 1 ? "" : "s") +
                                           " (0-based)");
      return {choice.index};
  }
  return {};
}

}  // namespace bouncecal
