// The guided search. See guided_search.hpp.
#include "guided_search.hpp"

#include <algorithm>
#include <cmath>
#include <utility>

#include <boost/math/distributions/chi_squared.hpp>

#include "bouncecal/acoustic/timing.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/fractional_delay.hpp"

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
  if (lpc_order < 0 || lpc_order > 256) return fail("GuidedOptions::lpc_order must be 0..256");
  if (!(noise_frames > 0.0 && noise_frames <= 1.0))
    return fail("GuidedOptions::noise_frames must be in (0, 1]");
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
// The noise's NCC spread for a look at t_c after a flight dn: measured in the middle of the flight
// before (what rings there, away from both impacts).
double LookNoise(const OnsetResult& onsets, const MatchTemplate& tpl, double t_c, double dn) {
  const double spread = NccNoiseSpread(onsets, tpl, t_c - 2.0 * dn / 3.0, t_c - dn / 3.0, 256);
  const double s = spread > 0.0 ? spread : 1.0 / std::sqrt(static_cast<double>(tpl.wave.size()));
  return s;
}

Look LookAt(const OnsetResult& onsets, const MatchTemplate& tpl, const std::vector<float>& x,
            const GuidedOptions& go, double t_c, double dn, double ratio_spread) {
  Look look;
  // At least two samples either side (the interpolated peak needs its neighbours).
  const double half = std::max(go.reach * ratio_spread * dn, 2.0 / onsets.rate_hz);
  look.any = FindByTemplate(onsets, tpl, x, t_c, half, -1.0, &look.match, go.edge_penalty);
  if (!look.any) return look;
  const double s = LookNoise(onsets, tpl, t_c, dn);
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

// The tail's second signal: x whitened by a predictor fitted to its room noise (the quietest
// GuidedOptions::noise_frames share of its 20-ms frames, each frame's autocorrelation normalised)
// instead of to the whole recording, whose autocorrelation the loud impacts dominate. That
// whitening flattens the impacts' own spectrum, so where a soft ball's thud stands above the
// noise (below a few kHz) it loses its lead: on a realsound tennis drop (one real sound at every
// impact) the template's NCC at impacts 31-35 dB above the room falls to 0.22-0.34, and with the
// noise whitened it is 0.85-0.95 (numpy, the true times) -- the matched filter's rule: whiten the
// noise, not the signal. What it leaves is the earlier impacts' ringing (next: cancellation).
OnsetResult NoiseWhitened(const OnsetResult& onsets, const std::vector<float>& x,
                          const GuidedOptions& go) {
  OnsetResult r;
  r.rate_hz = onsets.rate_hz;
  r.sigma_floor_s = onsets.sigma_floor_s;
  // The recording's template (TemplateAt takes its length and lead from it), cut from this signal.
  r.template_start = onsets.template_start;
  r.template_onset_s = onsets.template_onset_s;
  const long n = static_cast<long>(x.size());
  const long frame = std::max(1L, std::lround(0.02 * onsets.rate_hz));
  std::vector<std::pair<double, long>> energy;
  for (long b = 0; b + frame <= n; b += frame) {
    double e = 0.0;
    for (long i = b; i < b + frame; ++i)
      e += static_cast<double>(x[static_cast<std::size_t>(i)]) * x[static_cast<std::size_t>(i)];
    energy.push_back({e, b});
  }
  std::sort(energy.begin(), energy.end());
  const std::size_t quiet = std::min(
      energy.size(),
      std::max<std::size_t>(
          1, static_cast<std::size_t>(go.noise_frames * static_cast<double>(energy.size()))));
  // At most kNoiseFrames of them, evenly spread over that share's ranks: 2.6 s of noise fix its
  // autocorrelation at 48 lags to ~0.3 % (1 / sqrt(samples)); more only cost time.
  constexpr std::size_t kNoiseFrames = 128;
  const std::size_t rank_step = std::max<std::size_t>(1, quiet / kNoiseFrames);
  std::vector<long> starts;
  for (std::size_t i = 0; i < quiet; i += rank_step) starts.push_back(energy[i].second);
  std::sort(starts.begin(), starts.end());
  r.whitened = PredictionError(x, NeighbourhoodPredictor(x, starts, go.lpc_order, 0, frame));
  const long tl = static_cast<long>(onsets.template_wave.size());
  if (r.template_start >= 0 && r.template_start + tl <= n)
    r.template_wave.assign(r.whitened.begin() + r.template_start,
                           r.whitened.begin() + r.template_start + tl);
  r.noise_rms = RobustRms(r.whitened);
  return r;
}

// Cancellation. In the noise-whitened signal an impact's ringing (the plate's, the ball's, the
// room's) stays, and a tail impact 3-30 ms after the one before sits inside it. The impacts of one
// drop share one ball, one impact point and one plate, so each member's sound is, to first order,
// the sequence's own impact response scaled: the noise-whitened signal from the template member's
// template start to the next member's, as long as its 10-ms blocks stay measurably above the noise
// (block energy above noise_rms^2 by two standard errors of a block's mean square, sqrt(2 / B) for
// B samples of Gaussian noise). Each member's response, aligned on its template match (within the
// timing stage's lag search, TimingOptions::search_s: detection times sit that far from the
// template's convention) and sub-sample (the correlation peak's parabola, then a Kaiser-windowed
// sinc shift), scaled by its least-squares amplitude a over the template window, is subtracted
// before the looks past it. A member whose sound differs from the template is subtracted only as
// far as it projects on it (a = ncc |y| / |h|). On the same tennis drop the next impact's NCC
// after cancellation is 0.99-1.00 down to 17-ms flights (the detector's own looks).
constexpr long kCancelHalf = 16;  // the cancellation's windowed-sinc half width (samples)
struct ImpactResponse {
  std::vector<double> s;       // starts at the template's start (onset - lead)
  std::vector<double> padded;  // s with 2 kCancelHalf zeros on each side
  double hh = 0.0;             // energy of its first template-length samples (the template window)
};

ImpactResponse ResponseOf(const OnsetResult& noise, const MatchTemplate& tpl, const Sequence& q,
                          double min_interval_s) {
  ImpactResponse r;
  const long n = static_cast<long>(noise.whitened.size());
  const long tl = static_cast<long>(tpl.wave.size());
  long end = n;
  for (const Impact& im : q.impacts)
    if (im.time_s > tpl.onset_s + min_interval_s) {
      end = std::min(end, tpl.start + std::lround((im.time_s - tpl.onset_s) * noise.rate_hz));
      break;
    }
  if (tpl.start < 0 || end <= tpl.start + tl) return r;
  const long block = std::max(1L, std::lround(0.01 * noise.rate_hz));
  const double measurable = (1.0 + 2.0 * std::sqrt(2.0 / static_cast<double>(block))) *
                            noise.noise_rms * noise.noise_rms * static_cast<double>(block);
  long cut = tpl.start + tl;
  for (long b = tpl.start; b + block <= end; b += block) {
    double e = 0.0;
    for (long i = b; i < b + block; ++i)
      e += static_cast<double>(noise.whitened[static_cast<std::size_t>(i)]) *
           noise.whitened[static_cast<std::size_t>(i)];
    if (e <= measurable) break;
    cut = std::max(cut, b + block);
  }
  r.s.assign(noise.whitened.begin() + tpl.start, noise.whitened.begin() + std::min(end, cut));
  for (long j = 0; j < tl; ++j)
    r.hh += r.s[static_cast<std::size_t>(j)] * r.s[static_cast<std::size_t>(j)];
  r.padded.assign(r.s.size() + 4 * kCancelHalf, 0.0);
  std::copy(r.s.begin(), r.s.end(), r.padded.begin() + 2 * kCancelHalf);
  return r;
}

// Subtracts the response (ImpactResponse) of the member at time_s from w.
void CancelMember(const ImpactResponse& r, const MatchTemplate& tpl, double rate_hz, double time_s,
                  std::vector<float>* w) {
  constexpr long kHalf = kCancelHalf;
  const long n = static_cast<long>(w->size());
  const long tl = static_cast<long>(tpl.wave.size());
  if (r.s.empty() || !(r.hh > 0.0)) return;
  const long m0 = tpl.start + std::lround((time_s - tpl.onset_s) * rate_hz);
  const long search = std::max(2L, std::lround(TimingOptions{}.search_s * rate_hz));
  if (m0 - search - 1 - kHalf < 0 || m0 + search + 1 + tl >= n) return;
  auto xc = [&](long l) {
    double acc = 0.0;
    for (long j = 0; j < tl; ++j)
      acc += r.s[static_cast<std::size_t>(j)] * (*w)[static_cast<std::size_t>(l + j)];
    return acc;
  };
  long best = m0;
  double cb = xc(m0);
  for (long l = m0 - search; l <= m0 + search; ++l) {
    const double c = xc(l);
    if (c > cb) cb = c, best = l;
  }
  const double cm = xc(best - 1), cp = xc(best + 1);
  const double curv = cm - 2.0 * cb + cp;
  const double d = curv < 0.0 ? std::clamp(0.5 * (cm - cp) / curv, -0.5, 0.5) : 0.0;
  const double a = (cb - 0.25 * (cm - cp) * d) / r.hh;
  if (!(a > 0.0)) return;
  const long len = std::min(static_cast<long>(r.s.size()), n - kHalf - best);
  // realsound's placement kernel (fractional_delay.hpp), its window spanning kHalf + 1.
  std::vector<double> taps(static_cast<std::size_t>(2 * kHalf + 1));
  for (long k = -kHalf; k <= kHalf; ++k)
    taps[static_cast<std::size_t>(k + kHalf)] =
        fractional_delay::Kernel(static_cast<double>(k) - d, static_cast<int>(kHalf + 1));
  // Sample best + i holds the response at i - d: y[i + kHalf] = sum over k of taps[k + kHalf]
  // s[i - k], s zero outside (one pass per tap over all samples: no reduction in the inner loop).
  const std::size_t out = static_cast<std::size_t>(len + 2 * kHalf);
  std::vector<double> y(out, 0.0);
  for (long k = -kHalf; k <= kHalf; ++k) {
    const double tk = taps[static_cast<std::size_t>(k + kHalf)];
    const double* sp = r.padded.data() + (kHalf - k);  // s[i - k] at sp[i + kHalf]
    for (std::size_t j = 0; j < out; ++j) y[j] += tk * sp[j];
  }
  for (std::size_t j = 0; j < out; ++j)
    (*w)[static_cast<std::size_t>(best - kHalf) + j] -= static_cast<float>(a * y[j]);
}

// How far member k of q stands out in a signal: its template match (within the timing stage's lag
// search of its time) over the NCC's noise spread in the middle of the flight before it (LookAt's).
double StandOut(const OnsetResult& onsets, const MatchTemplate& tpl, const std::vector<float>& x,
                const Sequence& q, std::size_t k) {
  if (k == 0) return 0.0;
  const double t = q.impacts[k].time_s, dn = t - q.impacts[k - 1].time_s;
  Impact m;
  if (!FindByTemplate(onsets, tpl, x, t, TimingOptions{}.search_s, -1.0, &m)) return 0.0;
  return m.score / LookNoise(onsets, tpl, t, dn);
}

// The tail: up to max_missed + 1 looks ahead at the trend's predictions (each from the match of
// the look before when it is better than noise's), as long as the interval stays resolvable and
// inside [.., limit_s). The longest run of looks that noise alone explains with probability below
// go.false_alarm joins the sequence: its matches with p <= go.member_p as members, up to the
// first look that found none (an unheard impact ends the tail). It stops where no run is
// significant: the noise won or the ball stopped. Each round of looks searches the recording's
// whitened signal or the noise-whitened one with the members cancelled (NoiseWhitened,
// CancelMember), whichever the tail's last members stand out in more. Returns whether the
// sequence grew.
bool ExtendTail(const OnsetResult& whitened, const MatchTemplate& tpl_w, OnsetResult* noise,
                const MatchTemplate& tpl_n, const ImpactResponse& response,
                const std::vector<float>& x, double limit_s, const TrackOptions& to,
                const GuidedOptions& go, Sequence* q) {
  bool extended = false;
  if (q->impacts.size() < 3) return false;
  auto cancel = [&](const Impact& im) {
    CancelMember(response, tpl_n, noise->rate_hz, im.time_s, &noise->whitened);
  };
  // Every member but the last whose response reaches past the last one, in time order (each
  // one's alignment and amplitude are measured with the ones before it taken out); the last is
  // cancelled once it has been weighed, below.
  const double reach_s = static_cast<double>(response.s.size()) / noise->rate_hz;
  for (std::size_t k = 0; go.noise_signal && k + 1 < q->impacts.size(); ++k)
    if (q->impacts[k].time_s > q->impacts.back().time_s - reach_s) cancel(q->impacts[k]);
  std::vector<double> z_noise, z_white;
  while (q->impacts.size() >= 3) {
    // Which signal the next looks search: the one the tail's last members (up to trend_flights
    // of them, weighed as each became the last) stand out in more, summed. Decided from members,
    // never from the looks, so their p-values need no correction for the choice. (From the last
    // member alone, measured on the 42 off-board files: the same gains, but a ringing plate's
    // tail switched to the noise-whitened signal on one noisy weighing and stopped 1-4 impacts
    // early on five files; summed over the trend's flights, on none.)
    const std::size_t last = q->impacts.size() - 1;
    if (go.noise_signal) {
      z_noise.push_back(StandOut(*noise, tpl_n, x, *q, last));
      z_white.push_back(StandOut(whitened, tpl_w, x, *q, last));
      cancel(q->impacts[last]);
    }
    const std::size_t mz = std::min(z_noise.size(), go.trend_flights);
    double zn = 0.0, zw = 0.0;
    for (std::size_t i = z_noise.size() - mz; i < z_noise.size(); ++i)
      zn += z_noise[i], zw += z_white[i];
    const bool in_noise = go.noise_signal && zn > zw;
    const OnsetResult& onsets = in_noise ? *noise : whitened;
    const MatchTemplate& tpl = in_noise ? tpl_n : tpl_w;
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
      if (grew && go.noise_signal) {
        const std::size_t b = q->impacts.size() - 1;
        z_noise.push_back(StandOut(*noise, tpl_n, x, *q, b));
        z_white.push_back(StandOut(whitened, tpl_w, x, *q, b));
        cancel(q->impacts.back());
      }
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
  OnsetResult noise = go.noise_signal ? NoiseWhitened(onsets, x, go) : OnsetResult{};
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
    const MatchTemplate tpl_n = go.noise_signal ? SequenceTemplate(noise, q) : MatchTemplate{};
    const ImpactResponse response =
        go.noise_signal ? ResponseOf(noise, tpl_n, q, to.min_interval_s) : ImpactResponse{};
    if (!ExtendTail(onsets, tpl, &noise, tpl_n, response, x, limit, to, go, &q)) continue;
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
