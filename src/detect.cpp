// The detect pipeline: channel selection -> onsets -> bounce-sequence tracking.
// See include/bouncecal/detect.hpp.
#include "bouncecal/detect.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "bouncecal/error.hpp"
#include "bouncecal/onsets.hpp"
#include "bouncecal/sequence.hpp"

namespace bouncecal {
namespace {

// One step of 16-bit PCM: a recording whose peak stays at or below it carries no impacts.
constexpr double kSilencePeak = 1.0 / 32768.0;

std::string Fmt(const char* f, double v) {
  char buf[64];
  std::snprintf(buf, sizeof buf, f, v);
  return buf;
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
  oo.refine = options.refine;
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
  if (res.sequences.empty())
    throw Error(ErrorCode::kNoBounces,
                path + ": no bounce sequence found (" + std::to_string(res.candidates.size()) +
                    " onset candidates; none form " + std::to_string(options.min_sequence_impacts) +
                    " or more impacts with shrinking intervals)");
  res.main_sequence = 0;
  for (std::size_t s = 1; s < res.sequences.size(); ++s)
    if (res.sequences[s].impacts.size() >
        res.sequences[static_cast<std::size_t>(res.main_sequence)].impacts.size())
      res.main_sequence = static_cast<int>(s);

  for (const ClippingReport& c : audio.clipping)
    if (c.clipped())
      res.warnings.push_back("channel " + std::to_string(c.channel) + " is clipped (" +
                             std::to_string(c.clipped_samples) +
                             " samples at its extreme value); onsets are still usable, "
                             "amplitudes are not");
  for (std::size_t s = 0; s < res.sequences.size(); ++s) {
    const Sequence& q = res.sequences[s];
    for (int k : q.missed_after)
      res.warnings.push_back("sequence " + std::to_string(s) + ": an impact seems missing after " +
                             "impact " + std::to_string(k) +
                             " (t = " + Fmt("%.4f", q.impacts[static_cast<std::size_t>(k)].time_s) +
                             " s); its interval is about two expected ones");
  }
  return res;
}

}  // namespace bouncecal
