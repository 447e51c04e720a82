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
namespace {

// RawRiseDb: mean square over [t, t + kRiseAfterS) against
// [t - kRiseBeforeS, t - kRiseGuardS). One millisecond holds a hard impact's attack (contact
// 20-150 us) and its first response; 3 ms before (beyond a guard for the onset's own timing
// error) holds the decaying sound of what came earlier, even at a low plate mode's period.
constexpr double kRiseAfterS = 0.001, kRiseBeforeS = 0.0035, kRiseGuardS = 0.0005;

}  // namespace

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
  if (options.guided_search)
    ExtendByTemplate(onsets, x, duration_s, to, GuidedOptions{}, &out.sequences);

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
