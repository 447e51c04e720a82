// The test-recording renderers' random numbers (internal to src/synth): one fixed generator, so
// that the same seed gives bit-identical recordings on every platform (std:: distributions are
// implementation-defined).
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace bouncecal::synth_random {

// SplitMix64 (Steele, Lea & Flood 2014): tiny, fast, identical on every platform.
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed) {}
  std::uint64_t Next() {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ULL);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(Next() >> 11) * (1.0 / 9007199254740992.0); }
  double Uniform(double a, double b) { return a + (b - a) * Uniform(); }
  // Standard normal, Box–Muller (both values used).
  double Normal() {
    if (has_spare_) {
      has_spare_ = false;
      return spare_;
    }
    double u1 = Uniform();
    while (u1 <= 0.0) u1 = Uniform();
    const double u2 = Uniform();
    const double r = std::sqrt(-2.0 * std::log(u1));
    spare_ = r * std::sin(2.0 * std::numbers::pi * u2);
    has_spare_ = true;
    return r * std::cos(2.0 * std::numbers::pi * u2);
  }

 private:
  std::uint64_t state_;
  double spare_ = 0.0;
  bool has_spare_ = false;
};

// An independent stream per purpose, so e.g. adding distractors does not change the noise.
inline Rng Stream(std::uint64_t seed, std::uint64_t purpose, std::uint64_t index = 0) {
  Rng mix(seed ^ (purpose * 0xD1B54A32D192ED03ULL) ^ (index * 0x8CB92BA72F3D8DD7ULL));
  return Rng(mix.Next());
}

}  // namespace bouncecal::synth_random
