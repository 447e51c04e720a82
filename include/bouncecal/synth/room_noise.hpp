// bouncecal/synth/room_noise.hpp — a room's background noise, measured on a recording's quiet
// stretches and synthesised for any length.
//
// The model is the noise's power spectral density (PSD), estimated with a robust Welch method:
// Hann frames with 50 % overlap over every quiet stretch, and per frequency bin the MEDIAN of the
// frames' periodograms divided by ln 2 (the median of a chi-square variable with 2 degrees of
// freedom is ln 2 times its mean), so that a door, a cough or an unmarked bounce in a few frames
// does not colour the model. Synthesis shapes white Gaussian noise with the PSD: a zero-phase FIR
// filter whose magnitude is sqrt(PSD) (one frame long, Hann-tapered), applied by FFT convolution
// with overlap-add. Every output sample is a fresh random value: nothing of the recording is
// repeated, so the noise has no period (a looped stretch of a recording would repeat its
// transients and become a metronome for a detector).
//
//   RoomNoise n = RoomNoise::FromSegments({quiet1, quiet2}, 44100.0);
//   std::vector<double> x = n.Synthesize(10 * 44100, /*seed=*/7);   // 10 s of that room
//   n.rms();                                                          // full-scale RMS
//
// Hum and other tones of the room come out as narrow-band noise of the same power (a random
// amplitude and phase instead of a steady sine): the model keeps the power spectrum, not phases.
// Throws Error(kBadParameter) when the quiet stretches hold less than two frames of the shortest
// frame (kMinFrame samples each), or for a sample rate outside [8 kHz, 384 kHz].
#pragma once

#include <cstdint>
#include <vector>

#include <nlohmann/json.hpp>

namespace bouncecal {

class RoomNoise {
 public:
  // Frame length bounds (samples, powers of two): 256 resolves 172 Hz at 44.1 kHz, enough for a
  // room's broadband colour; 4096 resolves 11 Hz (hum lines) when there is enough quiet.
  static constexpr int kMinFrame = 256;
  static constexpr int kMaxFrame = 4096;
  // Frames at least per estimate when the quiet allows: the median of 16 periodograms is within
  // about +-1.5 dB of the mean per bin (chi-square, 2 dof), and bands average many bins.
  static constexpr int kTargetFrames = 16;

  RoomNoise() = default;
  // Estimates the PSD of the quiet stretches (each a run of samples at rate_hz). The frame is the
  // longest power of two in [kMinFrame, kMaxFrame] that gives kTargetFrames frames.
  static RoomNoise FromSegments(const std::vector<std::vector<double>>& segments, double rate_hz);

  // `frames` samples of noise with this PSD (and so this RMS), deterministic in seed.
  std::vector<double> Synthesize(std::int64_t frames, std::uint64_t seed) const;
  // Adds gain times Synthesize(out->size(), seed) to *out (no second buffer of that length).
  void AddTo(double gain, std::uint64_t seed, std::vector<double>* out) const;

  double sample_rate_hz() const { return rate_hz_; }
  int frame() const { return frame_; }
  int frames_used() const { return frames_used_; }
  double quiet_s() const { return quiet_s_; }
  // One-sided PSD, full scale^2 per Hz, bins k = 0..frame/2 at k * rate / frame.
  const std::vector<double>& psd() const { return psd_; }
  // RMS of the modelled noise (full scale): sqrt of the PSD integrated over frequency.
  double rms() const;
  // Power in each band [edges[i], edges[i+1]) as dB re full scale^2.
  std::vector<double> BandLevelsDb(const std::vector<double>& edges_hz) const;
  // {"method", "frame", "frames_used", "quiet_s", "rms", "band_edges_hz", "band_levels_db"}.
  nlohmann::json ToJson() const;

 private:
  double rate_hz_ = 0.0;
  int frame_ = 0;
  int frames_used_ = 0;
  double quiet_s_ = 0.0;
  std::vector<double> psd_;
};

// Robust Welch PSD (one-sided, full scale^2 per Hz, frame/2 + 1 bins) of the segments: Hann
// frames of `frame` samples, hop frame/2, per bin the median periodogram / ln 2. Segments shorter
// than a frame are skipped; *frames_used (optional) counts the frames. Throws Error(kBadParameter)
// when no frame fits.
std::vector<double> RobustPsd(const std::vector<std::vector<double>>& segments, int frame,
                              double rate_hz, int* frames_used = nullptr);
// Power of a one-sided PSD (bins k * rate / frame) in each band [edges[i], edges[i+1]), dB re
// full scale^2 (-300 for an empty band).
std::vector<double> PsdBandLevelsDb(const std::vector<double>& psd, double rate_hz,
                                    const std::vector<double>& edges_hz);
// Octave band edges from 62.5 Hz up to the Nyquist frequency (the last band ends there).
std::vector<double> OctaveBandEdgesHz(double rate_hz);

}  // namespace bouncecal
