// The candidate signals of a detection (internal to the library, src/): which channels (and the
// mix) to try, the mix itself, decimation of recordings above 64 kHz, and the choice among the
// signals' results (ChannelSelection auto).
#pragma once

#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "detect_signal.hpp"

namespace bouncecal {

// The signals `selection` asks for in a recording (`info`): channel indices, -1 for the mix.
// Throws Error(kUsage) for a channel index past the last one.
std::vector<int> CandidateSignals(const ChannelSelection& selection, const AudioInfo& info);

// The signal of one choice (a channel or the mix) over frames [from, to) of a block.
void SignalOf(const std::vector<std::vector<float>>& block, int channel, std::size_t from,
              std::size_t to, std::vector<float>* x);

// The level from which an impact of `channel` (-1: the mix) counts as clipped (0: none).
double ClipPeak(const std::vector<ClippingReport>& clipping, int channel, std::size_t channels);
void MarkClipped(double clip_peak, SignalDetection* d);

// The integer factor a recording at rate_hz is decimated by before detection (1: none).
int DecimationFactor(double rate_hz);
// y[k] = sum_j h[j] x[k f + j], |j| <= 12 f: a Blackman-windowed sinc low-pass with its cutoff at
// 0.45 of the new rate, centred (zero phase: no delay to correct), x taken as 0 beyond its ends.
void Decimate(const std::vector<float>& x, int factor, std::vector<float>* y);
// After detection at a decimated rate: each impact's amplitude is the peak |x| of the signal at
// the file's rate over the same 3 ms (the low-pass lowers peaks, and `clipped` compares
// amplitudes with the channel's full-rate peak).
void FullRateAmplitudes(const std::vector<float>& x, double rate_hz, SignalDetection* d);
// Adds dt to every time of d.
void ShiftTimes(double dt, SignalDetection* d);

// One candidate signal's detections over the blocks read so far (blocks.hpp merges them).
struct SignalAcrossBlocks {
  SignalDetection merged;
  bool sound = false;   // a block was not silent
  double peak = 0.0;    // max |x| over the blocks
  std::string failure;  // the last block's reason for finding no sequence
  // The last member of the last sequence merged (file seconds): a later block's sequences start
  // after it (blocks overlap, blocks.cpp).
  double merged_until_s = -1e300;
};

// The best-scoring signal's detection (a later one replaces an earlier one only when clearly
// better), with every signal's score in res->channel_scores and res->channel set. `window`: the
// analysed window as text, for the messages when it is not the whole recording (empty).
// Throws Error(kSilence) when every signal is silent, Error(kNoBounces) when none has a
// sequence.
SignalDetection ChooseSignal(const std::vector<int>& choices,
                             std::vector<SignalAcrossBlocks>* signals, const std::string& window,
                             DetectionResult* res);

// When auto had a real choice and the signals disagree on the main sequence, say which was
// used and why (the scores of all are in DetectionResult::channel_scores).
void ChannelChoiceWarning(const DetectionResult& r, std::vector<Warning>* out);

}  // namespace bouncecal
