// Tests of the real-sound test recordings (synth/realsound.hpp, synth/room_noise.hpp): the truth
// times are where the sound is, the noise has the room's spectrum and no period, the schedule is
// physical, identical drops are identical, the same seed gives the same file, bad input fails.
//
// Two kinds of source: a recording rendered by synth with exact marks (always available: the
// alignment is checked against known onsets), and the real recordings of ../shared/recordings
// (skipped cleanly when the folder is absent, as on a user's machine, but not under CI=true).
//
// The measuring instrument is independent of the renderer's windowed-sinc placement: the lag
// between a stretch of the file and a cut is the maximum of their band-limited cross-correlation
// computed from the DFT (sum_k X_k conj(C_k) e^(2 pi i k tau / N), any real tau), refined to a
// thousandth of a sample.
#include "bouncecal/synth/realsound.hpp"

#include <fftw3.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

namespace fs = std::filesystem;
using testing_util::ScratchDir;

bool UnderCi() {
  const char* ci = std::getenv("CI");
  return ci != nullptr && std::string(ci) == "true";
}

#define REQUIRE_RECORDING(wav)                                            \
  do {                                                                    \
    if (!fs::exists(wav)) {                                               \
      if (UnderCi()) FAIL() << "CI=true but " << (wav) << " is missing";  \
      GTEST_SKIP() << "no " << (wav) << " (../shared/recordings absent)"; \
    }                                                                     \
  } while (0)

std::string Shared(const std::string& name) {
  return (fs::path(BOUNCECAL_SHARED_RECORDINGS) / (name + ".wav")).string();
}

// ---- the measuring instrument ------------------------------------------------------------------

struct LagFit {
  double lag = 0.0;   // samples: y(t) ~ gain * x(t - lag)
  double gain = 0.0;  // least-squares gain at that lag
};

// The band-limited lag of y against x (both starting at the same sample), searched in
// [-max_lag, max_lag] samples, from the DFT of both zero-padded to twice their length.
LagFit FitLag(const std::vector<double>& y, const std::vector<double>& x, double max_lag = 3.0) {
  std::size_t n = 1;
  while (n < 2 * std::max(x.size(), y.size())) n *= 2;
  auto dft = [n](const std::vector<double>& v) {
    std::vector<double> in(n, 0.0);
    std::copy(v.begin(), v.end(), in.begin());
    std::vector<std::complex<double>> out(n / 2 + 1);
    fftw_plan p = fftw_plan_dft_r2c_1d(static_cast<int>(n), in.data(),
                                       reinterpret_cast<fftw_complex*>(out.data()), FFTW_ESTIMATE);
    fftw_execute(p);
    fftw_destroy_plan(p);
    return out;
  };
  const auto Y = dft(y), X = dft(x);
  double xx = 0.0;
  for (std::size_t k = 0; k < X.size(); ++k)
    xx += (k == 0 || k == n / 2 ? 1.0 : 2.0) * std::norm(X[k]);
  auto corr = [&](double tau) {  // sum_t y(t) x(t - tau) times n
    double s = 0.0;
    for (std::size_t k = 0; k < Y.size(); ++k) {
      const double w = (k == 0 || k == n / 2) ? 1.0 : 2.0;
      const double ph = -2.0 * M_PI * static_cast<double>(k) * tau / static_cast<double>(n);
      s += w * (Y[k] * std::conj(X[k]) * std::complex<double>(std::cos(ph), -std::sin(ph))).real();
    }
    return s;
  };
  // The sign: x delayed by tau has spectrum X e^(-2 pi i k tau / n); corr(tau) = <y, x(. - tau)>.
  double best = 0.0, best_c = -1e300;
  for (double tau = -max_lag; tau <= max_lag; tau += 0.05) {
    const double c = corr(tau);
    if (c > best_c) best_c = c, best = tau;
  }
  for (double step = 0.025; step > 1e-4; step /= 2.0)
    for (double cand : {best - step, best + step}) {
      const double c = corr(cand);
      if (c > best_c) best_c = c, best = cand;
    }
  return {best, best_c / xx};
}

std::vector<double> Stretch(const std::vector<float>& x, std::int64_t start, std::size_t n) {
  std::vector<double> out(n, 0.0);
  for (std::size_t i = 0; i < n; ++i) {
    const std::int64_t j = start + static_cast<std::int64_t>(i);
    if (j >= 0 && j < static_cast<std::int64_t>(x.size())) out[i] = x[static_cast<std::size_t>(j)];
  }
  return out;
}

// Lag (against the truth: 0 = the cut sits exactly at its truth time) and gain of one impact.
LagFit ImpactFit(const SoundSource& src, const RealSoundResult& r, std::size_t d, std::size_t k) {
  const RealSoundCut& cut = src.cuts[static_cast<std::size_t>(r.cut_of_impact[d][k])];
  const double pos = r.truth[d][k].time_s * src.sample_rate_hz - cut.onset_index;  // of cut[0]
  const auto start = static_cast<std::int64_t>(std::floor(pos));
  const std::vector<double> cut_d(cut.samples.begin(), cut.samples.end());
  LagFit f = FitLag(Stretch(r.recording.channels[0], start, cut.samples.size()), cut_d);
  f.lag -= pos - static_cast<double>(start);
  return f;
}

// Whether impact k of drop d is heard alone: no other impact within its cut's length.
bool Alone(const SoundSource& src, const RealSoundResult& r, std::size_t d, std::size_t k) {
  const RealSoundCut& cut = src.cuts[static_cast<std::size_t>(r.cut_of_impact[d][k])];
  const double len = static_cast<double>(cut.samples.size()) / src.sample_rate_hz;
  const auto& t = r.truth[d];
  return (k == 0 || t[k].time_s - t[k - 1].time_s > len) &&
         (k + 1 == t.size() || t[k + 1].time_s - t[k].time_s > len);
}

// ---- a source made by synth, with exact marks ------------------------------------------------

// pingpong-wood rendered without hum and stray clicks, the marks at the exact onsets (H). Its
// contact duration is fixed, so every impact makes the same sound, scaled.
struct SynthSource {
  ScratchDir dir{"realsound"};
  std::string wav = dir / "synth_source.wav";
  std::vector<double> onsets;
  explicit SynthSource(double shift_mark_2_s = 0.0, double snr_db = 50.0) {
    SynthSpec spec = SynthPreset("pingpong-wood");
    spec.scene.drop.height_m = 1.0;  // intervals long enough for the table to fall quiet
    spec.render.hum_hz = 0.0;
    spec.render.distractors = 0;
    spec.render.snr_db = snr_db;
    spec.render.noise_color = NoiseColor::kWhite;
    const SynthResult r = Synthesize(spec);
    WriteAudio(wav, r.recording.channels, r.recording.sample_rate_hz, {"FLOAT"});
    std::ofstream csv(dir / "synth_source.impacts.csv");
    csv << "k,t_impact_s,confidence,dt_prev_s,e_k,note\n";
    for (std::size_t k = 0; k < r.recording.drops[0].size(); ++k) {
      onsets.push_back(r.recording.drops[0][k].onset_s);
      const double mark = onsets.back() + (k == 2 ? shift_mark_2_s : 0.0);
      csv << k << "," << FormatShortest(mark) << ",H,,,\"\"\n";
    }
  }
};

TEST(RealSoundSource, CutsOfExactMarksAlignWithinMicroseconds) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  ASSERT_GE(src.cuts.size(), 3u) << "a closure needs three cuts";
  ASSERT_TRUE(src.alignment_sigma_s);
  // The same sound (one contact duration, linear modes) at other speeds: the lags are zero.
  for (const RealSoundCut& c : src.cuts) {
    EXPECT_LT(std::fabs(c.lag_s), 1e-6) << "cut of mark " << c.mark;
    EXPECT_GT(c.correlation, 0.99);
    EXPECT_NEAR(c.onset_s, s.onsets[static_cast<std::size_t>(c.mark)], 1e-6);
  }
  EXPECT_LT(*src.alignment_sigma_s, 1e-6);
  // Loudest first, each cut's peak its own.
  for (std::size_t i = 1; i < src.cuts.size(); ++i)
    EXPECT_GE(src.cuts[i - 1].peak, src.cuts[i].peak);
}

TEST(RealSoundSource, AMisplacedMarkIsCorrectedByTheAlignment) {
  const SynthSource s(3e-4, 30.0);  // mark 2 placed 0.3 ms late, a noisier recording
  const SoundSource src = LoadSoundSource(s.wav);
  bool seen = false;
  for (const RealSoundCut& c : src.cuts) {
    if (c.mark != 2) continue;
    seen = true;
    // At 30 dB the noise moves a lag by a few microseconds; the closure of the lags sees it.
    EXPECT_NEAR(c.lag_s, -3e-4, 1e-5);
    EXPECT_NEAR(c.onset_s, s.onsets[2], 1e-5);
  }
  ASSERT_TRUE(seen) << "mark 2 is among the loudest clean cuts";
  ASSERT_TRUE(src.alignment_sigma_s);
  EXPECT_GT(*src.alignment_sigma_s, 1e-7);
  EXPECT_LT(*src.alignment_sigma_s, 1e-5);
}

TEST(RealSoundSource, SpeedsOfTheCutsComeFromTheMarkedIntervals) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  for (const RealSoundCut& c : src.cuts) {
    const auto k = static_cast<std::size_t>(c.mark);
    if (k == 0) continue;
    EXPECT_DOUBLE_EQ(c.speed_m_s, 9.81 * (src.marks[k].time_s - src.marks[k - 1].time_s) / 2.0);
  }
}

// ---- rendering: truth, schedule, determinism -------------------------------------------------

RealSoundSpec VacuumSpec(const SoundSource& src, double e) {
  RealSoundSpec spec = RealSoundSpecFor(src);
  spec.scene.effects.drag = DragModel::kNone;
  spec.scene.effects.buoyancy = false;
  spec.restitution = RestitutionModel::Constant(e);
  return spec;
}

TEST(RealSoundRender, TruthTimesAreWhereTheSoundIs) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  RealSoundSpec spec = VacuumSpec(src, 0.8);
  spec.scene.drop.height_m = 4.0 * spec.scene.drop.height_m.value();  // long first intervals
  spec.cut_choice = CutChoice::kPerImpact;
  spec.noise_gain_db = -20.0;
  const RealSoundResult r = RenderRealSound(src, spec);
  std::set<int> cuts_checked;
  for (std::size_t k = 0; k < r.truth[0].size(); ++k) {
    if (!Alone(src, r, 0, k)) continue;
    const LagFit f = ImpactFit(src, r, 0, k);
    EXPECT_LT(std::fabs(f.lag), 0.01) << "impact " << k << " (samples)";
    cuts_checked.insert(r.cut_of_impact[0][k]);
  }
  EXPECT_GE(cuts_checked.size(), 2u);
}

TEST(RealSoundRender, ScheduleIsPhysicalAndAmplitudesFollowSpeed) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  for (double a : {1.0, 2.0}) {
    RealSoundSpec spec = VacuumSpec(src, 0.75);
    spec.scene.drop.height_m = 4.0 * spec.scene.drop.height_m.value();
    spec.amplitude_exponent = a;
    spec.noise = false;
    spec.truth.scatter_e = 0.02;
    const RealSoundResult r = RenderRealSound(src, spec);
    const auto& t = r.truth[0];
    ASSERT_GE(t.size(), 6u);
    for (std::size_t k = 1; k + 1 < t.size(); ++k) {
      // Vacuum: the interval after impact k over the one before is impact k's own e.
      const double ratio = (t[k + 1].time_s - t[k].time_s) / (t[k].time_s - t[k - 1].time_s);
      EXPECT_NEAR(ratio, t[k].e(), 1e-9) << k;
    }
    const double v_cut = src.cuts[0].speed_m_s;
    int checked = 0;
    for (std::size_t k = 0; k < t.size(); ++k) {
      if (!Alone(src, r, 0, k)) continue;
      const LagFit f = ImpactFit(src, r, 0, k);
      EXPECT_NEAR(f.gain, r.output_gain * std::pow(t[k].v_in_m_s / v_cut, a), 1e-3 * f.gain)
          << "a " << a;
      ++checked;
    }
    EXPECT_GE(checked, 3);
  }
}

TEST(RealSoundRender, IdenticalDropsAreIdenticalVariedOnesAreNot) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  RealSoundSpec spec = VacuumSpec(src, 0.8);
  spec.drops.drops = 4;
  spec.drops.gap_min_s = 0.1;
  spec.drops.gap_max_s = 1.3;
  spec.truth.scatter_e = 0.01;
  spec.cut_choice = CutChoice::kPerImpact;
  spec.noise = false;
  const RealSoundResult r = RenderRealSound(src, spec);
  ASSERT_EQ(r.truth.size(), 4u);
  std::vector<double> gaps;
  for (std::size_t d = 1; d < 4; ++d) {
    ASSERT_EQ(r.truth[d].size(), r.truth[0].size());
    EXPECT_EQ(r.cut_of_impact[d], r.cut_of_impact[0]);
    gaps.push_back(r.truth[d][0].time_s - r.truth[d - 1].back().time_s);
    EXPECT_GE(gaps.back(), 0.1);
    EXPECT_LE(gaps.back(), 1.3);
    for (std::size_t k = 0; k < r.truth[0].size(); ++k) {
      EXPECT_NEAR(r.truth[d][k].time_s - r.truth[d][0].time_s,
                  r.truth[0][k].time_s - r.truth[0][0].time_s, 1e-12);
      EXPECT_EQ(r.truth[d][k].v_in_m_s, r.truth[0][k].v_in_m_s);
    }
    // The sound of the first 0.3 s of the copy is the original's at the copy's offset.
    const double rate = src.sample_rate_hz;
    const double shift = (r.truth[d][0].time_s - r.truth[0][0].time_s) * rate;
    const auto a0 = static_cast<std::int64_t>(r.truth[0][0].time_s * rate) - 100;
    const auto n = static_cast<std::size_t>(0.3 * rate);
    const auto ad = a0 + static_cast<std::int64_t>(std::floor(shift));
    const LagFit f =
        FitLag(Stretch(r.recording.channels[0], ad, n), Stretch(r.recording.channels[0], a0, n));
    EXPECT_NEAR(f.lag, shift - std::floor(shift), 0.02) << "drop " << d;
    EXPECT_NEAR(f.gain, 1.0, 2e-3);
  }
  EXPECT_NE(gaps[0], gaps[1]);  // random gaps

  spec.drops.height_spread = 0.3;
  spec.drops.e_spread = 0.05;
  const RealSoundResult v = RenderRealSound(src, spec);
  EXPECT_NE(v.truth[1][0].v_in_m_s, v.truth[0][0].v_in_m_s);
  EXPECT_NE(v.truth[1][1].e(), v.truth[0][1].e());
  EXPECT_NE(v.cut_of_impact[1], v.cut_of_impact[0]);
}

TEST(RealSoundRender, SameSeedGivesTheSameFileOtherSeedsDiffer) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  RealSoundSpec spec = VacuumSpec(src, 0.8);
  spec.drops.drops = 2;
  spec.cut_choice = CutChoice::kPerImpact;
  spec.seed = 11;
  const RealSoundResult a = RenderRealSound(src, spec);
  const RealSoundResult b = RenderRealSound(src, spec);
  EXPECT_EQ(a.recording.channels, b.recording.channels);
  EXPECT_EQ(DumpJson(RealSoundTruthJson(src, spec, a)), DumpJson(RealSoundTruthJson(src, spec, b)));
  spec.seed = 12;
  const RealSoundResult c = RenderRealSound(src, spec);
  EXPECT_NE(a.recording.channels, c.recording.channels);
}

TEST(RealSoundRender, TruthFileIsReadByLoadTruthWithItsExtraKeys) {
  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  RealSoundSpec spec = VacuumSpec(src, 0.8);
  const RealSoundResult whole = RenderRealSound(src, spec);
  spec.clip_start_s = 1.0;
  spec.clip_length_s = 0.9;
  const RealSoundResult r = RenderRealSound(src, spec);
  const std::string path = s.dir / "clip.truth.json";
  std::ofstream(path) << DumpJson(RealSoundTruthJson(src, spec, r), 1);
  const TruthFile t = LoadTruth(path);
  EXPECT_EQ(t.sample_rate_hz, src.sample_rate_hz);
  ASSERT_EQ(t.drops.size(), 1u);
  EXPECT_EQ(r.recording.channels[0].size(), static_cast<std::size_t>(0.9 * src.sample_rate_hz));
  for (const RenderedImpact& i : t.drops[0]) {
    EXPECT_GE(i.onset_s, 0.0);
    EXPECT_LT(i.onset_s, 0.9);
  }
  // The clip starts mid-sequence: its first impact is a later one of the drop, on its clock.
  std::size_t skipped = 0;
  while (whole.truth[0][skipped].time_s < 1.0) ++skipped;
  ASSERT_GT(skipped, 0u);
  EXPECT_EQ(t.drops[0].front().truth.v_in_m_s, whole.truth[0][skipped].v_in_m_s);
  EXPECT_NEAR(t.drops[0].front().onset_s, whole.truth[0][skipped].time_s - 1.0, 1e-12);
  const auto& rs = t.document.at("realsound");
  EXPECT_EQ(rs.at("cuts").size(), src.cuts.size());
  EXPECT_TRUE(rs.contains("alignment_sigma_s"));
  EXPECT_TRUE(rs.at("noise").contains("band_levels_db"));
  EXPECT_EQ(rs.at("clip_start_s").get<double>(), 1.0);
  EXPECT_TRUE(t.document.at("drops")[0].at("impacts")[0].contains("cut"));
}

// ---- the room's noise --------------------------------------------------------------------------

// Normalised autocorrelation of the 10-ms RMS envelope (mean removed), largest |rho| over lags
// from 0.5 s (beyond the envelope's own correlation time: a hum line 2 bins of 6 Hz wide keeps
// its envelope for ~0.2 s) to a third of the length: a metronome's beat, not the noise's colour.
double EnvelopePeriodicity(const std::vector<double>& x, double rate) {
  const auto w = static_cast<std::size_t>(0.01 * rate);
  std::vector<double> env;
  for (std::size_t i = 0; i + w <= x.size(); i += w) {
    double s = 0.0;
    for (std::size_t j = 0; j < w; ++j) s += x[i + j] * x[i + j];
    env.push_back(std::sqrt(s / static_cast<double>(w)));
  }
  double mean = 0.0;
  for (double v : env) mean += v;
  mean /= static_cast<double>(env.size());
  for (double& v : env) v -= mean;
  double var = 0.0;
  for (double v : env) var += v * v;
  double worst = 0.0;
  for (std::size_t lag = 50; lag < env.size() / 3; ++lag) {
    double c = 0.0;
    for (std::size_t i = 0; i + lag < env.size(); ++i) c += env[i] * env[i + lag];
    worst = std::max(worst, std::fabs(c / var));
  }
  return worst;
}

void ExpectRoomNoise(const RoomNoise& model) {
  const double rate = model.sample_rate_hz();
  const std::vector<double> x = model.Synthesize(static_cast<std::int64_t>(30.0 * rate), 5);
  // RMS as modelled (the filter's scale is exact; 30 s of noise estimate it to ~0.1 dB).
  double ss = 0.0;
  for (double v : x) ss += v * v;
  EXPECT_NEAR(20.0 * std::log10(std::sqrt(ss / static_cast<double>(x.size())) / model.rms()), 0.0,
              0.2);
  // The spectrum, octave band by octave band, within 1 dB of the model, measured with frames
  // four times the model's (so that the measurement's own leakage adds little to the model's),
  // in the bands that hold at least 8 of the model's bins and carry at least 1e-4 of the
  // strongest band's power (below, the Hann leakage of the neighbouring bands dominates).
  const std::vector<double> edges = OctaveBandEdgesHz(rate);
  const std::vector<double> want = model.BandLevelsDb(edges);
  const std::vector<double> got =
      PsdBandLevelsDb(RobustPsd({x}, 4 * model.frame(), rate), rate, edges);
  const double strongest = *std::max_element(want.begin(), want.end());
  int compared = 0;
  for (std::size_t b = 0; b < want.size(); ++b) {
    if (edges[b + 1] - edges[b] < 8.0 * rate / model.frame() || want[b] < strongest - 40.0)
      continue;
    EXPECT_NEAR(got[b], want[b], 1.0) << "band " << edges[b] << "-" << edges[b + 1] << " Hz";
    ++compared;
  }
  EXPECT_GE(compared, 4);
  // No period: fresh noise everywhere. (A 2-s loop of the same noise is caught by the measure.)
  const double periodicity = EnvelopePeriodicity(x, rate);
  std::printf("periodicity %.3f\n", periodicity);
  EXPECT_LT(periodicity, 0.12);
  std::vector<double> looped(x.size());
  const auto loop = static_cast<std::size_t>(2.0 * rate);
  for (std::size_t i = 0; i < x.size(); ++i) looped[i] = x[i % loop];
  EXPECT_GT(EnvelopePeriodicity(looped, rate), 0.9);
}

TEST(RoomNoiseModel, SynthesisHasTheModelsSpectrumLevelAndNoPeriod) {
  // A room with a coloured spectrum: white noise through a resonance, then measured.
  const double rate = 44100.0;
  std::vector<double> quiet(static_cast<std::size_t>(3.0 * rate));
  double y1 = 0.0, y2 = 0.0;
  unsigned seed = 7;
  for (double& v : quiet) {
    seed = seed * 1664525u + 1013904223u;
    const double w = (static_cast<double>(seed >> 8) / 16777216.0 - 0.5) * 1e-3;
    const double y = w + 1.6 * y1 - 0.8 * y2;
    y2 = y1;
    y1 = y;
    v = y;
  }
  const RoomNoise model = RoomNoise::FromSegments({quiet}, rate);
  EXPECT_EQ(model.frame(), RoomNoise::kMaxFrame);
  ExpectRoomNoise(model);
  // The model is the recording's spectrum: band levels of the quiet itself agree.
  const std::vector<double> edges = OctaveBandEdgesHz(rate);
  const std::vector<double> direct =
      PsdBandLevelsDb(RobustPsd({quiet}, model.frame(), rate), rate, edges);
  EXPECT_EQ(direct, model.BandLevelsDb(edges));
}

TEST(RoomNoiseModel, RefusesTooLittleQuietAndBadRates) {
  EXPECT_THROW(RoomNoise::FromSegments({std::vector<double>(300, 0.1)}, 44100.0), Error);
  EXPECT_THROW(RoomNoise::FromSegments({std::vector<double>(44100, 0.1)}, 1000.0), Error);
  EXPECT_THROW(RobustPsd({std::vector<double>(1000, 0.0)}, 100, 44100.0), Error);
}

// ---- the shared real recordings ------------------------------------------------------------

class SharedSources : public ::testing::TestWithParam<std::string> {};

TEST_P(SharedSources, CutsNoiseAndTruthOfARealRecording) {
  const std::string wav = Shared(GetParam());
  REQUIRE_RECORDING(wav);
  const SoundSource src = LoadSoundSource(wav);
  ASSERT_GE(src.cuts.size(), 1u);
  for (const RealSoundCut& c : src.cuts) {
    EXPECT_EQ(src.marks[static_cast<std::size_t>(c.mark)].confidence, 'H');
    EXPECT_LT(c.peak, 0.99);
    EXPECT_LE(std::fabs(c.lag_s), 1e-3);
  }
  ExpectRoomNoise(src.noise);
  // One drop like the recording's, every impact its own cut: the sound sits at its truth time.
  RealSoundSpec spec = RealSoundSpecFor(src);
  spec.cut_choice = CutChoice::kPerImpact;
  const RealSoundResult r = RenderRealSound(src, spec);
  int checked = 0;
  for (std::size_t k = 0; k < r.truth[0].size() && checked < 5; ++k) {
    if (!Alone(src, r, 0, k)) continue;
    const LagFit f = ImpactFit(src, r, 0, k);
    EXPECT_LT(std::fabs(f.lag), 0.05) << GetParam() << " impact " << k;
    ++checked;
  }
  EXPECT_GE(checked, 1);
}

INSTANTIATE_TEST_SUITE_P(Shared, SharedSources,
                         ::testing::Values("eeps_pingpong", "pfe_bouncyball_h0.9m_stereo48k",
                                           "pisa_fr4nci_tennis_h2.50m", "mth337_basketball_24k",
                                           "mth337_rubberball"),
                         [](const ::testing::TestParamInfo<std::string>& i) {
                           std::string n = i.param;
                           for (char& c : n)
                             if (!std::isalnum(static_cast<unsigned char>(c))) c = '_';
                           return n;
                         });

// ---- bad input -----------------------------------------------------------------------------

TEST(RealSoundBadInput, MarksSpecAndSourceErrorsNameTheProblem) {
  ScratchDir dir("realsound_bad");
  EXPECT_THROW(ReadHandMarks(dir / "none.csv"), Error);
  std::ofstream(dir / "bad.csv") << "k,t_impact_s,confidence\n0,abc,H\n";
  try {
    ReadHandMarks(dir / "bad.csv");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadScene);
    EXPECT_NE(std::string(e.what()).find("bad.csv:2"), std::string::npos) << e.what();
  }
  std::ofstream(dir / "unsorted.csv") << "k,t_impact_s,confidence\n0,1.0,H\n1,0.5,H\n2,2,H\n";
  EXPECT_THROW(ReadHandMarks(dir / "unsorted.csv"), Error);
  std::ofstream(dir / "two.csv") << "k,t_impact_s,confidence\n0,1.0,H\n1,1.5,H\n";
  EXPECT_THROW(ReadHandMarks(dir / "two.csv"), Error);
  try {
    LoadSoundSource(dir / "missing.wav");
    ADD_FAILURE() << "no error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kInputMissing) << e.what();
  }
  SoundSourceOptions o;
  o.pre_s = 0.001;  // shorter than fade-in + max lag
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("pre_s"), std::string::npos);

  const SynthSource s;
  const SoundSource src = LoadSoundSource(s.wav);
  RealSoundSpec spec = RealSoundSpecFor(src);
  spec.cut = static_cast<int>(src.cuts.size());
  EXPECT_THROW(RenderRealSound(src, spec), Error);
  spec.cut = 0;
  spec.drops.drops = 0;
  EXPECT_THROW(RenderRealSound(src, spec), Error);
  spec.drops.drops = 1;
  spec.clip_start_s = 1e4;
  EXPECT_THROW(RenderRealSound(src, spec), Error);
}

// The program (tools/realsound.cpp): writes audio and truth together, refuses to overwrite,
// names bad arguments with the CLI's exit codes.
TEST(RealSoundTool, WritesBothFilesAndFailsCleanly) {
  const std::string tool = std::string(BOUNCECAL_BUILD_DIR) + "/realsound";
  if (!fs::exists(tool)) GTEST_SKIP() << tool << " not built";
  const SynthSource s;
  const std::string out = s.dir / "out.flac";
  auto run = [&](const std::string& args) {
    return testing_util::RunCommand(tool, "--source " + s.wav + " " + args);
  };
  auto r = run("-o " + out + " --drops 2 --gap 0.2,0.4 --seed 3");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const TruthFile t = LoadTruth(s.dir / "out.truth.json");
  EXPECT_EQ(t.drops.size(), 2u);
  EXPECT_EQ(ReadAudio(out).info.sample_rate_hz, t.sample_rate_hz);
  r = run("-o " + out);  // exists
  EXPECT_EQ(r.exit_code, 11) << r.err;
  EXPECT_EQ(run("-o " + out + " --force").exit_code, 0);
  EXPECT_EQ(run("--list").exit_code, 0);
  EXPECT_EQ(run("-o " + (s.dir / "x.wav") + " --banana").exit_code, 2);
  EXPECT_EQ(run("-o " + (s.dir / "x.wav") + " --cut-choice nope").exit_code, 2);
  EXPECT_EQ(run("-o " + (s.dir / "x.wav") + " --drops 0").exit_code, 9);
  EXPECT_EQ(run("-o " + (s.dir / "x.wav") + " --cut 99").exit_code, 9);
  EXPECT_FALSE(fs::exists(s.dir / "x.wav"));
  EXPECT_FALSE(fs::exists(s.dir / "x.truth.json"));
  r = testing_util::RunCommand(tool, "--source " + (s.dir / "absent.wav") + " -o " + out);
  EXPECT_EQ(r.exit_code, 3) << r.err;
  EXPECT_NE(r.err.find("absent"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace bouncecal
