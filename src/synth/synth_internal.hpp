// What the synth wing's files share (internal to the library, src/): the random streams and
// the modes' JSON.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/synth/synth.hpp"
#include "synth/random.hpp"

namespace bouncecal::synth {

using synth_random::Rng;
using synth_random::Stream;

enum Purpose : std::uint64_t {
  kNoise = 1,
  kHum = 2,
  kDistractor = 3,
  kModeSpread = 4,
  kScatter = 5
};

inline bool Finite(double v) { return std::isfinite(v); }

nlohmann::json ModesJson(const std::vector<Mode>& modes);

}  // namespace bouncecal::synth
