// Bounce-sequence tracking by dynamic programming over candidate pairs.
// See include/bouncecal/acoustic/sequence.hpp.
#include "bouncecal/acoustic/sequence.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr int kKeep = 2;  // extended histories kept per candidate pair

struct State {
  int i = -1, k = -1;  // last two impacts (candidate indices), i < k
  double score = 0.0;
  double ratio = kNaN;     // last ratio r = dt / dt_prev (NaN for the first pair)
  double d_eff = 0.0;      // last single interval (estimated one after a missed impact)
  bool missed = false;     // an impact seems missing between i and k
  bool irregular = false;  // the step to k broke the smooth ratio pattern (tolerated once)
  int back = -1;           // previous state
  int len = 2;
};

struct Chain {
  std::vector<int> members;  // candidate indices
  std::vector<int> missed_after;
  std::vector<int> irregular_after;
  double last_ratio = kNaN;
  double last_interval = 0.0;
  double score = 0.0;
};

// Whether |log u| < t (strict) or <= t, deciding from u alone where the answer is certain: the
// tracker compares most ratios of candidate pairs (noise among impacts) with bounds they are far
// outside or inside, and std::log was a third of its time. u is compared with e^t and e^-t
// widened (or narrowed) by kLogBoundMargin relative: outside the wide interval |log u| exceeds t
// by ~1e-12, inside the narrow one it falls short by as much, both far more than the rounding of
// a computed log (an ulp, ~1e-16 near these bounds), so the computed log would answer the same.
// Between them (and for NaN, 0 or negative u) the log is computed as before.
constexpr double kLogBoundMargin = 1e-12;
struct AbsLogBound {
  double t = 0.0, out_lo = 0.0, out_hi = 0.0, in_lo = 0.0, in_hi = 0.0;
  explicit AbsLogBound(double bound) : t(bound) {
    out_lo = std::exp(-t) * (1.0 - kLogBoundMargin);
    out_hi = std::exp(t) * (1.0 + kLogBoundMargin);
    in_lo = std::exp(-t) * (1.0 + kLogBoundMargin);
    in_hi = std::exp(t) * (1.0 - kLogBoundMargin);
  }
  bool SurelyOutside(double u) const { return u < out_lo || u > out_hi; }
  bool Below(double u) const {  // |log u| < t
    if (SurelyOutside(u)) return false;
    if (u >= in_lo && u <= in_hi) return true;
    return std::fabs(std::log(u)) < t;
  }
};

// Best chain among candidates[idx] (idx sorted by time). Empty if none qualifies.
// The dynamic programme's states over candidates[idx] (idx sorted by time), in the order they
// are made: by their last impact k. A state depends only on the candidates up to its k, so the
// states with k inside a prefix of idx are the prefix's own, in the same order (PickChain).
std::vector<State> ChainStates(const std::vector<Impact>& c, const std::vector<int>& idx,
                               const std::vector<double>& w, const TrackOptions& o) {
  std::vector<State> states;
  const int m = static_cast<int>(idx.size());
  if (m < o.min_sequence_impacts) return states;
  std::vector<std::vector<int>> ending(static_cast<std::size_t>(m));  // state ids ending at pos
  std::vector<double> level(static_cast<std::size_t>(m));             // dBFS
  for (int p = 0; p < m; ++p)
    level[static_cast<std::size_t>(p)] =
        20.0 * std::log10(std::max(
                   c[static_cast<std::size_t>(idx[static_cast<std::size_t>(p)])].amplitude, 1e-12));
  const double two_sigma2 = 2.0 * o.ratio_sigma * o.ratio_sigma;
  const AbsLogBound same_ratio(0.5 * o.ratio_sigma);
  // Beyond both jump bounds a history's step is neither regular nor irregular: its log is not
  // needed (AbsLogBound: certain from the ratio alone).
  const AbsLogBound any_jump(std::max(o.max_log_ratio_jump, o.max_irregular_log_jump));
  for (int kp = 1; kp < m; ++kp) {
    const double tk = c[static_cast<std::size_t>(idx[static_cast<std::size_t>(kp)])].time_s;
    const double wk = w[static_cast<std::size_t>(idx[static_cast<std::size_t>(kp)])];
    int fan = 0;
    for (int ip = kp - 1; ip >= 0 && fan < o.max_predecessors; --ip) {
      const double ti = c[static_cast<std::size_t>(idx[static_cast<std::size_t>(ip)])].time_s;
      const double d = tk - ti;
      if (d < o.min_interval_s) continue;
      if (d > o.max_interval_s) break;
      ++fan;
      // An earlier impact is faster, so not much quieter (plausibility.hpp, the level model).
      if (level[static_cast<std::size_t>(kp)] - level[static_cast<std::size_t>(ip)] >
          o.max_level_rise_db)
        continue;
      // The fresh start (i, k) and up to kKeep extensions with distinct last ratios: the
      // best-scoring history is not always the one the future can continue.
      State fresh;
      fresh.i = ip;
      fresh.k = kp;
      fresh.score = w[static_cast<std::size_t>(idx[static_cast<std::size_t>(ip)])] + wk;
      fresh.d_eff = d;
      // Top kKeep extensions by score, with distinct last ratios (insertion, no sort).
      State keep_buf[kKeep];
      int nkeep = 0;
      auto offer = [&](const State& s) {
        for (int q = 0; q < nkeep; ++q)
          if (same_ratio.Below(s.ratio / keep_buf[q].ratio)) {
            if (s.score > keep_buf[q].score) keep_buf[q] = s;
            return;
          }
        if (nkeep < kKeep) {
          keep_buf[nkeep++] = s;
          return;
        }
        int worst = 0;
        for (int q = 1; q < nkeep; ++q)
          if (keep_buf[q].score < keep_buf[worst].score) worst = q;
        if (s.score > keep_buf[worst].score) keep_buf[worst] = s;
      };
      for (int prev_id : ending[static_cast<std::size_t>(ip)]) {
        const State& p = states[static_cast<std::size_t>(prev_id)];
        const double r = d / p.d_eff;
        if (r < o.min_ratio) continue;
        State s = fresh;
        s.back = prev_id;
        s.len = p.len + 1;
        const bool has_trend = !std::isnan(p.ratio);
        double jump = 0.0;
        if (has_trend) {
          const double u = r / p.ratio;
          jump = any_jump.SurelyOutside(u) ? std::numeric_limits<double>::infinity() : std::log(u);
        }
        if (r <= o.max_ratio && std::fabs(jump) <= o.max_log_ratio_jump) {
          s.score = p.score + wk - jump * jump / two_sigma2;
          s.ratio = r;
          s.d_eff = d;
          offer(s);
        } else if (has_trend && p.len >= 4 && !p.irregular && !p.missed &&
                   r <= o.max_irregular_ratio && std::fabs(jump) <= o.max_irregular_log_jump) {
          // Spin or an uneven spot: one interval off the pattern, tolerated at a cost; the
          // trend ratio carries on to judge the next step.
          State irr = s;
          irr.score = p.score + wk - o.irregular_penalty;
          irr.ratio = p.ratio;
          irr.d_eff = d;
          irr.irregular = true;
          offer(irr);
        }
        if (r > o.max_ratio && has_trend && !p.missed) {
          // One impact missed between i and k: d ~ d_prev (e + e^2).
          const double e = p.ratio;
          const double expected = p.d_eff * (e + e * e);
          // Both flights around the missed impact must themselves be resolvable.
          if (std::fabs(d / expected - 1.0) <= o.missed_tolerance &&
              p.d_eff * e * e >= o.min_interval_s) {
            s.score = p.score + wk - o.missed_penalty;
            s.ratio = e;
            s.d_eff = d * e / (1.0 + e);  // the second of the two flights
            s.missed = true;
            offer(s);
          }
        }
      }
      for (int q = 0; q <= nkeep; ++q) {  // the kept extensions, then the fresh start
        ending[static_cast<std::size_t>(kp)].push_back(static_cast<int>(states.size()));
        states.push_back(q < nkeep ? keep_buf[q] : fresh);
      }
    }
  }
  return states;
}

// Best chain among candidates[idx] from the states ChainStates made for idx or for a longer
// list that idx begins (the states past idx's last candidate are not looked at). Empty if none
// qualifies.
Chain PickChain(const std::vector<State>& states, const std::vector<int>& idx,
                const std::vector<double>& w, const TrackOptions& o, double min_mean_weight) {
  Chain best_chain;
  const int m = static_cast<int>(idx.size());
  if (m < o.min_sequence_impacts) return best_chain;
  int best = -1;
  for (int s = 0; s < static_cast<int>(states.size()); ++s) {
    const State& st = states[static_cast<std::size_t>(s)];
    if (st.k >= m) break;  // made in order of k
    if (st.len < o.min_sequence_impacts) continue;
    if (best < 0 || st.score > states[static_cast<std::size_t>(best)].score) best = s;
  }
  if (best < 0) return best_chain;
  Chain chain;
  chain.score = states[static_cast<std::size_t>(best)].score;
  chain.last_ratio = states[static_cast<std::size_t>(best)].ratio;
  chain.last_interval = states[static_cast<std::size_t>(best)].d_eff;
  std::vector<int> rev;
  std::vector<bool> rev_missed, rev_irregular;
  for (int s = best; s >= 0; s = states[static_cast<std::size_t>(s)].back) {
    const State& st = states[static_cast<std::size_t>(s)];
    rev.push_back(st.k);
    rev_missed.push_back(st.missed);
    rev_irregular.push_back(st.irregular);
    if (st.back < 0) {
      rev.push_back(st.i);
      rev_missed.push_back(false);
      rev_irregular.push_back(false);
    }
  }
  std::reverse(rev.begin(), rev.end());
  std::reverse(rev_missed.begin(), rev_missed.end());
  std::reverse(rev_irregular.begin(), rev_irregular.end());
  // rev_missed[j] refers to the step arriving at rev[j].
  double wsum = 0.0;
  for (std::size_t j = 0; j < rev.size(); ++j) {
    chain.members.push_back(idx[static_cast<std::size_t>(rev[j])]);
    wsum += w[static_cast<std::size_t>(idx[static_cast<std::size_t>(rev[j])])];
    if (rev_missed[j]) chain.missed_after.push_back(static_cast<int>(j) - 1);
    if (rev_irregular[j]) chain.irregular_after.push_back(static_cast<int>(j) - 1);
  }
  if (wsum / static_cast<double>(rev.size()) < min_mean_weight) return best_chain;
  return chain;
}

}  // namespace

bool TrackOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(min_interval_s > 0.0)) return fail("TrackOptions::min_interval_s must be > 0");
  if (!(max_interval_s > min_interval_s))
    return fail("TrackOptions::max_interval_s must be > min_interval_s");
  if (!(min_ratio > 0.0) || !(max_ratio > min_ratio))
    return fail("TrackOptions: need 0 < min_ratio < max_ratio");
  if (!(ratio_sigma > 0.0)) return fail("TrackOptions::ratio_sigma must be > 0");
  if (!(max_log_ratio_jump > 0.0)) return fail("TrackOptions::max_log_ratio_jump must be > 0");
  if (!(max_irregular_ratio >= max_ratio))
    return fail("TrackOptions::max_irregular_ratio must be >= max_ratio");
  if (!(max_irregular_log_jump >= max_log_ratio_jump))
    return fail("TrackOptions::max_irregular_log_jump must be >= max_log_ratio_jump");
  if (!(irregular_penalty >= 0.0)) return fail("TrackOptions::irregular_penalty must be >= 0");
  if (!(max_level_rise_db > 0.0)) return fail("TrackOptions::max_level_rise_db must be > 0");
  if (!(missed_tolerance >= 0.0) || missed_tolerance > 0.5)
    return fail("TrackOptions::missed_tolerance must be in [0, 0.5]");
  if (min_sequence_impacts < 3)
    return fail("TrackOptions::min_sequence_impacts = " + std::to_string(min_sequence_impacts) +
                ": must be >= 3 (a ratio needs three impacts)");
  if (max_predecessors < 1) return fail("TrackOptions::max_predecessors must be >= 1");
  if (max_candidates < 3) return fail("TrackOptions::max_candidates must be >= 3");
  if (max_sequences < 1) return fail("TrackOptions::max_sequences must be >= 1");
  return true;
}

double CandidateWeight(const Impact& c) {
  return 0.5 + std::clamp(c.snr_db / 20.0, 0.0, 2.0) + 0.5 * std::clamp(c.score, 0.0, 1.0);
}

std::vector<Sequence> TrackSequences(const std::vector<Impact>& c, double duration_s,
                                     const TrackOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  std::vector<double> w(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) w[i] = CandidateWeight(c[i]);
  // Too many candidates (a noisy file): keep the strongest max_candidates for the DP, so the
  // fan-in limit still spans the longest flights.
  std::vector<int> all;
  for (std::size_t i = 0; i < c.size(); ++i) all.push_back(static_cast<int>(i));
  if (static_cast<int>(all.size()) > o.max_candidates) {
    std::stable_sort(all.begin(), all.end(), [&](int a, int b) {
      return w[static_cast<std::size_t>(a)] > w[static_cast<std::size_t>(b)];
    });
    all.resize(static_cast<std::size_t>(o.max_candidates));
    std::sort(all.begin(), all.end());
  }
  std::vector<Chain> chains;
  // Segments still to search, each with the states of a list it begins (ChainStates), when known:
  // the candidates before a chain found in a segment begin that segment.
  struct Work {
    std::vector<int> seg;
    std::shared_ptr<const std::vector<State>> states;
  };
  std::vector<Work> work;
  work.push_back({std::move(all), nullptr});
  while (!work.empty() && static_cast<int>(chains.size()) < o.max_sequences) {
    std::vector<int> seg = std::move(work.back().seg);
    std::shared_ptr<const std::vector<State>> states = std::move(work.back().states);
    work.pop_back();
    if (!states) states = std::make_shared<const std::vector<State>>(ChainStates(c, seg, w, o));
    Chain ch =
        PickChain(*states, seg, w, o, chains.empty() ? o.min_mean_weight : o.min_mean_weight_more);
    if (ch.members.empty()) continue;
    const double t0 = c[static_cast<std::size_t>(ch.members.front())].time_s;
    const double t1 = c[static_cast<std::size_t>(ch.members.back())].time_s;
    std::vector<int> before, after;
    for (int i : seg) {
      if (c[static_cast<std::size_t>(i)].time_s < t0) before.push_back(i);
      if (c[static_cast<std::size_t>(i)].time_s > t1) after.push_back(i);
    }
    if (!before.empty()) work.push_back({std::move(before), states});
    if (!after.empty()) work.push_back({std::move(after), nullptr});
    chains.push_back(std::move(ch));
  }
  std::sort(chains.begin(), chains.end(), [&](const Chain& a, const Chain& b) {
    return c[static_cast<std::size_t>(a.members.front())].time_s <
           c[static_cast<std::size_t>(b.members.front())].time_s;
  });
  std::vector<Sequence> out;
  for (std::size_t s = 0; s < chains.size(); ++s) {
    const Chain& ch = chains[s];
    Sequence seq;
    for (int i : ch.members) seq.impacts.push_back(c[static_cast<std::size_t>(i)]);
    seq.missed_after = ch.missed_after;
    seq.irregular_after = ch.irregular_after;
    const double t_last = seq.impacts.back().time_s;
    const double next_dt = ch.last_interval * ch.last_ratio;
    const double next_t = t_last + next_dt;
    if (next_dt < 1.5 * o.min_interval_s) {
      seq.end_reason = "resolved_limit";
    } else if (next_t > duration_s) {
      seq.end_reason = "end_of_file";
    } else if (s + 1 < chains.size() &&
               c[static_cast<std::size_t>(chains[s + 1].members.front())].time_s <
                   next_t + next_dt) {
      seq.end_reason = "next_drop";
    } else {
      seq.end_reason = "snr_limit";
    }
    out.push_back(std::move(seq));
  }
  return out;
}

}  // namespace bouncecal
