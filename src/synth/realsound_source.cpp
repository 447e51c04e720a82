// Real impact sounds from a hand-marked recording: the clean cuts, their common onset
// convention and the room's noise (see include/bouncecal/synth/realsound.hpp).
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/fractional_delay.hpp"
#include "bouncecal/core/stats.hpp"
#include "bouncecal/synth/realsound.hpp"

namespace bouncecal {
namespace {

namespace fd = fractional_delay;

// The window of the RMS envelope that says whether a sound has decayed into the noise: 10 ms
// holds several periods of anything above 200 Hz, and is shorter than the shortest marked
// interval (27 ms, eeps_pingpong).
constexpr double kEnvelopeWindow_s = 0.010;
// "Decayed into the noise": the envelope at most 3 dB above the noise RMS, i.e. the residual
// sound's power at most the noise's.
constexpr double kDecayedPowerRatio = 2.0;
// Quiet stretches for the noise model end this long before a hand mark (the M/L marks are +-3 ms,
// the cut's pre-roll 4 ms) and start three envelope windows after an impact's sound has reached
// the 3-dB level (its tail is then well below the noise), so no impact sound enters the model.
constexpr double kQuietGuardBefore_s = 0.010;
constexpr double kQuietGuardAfter_s = 3 * kEnvelopeWindow_s;
// Cuts aligned to the reference share at least NCC^2 = 0.64 of their attack's energy with it.
constexpr double kMinAlignCorrelation = 0.8;
// A cut whose peak reaches full scale may have clipped between samples: its true shape is lost.
constexpr double kFullScale = 0.99;
// Gravity for the speeds read from the marked intervals (standard gravity).
constexpr double kG_m_s2 = 9.81;

// RMS of x over [i, i + w) from the running sum of squares (0 outside).
struct Envelope {
  std::vector<double> cum;  // cum[i] = sum of x^2 over [0, i)
  std::size_t w = 1;
  double At(std::int64_t i) const {
    const auto n = static_cast<std::int64_t>(cum.size()) - 1;
    const std::int64_t a = std::clamp<std::int64_t>(i, 0, n);
    const std::int64_t b = std::clamp<std::int64_t>(i + static_cast<std::int64_t>(w), 0, n);
    if (b <= a) return 0.0;
    return std::sqrt((cum[static_cast<std::size_t>(b)] - cum[static_cast<std::size_t>(a)]) /
                     static_cast<double>(b - a));
  }
};

Envelope MakeEnvelope(const std::vector<double>& x, double rate_hz) {
  Envelope e;
  e.w =
      std::max<std::size_t>(1, static_cast<std::size_t>(std::lround(kEnvelopeWindow_s * rate_hz)));
  e.cum.resize(x.size() + 1, 0.0);
  for (std::size_t i = 0; i < x.size(); ++i) e.cum[i + 1] = e.cum[i] + x[i] * x[i];
  return e;
}

std::int64_t Sample(double t_s, double rate_hz) {
  return static_cast<std::int64_t>(std::llround(t_s * rate_hz));
}

// Where the sound of the impact marked at t has decayed into the noise: the first window start
// after the envelope's peak (within 20 ms of the mark) whose RMS is at most sqrt(2) x floor;
// `limit` if none before it.
double DecayEnd(const Envelope& env, double t_s, double limit_s, double floor_rms, double rate) {
  const std::int64_t a = Sample(t_s, rate), lim = Sample(limit_s, rate);
  const std::int64_t step = std::max<std::int64_t>(1, Sample(0.001, rate));  // 1 ms
  std::int64_t peak = a;
  for (std::int64_t i = a; i < std::min(lim, a + Sample(0.020, rate)); i += step)
    if (env.At(i) > env.At(peak)) peak = i;
  const double level = std::sqrt(kDecayedPowerRatio) * floor_rms;
  for (std::int64_t i = peak; i < lim; i += step)
    if (env.At(i) <= level) return static_cast<double>(i) / rate;
  return limit_s;
}

// Speed of the impact at marks[k] from the marked intervals (vacuum flights: v = g dt / 2).
double MarkSpeed(const std::vector<HandMark>& m, std::size_t k) {
  if (k >= 1) return kG_m_s2 * (m[k].time_s - m[k - 1].time_s) / 2.0;
  const double d1 = m[1].time_s - m[0].time_s, d2 = m[2].time_s - m[1].time_s;
  return kG_m_s2 * d1 / 2.0 / (d2 / d1);  // v_in = v_out / e, e from the next two intervals
}

// Normalised cross-correlation of ref (fixed) with x at real position `pos` onwards.
double Ncc(const std::vector<double>& ref, const std::vector<double>& x, double pos) {
  const std::vector<double> y = fd::Resample(x, pos, ref.size());
  double xy = 0.0, xx = 0.0, yy = 0.0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    xy += ref[i] * y[i];
    xx += ref[i] * ref[i];
    yy += y[i] * y[i];
  }
  return xx > 0.0 && yy > 0.0 ? xy / std::sqrt(xx * yy) : 0.0;
}

// The lag (samples) in [-max_lag, max_lag] at which x from `pos` + lag best matches ref, to
// 1/256 sample (integer search, then halving steps around the best), and its correlation.
std::pair<double, double> BestLag(const std::vector<double>& ref, const std::vector<double>& x,
                                  double pos, double max_lag) {
  double best = 0.0, best_c = Ncc(ref, x, pos);
  for (double lag = -std::floor(max_lag); lag <= max_lag; lag += 1.0) {
    const double c = Ncc(ref, x, pos + lag);
    if (c > best_c) best_c = c, best = lag;
  }
  for (double step = 0.5; step >= 1.0 / 256.0; step /= 2.0) {
    for (double cand : {best - step, best + step}) {
      if (std::fabs(cand) > max_lag) continue;
      const double c = Ncc(ref, x, pos + cand);
      if (c > best_c) best_c = c, best = cand;
    }
  }
  return {best, best_c};
}

// The attack of the sound marked at t: 1 ms before the mark to attack_s after it.
std::vector<double> Attack(const std::vector<double>& x, double t_s, double attack_s, double rate) {
  const double start = t_s * rate - 0.001 * rate;
  return fd::Resample(x, start, static_cast<std::size_t>(std::lround((0.001 + attack_s) * rate)));
}

// Raised-cosine fade-in over the first n_in samples and fade-out over the last n_out.
void Taper(std::vector<float>* s, std::size_t n_in, std::size_t n_out) {
  const std::size_t n = s->size();
  for (std::size_t i = 0; i < n_in && i < n; ++i)
    (*s)[i] *= static_cast<float>(
        0.5 - 0.5 * std::cos(M_PI * (static_cast<double>(i) + 0.5) / static_cast<double>(n_in)));
  for (std::size_t i = 0; i < n_out && i < n; ++i)
    (*s)[n - 1 - i] *= static_cast<float>(
        0.5 - 0.5 * std::cos(M_PI * (static_cast<double>(i) + 0.5) / static_cast<double>(n_out)));
}

// The source's schedule from its H marks: median ratio of successive intervals and the height
// whose vacuum fall and rebound with that e give the first interval.
void EstimateSchedule(SoundSource* s) {
  std::vector<double> ratios;
  const auto& m = s->marks;
  for (std::size_t k = 2; k < m.size(); ++k)
    if (m[k].confidence == 'H' && m[k - 1].confidence == 'H' && m[k - 2].confidence == 'H')
      ratios.push_back((m[k].time_s - m[k - 1].time_s) / (m[k - 1].time_s - m[k - 2].time_s));
  s->e_estimate = ratios.empty() ? 0.9 : std::clamp(UpperMedian(ratios), 0.05, 0.995);
  const double v_out = kG_m_s2 * (m[1].time_s - m[0].time_s) / 2.0;
  const double v_in = v_out / s->e_estimate;
  s->height_estimate_m = v_in * v_in / (2.0 * kG_m_s2);
}

struct CutPlan {
  std::size_t mark;
  double start_s, end_s, peak;
};

// The clean H-marked impacts, loudest first (rule: realsound.hpp, point 1).
std::vector<CutPlan> PlanCuts(const std::vector<double>& x, const Envelope& env,
                              const SoundSource& s, const SoundSourceOptions& o) {
  const double rate = s.sample_rate_hz;
  const double level = std::sqrt(kDecayedPowerRatio) * s.noise_floor_rms;
  const double duration = static_cast<double>(x.size()) / rate;
  std::vector<CutPlan> plans;
  for (std::size_t k = 0; k < s.marks.size(); ++k) {
    const HandMark& mk = s.marks[k];
    if (mk.confidence != 'H') continue;
    const double start = mk.time_s - o.pre_s;
    if (start - kEnvelopeWindow_s < 0.0) continue;
    // The 10 ms just before the cut: has the previous sound decayed into the noise?
    if (env.At(Sample(start - kEnvelopeWindow_s, rate)) > level) continue;
    const double limit =
        k + 1 < s.marks.size() ? s.marks[k + 1].time_s - o.pre_s : duration - o.pre_s;
    const double end = DecayEnd(env, mk.time_s, limit, s.noise_floor_rms, rate);
    double peak = 0.0;
    for (std::int64_t i = Sample(start, rate); i < Sample(end, rate); ++i)
      peak = std::max(peak, std::fabs(x[static_cast<std::size_t>(i)]));
    if (peak >= kFullScale || end - mk.time_s < 4.0 * o.fade_out_s) continue;
    plans.push_back({k, start, end, peak});
  }
  std::stable_sort(plans.begin(), plans.end(),
                   [](const CutPlan& a, const CutPlan& b) { return a.peak > b.peak; });
  if (plans.size() > static_cast<std::size_t>(o.max_cuts))
    plans.resize(static_cast<std::size_t>(o.max_cuts));
  return plans;
}

// Aligns the cuts' attacks to cuts[0]'s and measures the closure of the pairwise lags.
void AlignCuts(const std::vector<double>& x, const SoundSourceOptions& o, SoundSource* s) {
  const double rate = s->sample_rate_hz;
  const double max_lag = o.max_lag_s * rate;
  auto& cuts = s->cuts;
  std::vector<std::vector<double>> attacks;
  for (const RealSoundCut& c : cuts) attacks.push_back(Attack(x, c.mark_s, o.attack_s, rate));
  std::vector<RealSoundCut> kept = {std::move(cuts[0])};
  std::vector<std::vector<double>> kept_attacks = {attacks[0]};
  for (std::size_t i = 1; i < cuts.size(); ++i) {
    const double pos = cuts[i].mark_s * rate - 0.001 * rate;
    const auto [lag, c] = BestLag(attacks[0], x, pos, max_lag);
    // A cut that shares less than two thirds of its attack's energy with the reference's
    // (NCC^2 < 0.64), or whose best lag sits at the edge of the search (no interior maximum),
    // is not the same sound shifted: it cannot be aligned and is left out.
    if (c < kMinAlignCorrelation || std::fabs(lag) > max_lag - 1.0) continue;
    cuts[i].lag_s = lag / rate;
    cuts[i].correlation = c;
    kept.push_back(std::move(cuts[i]));
    kept_attacks.push_back(attacks[i]);
  }
  cuts = std::move(kept);
  attacks = std::move(kept_attacks);
  std::vector<double> closures;
  for (std::size_t i = 1; i < cuts.size(); ++i)
    for (std::size_t j = i + 1; j < cuts.size(); ++j) {
      // lag of cut j against cut i's attack: should be lag_j - lag_i.
      const double pos = cuts[j].mark_s * rate - 0.001 * rate;
      const double lag_ij = BestLag(attacks[i], x, pos, max_lag).first / rate;
      closures.push_back(lag_ij - (cuts[j].lag_s - cuts[i].lag_s));
    }
  if (!closures.empty()) {
    double ss = 0.0;
    for (double c : closures) ss += c * c;
    s->alignment_sigma_s = std::sqrt(ss / static_cast<double>(closures.size()) / 3.0);
  }
  for (RealSoundCut& c : cuts) {
    c.onset_s = c.mark_s + c.lag_s;
    c.onset_index = (c.onset_s - c.start_s) * rate;
  }
}

// The recording's channel as doubles (the chosen or the best one).
std::vector<double> SourceChannel(const Audio& audio, const SoundSourceOptions& o, int* channel) {
  ChannelSelection sel;
  if (o.channel >= 0) {
    sel.kind = ChannelSelection::Kind::kIndex;
    sel.index = o.channel;
  }
  const SelectedSignal sig = SelectChannel(audio, sel);
  *channel = sig.channel < 0 ? 0 : sig.channel;
  const std::vector<float>& f = audio.channels.at(static_cast<std::size_t>(*channel));
  return std::vector<double>(f.begin(), f.end());
}

// The quiet stretches: before the first mark, and between an impact's decayed sound and the
// next mark. Nothing after the last mark (unmarked tail bounces may follow).
std::vector<std::vector<double>> QuietStretches(const std::vector<double>& x, const Envelope& env,
                                                const SoundSource& s) {
  const double rate = s.sample_rate_hz;
  std::vector<std::pair<double, double>> spans = {{0.0, s.marks[0].time_s - kQuietGuardBefore_s}};
  for (std::size_t k = 0; k + 1 < s.marks.size(); ++k) {
    const double next = s.marks[k + 1].time_s;
    const double end = DecayEnd(env, s.marks[k].time_s, next, s.noise_floor_rms, rate);
    if (end < next) spans.push_back({end + kQuietGuardAfter_s, next - kQuietGuardBefore_s});
  }
  std::vector<std::vector<double>> out;
  for (const auto& [a, b] : spans) {
    const std::int64_t i = Sample(a, rate), j = Sample(b, rate);
    if (j - i < RoomNoise::kMinFrame) continue;
    out.emplace_back(x.begin() + i, x.begin() + j);
  }
  return out;
}

}  // namespace

bool SoundSourceOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error) *error = "sound source: " + m;
    return false;
  };
  if (max_cuts < 1) return fail("max_cuts = " + std::to_string(max_cuts) + " (expected >= 1)");
  if (!(fade_in_s > 0.0 && max_lag_s > 0.0 && fade_out_s > 0.0 && attack_s > 0.0))
    return fail("fade_in_s, fade_out_s, attack_s and max_lag_s must be > 0");
  if (!(pre_s > fade_in_s + max_lag_s && pre_s < 0.05))
    return fail("pre_s = " + FormatGeneral(pre_s) +
                " (expected fade_in_s + max_lag_s < pre_s < 0.05 s)");
  if (channel < -1) return fail("channel = " + std::to_string(channel) + " (expected >= -1)");
  return true;
}

std::vector<HandMark> ReadHandMarks(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot be opened (hand marks)");
  std::vector<HandMark> out;
  std::string line;
  int n = 1;
  if (!std::getline(in, line) || line.find("t_impact_s") == std::string::npos)
    throw Error(ErrorCode::kBadScene, path + ":1: expected the header k,t_impact_s,confidence,...");
  while (std::getline(in, line)) {
    ++n;
    if (line.empty() || line == "\r") continue;
    std::stringstream ss(line);
    std::string k, t, c;
    std::getline(ss, k, ',');
    std::getline(ss, t, ',');
    std::getline(ss, c, ',');
    HandMark m;
    try {
      std::size_t used = 0;
      m.k = std::stoi(k);
      m.time_s = std::stod(t, &used);
      if (used != t.size()) throw std::invalid_argument(t);
    } catch (const std::exception&) {
      throw Error(ErrorCode::kBadScene, path + ":" + std::to_string(n) + ": '" + line +
                                            "' is not k,t_impact_s,confidence,...");
    }
    m.confidence = c.empty() ? 'L' : c[0];
    if (!std::isfinite(m.time_s) || m.time_s < 0.0 ||
        (!out.empty() && m.time_s <= out.back().time_s))
      throw Error(ErrorCode::kBadScene, path + ":" + std::to_string(n) + ": time " + t +
                                            " s is not after the previous mark");
    out.push_back(m);
  }
  if (out.size() < 3)
    throw Error(ErrorCode::kBadScene,
                path + ": " + std::to_string(out.size()) + " marks; at least 3 are needed");
  return out;
}

SoundSource LoadSoundSource(const std::string& wav_path, const SoundSourceOptions& o) {
  std::string err;
  if (!o.IsValid(&err)) throw Error(ErrorCode::kBadParameter, err);
  namespace fs = std::filesystem;
  const fs::path wav(wav_path);
  SoundSource s;
  s.path = wav_path;
  s.name = wav.stem().string();
  s.marks = ReadHandMarks((wav.parent_path() / (s.name + ".impacts.csv")).string());
  const Audio audio = ReadAudio(wav_path);
  s.sample_rate_hz = audio.info.sample_rate_hz;
  const std::vector<double> x = SourceChannel(audio, o, &s.channel);
  const double rate = s.sample_rate_hz;
  if (s.marks.back().time_s + o.pre_s >= static_cast<double>(x.size()) / rate)
    throw Error(ErrorCode::kBadScene, wav_path + ": a hand mark lies beyond the recording's end");
  const Envelope env = MakeEnvelope(x, rate);
  // The noise floor: the median 10-ms RMS before the first impact (the ball falls silently).
  std::vector<double> pre;
  for (std::int64_t i = 0; i + static_cast<std::int64_t>(env.w) <=
                           Sample(s.marks[0].time_s - kQuietGuardBefore_s, rate);
       i += static_cast<std::int64_t>(env.w))
    pre.push_back(env.At(i));
  if (pre.size() < 2)
    throw Error(ErrorCode::kBadParameter,
                wav_path +
                    ": less than 20 ms before the first marked impact: no quiet to measure "
                    "the room's noise in");
  s.noise_floor_rms = pre.empty() ? 0.0 : UpperMedian(pre);
  s.noise = RoomNoise::FromSegments(QuietStretches(x, env, s), rate);
  for (const CutPlan& p : PlanCuts(x, env, s, o)) {
    RealSoundCut c;
    c.mark = static_cast<int>(p.mark);
    c.mark_s = s.marks[p.mark].time_s;
    c.speed_m_s = MarkSpeed(s.marks, p.mark);
    c.peak = p.peak;
    const std::int64_t a = Sample(p.start_s, rate), b = Sample(p.end_s, rate);
    c.start_s = static_cast<double>(a) / rate;
    for (std::int64_t i = a; i < b; ++i)
      c.samples.push_back(static_cast<float>(x[static_cast<std::size_t>(i)]));
    Taper(
        &c.samples, static_cast<std::size_t>(std::lround(o.fade_in_s * rate)),
        std::min(c.samples.size() / 4, static_cast<std::size_t>(std::lround(o.fade_out_s * rate))));
    s.cuts.push_back(std::move(c));
  }
  if (s.cuts.empty())
    throw Error(ErrorCode::kBadParameter,
                wav_path +
                    ": no clean high-confidence impact (each H-marked impact follows one "
                    "whose sound has not decayed into the noise, or reaches full scale)");
  AlignCuts(x, o, &s);
  EstimateSchedule(&s);
  return s;
}

}  // namespace bouncecal
