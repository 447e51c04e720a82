// What a user's recording must never do to the detector: signals that are not a bouncing ball
// (one click, a click in digital silence, a metronome), handling taps before a drop, and a
// real ball's irregular bounce. Each stage of plausibility.hpp also has its own test.
#include "bouncecal/acoustic/plausibility.hpp"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <sstream>
#include <string>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"

namespace bouncecal {
namespace {

constexpr double kRate = 48000.0;

Audio InMemory(std::vector<float> x, const std::string& name) {
  Audio a;
  a.info.path = name;
  a.info.sample_rate_hz = kRate;
  a.info.channels = 1;
  a.info.frames = static_cast<std::int64_t>(x.size());
  ClippingReport r;
  for (float v : x) r.peak = std::max(r.peak, static_cast<double>(std::fabs(v)));
  a.clipping.push_back(r);
  a.channels.push_back(std::move(x));
  return a;
}

// A 5 ms noise click (exponential decay, time constant 1.25 ms) of peak ~amp at t_s.
void AddClick(std::vector<float>* x, double t_s, double amp, std::mt19937* rng) {
  std::normal_distribution<double> g(0.0, 1.0);
  const long k0 = std::lround(t_s * kRate);
  for (long n = 0; n < static_cast<long>(0.005 * kRate); ++n)
    (*x)[static_cast<std::size_t>(k0 + n)] +=
        static_cast<float>(amp / 3.0 * g(*rng) * std::exp(-static_cast<double>(n) / 60.0));
}

struct Outcome {
  ErrorCode code = ErrorCode::kOk;
  std::string message;
  DetectionResult result;
};

Outcome RunDetect(const Audio& a, const DetectOptions& o = {}) {
  Outcome out;
  try {
    out.result = DetectImpacts(a, o);
  } catch (const Error& e) {
    out.code = e.code();
    out.message = e.what();
  }
  return out;
}

// Every impact of the main sequence, for failure messages.
std::string Describe(const DetectionResult& r) {
  std::ostringstream s;
  for (std::size_t q = 0; q < r.sequences.size(); ++q) {
    s << "sequence " << q << ":";
    for (const Impact& i : r.sequences[q].impacts)
      s << " " << i.time_s << " (" << i.snr_db << " dB, a " << i.amplitude << ")";
    s << "\n";
  }
  for (const Warning& w : r.warnings) s << w.code << ": " << w.message << "\n";
  return s.str();
}

TEST(Trust, SingleClickInDitherIsNoBounceSequence) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<float> x(static_cast<std::size_t>(3 * kRate));
  for (float& v : x) v = static_cast<float>((u(rng) + u(rng)) / 32768.0);  // TPDF dither
  AddClick(&x, 1.0, 0.5, &rng);
  const Outcome o = RunDetect(InMemory(x, "click.wav"));
  EXPECT_EQ(o.code, ErrorCode::kNoBounces) << Describe(o.result);
  EXPECT_NE(o.message.find("click.wav"), std::string::npos) << o.message;
}

TEST(Trust, ClickInDigitalSilenceIsNoBounceSequence) {
  std::mt19937 rng(2);
  std::vector<float> x(static_cast<std::size_t>(3 * kRate), 0.0f);
  AddClick(&x, 1.0, 0.5, &rng);
  const Outcome o = RunDetect(InMemory(x, "silent_click.wav"));
  EXPECT_EQ(o.code, ErrorCode::kNoBounces) << Describe(o.result);
}

TEST(Trust, MetronomeIsNoBounceSequence) {
  // The lead's pre-stop check: 4 equal noise clicks 0.6 s apart in Gaussian noise.
  std::mt19937 rng(3);
  std::normal_distribution<double> g(0.0, 3e-4);
  std::vector<float> x(static_cast<std::size_t>(3 * kRate));
  for (float& v : x) v = static_cast<float>(g(rng));
  for (double c : {0.6, 1.2, 1.8, 2.4}) AddClick(&x, c, 1.2, &rng);
  const Outcome o = RunDetect(InMemory(x, "metronome.wav"));
  EXPECT_EQ(o.code, ErrorCode::kNoBounces) << Describe(o.result);
  EXPECT_NE(o.message.find("do not shrink"), std::string::npos) << o.message;
}

}  // namespace
}  // namespace bouncecal
