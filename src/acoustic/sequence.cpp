// Bounce-sequence tracking: one dynamic programme over the candidates finds every drop of a
// recording together. See include/bouncecal/acoustic/sequence.hpp.
#include "bouncecal/acoustic/sequence.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/stats.hpp"

namespace bouncecal {
namespace {

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();
// The learned scale of a ball's scatter (Tracker::Propose): the prior's weight in bounces at the
// nominal scatter_sigma, and the smallest scale (real balls scatter by sigma_e >= 0.005, a
// quarter of scatter_sigma; a synthetic ball's exact ratios still sharpen the prediction 4-fold).
constexpr double kPriorBounces = 2.0;
constexpr double kMinScale = 0.25;

// log of the Student t density with `dof` degrees of freedom and scale `scale` at x.
double LogStudentT(double x, double scale, double dof) {
  const double u = x / scale;
  return LogGamma(0.5 * (dof + 1.0)) - LogGamma(0.5 * dof) - 0.5 * std::log(dof * M_PI) -
         std::log(scale) - 0.5 * (dof + 1.0) * std::log1p(u * u / dof);
}

constexpr double kMaxLevelExponent = 2.1;  // level ~ v^a: a = 0.6-2.1 on the real recordings
constexpr double kG = 9.81;                // m/s^2 (the release-height rule needs no better)

// What the tracker reads of a candidate.
struct Cand {
  double t = 0.0;
  double value = 0.0;     // CandidateWeight - clutter_weight
  double weight = 0.0;    // CandidateWeight
  double level_db = 0.0;  // 20 log10 amplitude
  double sigma = 0.0;     // timing sigma (s), at least a microsecond
  double snr_db = 0.0;
  double log_rho = 0.0;  // log of the local candidate rate (1/s)
};

// A hypothesis: the sequence's members up to candidate k (the one before it: i).
struct State {
  int k = -1, i = -1;
  double score = 0.0;      // total, with the sequences before this one (prefix)
  double trend = kNaN;     // Kalman estimate of log e (NaN: two members, no ratio yet)
  double trend_var = 0.0;  // its variance
  double d = 0.0;          // last single flight (estimated after missed impacts)
  int back = -1;           // previous state of this sequence (-1: the sequence starts at i, k)
  int prefix = -1;         // first state: the state ending the previous sequence (-1: none)
  int len = 2;
  int regular_run = 0;     // regular steps in a row ending here
  int missed = 0;          // impacts missed in the step to k
  bool irregular = false;  // the step to k broke the pattern
  double sum_log_r = 0.0;  // log ratios of the regular steps (the first ratio included) ...
  int n_r = 0;             // ... and how many
  double sum_z2 = 0.0;     // squared innovations of the trend, in nominal spreads ...
  int n_z = 0;             // ... and how many (the learned scale of this ball's scatter)
};

// The strongest candidates (by weight) of an index range: a segment tree whose nodes keep their
// `top` strongest, merged on the way down.
class StrongestIn {
 public:
  StrongestIn(const std::vector<Cand>& c, int top) : c_(c), top_(top) {
    n_ = 1;
    while (n_ < static_cast<int>(c.size())) n_ *= 2;
    node_.assign(static_cast<std::size_t>(2 * n_), {});
    for (int j = 0; j < static_cast<int>(c.size()); ++j) node_[Idx(n_ + j)] = {j};
    for (int v = n_ - 1; v >= 1; --v)
      node_[Idx(v)] = Merge(node_[Idx(2 * v)], node_[Idx(2 * v + 1)]);
  }
  // Up to `limit` (at most the tree's `top`) indices in [lo, hi), strongest first (ties: earlier
  // first).
  std::vector<int> Query(int lo, int hi, int limit) const {
    std::vector<int> out;
    if (lo >= hi) return out;
    if (hi - lo <= top_) {
      for (int j = lo; j < hi; ++j) out.push_back(j);
      Sort(&out);
    } else {
      for (int a = lo + n_, b = hi + n_; a < b; a /= 2, b /= 2) {
        if (a & 1) out = Merge(out, node_[Idx(a++)]);
        if (b & 1) out = Merge(out, node_[Idx(--b)]);
      }
    }
    if (static_cast<int>(out.size()) > limit) out.resize(Idx(limit));
    return out;
  }

 private:
  static std::size_t Idx(int v) { return static_cast<std::size_t>(v); }
  bool Stronger(int a, int b) const {
    const double wa = c_[Idx(a)].weight, wb = c_[Idx(b)].weight;
    return wa > wb || (wa == wb && a < b);
  }
  void Sort(std::vector<int>* v) const {
    std::sort(v->begin(), v->end(), [this](int a, int b) { return Stronger(a, b); });
    if (static_cast<int>(v->size()) > top_) v->resize(Idx(top_));
  }
  std::vector<int> Merge(const std::vector<int>& a, const std::vector<int>& b) const {
    std::vector<int> m;
    std::size_t x = 0, y = 0;
    while (static_cast<int>(m.size()) < top_ && (x < a.size() || y < b.size())) {
      if (y >= b.size() || (x < a.size() && Stronger(a[x], b[y])))
        m.push_back(a[x++]);
      else
        m.push_back(b[y++]);
    }
    return m;
  }
  const std::vector<Cand>& c_;
  int top_;
  int n_ = 1;
  std::vector<std::vector<int>> node_;
};

// The best way the sequences before a new drop can end: ended states by the length of their
// last interval (log-spaced bins), each bin a list of (time of the last member, best total score
// so far, state) that only grows in score. A new drop with first interval d may follow the
// states of the bins wholly below d that ended by a given time.
class EndedSequences {
 public:
  explicit EndedSequences(const TrackOptions& o)
      : lo_(std::log(o.min_interval_s)), bins_(static_cast<std::size_t>(kBins)) {
    width_ = (std::log(o.max_interval_s) - lo_) / kBins;
  }
  void Add(double t, double last_interval, double score, int state) {
    std::vector<Entry>& b = bins_[Idx(Bin(last_interval))];
    if (!b.empty() && score <= b.back().score) return;
    b.push_back({t, score, state});
  }
  // The best (score, state) of an ended state whose last member is at or before t and whose
  // last interval is shorter than first_interval (its bin wholly below). {0, -1}: none better
  // than nothing.
  std::pair<double, int> Best(double t, double first_interval) const {
    std::pair<double, int> best{0.0, -1};
    const int top = Bin(first_interval);
    for (int b = 0; b < top; ++b) {
      const std::vector<Entry>& e = bins_[Idx(b)];
      auto it = std::upper_bound(e.begin(), e.end(), t,
                                 [](double x, const Entry& en) { return x < en.t; });
      if (it == e.begin()) continue;
      --it;
      if (it->score > best.first) best = {it->score, it->state};
    }
    return best;
  }
  std::pair<double, int> Overall() const { return Best(kInf, kInf); }

 private:
  static constexpr int kBins = 24;  // factor 1.33 per bin from 3 ms to 3 s
  struct Entry {
    double t, score;
    int state;
  };
  static std::size_t Idx(int b) { return static_cast<std::size_t>(b); }
  int Bin(double d) const {
    if (!(d < kInf)) return kBins;
    return std::clamp(static_cast<int>(std::floor((std::log(d) - lo_) / width_)), 0, kBins - 1);
  }
  double lo_, width_ = 1.0;
  std::vector<std::vector<Entry>> bins_;
};

// A proposed state for a later candidate, kept in that candidate's bounded list.
void Offer(std::vector<State>* list, const State& s, int keep) {
  // The same predecessor with a close trend is the same hypothesis: keep the better.
  for (State& q : *list)
    if (q.i == s.i && q.missed == s.missed &&
        (std::isnan(q.trend) ? std::isnan(s.trend)
                             : !std::isnan(s.trend) && std::fabs(q.trend - s.trend) < 0.01)) {
      if (s.score > q.score) q = s;
      return;
    }
  if (static_cast<int>(list->size()) < keep) {
    list->push_back(s);
    return;
  }
  auto worst = std::min_element(list->begin(), list->end(),
                                [](const State& a, const State& b) { return a.score < b.score; });
  if (s.score > worst->score) *worst = s;
}

class Tracker {
 public:
  Tracker(const std::vector<Impact>& impacts, double duration_s, const TrackOptions& o)
      : o_(o),
        duration_s_(duration_s),
        c_(Candidates(impacts, o)),
        strongest_(c_, std::max(o.window_candidates, o.start_candidates)),
        ended_(o),
        pending_(c_.size()),
        log_interval_range_(std::log(o.max_interval_s / o.min_interval_s)) {}

  // Runs the programme; returns the chosen sequences' last states, in time order.
  std::vector<int> Run() {
    for (int k = 0; k < static_cast<int>(c_.size()); ++k) {
      std::vector<State> here = std::move(pending_[Idx(k)]);
      StartAt(k, &here);
      Prune(&here);
      for (State& s : here) {
        const int id = static_cast<int>(states_.size());
        states_.push_back(s);
        // A sequence may end here when it is long enough and its intervals shrink on average as
        // a ball's do (TrackOptions::max_mean_ratio).
        if (s.len >= o_.min_sequence_impacts && s.n_r > 0 &&
            s.sum_log_r <= s.n_r * std::log(o_.max_mean_ratio))
          ended_.Add(c_[Idx(k)].t, s.d, s.score - EndPenalty(s), id);
        Propose(id);
      }
    }
    std::vector<int> last;
    for (int s = ended_.Overall().second; s >= 0;) {
      last.push_back(s);
      int first = s;
      while (states_[Idx(first)].back >= 0) first = states_[Idx(first)].back;
      s = states_[Idx(first)].prefix;
    }
    std::reverse(last.begin(), last.end());
    return last;
  }

  const State& state(int s) const { return states_[Idx(s)]; }

  // The beam at one candidate: the best `beam` new sequences (two members) and the best `beam`
  // longer ones, apart (a sequence's third member pays for its unknown ratio, so young chains
  // trail the new pairs at first and would be crowded out), at most kPerPredecessor of them
  // through the same previous member (else one loud clutter candidate's hypotheses fill it).
  void Prune(std::vector<State>* here) const {
    constexpr int kPerPredecessor = 2;
    std::sort(here->begin(), here->end(), [](const State& a, const State& b) {
      return a.score > b.score || (a.score == b.score && a.i < b.i);
    });
    std::vector<State> kept;
    int pairs = 0, longer = 0;
    for (const State& s : *here) {
      int& n = s.len == 2 ? pairs : longer;
      if (n >= o_.beam) continue;
      const auto same = std::count_if(kept.begin(), kept.end(), [&](const State& q) {
        return q.i == s.i && q.len > 2 && s.len > 2;
      });
      if (same >= kPerPredecessor) continue;
      kept.push_back(s);
      ++n;
    }
    *here = std::move(kept);
  }
  const std::vector<Cand>& candidates() const { return c_; }

 private:
  static std::size_t Idx(int v) { return static_cast<std::size_t>(v); }

  static std::vector<Cand> Candidates(const std::vector<Impact>& impacts, const TrackOptions& o) {
    std::vector<Cand> c(impacts.size());
    for (std::size_t j = 0; j < impacts.size(); ++j) {
      const Impact& im = impacts[j];
      c[j].t = im.time_s;
      c[j].weight = CandidateWeight(im);
      c[j].value = c[j].weight - o.clutter_weight;
      c[j].level_db = 20.0 * std::log10(std::max(im.amplitude, 1e-12));
      c[j].sigma = std::isfinite(im.sigma_s) ? std::max(im.sigma_s, 1e-6) : 1e-3;
      c[j].snr_db = std::isfinite(im.snr_db) ? im.snr_db : 0.0;
    }
    // The local clutter rate: candidates within +-half of density_window_s around t (itself
    // included).
    const double half = 0.5 * o.density_window_s;
    std::size_t a = 0, b = 0;
    for (std::size_t j = 0; j < c.size(); ++j) {
      while (c[a].t < c[j].t - half) ++a;
      while (b < c.size() && c[b].t <= c[j].t + half) ++b;
      c[j].log_rho = std::log(static_cast<double>(b - a) / o.density_window_s);
    }
    return c;
  }

  // Candidates with time in [t0, t1): index range.
  std::pair<int, int> Range(double t0, double t1) const {
    auto lo =
        std::lower_bound(c_.begin(), c_.end(), t0, [](const Cand& x, double t) { return x.t < t; });
    auto hi = std::lower_bound(lo, c_.end(), t1, [](const Cand& x, double t) { return x.t < t; });
    return {static_cast<int>(lo - c_.begin()), static_cast<int>(hi - c_.begin())};
  }

  // The level model (plausibility.hpp): a member is not louder than the one before by more than
  // max_level_rise_db, nor quieter by more than the speed ratio `r` over the step explains at the
  // steepest level exponent seen (v^2.1 on the real recordings) plus the same tolerance.
  bool LevelOk(int from, int to, double r = 1.0) const {
    const double step = c_[Idx(to)].level_db - c_[Idx(from)].level_db;
    return step <= o_.max_level_rise_db &&
           step >= kMaxLevelExponent * 20.0 * std::log10(r) - o_.max_level_rise_db;
  }

  // New sequences (i, k): the strongest predecessors in range, after the best way the earlier
  // sequences can end (a release before i, a shorter last interval).
  // The candidates of [lo, hi) a state looks at: all of them when there are at most
  // window_candidates (each is then judged by its whole score, timing included), else the
  // strongest window_candidates (a window crowded by clutter).
  std::vector<int> InWindow(int lo, int hi) const {
    if (hi - lo > o_.window_candidates) return strongest_.Query(lo, hi, o_.window_candidates);
    std::vector<int> all;
    for (int j = lo; j < hi; ++j) all.push_back(j);
    return all;
  }

  // The predecessors: the strongest two of each of start_candidates / 2 log-spaced bins of the
  // first flight, so that every scale of drop height is looked at.
  void StartAt(int k, std::vector<State>* here) const {
    const Cand& ck = c_[Idx(k)];
    const int bins = std::max(1, o_.start_candidates / 2);
    std::vector<int> from;
    for (int b = 0; b < bins; ++b) {
      const double d_lo = o_.min_interval_s * std::exp(log_interval_range_ * b / bins);
      const double d_hi = o_.min_interval_s * std::exp(log_interval_range_ * (b + 1) / bins);
      const auto [lo, hi] = Range(ck.t - d_hi, ck.t - d_lo + 1e-12);
      for (int i : strongest_.Query(lo, std::min(hi, k), 2)) from.push_back(i);
    }
    for (int i : from) {
      if (!LevelOk(i, k)) continue;
      const double d = ck.t - c_[Idx(i)].t;
      const auto [prefix_score, prefix] = ended_.Best(c_[Idx(i)].t - 0.5 * d, d);
      State s;
      s.k = k;
      s.i = i;
      s.d = d;
      s.prefix = prefix;
      // The first member where drops start (drop_rate_hz), the second anywhere in a log-uniform
      // first flight over [min_interval_s, max_interval_s] (drop heights of every decade).
      s.score = prefix_score + c_[Idx(i)].value + ck.value + std::log(o_.drop_rate_hz) -
                c_[Idx(i)].log_rho - std::log(d * log_interval_range_) - ck.log_rho;
      Offer(here, s, 2 * o_.beam);
    }
  }

  // -log P(a member goes unheard) for a gap between members of SNR snr_db (dB), between
  // missed_penalty and max_missed_penalty (TrackOptions).
  double UnheardPenalty(double snr_db) const {
    return std::clamp(-std::log(0.5 * std::erfc(snr_db / (o_.level_sigma_db * std::sqrt(2.0)))),
                      o_.missed_penalty, o_.max_missed_penalty);
  }

  // A sequence that ends at s although its next impact would come inside the recording and be
  // resolvable: that impact went unheard, at the SNR the level model predicts (its speed, and so
  // its level, falls by r: 20 log10 r dB, a = 1). Only the next one counts: a sequence may end
  // because the ball was caught (a dropper rig) or the recording of a drop was cut.
  double EndPenalty(const State& s) const {
    const double r = std::exp(s.trend);
    const double next = s.d * r;
    if (next < o_.min_interval_s || c_[Idx(s.k)].t + next > duration_s_) return 0.0;
    return UnheardPenalty(c_[Idx(s.k)].snr_db + 20.0 * std::log10(r));
  }

  // The spread of log r at a step arriving at j after flights d0 (before) and d1.
  double TimingSpread(const State& s, int j, double d1) const {
    const double si = c_[Idx(s.i)].sigma, sk = c_[Idx(s.k)].sigma, sj = c_[Idx(j)].sigma;
    const double d0 = s.d;
    // log r = log(t_j - t_k) - log(t_k - t_i): first order in the three times.
    const double a = sj / d1, b = sk * (1.0 / d1 + 1.0 / d0), c = si / d0;
    return std::sqrt(a * a + b * b + c * c);
  }

  void Push(int j, const State& s) { Offer(&pending_[Idx(j)], s, 2 * o_.beam); }

  // Every continuation of state `id` to later candidates.
  void Propose(int id) {
    const State p = states_[Idx(id)];
    const Cand& ck = c_[Idx(p.k)];
    const double max_irr = std::log(o_.max_irregular_ratio);
    if (std::isnan(p.trend)) {
      // The first ratio: any r in [min_ratio, 1] (+ timing noise).
      const double slack = 3.0 * std::hypot(ck.sigma, c_[Idx(p.i)].sigma) / p.d;
      const double dlog = std::log(o_.max_ratio / o_.min_ratio);
      const auto [lo, hi] = Range(ck.t + p.d * o_.min_ratio, ck.t + p.d * (o_.max_ratio + slack));
      // Where the sequence starts, the ball was released from rest at a height g d0^2 / (8 e^2)
      // (e ~ this first ratio); unless the ball may have been bouncing before the signal began
      // (its previous flight, d0 / e, reaches back before t = 0), that is at least
      // min_drop_height_m.
      const bool first_pair = p.back < 0;
      const double t0 = c_[Idx(p.i)].t;
      for (int j : InWindow(lo, hi)) {
        const double d1 = c_[Idx(j)].t - ck.t;
        const double r = d1 / p.d;
        if (d1 < o_.min_interval_s || !LevelOk(p.k, j, r) || !LevelOk(p.i, p.k, r)) continue;
        if (first_pair && t0 > p.d / r && kG * p.d * p.d / (8.0 * r * r) < o_.min_drop_height_m)
          continue;
        State s = Next(p, id, j, d1);
        const double timing = TimingSpread(p, j, d1);
        s.trend = std::log(r);
        s.trend_var = o_.scatter_sigma * o_.scatter_sigma + timing * timing;
        s.sum_log_r = s.trend;
        s.n_r = 1;
        s.regular_run = 1;
        s.score += c_[Idx(j)].value - std::log(d1 * dlog) - c_[Idx(j)].log_rho;
        Push(j, s);
      }
      return;
    }
    const double r_hat = std::exp(p.trend);
    // The trend of log e is a random walk (drift_sigma per bounce) seen through each bounce's
    // scatter (scatter_sigma) and the timing noise: a Kalman filter (local level model). How
    // much a ball scatters is its own: the nominal variances are scaled by lambda^2, learned from
    // the chain's innovations with a conjugate prior of kPriorBounces bounces at lambda = 1
    // (lambda^2 = (nu0 + sum z^2) / (nu0 + n), at least kMinScale^2), and the prediction is a
    // Student t with nu0 + n degrees of freedom: a synthetic ball's exact ratios sharpen the
    // prediction bounce after bounce, a real ball's scatter keeps it wide.
    const double drift2 = o_.drift_sigma * o_.drift_sigma;
    const double scatter2 = o_.scatter_sigma * o_.scatter_sigma;
    const double prior_var = p.trend_var + drift2;
    const double lambda2 =
        std::max(kMinScale * kMinScale, (kPriorBounces + p.sum_z2) / (kPriorBounces + p.n_z));
    const double dof = kPriorBounces + p.n_z;
    // Regular step (and irregular ones in a wider window).
    {
      const double d_hat = p.d * r_hat;
      const double timing_hat = std::sqrt(2.0) * ck.sigma * (1.0 / d_hat + 1.0 / p.d);
      const double reach =
          o_.max_z * std::sqrt(lambda2 * (prior_var + scatter2) + timing_hat * timing_hat);
      const double wide = p.regular_run >= 3 && !p.irregular && p.missed == 0
                              ? std::max(o_.max_irregular_log_jump, reach)
                              : reach;
      const double hi_t = ck.t + std::min(d_hat * std::exp(wide), p.d * o_.max_irregular_ratio);
      const auto [lo, hi] = Range(ck.t + d_hat * std::exp(-wide), hi_t + 1e-12);
      for (int j : InWindow(lo, hi)) {
        const double d1 = c_[Idx(j)].t - ck.t;
        const double r = d1 / p.d, lr = std::log(r);
        if (d1 < o_.min_interval_s || !LevelOk(p.k, j, std::min(r, 1.0))) continue;
        const double timing = TimingSpread(p, j, d1);
        const double innov = lr - p.trend;
        const double spread = std::sqrt(lambda2 * (prior_var + scatter2) + timing * timing);
        State s = Next(p, id, j, d1);
        if (std::fabs(innov) <= o_.max_z * spread && r <= o_.max_ratio + 3.0 * timing) {
          const double gain = lambda2 * prior_var / (spread * spread);
          s.trend = p.trend + gain * innov;
          s.trend_var = (1.0 - gain) * prior_var;
          s.sum_log_r = p.sum_log_r + lr;
          s.n_r = p.n_r + 1;
          s.sum_z2 = p.sum_z2 + innov * innov / (prior_var + scatter2 + timing * timing);
          s.n_z = p.n_z + 1;
          s.regular_run = p.regular_run + 1;
          s.score += c_[Idx(j)].value + LogStudentT(innov, spread, dof) - std::log(d1) -
                     c_[Idx(j)].log_rho;
          Push(j, s);
        } else if (p.regular_run >= 3 && !p.irregular && p.missed == 0 &&
                   std::fabs(lr - p.trend) <= o_.max_irregular_log_jump && lr <= max_irr) {
          s.trend = p.trend;  // the trend before the irregular step judges the next one
          s.trend_var = prior_var;
          s.irregular = true;
          s.score += c_[Idx(j)].value - std::log(d1 * 2.0 * o_.max_irregular_log_jump) -
                     c_[Idx(j)].log_rho - o_.irregular_penalty;
          Push(j, s);
        }
      }
    }
    // One to max_missed impacts unheard: the gap is d (r + ... + r^(m+1)).
    double sum = r_hat, power = r_hat;
    for (int m = 1; m <= o_.max_missed; ++m) {
      power *= r_hat;
      sum += power;
      if (p.d * power < o_.min_interval_s) break;  // the last missing flight resolvable
      const double gap_hat = p.d * sum;
      const double spread = std::sqrt(lambda2 * (p.trend_var + (m + 1) * drift2 + scatter2));
      const auto [lo, hi] = Range(ck.t + gap_hat * std::exp(-o_.max_z * spread),
                                  ck.t + gap_hat * std::exp(o_.max_z * spread));
      for (int j : InWindow(lo, hi)) {
        const double gap = c_[Idx(j)].t - ck.t;
        if (!LevelOk(p.k, j, power)) continue;
        const double innov = std::log(gap / gap_hat);
        // An impact between two heard ones was at least as loud as the quieter of them (levels
        // fall along a sequence) give or take the level scatter: it goes unheard with
        // probability Phi(-snr / level_sigma_db) (0 dB: the onset detector's floor).
        const double unheard = UnheardPenalty(std::min(ck.snr_db, c_[Idx(j)].snr_db));
        State s = Next(p, id, j, gap * power / sum);
        s.trend = p.trend;
        s.trend_var = p.trend_var + (m + 1) * drift2;
        s.missed = m;
        s.regular_run = 0;
        s.score += c_[Idx(j)].value + LogStudentT(innov, spread, dof) - std::log(gap) -
                   c_[Idx(j)].log_rho - m * unheard;
        Push(j, s);
      }
    }
  }

  State Next(const State& p, int id, int j, double d1) const {
    State s;
    s.sum_log_r = p.sum_log_r;
    s.n_r = p.n_r;
    s.sum_z2 = p.sum_z2;
    s.n_z = p.n_z;
    s.k = j;
    s.i = p.k;
    s.score = p.score;
    s.d = d1;
    s.back = id;
    s.prefix = -1;
    s.len = p.len + 1;
    return s;
  }

  const TrackOptions& o_;
  double duration_s_;
  std::vector<Cand> c_;
  StrongestIn strongest_;
  EndedSequences ended_;
  std::vector<std::vector<State>> pending_;
  std::vector<State> states_;
  double log_interval_range_;
};

std::string EndReason(const Sequence& q, double last_d, double trend, double duration_s,
                      double next_start_s, const TrackOptions& o) {
  const double next_dt = last_d * std::exp(trend);
  const double next_t = q.impacts.back().time_s + next_dt;
  if (next_dt < 1.5 * o.min_interval_s) return "resolved_limit";
  if (next_t > duration_s) return "end_of_file";
  if (next_start_s < next_t + next_dt) return "next_drop";
  return "snr_limit";
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
  if (!(scatter_sigma > 0.0)) return fail("TrackOptions::scatter_sigma must be > 0");
  if (!(drift_sigma >= 0.0)) return fail("TrackOptions::drift_sigma must be >= 0");
  if (!(max_z > 0.0)) return fail("TrackOptions::max_z must be > 0");
  if (!(max_irregular_ratio >= max_ratio))
    return fail("TrackOptions::max_irregular_ratio must be >= max_ratio");
  if (!(max_irregular_log_jump >= 0.0))
    return fail("TrackOptions::max_irregular_log_jump must be >= 0");
  if (!(irregular_penalty >= 0.0)) return fail("TrackOptions::irregular_penalty must be >= 0");
  if (!(max_level_rise_db > 0.0)) return fail("TrackOptions::max_level_rise_db must be > 0");
  if (max_missed < 0 || max_missed > 16) return fail("TrackOptions::max_missed must be 0..16");
  if (!(missed_penalty >= 0.0)) return fail("TrackOptions::missed_penalty must be >= 0");
  if (!(level_sigma_db > 0.0)) return fail("TrackOptions::level_sigma_db must be > 0");
  if (!std::isfinite(clutter_weight)) return fail("TrackOptions::clutter_weight must be finite");
  if (!(drop_rate_hz > 0.0) || !std::isfinite(drop_rate_hz))
    return fail("TrackOptions::drop_rate_hz must be a finite number > 0");
  if (!(density_window_s > 0.0)) return fail("TrackOptions::density_window_s must be > 0");
  if (!(min_drop_height_m >= 0.0)) return fail("TrackOptions::min_drop_height_m must be >= 0");
  if (!(max_mean_ratio > 0.0 && max_mean_ratio <= 1.05))
    return fail("TrackOptions::max_mean_ratio must be in (0, 1.05]");
  if (min_sequence_impacts < 3)
    return fail("TrackOptions::min_sequence_impacts = " + std::to_string(min_sequence_impacts) +
                ": must be >= 3 (a ratio needs three impacts)");
  if (beam < 1 || window_candidates < 1 || start_candidates < 1)
    return fail("TrackOptions: beam, window_candidates and start_candidates must be >= 1");
  return true;
}

// The raw rise's share (Impact::rise_db): 30 dB, an impact out of room noise, weighs as much as a
// perfect template match; the impacts of the five shared recordings rise 9-35 dB (5th-95th
// percentile), their clutter -7 to +14 dB, the tail of a ringing dish's impacts -1 to +5 dB.
double CandidateWeight(const Impact& c) {
  return 0.5 + std::clamp(c.snr_db / 20.0, 0.0, 2.0) + 0.5 * std::clamp(c.score, 0.0, 1.0) +
         std::clamp(c.rise_db / 40.0, 0.0, 0.75);
}

std::vector<Sequence> TrackSequences(const std::vector<Impact>& c, double duration_s,
                                     const TrackOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  Tracker tracker(c, duration_s, o);
  const std::vector<int> last = tracker.Run();
  std::vector<Sequence> out;
  std::vector<std::pair<double, double>> tail;  // last flight and trend of each
  for (int s : last) {
    std::vector<int> chain;
    for (int q = s; q >= 0; q = tracker.state(q).back) chain.push_back(q);
    std::reverse(chain.begin(), chain.end());
    Sequence seq;
    seq.impacts.push_back(c[static_cast<std::size_t>(tracker.state(chain.front()).i)]);
    for (int q : chain) {
      const State& st = tracker.state(q);
      const int before = static_cast<int>(seq.impacts.size()) - 1;
      if (st.missed > 0) seq.missed_after.push_back(before);
      if (st.irregular) seq.irregular_after.push_back(before);
      seq.impacts.push_back(c[static_cast<std::size_t>(st.k)]);
    }
    const State& end = tracker.state(s);
    tail.push_back({end.d, end.trend});
    out.push_back(std::move(seq));
  }
  for (std::size_t q = 0; q < out.size(); ++q) {
    const double next_start = q + 1 < out.size() ? out[q + 1].impacts.front().time_s : kInf;
    out[q].end_reason = EndReason(out[q], tail[q].first, tail[q].second, duration_s, next_start, o);
  }
  return out;
}

}  // namespace bouncecal
