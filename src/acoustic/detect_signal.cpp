// The detection of one candidate signal. See detect_signal.hpp.
#include "detect_signal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include <boost/math/distributions/chi_squared.hpp>

#include "bouncecal/acoustic/plausibility.hpp"
#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/acoustic/timing.hpp"
#include "bouncecal/core/parallel.hpp"

namespace bouncecal {
namespace {

// Guided search: the window spans kGuidedReach spreads of the predicted time on each side
// (TrackOptions::max_z), the spread of log r the sequence's own (TrendAt) but at least
// kMinRatioSpread (a quarter of TrackOptions::scatter_sigma: real balls scatter by >= 0.005 in e).
constexpr double kGuidedReach = 4.0;
constexpr double kMinRatioSpread = 0.005;
// Ranking penalty at the window edge (NCC units): near the noise level a noise peak 0.4 ms from
// the prediction matched as well as the impact (corpus: NCC 0.37 vs 0.36, a 433 us error).
constexpr double kGuidedEdgePenalty = 0.15;

// One look where a sequence predicts an impact: the best template match in a window
// kGuidedReach spreads wide around the prediction (FindByTemplate, ranked by NCC - edge
// penalty towards the window's edges) and its p-value, the chance that noise alone ranks as well
// somewhere in the window: the NCC where the template meets no impact spreads by
// s = max(1 / sqrt(L), its robust spread in the middle of the flight before) (whitened white
// noise: 1 / sqrt(L) for a template of L samples).
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
  look.any = FindByTemplate(onsets, x, t_c, half, -1.0, &look.match, kGuidedEdgePenalty);
  if (!look.any) return look;
  // The noise's NCC measured in the middle of the flight before (what rings there, away from
  // both impacts).
  const double spread = NccNoiseSpread(onsets, t_c - 2.0 * dn / 3.0, t_c - dn / 3.0, 256);
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
  return look;
}

// A match joins a sequence when noise alone would match as well in at most one window of twenty
// (its own p-value), inside a run of looks that noise alone explains with probability at most
// kGuidedFalseAlarm (Fisher's combination of their p-values).
constexpr double kGuidedMemberP = 0.05;
constexpr double kGuidedFalseAlarm = 0.01;

// The trend of log r at the end of impacts [0, end): a straight line in the flight's index fitted
// to the last kTrendFlights regular ratios (flights across a flagged gap or next to an irregular
// step left out; e drifts steadily with the impact speed, and with drag), and the spread of the
// ratios about it: 1.4826 MAD of the residuals, with the last flight's timing noise, at least
// kMinRatioSpread. With fewer than 3 regular ratios: their median and the floor.
constexpr std::size_t kTrendFlights = 6;
struct RatioTrend {
  double log_r = 0.0;  // predicted log ratio of the next flight
  double slope = 0.0;  // change of log r per flight
  double spread = kMinRatioSpread;
};
RatioTrend TrendAt(const Sequence& seq, std::size_t end) {
  const std::vector<Impact>& q = seq.impacts;
  auto flagged = [&](std::size_t j) {  // interval j -> j + 1
    const int k = static_cast<int>(j);
    return std::find(seq.missed_after.begin(), seq.missed_after.end(), k) !=
               seq.missed_after.end() ||
           std::find(seq.irregular_after.begin(), seq.irregular_after.end(), k) !=
               seq.irregular_after.end();
  };
  std::vector<double> x, y;  // flight index of the later flight, log r
  for (std::size_t k = end - 1; k >= 2 && y.size() < kTrendFlights; --k) {
    if (flagged(k - 1) || flagged(k - 2)) continue;
    x.push_back(static_cast<double>(k));
    y.push_back(std::log((q[k].time_s - q[k - 1].time_s) / (q[k - 1].time_s - q[k - 2].time_s)));
  }
  RatioTrend t;
  const double next = static_cast<double>(end);
  if (y.size() < 3) {
    if (y.empty()) {
      t.log_r = std::log((q[end - 1].time_s - q[end - 2].time_s) /
                         (q[end - 2].time_s - q[end - 3].time_s));
    } else {
      std::vector<double> sorted = y;
      std::sort(sorted.begin(), sorted.end());
      t.log_r = sorted[sorted.size() / 2];
    }
  } else {
    const double n = static_cast<double>(y.size());
    double mx = 0.0, my = 0.0;
    for (std::size_t j = 0; j < y.size(); ++j) mx += x[j] / n, my += y[j] / n;
    double sxx = 0.0, sxy = 0.0;
    for (std::size_t j = 0; j < y.size(); ++j)
      sxx += (x[j] - mx) * (x[j] - mx), sxy += (x[j] - mx) * (y[j] - my);
    t.slope = sxx > 0.0 ? sxy / sxx : 0.0;
    t.log_r = my + t.slope * (next - mx);
    std::vector<double> res;
    for (std::size_t j = 0; j < y.size(); ++j)
      res.push_back(std::fabs(y[j] - my - t.slope * (x[j] - mx)));
    const auto mid = res.begin() + static_cast<std::ptrdiff_t>(res.size() / 2);
    std::nth_element(res.begin(), mid, res.end());
    t.spread = std::max(t.spread, 1.4826 * *mid);
  }
  const double d = q[end - 1].time_s - q[end - 2].time_s;
  t.spread = std::hypot(t.spread, std::sqrt(2.0) * q[end - 1].sigma_s / d);
  return t;
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
    const double r0 = std::clamp(std::exp(TrendAt(*q, k + 1).log_r), to.min_ratio, to.max_ratio);
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
      const Look look = LookAt(onsets, x, t, dn, TrendAt(*q, k + 1).spread);
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
// kGuidedFalseAlarm joins the sequence: its matches with p <= kGuidedMemberP as members, up to the
// first look that found none (an unheard impact ends the tail). It stops where no run is
// significant: the noise won or the ball stopped. Returns whether the sequence grew.
bool ExtendTail(const OnsetResult& onsets, const std::vector<float>& x, double limit_s,
                const TrackOptions& to, Sequence* q) {
  bool extended = false;
  while (q->impacts.size() >= 3) {
    const RatioTrend trend = TrendAt(*q, q->impacts.size());
    double t = q->impacts.back().time_s;
    double d = t - q->impacts[q->impacts.size() - 2].time_s;
    const double spread = trend.spread;
    std::vector<Look> looks;
    for (int j = 0; j <= to.max_missed; ++j) {
      const double r =
          std::clamp(std::exp(trend.log_r + trend.slope * j), to.min_ratio, to.max_ratio);
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
    // Members up to the first unheard impact only: past a gap the flight the looks were made
    // from spans two bounces, and the next prediction locks onto every other impact (a 10 mm
    // steel ball's tail: four double flights taken for bounces, e ~ e^2).
    bool grew = false;
    for (std::size_t n = 0; n < best_n; ++n) {
      if (!looks[n].any || looks[n].p > kGuidedMemberP) break;
      // Right after a member, the flight must not be longer than the one before beyond the
      // timing noise (e <= 1, TrackOptions::max_ratio): a match past it is not the next bounce.
      const Impact& f = looks[n].match;
      const std::size_t m = q->impacts.size();
      const double before = q->impacts[m - 1].time_s - q->impacts[m - 2].time_s;
      if ((f.time_s - q->impacts[m - 1].time_s) / before >
          to.max_ratio + 3.0 * std::hypot(f.sigma_s, q->impacts[m - 1].sigma_s) / before)
        break;
      q->impacts.push_back(f);
      grew = true;
    }
    if (!grew) break;
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
    const double next_dt = d * std::exp(TrendAt(q, q.impacts.size()).log_r);
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

}  // namespace

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

// The onset detector's options in a detection with `options`.
OnsetOptions OnsetOptionsOf(const DetectOptions& options) {
  OnsetOptions oo;
  oo.hop_s = options.hop_s;
  oo.refine = true;  // locate at full resolution; refine = false coarsens the times at the end
  oo.lpc_order = options.lpc_order;
  oo.threads = options.threads;
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

  TimingOptions tim;
  tim.lpc_order = options.lpc_order;
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
    const int threads = ResolveThreads(options.threads);
    std::vector<std::vector<double>> anchors(which.size());
    std::vector<Sequence> timed(which.size());
    for (std::size_t i = 0; i < which.size(); ++i) anchors[i] = anchors_of(*which[i]);
    const int inner = which.size() == 1 ? threads : 1;
    ParallelFor(threads, which.size(), [&](std::size_t i) {
      timed[i] = *which[i];
      time_at(anchors[i], inner, &timed[i]);
    });
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

}  // namespace bouncecal
