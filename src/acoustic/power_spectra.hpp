// The power spectra of short windowed frames, four frames at a time (internal to the library,
// src/): the onset detector's novelty takes one per STFT hop, 1.8 million for a 10-minute
// recording at 48 kHz, of 64 points each.
//
// FFTW transforms one 64-point frame in ~85 ns on this project's machine (its plan for one
// real transform of that size is scalar; a batched plan, howmany 256, took 100 ns per frame).
// Here one radix-2 transform runs on four frames at once, each frame a lane of 4-lane vectors,
// as the real input of n points packed into a complex one of n/2 points and split after.
// The values are the same discrete Fourier transform's (to rounding: the power of a bin differs
// from FFTW's by a few units in the last place of the frame's largest power).
#pragma once

#include <cstddef>
#include <vector>

namespace bouncecal {

class PowerSpectra4 {
 public:
  // The sizes it transforms: powers of two from kMinPoints to kMaxPoints.
  static constexpr int kMinPoints = 8;
  static constexpr int kMaxPoints = 256;
  static bool Supports(int n);

  // n: the frame's points (Supports(n)). window: n weights applied to every frame.
  PowerSpectra4(int n, std::vector<double> window);

  // out[j][k] = |X_j(k)|^2 for k in [0, n/2], X_j the DFT (sum_i x_i e^(-2 pi i k i' / n),
  // unnormalised, like FFTW's r2c) of frame j's samples src[j][0, n) times the window.
  void Compute(const float* const src[4], double* const out[4]) const;

  int points() const { return n_; }

 private:
  int n_;
  std::vector<double> window_;
  std::vector<double> cos_, sin_;  // the complex transform's twiddles, e^(-2 pi i j / (n/2))
  std::vector<double> split_cos_, split_sin_;  // the split's, e^(-2 pi i k / n), k in [0, n/2]
  std::vector<int> bit_reversed_;              // the load order of the n/2 complex points
};

}  // namespace bouncecal
