// Long recordings in blocks (internal to the library, src/): the recording is read block by
// block, cut at quiet moments between drops, each block's candidate signals detected (as jobs on
// the executor while the next block is read) and their results merged in block order.
#pragma once

#include <cstdint>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "signals.hpp"

namespace bouncecal {

// Reads frames [i0, i1) of the recording and detects every candidate signal (`choices`, as
// CandidateSignals gives them) block by block; then reads the rest of the file, so that every
// sample is checked and the clipping reports are complete. (*signals)[c]: choice c's merged
// result (times in file seconds).
void DetectBlocks(AudioReader* reader, std::int64_t i0, std::int64_t i1,
                  const std::vector<int>& choices, const DetectOptions& options,
                  std::vector<SignalAcrossBlocks>* signals);

}  // namespace bouncecal
