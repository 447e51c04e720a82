// Pieces the timing stage (timing.cpp) shares with its sigma model (timing_sigma.cpp): the
// whitened neighbourhoods, the template, the sizes, one member's timing (internal to the library,
// src/; include/bouncecal/acoustic/timing.hpp documents the stage and the model).
#pragma once

#include <cstddef>
#include <vector>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/acoustic/timing.hpp"

namespace bouncecal::timing_parts {

// Half width (samples) of the windowed-sinc interpolation kernel (and of the band-limited
// differentiators). Measured (a real impact sound placed 30 times at random sub-sample times by
// a 512-tap Kaiser sinc, no noise, RMS interval error): with 8, the whitened sounds' energy near
// Nyquist (where a short Hann window's kernel fails) left 0.01-1.16 us (superball: 0.056
// samples); with 32, 0.002-0.2 us.
inline constexpr long kSincHalf = 32;

// The whitened neighbourhood of one member: w[i] is the whitened sample begin + i.
struct Neighbourhood {
  long begin = 0;
  std::vector<float> w;
  long end() const { return begin + static_cast<long>(w.size()); }
  float at(long n) const {
    return n >= begin && n < end() ? w[static_cast<std::size_t>(n - begin)] : 0.0f;
  }
};

// Sizes (samples) the stages use, from the options and the rate.
struct Geometry {
  long tl, lead, near, aic_pre, aic_post, before, after;
  Geometry(const TimingOptions& o, double rate_hz) {
    auto samples = [&](double s) { return std::max(1L, std::lround(s * rate_hz)); };
    tl = std::max(8L, samples(o.template_s));
    lead = samples(o.lead_s);
    near = samples(o.search_s);
    aic_pre = std::max(16L, samples(o.aic_pre_s));
    aic_post = std::max(8L, samples(o.aic_post_s));
    before = std::max({near + lead, aic_pre, samples(o.noise_window_s + o.noise_guard_s)}) +
             2 * kSincHalf + 2;
    after = std::max({near + tl, aic_post, samples(o.level_window_s)}) + 2 * kSincHalf;
  }
};

// The template: the whitened waveform of one member from `lead` before its AIC onset, and its
// band-limited derivative.
struct Template {
  std::size_t member = 0;
  double t_ref = 0.0;  // onset sample (fractional) of the template impact
  long start = 0;      // sample where the template starts
  long anchor = 0;     // the template member's detection time (sample)
  std::vector<double> h, hd, hdd;
  double hh = 0.0, dd = 0.0;
  bool usable() const { return hh > 0.0 && dd > 0.0; }
};

// One member timed: onset (fractional sample), variance (samples^2) and the model's parts.
struct MemberTime {
  double onset = 0.0;
  double sigma2 = 0.0;
  long lag = 0;                        // chosen integer template start (template-timed members)
  double ncc_noise = 0.0;              // s_c: the NCC's spread under the local noise
  double yy = 0.0;                     // the member's energy over the template at the chosen lag
  double noise_rms_at_template = 0.0;  // the local noise rms under the template (its decay)
};

// Normalised cross-correlation of the template h (energy hh) with nb at template start l.
double NccAt(const Neighbourhood& nb, const std::vector<double>& h, double hh, long l);

// Cross-correlation <h, nb[l, l + |h|)> of the template h with nb at template start l.
double XcAt(const Neighbourhood& nb, const std::vector<double>& h, long l);

// The sub-sample position of the peak of <h, nb[l, l + |h|)> near the integer start `at`: the
// band-limited interpolation of the cross-correlation at starts at +- kSincHalf. The
// correlation of band-limited signals is band-limited in the lag; the NCC, divided by each
// lag's |y|, is not (its interpolation moved the peak by up to 0.02 samples). *peak: the
// interpolated correlation there.
double CorrelationPeak(const Neighbourhood& nb, const std::vector<double>& h, long at,
                       double* peak);

// AIC pick in the window [anchor - aic_pre, anchor + aic_post) of one neighbourhood.
AicPick AicAround(const Neighbourhood& nb, long anchor, const Geometry& g);

// What a perfect copy of the template shows when it sits at another sub-sample phase: the
// template member's own whitened neighbourhood delayed by known fractions of a sample (a longer,
// Kaiser-windowed sinc than the estimator's: half width kShiftHalf, beta 10, flat to ~0.95
// Nyquist) and timed against the template as every member is.
//   floor_samples: the RMS of the timing errors, the estimator's own resolution for this sound.
//     Measured on real impact sounds: 0.0002-0.007 samples (the superball's ringing, whitened,
//     puts the most energy near Nyquist); no floor is assumed.
//   residual_share: the mean 1 - ncc^2 there. The template window cuts a ringing sound off, and
//     a shifted copy is cut at another phase: a superball's copies keep 1 - ncc^2 ~ 0.03 with no
//     noise and no other difference. That share is not a shape mismatch (its timing effect is the
//     floor above), so the mismatch term counts only what a member shows beyond it.
struct SelfMatch {
  double floor_samples = 0.0;
  double residual_share = 0.0;
};
SelfMatch MeasureSelfMatch(const Neighbourhood& nb, const Template& t);

// The cycle-slip stage (timing.hpp): the sequence's slip mixture fitted to the members' AIC
// residuals, each template-timed member's slip term added to its sigma_s, the AIC-timed members'
// sigma_s set. own_aic: each member's own AIC pick (samples; NaN: none); own_spread: its
// posterior spread; tk: the template member.
void SlipModel(const std::vector<double>& own_aic, const std::vector<double>& own_spread,
               const std::vector<MemberTime>& mts, const std::vector<Neighbourhood>& nb,
               const Template& tpl, const Geometry& g, const TimingOptions& o, double rate_hz,
               std::size_t tk, std::vector<Impact>* imps, TimingResult* res);

// The template member's mismatch term: the median of the other template-timed members' (its own
// residual share is 0 by definition); its sigma_s recomputed.
void TemplateMemberMismatch(std::size_t tk, double rate_hz, TimingResult* res,
                            std::vector<Impact>* imps);

}  // namespace bouncecal::timing_parts
