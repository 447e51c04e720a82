// A room's background noise: robust Welch PSD of quiet stretches, and white noise shaped by it
// (see include/bouncecal/synth/room_noise.hpp).
#include "bouncecal/synth/room_noise.hpp"

#include <fftw3.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <mutex>
#include <new>
#include <numbers>
#include <string>

#include "bouncecal/core/error.hpp"
#include "random.hpp"

namespace bouncecal {
namespace {

// FFTW's planner is not thread-safe; plans are made and destroyed under this lock.
std::mutex& PlanLock() {
  static std::mutex m;
  return m;
}

// One real FFT of n points, both directions, with its own arrays.
class RealFft {
 public:
  explicit RealFft(int n) : n_(n) {
    std::lock_guard<std::mutex> lock(PlanLock());
    real_ = static_cast<double*>(fftw_malloc(sizeof(double) * static_cast<std::size_t>(n)));
    spec_ = static_cast<fftw_complex*>(
        fftw_malloc(sizeof(fftw_complex) * static_cast<std::size_t>(n / 2 + 1)));
    if (!real_ || !spec_) {
      fftw_free(real_);
      fftw_free(spec_);
      throw std::bad_alloc();
    }
    forward_ = fftw_plan_dft_r2c_1d(n, real_, spec_, FFTW_ESTIMATE);
    inverse_ = fftw_plan_dft_c2r_1d(n, spec_, real_, FFTW_ESTIMATE);
  }
  ~RealFft() {
    std::lock_guard<std::mutex> lock(PlanLock());
    fftw_destroy_plan(forward_);
    fftw_destroy_plan(inverse_);
    fftw_free(real_);
    fftw_free(spec_);
  }
  RealFft(const RealFft&) = delete;
  RealFft& operator=(const RealFft&) = delete;

  double* real() { return real_; }
  fftw_complex* spec() { return spec_; }
  void Forward() { fftw_execute(forward_); }
  void Inverse() { fftw_execute(inverse_); }  // unnormalised: n times the inverse DFT

 private:
  int n_;
  double* real_ = nullptr;
  fftw_complex* spec_ = nullptr;
  fftw_plan forward_ = nullptr, inverse_ = nullptr;
};

std::vector<double> Hann(int n) {  // periodic Hann (sums to a constant at 50 % overlap)
  std::vector<double> w(static_cast<std::size_t>(n));
  for (int i = 0; i < n; ++i)
    w[static_cast<std::size_t>(i)] =
        0.5 - 0.5 * std::cos(2.0 * std::numbers::pi * i / static_cast<double>(n));
  return w;
}

// The white noise of RoomNoise::Synthesize: its own stream, apart from any renderer's.
constexpr std::uint64_t kRoomNoisePurpose = 101;

}  // namespace

std::vector<double> RobustPsd(const std::vector<std::vector<double>>& segments, int frame,
                              double rate_hz, int* frames_used) {
  if (frame < 8 || (frame & (frame - 1)) != 0)
    throw Error(ErrorCode::kBadParameter,
                "noise PSD: frame " + std::to_string(frame) + " is not a power of two >= 8");
  const std::size_t n = static_cast<std::size_t>(frame), bins = n / 2 + 1;
  const std::vector<double> w = Hann(frame);
  double w2 = 0.0;
  for (double v : w) w2 += v * v;
  RealFft fft(frame);
  std::vector<std::vector<double>> per_bin(bins);
  int used = 0;
  for (const std::vector<double>& s : segments) {
    for (std::size_t start = 0; start + n <= s.size(); start += n / 2) {
      for (std::size_t i = 0; i < n; ++i) fft.real()[i] = s[start + i] * w[i];
      fft.Forward();
      for (std::size_t k = 0; k < bins; ++k) {
        const double p = fft.spec()[k][0] * fft.spec()[k][0] + fft.spec()[k][1] * fft.spec()[k][1];
        const double one_sided = (k == 0 || k == bins - 1) ? 1.0 : 2.0;
        per_bin[k].push_back(one_sided * p / (rate_hz * w2));
      }
      ++used;
    }
  }
  if (used == 0)
    throw Error(ErrorCode::kBadParameter, "noise PSD: no quiet stretch holds one frame of " +
                                              std::to_string(frame) + " samples");
  if (frames_used) *frames_used = used;
  std::vector<double> psd(bins);
  for (std::size_t k = 0; k < bins; ++k) {
    std::vector<double>& v = per_bin[k];
    std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
    // The median of a chi-square variable with 2 degrees of freedom is ln 2 times its mean.
    psd[k] = v[v.size() / 2] / std::numbers::ln2;
  }
  psd[0] = 0.0;  // a DC offset is the recorder's, not the room's noise
  return psd;
}

std::vector<double> PsdBandLevelsDb(const std::vector<double>& psd, double rate_hz,
                                    const std::vector<double>& edges_hz) {
  const double df = rate_hz / (2.0 * static_cast<double>(psd.size() - 1));
  std::vector<double> out;
  for (std::size_t b = 0; b + 1 < edges_hz.size(); ++b) {
    double p = 0.0;
    for (std::size_t k = 0; k < psd.size(); ++k) {
      const double f = static_cast<double>(k) * df;
      if (f >= edges_hz[b] && f < edges_hz[b + 1]) p += psd[k] * df;
    }
    out.push_back(p > 0.0 ? 10.0 * std::log10(p) : -300.0);
  }
  return out;
}

std::vector<double> OctaveBandEdgesHz(double rate_hz) {
  std::vector<double> edges;
  for (double f = 62.5; f < 0.5 * rate_hz; f *= 2.0) edges.push_back(f);
  edges.push_back(0.5 * rate_hz);
  return edges;
}

RoomNoise RoomNoise::FromSegments(const std::vector<std::vector<double>>& segments,
                                  double rate_hz) {
  if (!(rate_hz >= 8000.0 && rate_hz <= 384000.0))
    throw Error(ErrorCode::kBadParameter,
                "room noise: sample rate " + std::to_string(rate_hz) + " Hz outside 8-384 kHz");
  std::size_t total = 0;
  for (const auto& s : segments) total += s.size();
  // The longest frame that still gives kTargetFrames frames (hop frame/2) in the longest
  // stretches, within [kMinFrame, kMaxFrame].
  int frame = kMaxFrame;
  auto frames_with = [&](int f) {
    std::size_t count = 0;
    for (const auto& s : segments)
      if (s.size() >= static_cast<std::size_t>(f))
        count += (s.size() - static_cast<std::size_t>(f)) / static_cast<std::size_t>(f / 2) + 1;
    return count;
  };
  while (frame > kMinFrame && frames_with(frame) < static_cast<std::size_t>(kTargetFrames))
    frame /= 2;
  if (frames_with(frame) < 2)
    throw Error(ErrorCode::kBadParameter,
                "room noise: the quiet stretches (" + std::to_string(total) +
                    " samples) hold fewer than two frames of " + std::to_string(kMinFrame) +
                    " samples: too little quiet to measure the room's noise");
  RoomNoise n;
  n.rate_hz_ = rate_hz;
  n.frame_ = frame;
  n.quiet_s_ = static_cast<double>(total) / rate_hz;
  n.psd_ = RobustPsd(segments, frame, rate_hz, &n.frames_used_);
  return n;
}

double RoomNoise::rms() const {
  if (psd_.empty()) return 0.0;
  const double df = rate_hz_ / static_cast<double>(frame_);
  double p = 0.0;
  for (double v : psd_) p += v * df;
  return std::sqrt(p);
}

std::vector<double> RoomNoise::BandLevelsDb(const std::vector<double>& edges_hz) const {
  return PsdBandLevelsDb(psd_, rate_hz_, edges_hz);
}

std::vector<double> RoomNoise::Synthesize(std::int64_t frames, std::uint64_t seed) const {
  std::vector<double> out(static_cast<std::size_t>(std::max<std::int64_t>(frames, 0)), 0.0);
  AddTo(1.0, seed, &out);
  return out;
}

void RoomNoise::AddTo(double gain, std::uint64_t seed, std::vector<double>* out_samples) const {
  std::vector<double>& out = *out_samples;
  if (out.empty() || psd_.empty() || gain == 0.0) return;
  const int n = frame_;
  const std::size_t nn = static_cast<std::size_t>(n);
  // The zero-phase filter: |H(f)| = sqrt(PSD(f) rate / 2) makes unit white noise one-sided
  // PSD(f); its impulse response (the inverse DFT of the n bins: exact at every bin) centred in
  // n taps, scaled so that the output RMS is exactly rms(). No taper: a window would smooth the
  // spectrum over a few bins more than the estimate already is (a hum line would leak).
  std::vector<double> h(nn);
  {
    RealFft design(n);
    for (std::size_t k = 0; k < psd_.size(); ++k) {
      design.spec()[k][0] = std::sqrt(psd_[k] * rate_hz_ / 2.0);
      design.spec()[k][1] = 0.0;
    }
    design.Inverse();
    double e = 0.0;
    for (std::size_t i = 0; i < nn; ++i) {
      h[i] = design.real()[(i + nn / 2) % nn] / static_cast<double>(n);
      e += h[i] * h[i];
    }
    const double scale = e > 0.0 ? gain * rms() / std::sqrt(e) : 0.0;
    for (double& v : h) v *= scale;
  }
  // Overlap-add: blocks of n white samples, FFT of 2n points (the linear convolution of a block
  // with n taps fits). The first n - 1 outputs (the filter filling up) are dropped, so the noise
  // is stationary from the first sample.
  const std::size_t m = 2 * nn;
  RealFft conv(static_cast<int>(m));
  std::vector<std::complex<double>> hspec(nn + 1);
  std::fill(conv.real(), conv.real() + m, 0.0);
  std::copy(h.begin(), h.end(), conv.real());
  conv.Forward();
  for (std::size_t k = 0; k <= nn; ++k) hspec[k] = {conv.spec()[k][0], conv.spec()[k][1]};
  synth_random::Rng rng = synth_random::Stream(seed, kRoomNoisePurpose);
  const std::size_t total = out.size() + nn - 1;  // white samples needed
  for (std::size_t start = 0; start < total; start += nn) {
    std::fill(conv.real(), conv.real() + m, 0.0);
    for (std::size_t i = 0; i < nn && start + i < total; ++i) conv.real()[i] = rng.Normal();
    conv.Forward();
    for (std::size_t k = 0; k <= nn; ++k) {
      const std::complex<double> v =
          std::complex<double>(conv.spec()[k][0], conv.spec()[k][1]) * hspec[k];
      conv.spec()[k][0] = v.real();
      conv.spec()[k][1] = v.imag();
    }
    conv.Inverse();
    for (std::size_t i = 0; i < m; ++i) {
      // Convolution output index start + i; the kept output j = that - (n - 1).
      const std::size_t full = start + i;
      if (full < nn - 1) continue;
      const std::size_t j = full - (nn - 1);
      if (j >= out.size()) break;
      out[j] += conv.real()[i] / static_cast<double>(m);
    }
  }
}

nlohmann::json RoomNoise::ToJson() const {
  const std::vector<double> edges = OctaveBandEdgesHz(rate_hz_);
  return {{"method",
           "robust Welch PSD of the quiet stretches (Hann frames, 50 % overlap, per-bin median "
           "/ ln 2); white Gaussian noise shaped by a zero-phase FIR |H| = sqrt(PSD), FFT "
           "overlap-add; never a copy of the recording"},
          {"frame", frame_},
          {"frames_used", frames_used_},
          {"quiet_s", quiet_s_},
          {"rms", rms()},
          {"band_edges_hz", edges},
          {"band_levels_db", BandLevelsDb(edges)}};
}

}  // namespace bouncecal
