// bouncecal/acoustic/click_track.hpp — the recording with a click at every detected impact, so a
// user can hear what was found (as aubio's onset tool writes with -o).
//
//   std::vector<std::vector<float>> out = RenderClickTrack(audio, times_s, ClickTrackOptions{});
//   WriteAudio("clicks.wav", out, audio.info.sample_rate_hz);
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"

namespace bouncecal {

struct ClickTrackOptions {
  double click_s = 0.004;        // click length: a decaying sine burst
  double frequency_hz = 2000.0;  // its pitch (clamped below the Nyquist frequency)
  double level = 0.5;            // its peak, full scale = 1
  double recording_gain = 0.5;   // the recording is mixed in at this gain (headroom for clicks)
  bool IsValid(std::string* error) const;
};

// Every channel of `audio` times recording_gain plus the click at each time (seconds from the
// file start; times outside the recording are ignored). Throws Error(kBadParameter) for
// invalid options.
std::vector<std::vector<float>> RenderClickTrack(const Audio& audio,
                                                 const std::vector<double>& times_s,
                                                 const ClickTrackOptions& options = {});

}  // namespace bouncecal
