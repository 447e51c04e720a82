// The detection of one candidate signal. See detect_signal.hpp.
#include "detect_signal.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <map>

#include "bouncecal/acoustic/plausibility.hpp"
#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/acoustic/timing.hpp"
#include "bouncecal/core/parallel.hpp"

namespace bouncecal {
namespace {

// Guided search: NCC threshold (the blind pass asks for 4/sqrt(L), about 0.47 at 48 kHz; here
// the time is known to a few percent, so far fewer positions compete) and half window as a
// fraction of the predicted interval (the ratio of successive intervals drifts by ~1-3 %).
constexpr double kGuidedMinNcc = 0.35;
constexpr double kGuidedWindow = 0.04;
// Ranking penalty at the window edge (NCC units): near the noise level a noise peak 0.4 ms from
// the prediction matched as well as the impact (corpus: NCC 0.37 vs 0.36, a 433 us error).
constexpr double kGuidedEdgePenalty = 0.15;

// Tracking caps per second of signal (TrackOptions::max_candidates = 300 and max_sequences = 16
// hold up to 30 s and 64 s): a drop gives up to ~80 onsets (a steel ball's 76 impacts down to
// the 3 ms resolution limit) in ~8 s and takes at least ~4 s with the pick-up. Measured on a
// 10-minute synthetic file of 65 steel drops, one every 9.2 s (8.3 onsets/s): 5 onsets/s left
// 150-190 onsets per 2-minute block untracked (guided search found most of them again); 10/s
// tracks them all. The caps still bound the tracker's work on a noisy file.
constexpr double kCandidatesPerS = 10.0;
constexpr double kSecondsPerDrop = 4.0;

// Median of the last (up to) three interval ratios of a sequence.
double RecentRatio(const std::vector<Impact>& q) {
  std::vector<double> r;
  for (std::size_t k = q.size() - 1; k >= 2 && r.size() < 3; --k)
    r.push_back((q[k].time_s - q[k - 1].time_s) / (q[k - 1].time_s - q[k - 2].time_s));
  std::sort(r.begin(), r.end());
  return r[r.size() / 2];
}

// The tracker knows where the next impact of a sequence should be: search there with the
// template at a lower NCC threshold than the blind pass (a few percent of the interval wide),
// for the impacts the blind pass missed: flagged gaps (one missed impact) and the tail.
void ExtendByTemplate(const OnsetResult& onsets, const std::vector<float>& x, double duration_s,
                      const TrackOptions& to, std::vector<Sequence>* sequences) {
  if (onsets.template_wave.empty()) return;
  const double min_ncc =
      std::max(kGuidedMinNcc, 3.0 / std::sqrt(static_cast<double>(onsets.template_wave.size())));
  for (std::size_t s = 0; s < sequences->size(); ++s) {
    Sequence& q = (*sequences)[s];
    // 1. Fill flagged gaps: dt ~ d1 + d2 with d2 = e d1, so the impact is at t_k + dt / (1 + e).
    std::vector<int> still_missed;
    int inserted = 0;
    for (int k0 : q.missed_after) {
      const std::size_t k = static_cast<std::size_t>(k0 + inserted);
      const double dt = q.impacts[k + 1].time_s - q.impacts[k].time_s;
      // e from the flights before the gap (d_prev) and dt = d_prev (e + e^2).
      double e_est = 0.9;
      if (k >= 1) {
        const double d_prev = q.impacts[k].time_s - q.impacts[k - 1].time_s;
        e_est = 0.5 * (-1.0 + std::sqrt(1.0 + 4.0 * dt / d_prev));  // root of e^2 + e = dt/d_prev
      }
      const double t_c = q.impacts[k].time_s + dt / (1.0 + e_est);
      Impact found;
      if (FindByTemplate(onsets, x, t_c, kGuidedWindow * dt, min_ncc, &found, kGuidedEdgePenalty)) {
        q.impacts.insert(q.impacts.begin() + static_cast<std::ptrdiff_t>(k + 1), found);
        ++inserted;
      } else {
        still_missed.push_back(k0 + inserted);
      }
    }
    q.missed_after = still_missed;
    // 2. Extend the tail while the predicted interval stays resolvable.
    const double limit = s + 1 < sequences->size()
                             ? (*sequences)[s + 1].impacts.front().time_s - to.min_interval_s
                             : duration_s - 0.002;
    bool extended = false;
    while (q.impacts.size() >= 3) {
      const double d = q.impacts.back().time_s - q.impacts[q.impacts.size() - 2].time_s;
      const double e =
          std::clamp(RecentRatio(q.impacts), to.min_ratio, std::min(to.max_ratio, 0.999));
      const double dn = d * e;
      if (dn < to.min_interval_s) break;
      const double t_c = q.impacts.back().time_s + dn;
      if (t_c > limit) break;
      Impact found;
      if (!FindByTemplate(onsets, x, t_c, kGuidedWindow * dn, min_ncc, &found, kGuidedEdgePenalty))
        break;
      const double r = (found.time_s - q.impacts.back().time_s) / d;
      if (!(r >= to.min_ratio && r <= to.max_ratio) ||
          std::fabs(std::log(r / e)) > to.max_log_ratio_jump)
        break;
      q.impacts.push_back(found);
      extended = true;
    }
    if (extended) {
      const double d = q.impacts.back().time_s - q.impacts[q.impacts.size() - 2].time_s;
      const double next_dt = d * RecentRatio(q.impacts);
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
}

// Tracking keeps at most TrackOptions::max_candidates onsets (the strongest) and
// max_sequences drops per signal (per block of a long recording; the caps grow with the
// block's length). When either is reached, say so instead of dropping them silently (issue 14).
// [from_s, to_s): the stretch of the recording the signal covers.
void CapWarnings(std::size_t candidates, std::size_t sequences, double from_s, double to_s,
                 const TrackOptions& to, std::vector<Warning>* warnings) {
  char msg[400];
  if (candidates > static_cast<std::size_t>(to.max_candidates)) {
    std::snprintf(msg, sizeof msg,
                  "%zu onset candidates in [%.1f, %.1f) s: only the strongest %d entered "
                  "sequence tracking (TrackOptions::max_candidates), so weaker drops or bounces "
                  "may be missing",
                  candidates, from_s, to_s, to.max_candidates);
    warnings->push_back({"detection_capped", msg, -1,
                         "--start/--end around the drop (fewer onsets compete there)"});
  }
  if (sequences >= static_cast<std::size_t>(to.max_sequences)) {
    std::snprintf(msg, sizeof msg,
                  "%zu bounce sequences found in [%.1f, %.1f) s, the most tracked there "
                  "(TrackOptions::max_sequences): further drops in it are not reported",
                  sequences, from_s, to_s);
    warnings->push_back(
        {"detection_capped", msg, -1, "analyse the drops in parts with --start/--end"});
  }
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

SignalDetection DetectInSignal(const std::vector<float>& x, double rate_hz, double offset_s,
                               const DetectOptions& options) {
  SignalDetection out;
  const double duration_s = static_cast<double>(x.size()) / rate_hz;
  const OnsetDetector detector(OnsetOptionsOf(options), rate_hz);
  const OnsetResult onsets = detector.Detect(x);
  out.hop_samples = detector.hop_samples();
  out.candidates = onsets.onsets;

  TrackOptions to;
  to.min_interval_s = options.min_interval_s;
  to.min_sequence_impacts = options.min_sequence_impacts;
  // The caps grow with the signal's length past a minute (a block of a long recording holds
  // several drops): kCandidatesPerS onsets and a drop per kSecondsPerDrop.
  to.max_candidates = std::max(to.max_candidates, static_cast<int>(kCandidatesPerS * duration_s));
  to.max_sequences = std::max(to.max_sequences, static_cast<int>(duration_s / kSecondsPerDrop));
  out.sequences = TrackSequences(out.candidates, duration_s, to);
  CapWarnings(out.candidates.size(), out.sequences.size(), offset_s, offset_s + duration_s, to,
              &out.warnings);
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
