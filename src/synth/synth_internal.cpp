// What the synth wing's files share. See synth_internal.hpp.
#include "synth/synth_internal.hpp"

namespace bouncecal::synth {

nlohmann::json ModesJson(const std::vector<Mode>& modes) {
  nlohmann::json a = nlohmann::json::array();
  for (const Mode& m : modes) {
    a.push_back({{"freq_hz", m.freq_hz}, {"decay_s", m.decay_s}, {"gain", m.gain}});
  }
  return a;
}

}  // namespace bouncecal::synth
