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
#include "guided_search.hpp"

namespace bouncecal {

void MoveMembersToTheirAttacks(const std::vector<Impact>& candidates, const TrackOptions& to,
                               std::vector<Sequence>* sequences) {
  std::vector<double> members;
  for (const Sequence& q : *sequences)
    for (const Impact& m : q.impacts) members.push_back(m.time_s);
  std::sort(members.begin(), members.end());
  auto is_member = [&](double t) { return std::binary_search(members.begin(), members.end(), t); };
  for (Sequence& q : *sequences) {
    for (std::size_t k = 0; k < q.impacts.size(); ++k) {
      Impact& m = q.impacts[k];
      if (m.rise_db > 0.0) continue;
      // The strongest attack among the candidates whose sound the member's rise window holds
      // (begun 0.5-3.5 ms before it: RawRiseDb's window before the onset, past its guard).
      const Impact* attack = nullptr;
      // (The candidates are in time order: only those of the window are looked at.)
      const auto first =
          std::lower_bound(candidates.begin(), candidates.end(), m.time_s - 2.0 * kAttackReachS,
                           [](const Impact& c, double t) { return c.time_s < t; });
      for (auto c_it = first; c_it != candidates.end() && c_it->time_s < m.time_s; ++c_it) {
        const Impact& c = *c_it;
        const double before = m.time_s - c.time_s;
        if (before < 5e-4 || before > kAttackReachS || is_member(c.time_s)) continue;
        if (c.rise_db < kAttackRiseDb ||
            (k > 0 && c.time_s - q.impacts[k - 1].time_s < to.min_interval_s))
          continue;
        if (20.0 * std::log10(c.amplitude / std::max(m.amplitude, 1e-12)) < -kAttackLevelDb)
          continue;
        if (!attack || c.rise_db > attack->rise_db) attack = &c;
      }
      if (attack) m = *attack;
    }
  }
}

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
  MoveMembersToTheirAttacks(out.candidates, to, &out.sequences);
  if (options.guided_search) {
    GuidedOptions go;
    go.lpc_order = options.lpc_order;
    ExtendByTemplate(onsets, x, duration_s, to, go, &out.sequences);
  }

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
