// Long recordings in blocks. See blocks.hpp.
#include "blocks.hpp"

#include <algorithm>
#include <atomic>
#include <cstdio>
#include <deque>
#include <future>
#include <limits>
#include <optional>

#include "avx2_clones.hpp"
#include "bouncecal/core/parallel.hpp"
#include "detect_signal.hpp"

namespace bouncecal {
namespace {

// One step of 16-bit PCM: a recording whose peak stays at or below it carries no impacts.
constexpr double kSilencePeak = 1.0 / 32768.0;

// Long recordings are detected in blocks of at most DetectOptions::max_block_s (and
// kMaxBlockFrames frames: 44 s at 384 kHz), so that memory does not grow with the length; blocks
// bound memory only, they decide nothing. A block's own sequences are those that start before its
// cut, the quietest moment of its third quarter (at most kMaxCutSearchS long), and it reads a
// look-ahead beyond the cut (its last quarter, at most kMaxCutSearchS) so that a drop that began
// before the cut is tracked whole: a drop's bounces last d0 / (1 - e), 17 s for a ball of e 0.95
// dropped from 1 m. The next block starts kBlockMarginS before the cut (context for the
// whitening fit and running medians) and owns the sequences that start after both the cut and
// the last member of the sequences merged before it. A sequence that reaches the end of the
// look-ahead gets the warning block_split.
constexpr std::int64_t kMaxBlockFrames = std::int64_t{1} << 24;
constexpr double kBlockMarginS = 0.5;
constexpr double kMaxCutSearchS = 30.0;
// The quiet measure of a cut: the largest energy of the signal's first difference (a high-pass
// that keeps impact attacks) in 10 ms frames within +-kCutQuietS of it.
constexpr double kCutFrameS = 0.01;
constexpr double kCutQuietS = 0.5;

// The frame (block index) of the quietest moment in [lo, hi) of the block.
std::size_t QuietestCut(const std::vector<std::vector<float>>& block, std::size_t lo,
                        std::size_t hi, double rate_hz) {
  const std::size_t fl = std::max<std::size_t>(1, static_cast<std::size_t>(kCutFrameS * rate_hz));
  const std::size_t reach = static_cast<std::size_t>(kCutQuietS / kCutFrameS);
  const std::size_t n = block.front().size();
  // Frames over [lo - reach frames, hi + reach frames), clipped to the block.
  const std::size_t f0 = lo > reach * fl ? lo - reach * fl : 1;
  const std::size_t f1 = std::min(n, hi + reach * fl);
  const std::size_t nf = (f1 - f0) / fl;
  if (nf == 0) return lo;
  std::vector<double> energy(nf, 0.0);
  for (const std::vector<float>& c : block)
    for (std::size_t f = 0; f < nf; ++f) {
      double e = 0.0;
      for (std::size_t i = f0 + f * fl; i < f0 + (f + 1) * fl; ++i) {
        const double d = static_cast<double>(c[i]) - c[i - 1];
        e += d * d;
      }
      energy[f] += e;
    }
  // The latest frame whose +-reach neighbourhood has the smallest peak energy.
  std::size_t best = lo;
  double best_score = std::numeric_limits<double>::infinity();
  for (std::size_t f = 0; f < nf; ++f) {
    const std::size_t centre = f0 + f * fl + fl / 2;
    if (centre < lo || centre >= hi) continue;
    double score = 0.0;
    for (std::size_t g = f > reach ? f - reach : 0; g < std::min(nf, f + reach + 1); ++g)
      score = std::max(score, energy[g]);
    if (score <= best_score) {
      best_score = score;
      best = centre;
    }
  }
  return best;
}

// Adds what one block found (times already in file seconds) to `into`: the candidates in
// [own_lo_s, own_hi_s) and the sequences that start there after the last member merged before.
// A sequence that reaches the end of the block's audio (data_end_s) may have been cut short:
// block_split.
void MergeBlock(SignalDetection d, double own_lo_s, double own_hi_s, double data_end_s,
                bool last_block, SignalAcrossBlocks* into) {
  SignalDetection& m = into->merged;
  m.hop_samples = d.hop_samples;
  if (!d.failure.empty()) into->failure = d.failure;
  for (const Impact& i : d.candidates)
    if (i.time_s >= own_lo_s && i.time_s < own_hi_s) m.candidates.push_back(i);
  for (Sequence& q : d.sequences) {
    const double t0 = q.impacts.front().time_s;
    if (t0 < own_lo_s || t0 >= own_hi_s || t0 <= into->merged_until_s) continue;
    if (!last_block && q.impacts.back().time_s >= data_end_s - kBlockMarginS) {
      char msg[300];
      std::snprintf(msg, sizeof msg,
                    "the sequence from %.4f s runs to %.4f s, where the audio read for one "
                    "analysis block ends (DetectOptions::max_block_s): its later impacts may be "
                    "missing",
                    t0, data_end_s);
      d.warnings.push_back({"block_split", msg, -1, "--start/--end around this drop"});
    }
    into->merged_until_s = q.impacts.back().time_s;
    m.sequences.push_back(std::move(q));
  }
  for (Warning& w : d.warnings) {
    const bool seen = std::any_of(m.warnings.begin(), m.warnings.end(), [&](const Warning& o) {
      return o.code == w.code && o.message == w.message;
    });
    if (!seen) m.warnings.push_back(std::move(w));
  }
}

// One block of the recording as read and cut, handed to a detection worker.
struct Block {
  std::vector<std::vector<float>> channels;  // its frames, every channel
  std::int64_t start = 0;                    // its first frame in the file
  double own_lo_s = 0.0, own_hi_s = 0.0;     // the sequences that start in here are its own
  double data_end_s = 0.0;                   // where its audio ends (file seconds)
  bool last = false;
};

// What one block yields for each candidate signal: its peak and, when it is not silent there,
// what DetectInSignal found (times in file seconds).
struct BlockResult {
  std::vector<double> peak;
  std::vector<std::optional<SignalDetection>> found;
};

// max |x[i]| over x[0, n) (0 when empty) = max(-min, max), from the reader's vectorised MinMax:
// the same value as the largest of the doubles (the conversion is exact and keeps the order).
double MaxAbs(const float* x, std::size_t n) {
  if (n == 0) return 0.0;
  float lo, hi;
  MinMax(x, n, &lo, &hi);
  return static_cast<double>(std::max(0.0f, std::max(-lo, hi)));  // +0 for an all-zero block
}

// Every candidate signal of one block through DetectInSignal (at most at kMaxAnalysisRateHz).
BlockResult DetectBlock(const Block& b, double rate, const std::vector<int>& choices,
                        const DetectOptions& options) {
  BlockResult r;
  const int factor = DecimationFactor(rate);
  const double offset_s = static_cast<double>(b.start) / rate;
  std::vector<float> mix, xd;
  for (int choice : choices) {
    // A channel is detected on the block's own samples; the mix is made one signal at a time.
    const std::vector<float>* x = &mix;
    if (choice >= 0)
      x = &b.channels[static_cast<std::size_t>(choice)];
    else
      SignalOf(b.channels, choice, 0, b.channels.front().size(), &mix);
    const double peak = MaxAbs(x->data(), x->size());
    r.peak.push_back(peak);
    r.found.emplace_back();
    if (!(peak > kSilencePeak)) continue;
    SignalDetection d;
    if (factor > 1) {
      Decimate(*x, factor, &xd);
      d = DetectInSignal(xd, rate / factor, options);
      FullRateAmplitudes(*x, rate, &d);
      d.hop_samples *= factor;  // in samples of the file's rate (CoarsenToHop)
    } else {
      d = DetectInSignal(*x, rate, options);
    }
    ShiftTimes(offset_s, &d);
    r.found.back() = std::move(d);
  }
  return r;
}

// Adds one block's results to the signals' (in block order: the merged result is the serial one).
void MergeBlockResult(BlockResult r, double own_lo_s, double own_hi_s, double data_end_s, bool last,
                      std::vector<SignalAcrossBlocks>* signals) {
  for (std::size_t ci = 0; ci < signals->size(); ++ci) {
    SignalAcrossBlocks& sig = (*signals)[ci];
    sig.peak = std::max(sig.peak, r.peak[ci]);
    if (!r.found[ci]) continue;
    sig.sound = true;
    MergeBlock(std::move(*r.found[ci]), own_lo_s, own_hi_s, data_end_s, last, &sig);
  }
}

}  // namespace

// Reads frames [i0, i1) of the recording block by block and runs every candidate signal on
// each block (DetectBlock), merging what each finds in block order (MergeBlock); then reads the
// rest of the file, so that every sample is checked and the clipping reports are complete.
// A recording of one block is detected on this thread, its stages split among
// DetectOptions::threads. Several blocks are detected concurrently as jobs on the executor
// (core/parallel.hpp), while this thread reads ahead; one block more than the threads is handed
// out, so that a thread that finishes finds the next block queued: at most threads + 2 blocks in
// memory. Each block's stages ask for all the threads too: while every thread has a block their
// shares wait in the queue, and the threads that have no block left take them, so the last
// blocks end sooner. The cuts depend only on the audio, and the merge is in order, so the result
// is the serial one.
void DetectBlocks(AudioReader* reader, std::int64_t i0, std::int64_t i1,
                  const std::vector<int>& choices, const DetectOptions& options,
                  std::vector<SignalAcrossBlocks>* signals) {
  const double rate = reader->info().sample_rate_hz;
  const std::int64_t cap = std::max<std::int64_t>(
      16, std::min(kMaxBlockFrames, static_cast<std::int64_t>(options.max_block_s * rate)));
  const std::int64_t margin = static_cast<std::int64_t>(kBlockMarginS * rate);
  const std::int64_t search = std::min(cap / 4, static_cast<std::int64_t>(kMaxCutSearchS * rate));
  // (the look-ahead is `search` long too)
  const int threads = ResolveThreads(options.threads);
  DetectOptions per_block = options;
  per_block.threads = threads;

  struct InFlight {
    double own_lo_s, own_hi_s, data_end_s;
    bool last;
    std::future<BlockResult> result;
  };
  std::deque<InFlight> in_flight;
  // The jobs read per_block, rate and choices: an error that ends the reading waits for the
  // ones running (those not started yet return at once) before they go out of scope.
  std::atomic<bool> cancelled{false};
  struct Drain {
    std::deque<InFlight>* jobs;
    std::atomic<bool>* cancelled;
    ~Drain() {
      cancelled->store(true);
      for (InFlight& f : *jobs)
        if (f.result.valid()) f.result.wait();
    }
  } drain{&in_flight, &cancelled};
  auto merge_oldest = [&] {
    InFlight& f = in_flight.front();
    MergeBlockResult(f.result.get(), f.own_lo_s, f.own_hi_s, f.data_end_s, f.last, signals);
    in_flight.pop_front();
  };
  reader->Skip(i0);
  std::vector<std::vector<float>> buf(static_cast<std::size_t>(reader->info().channels));
  std::int64_t buf_start = i0;
  double own_lo_s = -std::numeric_limits<double>::infinity();
  for (bool first = true;; first = false) {
    // Fill the block up to `cap` frames (or the window's end).
    for (;;) {
      const std::int64_t have = static_cast<std::int64_t>(buf.front().size());
      const std::int64_t want = std::min(cap - have, i1 - (buf_start + have));
      if (want <= 0 || reader->Read(want, &buf) == 0) break;
    }
    const std::int64_t buf_end = buf_start + static_cast<std::int64_t>(buf.front().size());
    Block b;
    b.start = buf_start;
    b.own_lo_s = own_lo_s;
    b.last = buf_end >= i1 || buf_end - buf_start < cap;
    std::int64_t cut = buf_end;
    if (!b.last) {  // the third quarter, before the look-ahead
      const std::size_t lo = static_cast<std::size_t>(buf_end - 2 * search - buf_start);
      const std::size_t hi = static_cast<std::size_t>(buf_end - search - buf_start);
      cut = buf_start + static_cast<std::int64_t>(QuietestCut(buf, lo, hi, rate));
    }
    b.own_hi_s = b.last ? std::numeric_limits<double>::infinity() : static_cast<double>(cut) / rate;
    b.data_end_s = static_cast<double>(buf_end) / rate;
    // The block takes frames [buf_start, buf_end); the next starts kBlockMarginS before the cut.
    const std::int64_t next = b.last ? buf_end : std::max(buf_start, cut - margin);
    for (std::vector<float>& c : buf) {
      std::vector<float> rest(c.begin() + static_cast<std::ptrdiff_t>(next - buf_start), c.end());
      b.channels.push_back(std::move(c));
      c = std::move(rest);
    }
    buf_start = next;
    own_lo_s = b.own_hi_s;
    const double lo_s = b.own_lo_s, hi_s = b.own_hi_s, end_s = b.data_end_s;
    const bool last = b.last;
    if ((first && last) || threads == 1) {  // on this thread, with all the threads for its stages
      MergeBlockResult(DetectBlock(b, rate, choices, per_block), lo_s, hi_s, end_s, last, signals);
    } else {
      auto job = [&, b = std::move(b)] {
        return cancelled.load() ? BlockResult{} : DetectBlock(b, rate, choices, per_block);
      };
      in_flight.push_back({lo_s, hi_s, end_s, last, Async(threads, std::move(job))});
      while (static_cast<int>(in_flight.size()) > threads) merge_oldest();
    }
    if (last) break;
  }
  reader->Skip(std::numeric_limits<std::int64_t>::max());
  while (!in_flight.empty()) merge_oldest();
}

}  // namespace bouncecal
