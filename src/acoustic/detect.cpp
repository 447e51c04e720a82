// The detect pipeline: channel selection -> onsets -> bounce-sequence tracking.
// See include/bouncecal/acoustic/detect.hpp.
#include "bouncecal/acoustic/detect.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "bouncecal/acoustic/onsets.hpp"
#include "bouncecal/acoustic/sequence.hpp"
#include "bouncecal/core/error.hpp"

namespace bouncecal {
namespace {

// One step of 16-bit PCM: a recording whose peak stays at or below it carries no impacts.
constexpr double kSilencePeak = 1.0 / 32768.0;
// Guided search: NCC threshold (the blind pass asks for 4/sqrt(L), about 0.47 at 48 kHz; here
// the time is known to a few percent, so far fewer positions compete) and half window as a
// fraction of the predicted interval (the ratio of successive intervals drifts by ~1-3 %).
constexpr double kGuidedMinNcc = 0.35;
constexpr double kGuidedWindow = 0.04;
// Ranking penalty at the window edge (NCC units): near the noise level a noise peak 0.4 ms from
// the prediction matched as well as the impact (corpus: NCC 0.37 vs 0.36, a 433 us error).
constexpr double kGuidedEdgePenalty = 0.15;

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
}

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

}  // namespace

bool DetectOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(hop_s >= 0.0) || hop_s > 0.05)
    return fail("DetectOptions::hop_s = " + std::to_string(hop_s) + ": must be in [0, 0.05] s");
  if (min_sequence_impacts < 3)
    return fail("DetectOptions::min_sequence_impacts = " + std::to_string(min_sequence_impacts) +
                ": must be >= 3");
  if (!(min_interval_s > 0.0) || min_interval_s > 1.0)
    return fail("DetectOptions::min_interval_s = " + std::to_string(min_interval_s) +
                ": must be in (0, 1] s");
  if (lpc_order < 0 || lpc_order > 256)
    return fail("DetectOptions::lpc_order = " + std::to_string(lpc_order) + ": must be 0..256");
  if (channel.kind == ChannelSelection::Kind::kIndex && channel.index < 0)
    return fail("DetectOptions::channel.index must be >= 0");
  return true;
}

DetectionResult DetectImpacts(const Audio& audio, const DetectOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  const std::string& path = audio.info.path;
  DetectionResult res;
  res.audio = audio.info;
  res.clipping = audio.clipping;
  if (audio.channels.empty() || audio.channels.front().empty())
    throw Error(ErrorCode::kNotAudio, path + ": no samples");
  // One channel: nothing to choose (skips the auto score, which costs a full pass).
  ChannelSelection choice = options.channel;
  if (audio.channels.size() == 1 && choice.kind == ChannelSelection::Kind::kAuto)
    choice = ChannelSelection{ChannelSelection::Kind::kIndex, 0};
  const SelectedSignal sel = SelectChannel(audio, choice);
  res.channel = sel.channel;
  res.channel_score_db = sel.channel_score;
  double peak = 0.0;
  for (float v : sel.samples) peak = std::max(peak, static_cast<double>(std::fabs(v)));
  if (peak <= kSilencePeak)
    throw Error(ErrorCode::kSilence, path + ": recording is silent (peak |x| = " +
                                         Fmt("%.3g", peak) + ", at or below one 16-bit step)");

  OnsetOptions oo;
  oo.hop_s = options.hop_s;
  oo.refine = true;  // locate at full resolution; refine = false coarsens the times at the end
  oo.lpc_order = options.lpc_order;
  const OnsetDetector detector(oo, audio.info.sample_rate_hz);
  OnsetResult onsets = detector.Detect(sel.samples);

  // Clipped impacts: the impact's peak reaches a clipped channel's extreme value.
  for (Impact& imp : onsets.onsets) {
    for (const ClippingReport& c : audio.clipping) {
      if (sel.channel >= 0 && c.channel != sel.channel) continue;
      if (c.clipped() && imp.amplitude >= 0.999 * c.peak) imp.clipped = true;
    }
  }
  res.candidates = onsets.onsets;

  TrackOptions to;
  to.min_interval_s = options.min_interval_s;
  to.min_sequence_impacts = options.min_sequence_impacts;
  res.sequences = TrackSequences(res.candidates, audio.info.duration_s(), to);
  if (options.guided_search)
    ExtendByTemplate(onsets, sel.samples, audio.info.duration_s(), to, &res.sequences);
  if (res.sequences.empty())
    throw Error(ErrorCode::kNoBounces,
                path + ": no bounce sequence found (" + std::to_string(res.candidates.size()) +
                    " onset candidates; none form " + std::to_string(options.min_sequence_impacts) +
                    " or more impacts with shrinking intervals)");
  if (!options.refine) {
    for (Impact& im : res.candidates) CoarsenToHop(&im, detector.hop_samples(), onsets.rate_hz);
    for (Sequence& q : res.sequences)
      for (Impact& im : q.impacts) CoarsenToHop(&im, detector.hop_samples(), onsets.rate_hz);
  }
  res.main_sequence = 0;
  for (std::size_t s = 1; s < res.sequences.size(); ++s)
    if (res.sequences[s].impacts.size() >
        res.sequences[static_cast<std::size_t>(res.main_sequence)].impacts.size())
      res.main_sequence = static_cast<int>(s);

  for (const ClippingReport& c : audio.clipping)
    if (c.clipped())
      res.warnings.push_back({"clipped",
                              "channel " + std::to_string(c.channel) + " is clipped (" +
                                  std::to_string(c.clipped_samples) +
                                  " samples at its extreme value); onsets are still usable, "
                                  "amplitudes are not",
                              -1});
  for (std::size_t s = 0; s < res.sequences.size(); ++s) {
    const Sequence& q = res.sequences[s];
    for (int k : q.missed_after)
      res.warnings.push_back(
          {"missed_impact",
           "sequence " + std::to_string(s) + ": an impact seems missing after impact " +
               std::to_string(k) +
               " (t = " + Fmt("%.4f", q.impacts[static_cast<std::size_t>(k)].time_s) +
               " s); its interval is about two expected ones",
           k});
  }
  return res;
}

}  // namespace bouncecal
