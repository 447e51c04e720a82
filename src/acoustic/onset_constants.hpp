// Task sizes shared by the stages of onset detection (internal to the library, src/).
#pragma once

#include <cstddef>

namespace bouncecal {

// The novelty's frames are computed a chunk at a time (novelty.cpp), and its per-frame passes
// and the threshold's interpolation run in groups of at least this many frames per task.
constexpr std::size_t kSpectraChunk = 4096;

}  // namespace bouncecal
