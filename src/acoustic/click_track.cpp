// The listen-back track. See include/bouncecal/acoustic/click_track.hpp.
#include "bouncecal/acoustic/click_track.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "bouncecal/core/error.hpp"

namespace bouncecal {

bool ClickTrackOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (!(click_s > 0.0) || click_s > 1.0)
    return fail("ClickTrackOptions::click_s = " + std::to_string(click_s) +
                ": must be in (0, 1] s");
  if (!(frequency_hz > 0.0) || !std::isfinite(frequency_hz))
    return fail("ClickTrackOptions::frequency_hz must be a finite number > 0");
  if (!(level > 0.0) || level > 1.0)
    return fail("ClickTrackOptions::level = " + std::to_string(level) + ": must be in (0, 1]");
  if (!(recording_gain >= 0.0) || recording_gain > 1.0)
    return fail("ClickTrackOptions::recording_gain = " + std::to_string(recording_gain) +
                ": must be in [0, 1]");
  return true;
}

std::vector<std::vector<float>> RenderClickTrack(const Audio& audio,
                                                 const std::vector<double>& times_s,
                                                 const ClickTrackOptions& o) {
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kBadParameter, why);
  const double rate = audio.info.sample_rate_hz;
  std::vector<std::vector<float>> out = audio.channels;
  for (auto& c : out)
    for (float& v : c) v = static_cast<float>(o.recording_gain * v);
  if (out.empty()) return out;
  const long n = static_cast<long>(out[0].size());
  const double f = std::min(o.frequency_hz, 0.4 * rate);
  const long len = std::max(1L, std::lround(o.click_s * rate));
  std::vector<float> click(static_cast<std::size_t>(len));
  for (long i = 0; i < len; ++i) {  // sine burst, exponential decay to ~1 % at its end
    const double t = static_cast<double>(i) / rate;
    click[static_cast<std::size_t>(i)] = static_cast<float>(
        o.level * std::sin(2.0 * std::numbers::pi * f * t) * std::exp(-4.6 * t / o.click_s));
  }
  for (double t : times_s) {
    if (!std::isfinite(t)) continue;
    const long k0 = std::lround(t * rate);
    if (k0 < 0 || k0 >= n) continue;
    for (auto& c : out)
      for (long i = 0; i < len && k0 + i < n; ++i)
        c[static_cast<std::size_t>(k0 + i)] += click[static_cast<std::size_t>(i)];
  }
  return out;
}

}  // namespace bouncecal
