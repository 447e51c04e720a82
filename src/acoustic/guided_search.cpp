// The guided search. See guided_search.hpp.
#include "guided_search.hpp"

#include <algorithm>
#include <cmath>

#include <boost/math/distributions/chi_squared.hpp>

#include "bouncecal/core/error.hpp"

namespace bouncecal {

bool GuidedOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(reach > 0.0)) return fail("GuidedOptions::reach must be > 0");
  if (!(min_ratio_spread > 0.0)) return fail("GuidedOptions::min_ratio_spread must be > 0");
  if (!(edge_penalty >= 0.0)) return fail("GuidedOptions::edge_penalty must be >= 0");
  if (!(member_p > 0.0 && member_p < 1.0)) return fail("GuidedOptions::member_p must be in (0, 1)");
  if (!(false_alarm > 0.0 && false_alarm < 1.0))
    return fail("GuidedOptions::false_alarm must be in (0, 1)");
  if (trend_flights < 3) return fail("GuidedOptions::trend_flights must be >= 3");
  if (!(ratio_slack_sigmas >= 0.0)) return fail("GuidedOptions::ratio_slack_sigmas must be >= 0");
  return true;
}

namespace {

// One look where a sequence predicts an impact: the best template match in a window
// GuidedOptions::reach spreads wide around the prediction (FindByTemplate, ranked by NCC - edge
// penalty towards the window's edges) and its p-value, the chance that noise alone ranks as well
// somewhere in the window: the NCC where the template meets no impact spreads by s, its robust
// spread measured in the middle of the flight before (1 / sqrt(L) for a template of L samples,
// whitened white noise, only where that stretch is too short to measure). Not floored at
// 1 / sqrt(L): where the whitened signal is not white (a ringing plate's residual, which the
// template does not share) the spread is smaller, and the floor made p far too large. Measured
// on looks half a flight past each tail prediction (no impact there), 47 files that are not the
// scoreboard's (six synth presets, four real sounds, the five recordings): floored, 0.4 % of them
// had p <= 0.05 and 0.3 % p <= 0.01; measured, 6.6 % and 1.8 % (nominal 5 % and 1 %).
struct Look {
  Impact match;
  bool any = false;
  double p = 1.0;
};
Look LookAt(const OnsetResult& onsets, const MatchTemplate& tpl, const std::vector<float>& x,
            const GuidedOptions& go, double t_c, double dn, double ratio_spread) {
  Look look;
  // At least two samples either side (the interpolated peak needs its neighbours).
  const double half = std::max(go.reach * ratio_spread * dn, 2.0 / onsets.rate_hz);
  look.any = FindByTemplate(onsets, tpl, x, t_c, half, -1.0, &look.match, go.edge_penalty);
  if (!look.any) return look;
  // The noise's NCC measured in the middle of the flight before (what rings there, away from
  // both impacts).
  const double spread = NccNoiseSpread(onsets, tpl, t_c - 2.0 * dn / 3.0, t_c - dn / 3.0, 256);
  const double s = spread > 0.0 ? spread : 1.0 / std::sqrt(static_cast<double>(tpl.wave.size()));
  // The match was ranked by NCC - edge_penalty u^2 (u: distance from the centre in half
  // windows); noise alone ranks as well at position u with probability Q((rank + pen u^2) / s).
  const double u_match = (look.match.time_s - t_c) / half;
  const double rank = look.match.score - go.edge_penalty * u_match * u_match;
  const long positions = std::max(1L, std::lround(half * onsets.rate_hz));
  double p = 0.0;
  for (long l = -positions; l <= positions; ++l) {
    const double u = static_cast<double>(l) / static_cast<double>(positions);
    p += 0.5 * std::erfc((rank + go.edge_penalty * u * u) / s / std::sqrt(2.0));
  }
  look.p = std::min(1.0, p);
  return look;
}

// The trend of log r at the end of impacts [0, end): a straight line in the flight's index fitted
// to the last GuidedOptions::trend_flights regular ratios (flights across a flagged gap or next to
// an irregular step left out; e drifts steadily with the impact speed, and with drag), and the
// spread of the ratios about it: 1.4826 MAD of the residuals, with the last flight's timing noise,
// at least GuidedOptions::min_ratio_spread. With fewer than 3 regular ratios: their median and the
// floor.
struct RatioTrend {
  double log_r = 0.0;   // predicted log ratio of the next flight
  double slope = 0.0;   // change of log r per flight
  double spread = 0.0;  // of log r about the line
};
RatioTrend TrendAt(const Sequence& seq, std::size_t end, const GuidedOptions& go) {
  const std::vector<Impact>& q = seq.impacts;
  auto flagged = [&](std::size_t j) {  // interval j -> j + 1
    const int k = static_cast<int>(j);
    return std::find(seq.missed_after.begin(), seq.missed_after.end(), k) !=
               seq.missed_after.end() ||
           std::find(seq.irregular_after.begin(), seq.irregular_after.end(), k) !=
               seq.irregular_after.end();
  };
  std::vector<double> x, y;  // flight index of the later flight, log r
  for (std::size_t k = end - 1; k >= 2 && y.size() < go.trend_flights; --k) {
    if (flagged(k - 1) || flagged(k - 2)) continue;
    x.push_back(static_cast<double>(k));
    y.push_back(std::log((q[k].time_s - q[k - 1].time_s) / (q[k - 1].time_s - q[k - 2].time_s)));
  }
  RatioTrend t;
  t.spread = go.min_ratio_spread;
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
void FillGaps(const OnsetResult& onsets, const MatchTemplate& tpl, const std::vector<float>& x,
              const TrackOptions& to, const GuidedOptions& go, Sequence* q) {
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
    const RatioTrend trend = TrendAt(*q, k + 1, go);
    const double r0 = std::clamp(std::exp(trend.log_r), to.min_ratio, to.max_ratio);
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
      const Look look = LookAt(onsets, tpl, x, go, t, dn, trend.spread);
      if (look.any && look.p <= go.member_p) found.push_back(look.match);
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
// go.false_alarm joins the sequence: its matches with p <= go.member_p as members, up to the
// first look that found none (an unheard impact ends the tail). It stops where no run is
// significant: the noise won or the ball stopped. Returns whether the sequence grew.
bool ExtendTail(const OnsetResult& onsets, const MatchTemplate& tpl, const std::vector<float>& x,
                double limit_s, const TrackOptions& to, const GuidedOptions& go, Sequence* q) {
  bool extended = false;
  while (q->impacts.size() >= 3) {
    const RatioTrend trend = TrendAt(*q, q->impacts.size(), go);
    double t = q->impacts.back().time_s;
    double d = t - q->impacts[q->impacts.size() - 2].time_s;
    const double spread = trend.spread;
    std::vector<Look> looks;
    for (int j = 0; j <= to.max_missed; ++j) {
      const double r =
          std::clamp(std::exp(trend.log_r + trend.slope * j), to.min_ratio, to.max_ratio);
      const double dn = d * r;
      if (dn < to.min_interval_s || t + dn > limit_s) break;
      looks.push_back(LookAt(onsets, tpl, x, go, t + dn, dn,
                             spread * std::sqrt(1.0 + static_cast<double>(looks.size()))));
      const Look& l = looks.back();
      const double next = l.any && l.p <= go.member_p ? l.match.time_s : t + dn;
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
      if (p < best_p && looks[n - 1].any && looks[n - 1].p <= go.member_p) best_p = p, best_n = n;
    }
    if (best_n == 0 || best_p > go.false_alarm) break;
    // Members up to the first unheard impact only: past a gap the flight the looks were made
    // from spans two bounces, and the next prediction locks onto every other impact (a 10 mm
    // steel ball's tail: four double flights taken for bounces, e ~ e^2).
    bool grew = false;
    for (std::size_t n = 0; n < best_n; ++n) {
      if (!looks[n].any || looks[n].p > go.member_p) break;
      // Right after a member, the flight must not be longer than the one before beyond the
      // timing noise (e <= 1, TrackOptions::max_ratio): a match past it is not the next bounce.
      const Impact& f = looks[n].match;
      const std::size_t m = q->impacts.size();
      const double before = q->impacts[m - 1].time_s - q->impacts[m - 2].time_s;
      if ((f.time_s - q->impacts[m - 1].time_s) / before >
          to.max_ratio +
              go.ratio_slack_sigmas * std::hypot(f.sigma_s, q->impacts[m - 1].sigma_s) / before)
        break;
      q->impacts.push_back(f);
      grew = true;
    }
    if (!grew) break;
    extended = true;
  }
  return extended;
}

// The template cut at the sequence's strongest member (highest SNR), or the recording's own when
// that would leave the signal.
MatchTemplate SequenceTemplate(const OnsetResult& onsets, const Sequence& q) {
  const auto strongest =
      std::max_element(q.impacts.begin(), q.impacts.end(),
                       [](const Impact& a, const Impact& b) { return a.snr_db < b.snr_db; });
  MatchTemplate t = TemplateAt(onsets, strongest->time_s);
  return t.wave.empty() ? TemplateOf(onsets) : t;
}

}  // namespace

void ExtendByTemplate(const OnsetResult& onsets, const std::vector<float>& x, double duration_s,
                      const TrackOptions& to, const GuidedOptions& go,
                      std::vector<Sequence>* sequences) {
  std::string why;
  if (!go.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  if (onsets.template_wave.empty()) return;
  for (std::size_t s = 0; s < sequences->size(); ++s) {
    Sequence& q = (*sequences)[s];
    // The sequence's own sound: the whitened waveform of its strongest member (as the onset
    // detector's template is the recording's strongest onset). The impacts of one drop share an
    // impact point and a ball; another drop's may differ (real impacts of one tennis ball or
    // basketball: NCC 0.31-0.55 between two drops' templates, docs/physics.md §8.1).
    const MatchTemplate tpl = SequenceTemplate(onsets, q);
    FillGaps(onsets, tpl, x, to, go, &q);
    const double limit = s + 1 < sequences->size()
                             ? (*sequences)[s + 1].impacts.front().time_s - to.min_interval_s
                             : duration_s - 0.002;
    if (!ExtendTail(onsets, tpl, x, limit, to, go, &q)) continue;
    const double d = q.impacts.back().time_s - q.impacts[q.impacts.size() - 2].time_s;
    const double next_dt = d * std::exp(TrendAt(q, q.impacts.size(), go).log_r);
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

}  // namespace bouncecal
