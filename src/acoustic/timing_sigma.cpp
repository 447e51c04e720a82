// The timing stage's sigma model beyond the per-member terms: the self-match of the template
// (resolution floor, truncation share), the cycle-slip mixture, the template member's mismatch.
// See include/bouncecal/acoustic/timing.hpp.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <vector>

#include "bouncecal/core/stats.hpp"
#include "timing_parts.hpp"

namespace bouncecal::timing_parts {
namespace {

// Cycle-slip model (SlipModel): fewer template-timed members than this and the AIC scatter is
// not measured; the AIC scatter's floor (samples: the parabolic AIC pick's resolution); EM
// iterations (the fit settles in ~10 on the recordings and the corpus).
constexpr std::size_t kMinSlipMembers = 3;
constexpr double kMinAicSigma = 0.5;
constexpr int kSlipEmIterations = 50;

// The sequence's agreement between template and AIC timing: r_k = (own AIC pick) - (final time)
// of the template-timed members is a Gaussian N(mu, sigma_aic^2) (the AIC picks' own scatter)
// when the template lag is on the right cycle, and anywhere in the AIC window (uniform, width
// `width`) when one of the two slipped by a ringing period. Fitted by EM (Dempster, Laird &
// Rubin 1977) to the members' r_k; `prior` is the share of slipped members.
struct SlipFit {
  double mu = 0.0, sigma_aic = 0.0, prior = 0.0, width = 1.0;
  bool valid = false;
  // Posterior probability that the member with residual r slipped.
  double Posterior(double r) const {
    const double z = (r - mu) / sigma_aic;
    const double gauss = std::exp(-0.5 * z * z) / (std::sqrt(2.0 * std::numbers::pi) * sigma_aic);
    const double uniform = prior / width;
    return uniform / (uniform + (1.0 - prior) * gauss);
  }
};

SlipFit FitSlips(std::vector<double> r, double width, const TimingOptions& o) {
  SlipFit f;
  f.width = width;
  if (r.size() < kMinSlipMembers) return f;
  const double n = static_cast<double>(r.size());
  auto median = [](std::vector<double> v) {
    const auto mid = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
    std::nth_element(v.begin(), mid, v.end());
    return *mid;
  };
  f.mu = median(r);
  std::vector<double> dev;
  for (double x : r) dev.push_back(std::fabs(x - f.mu));
  f.sigma_aic = std::max(kMinAicSigma, 1.4826 * median(dev));
  f.prior = o.slip_prior;
  // The prior share stays within [1/(2n), 1/2]: at least half a member may have slipped (none
  // seen is not proof of none), and the Gaussian is the majority by definition.
  const double lo = 0.5 / n;
  for (int it = 0; it < kSlipEmIterations; ++it) {
    double sp = 0.0, sw = 0.0, swr = 0.0, swrr = 0.0;
    for (double x : r) {
      const double p = f.Posterior(x);
      sp += p;
      sw += 1.0 - p;
      swr += (1.0 - p) * x;
    }
    if (!(sw > 0.0)) break;
    f.mu = swr / sw;
    for (double x : r) swrr += (1.0 - f.Posterior(x)) * (x - f.mu) * (x - f.mu);
    f.sigma_aic = std::max(kMinAicSigma, std::sqrt(swrr / sw));
    f.prior = std::clamp(sp / n, lo, 0.5);
  }
  f.valid = true;
  return f;
}

// The sequence's shape mismatch W: the share of a member's energy (over the template, at its
// chosen lag) that the template does not explain and the noise does not either,
// max(0, 1 - ncc^2 - E_n / |y|^2) with E_n = L noise_rms^2 the local whitened noise's expected
// energy over the L template samples; the median over the template-timed members (not the
// template itself), since the mismatch belongs to the ball and surface, not to one impact.
// Measured: bundled steel recording (synthetic, exact truth) W = 0.02 (NCC 0.99 on the loud
// members); superball W = 0.8, ping-pong W = 0.8 (NCC 0.25-0.45 at 30-40 dB SNR).
double ShapeMismatch(const std::vector<TimingDetail>& detail, std::size_t tk) {
  std::vector<double> w;
  for (std::size_t k = 0; k < detail.size(); ++k)
    if (k != tk && detail[k].by_template) w.push_back(detail[k].residual_share);
  if (w.empty()) return 0.0;
  const auto mid = w.begin() + static_cast<std::ptrdiff_t>(w.size() / 2);
  std::nth_element(w.begin(), mid, w.end());
  return *mid;
}

// The delay of MeasureSelfMatch: a Kaiser-windowed sinc of half width kShiftHalf, beta 10 (flat
// to ~0.95 Nyquist), longer than the estimator's kernel, so that the floor it finds is the
// estimator's, not its own.
constexpr long kShiftHalf = 64;
constexpr double kShiftBeta = 10.0;

}  // namespace

SelfMatch MeasureSelfMatch(const Neighbourhood& nb, const Template& t) {
  static const double i0_beta = BesselI0(kShiftBeta);
  auto kernel = [](double u) {
    if (std::fabs(u) >= static_cast<double>(kShiftHalf)) return 0.0;
    const double r = u / static_cast<double>(kShiftHalf);
    const double sinc =
        std::fabs(u) < 1e-12 ? 1.0 : std::sin(std::numbers::pi * u) / (std::numbers::pi * u);
    return sinc * BesselI0(kShiftBeta * std::sqrt(1.0 - r * r)) / i0_beta;
  };
  const long tl = static_cast<long>(t.h.size());
  // The peak position with nb delayed by `delay` samples; *share: 1 - ncc^2 there.
  auto timed = [&](double delay, double* share) {
    Neighbourhood z;
    z.begin = t.start - kSincHalf - 2;
    z.w.resize(static_cast<std::size_t>(tl + 2 * kSincHalf + 4));
    std::vector<double> w(static_cast<std::size_t>(2 * kShiftHalf + 1));
    for (long k = -kShiftHalf; k <= kShiftHalf; ++k)
      w[static_cast<std::size_t>(k + kShiftHalf)] = kernel(static_cast<double>(k) - delay);
    for (std::size_t i = 0; i < z.w.size(); ++i) {
      const long n = z.begin + static_cast<long>(i);
      double acc = 0.0;
      for (long k = -kShiftHalf; k <= kShiftHalf; ++k)
        acc += w[static_cast<std::size_t>(k + kShiftHalf)] * nb.at(n - k);
      z.w[i] = static_cast<float>(acc);
    }
    double peak = 0.0;
    const double at = CorrelationPeak(z, t.h, t.start, &peak);
    const long lag = std::lround(at);
    double yy = 0.0;
    for (long j = 0; j < tl; ++j) yy += static_cast<double>(z.at(lag + j)) * z.at(lag + j);
    const double ncc =
        yy > 0.0 ? std::max(NccAt(z, t.h, t.hh, lag), peak / std::sqrt(t.hh * yy)) : 0.0;
    *share = std::max(0.0, 1.0 - std::min(1.0, ncc) * std::min(1.0, ncc));
    return at;
  };
  double unused = 0.0;
  const double at_zero = timed(0.0, &unused);
  SelfMatch m;
  int count = 0;
  for (double delay : {0.25, 0.5, 0.75}) {
    double share = 0.0;
    const double e = timed(delay, &share) - at_zero - delay;
    m.floor_samples += e * e;
    m.residual_share += share;
    ++count;
  }
  m.floor_samples = std::sqrt(m.floor_samples / count);
  m.residual_share /= count;
  return m;
}

// Cycle-slip stage. Measured: on the superball recording (pfe_bouncyball, 48 kHz) 8 of 33
// annotated impacts were timed 0.60-0.68 ms early by the template (one ringing period; the
// annotation is +-0.2 ms) and their own AIC picks sat 25-34 samples later than the template's,
// where the annotation is; on the ping-pong recording the template and AIC picks agree within
// the AIC's scatter (sigma_aic ~ 9 samples) for all but the last, noise-level members, and the
// annotations agree with the template within their +-0.2 ms. A rival correlation peak a ringing
// period away (the former ambiguity term) said nothing about this: on ping-pong it was higher
// than the chosen one on half the members, all timed right, and on the synthetic corpus the
// term overstated the error 4-8x (RMS(err/sigma) 0.13-0.28 on the members it touched).
// The AIC alone cannot say which of the two slipped: on the bundled steel recording (exact truth)
// the template is right to 12 us on every impact while the AIC picks of 13 of the 52 members,
// at 21-34 dB SNR, jump 6-70 samples on the ringing of earlier impacts. So a slip also needs the
// template to match about as well where the AIC pick puts the onset (the superball's slipped
// members: NCC 0.64 there against 0.27 at the chosen lag; steel: 0.9 at the chosen lag).
// Template-timed members: variance + q P(slip | r) (r - mu)^2, q the probability that the NCC
// at the AIC's lag beats the chosen one under the NCC noise (as the ambiguity term). AIC-timed
// members: the AIC scatter, the pick's posterior spread and, with the prior share of slips, the
// window's uniform variance.
void SlipModel(const std::vector<double>& own_aic, const std::vector<double>& own_spread,
               const std::vector<MemberTime>& mts, const std::vector<Neighbourhood>& nb,
               const Template& tpl, const Geometry& g, const TimingOptions& o, double rate_hz,
               std::size_t tk, std::vector<Impact>* imps, TimingResult* res) {
  const std::size_t n = imps->size();
  std::vector<double> r;
  for (std::size_t k = 0; k < n; ++k)
    if (res->detail[k].by_template && k != tk && std::isfinite(own_aic[k]))
      r.push_back(own_aic[k] - (*imps)[k].time_s * rate_hz);
  const double width = static_cast<double>(g.aic_pre + g.aic_post);
  const SlipFit f = FitSlips(r, width, o);
  if (!f.valid) return;
  res->aic_sigma_samples = f.sigma_aic;
  res->slip_prior = f.prior;
  const double shape_share = ShapeMismatch(res->detail, tk);
  res->shape_mismatch = shape_share;
  for (std::size_t k = 0; k < n; ++k) {
    TimingDetail& d = res->detail[k];
    Impact& im = (*imps)[k];
    const double var = im.sigma_s * im.sigma_s * rate_hz * rate_hz;
    if (d.by_template) {
      if (k == tk || !std::isfinite(own_aic[k])) continue;
      const double dr = own_aic[k] - im.time_s * rate_hz - f.mu;
      d.aic_residual = dr;
      // The template must match about as well where the AIC pick puts the onset (best NCC
      // within the AIC scatter of it): the NCC noise s_c decides, as for the ambiguity term.
      // A slip lands on another correlation peak: lags on the chosen peak's main lobe (where
      // the NCC falls monotonically from it) do not count. (Counted, the broad peak of a soft
      // ball's thud, still 0.99 eight samples from its top, made every member whose AIC pick
      // sat one AIC scatter away a half-likely slip: 5-13 us of sigma on 0.1 us errors.)
      const long at = mts[k].lag + std::lround(dr);
      const long w = std::max(2L, std::lround(f.sigma_aic));
      auto ncc = [&](long l) { return NccAt(nb[k], tpl.h, tpl.hh, l); };
      const long reach = g.aic_pre + g.aic_post;
      long lobe_lo = mts[k].lag, lobe_hi = mts[k].lag;
      while (lobe_lo > mts[k].lag - reach && ncc(lobe_lo - 1) < ncc(lobe_lo)) --lobe_lo;
      while (lobe_hi < mts[k].lag + reach && ncc(lobe_hi + 1) < ncc(lobe_hi)) ++lobe_hi;
      double c_alt = -2.0;
      for (long l = at - w; l <= at + w; ++l)
        if (l < lobe_lo || l > lobe_hi) c_alt = std::max(c_alt, ncc(l));
      // The NCC at each lag moves by the noise (s_c) and by the shape residual, an energy
      // W |y|^2 that projects on the template as the local noise's energy E_n does (s_c):
      // s_shape = s_c sqrt(W |y|^2 / E_n), added in quadrature (E_n under the template, as s_c).
      const double e_noise =
          static_cast<double>(g.tl) * mts[k].noise_rms_at_template * mts[k].noise_rms_at_template;
      const double s_shape =
          e_noise > 0.0 ? mts[k].ncc_noise * std::sqrt(shape_share * mts[k].yy / e_noise) : 0.0;
      const double s_ncc = std::hypot(mts[k].ncc_noise, s_shape);
      const double q = 0.5 * std::erfc((d.ncc - c_alt) / (2.0 * s_ncc));
      d.ncc_at_aic = c_alt;
      d.slip_q = q;
      d.slip_posterior = f.Posterior(dr + f.mu);
      d.sigma_slip = o.slip_gain * std::sqrt(q * d.slip_posterior) * std::fabs(dr);
      im.sigma_s = std::sqrt(var + d.sigma_slip * d.sigma_slip) / rate_hz;
    } else {
      d.sigma_noise = std::hypot(f.sigma_aic, own_spread[k]);
      d.sigma_slip = std::sqrt(f.prior * width * width / 12.0);
      im.sigma_s = std::sqrt(d.sigma_noise * d.sigma_noise + d.sigma_slip * d.sigma_slip +
                             d.sigma_resolution * d.sigma_resolution) /
                   rate_hz;
    }
  }
}

// The template member matches itself (its residual share is 0 by definition), but its shape
// departs from the sequence's as much as the others' do, and every other member's mismatch term
// measures its difference to the template: the template member takes the median of theirs.
void TemplateMemberMismatch(std::size_t tk, double rate_hz, TimingResult* res,
                            std::vector<Impact>* imps) {
  std::vector<double> others;
  for (std::size_t k = 0; k < imps->size(); ++k)
    if (k != tk && res->detail[k].by_template) others.push_back(res->detail[k].sigma_mismatch);
  TimingDetail& d = res->detail[tk];
  if (others.empty() || !d.by_template) return;
  const auto mid = others.begin() + static_cast<std::ptrdiff_t>(others.size() / 2);
  std::nth_element(others.begin(), mid, others.end());
  d.sigma_mismatch = *mid;
  (*imps)[tk].sigma_s =
      std::sqrt(d.sigma_noise * d.sigma_noise + d.sigma_mismatch * d.sigma_mismatch +
                d.sigma_resolution * d.sigma_resolution) /
      rate_hz;
}

}  // namespace bouncecal::timing_parts
