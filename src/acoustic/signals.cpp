// The candidate signals of a detection: channels, the mix, decimation, the choice. See
// signals.hpp.
#include "signals.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"

namespace bouncecal {
namespace {

// Channel choice (auto): a later candidate signal must score this much more (relative) to be
// chosen. The scores of the real stereo recording's channels and mix differ by 7-20 %; with the
// first 0.5-2.7 s cut off, the mix and channel 0 came within 3 % of each other.
constexpr double kChannelScoreMargin = 0.1;

// Detection runs at most at kMaxAnalysisRateHz: a recording at a higher rate (88.2 to 384 kHz)
// is low-passed and decimated by an integer factor first. The impact sound a microphone records
// lies below ~20 kHz; above it there is only noise, which the whitening (it flattens the whole
// band) then weighs like the clicks. Measured on a rendered steel drop before: recall 0.70 at
// 44.1 kHz, 0.59 at 96 kHz, 0.24 at 192 kHz, and no sequence at 384 kHz.
constexpr double kMaxAnalysisRateHz = 64000.0;

}  // namespace

std::vector<int> CandidateSignals(const ChannelSelection& selection, const AudioInfo& info) {
  std::vector<int> choices;
  const int nch = info.channels;
  switch (selection.kind) {
    case ChannelSelection::Kind::kIndex:
      if (selection.index >= nch)
        throw Error(ErrorCode::kUsage, info.path + ": channel " + std::to_string(selection.index) +
                                           " out of range (" + std::to_string(nch) + " channel" +
                                           (nch == 1 ? "" : "s") + ", 0-based)");
      choices = {selection.index};
      break;
    case ChannelSelection::Kind::kMix:
      choices = {-1};
      break;
    case ChannelSelection::Kind::kAuto:
      for (int c = 0; c < nch; ++c) choices.push_back(c);
      if (nch > 1) choices.push_back(-1);
      break;
  }
  return choices;
}

void SignalOf(const std::vector<std::vector<float>>& block, int channel, std::size_t from,
              std::size_t to, std::vector<float>* x) {
  if (channel >= 0) {
    const std::vector<float>& c = block[static_cast<std::size_t>(channel)];
    x->assign(c.begin() + static_cast<std::ptrdiff_t>(from),
              c.begin() + static_cast<std::ptrdiff_t>(to));
    return;
  }
  // The mix: the mean of the channels (SelectChannel's kMix).
  const double nch = static_cast<double>(block.size());
  x->resize(to - from);
  for (std::size_t i = from; i < to; ++i) {
    double acc = 0.0;
    for (const std::vector<float>& c : block) acc += c[i];
    (*x)[i - from] = static_cast<float>(acc / nch);
  }
}

double ClipPeak(const std::vector<ClippingReport>& clipping, int channel, std::size_t channels) {
  double clip_peak = 0.0;
  for (const ClippingReport& c : clipping)
    if (c.clipped() && (channel < 0 || c.channel == channel))
      clip_peak = channel < 0 ? 0.999 * c.peak / static_cast<double>(channels) : c.peak;
  return clip_peak;
}

void MarkClipped(double clip_peak, SignalDetection* d) {
  auto mark = [&](Impact& imp) {
    imp.clipped = clip_peak > 0.0 && imp.amplitude >= 0.999 * clip_peak;
  };
  for (Impact& imp : d->candidates) mark(imp);
  for (Sequence& q : d->sequences)
    for (Impact& imp : q.impacts) mark(imp);
}

int DecimationFactor(double rate_hz) {
  return std::max(1, static_cast<int>(std::ceil(rate_hz / kMaxAnalysisRateHz)));
}

void Decimate(const std::vector<float>& x, int factor, std::vector<float>* y) {
  const long f = factor, half = 12 * f, n = static_cast<long>(x.size());
  const double fc = 0.45 / static_cast<double>(f);  // cycles per input sample
  std::vector<float> h(static_cast<std::size_t>(2 * half + 1));
  double sum = 0.0;
  for (long j = -half; j <= half; ++j) {
    const double t = static_cast<double>(j);
    const double sinc = j == 0 ? 2.0 * fc : std::sin(2.0 * M_PI * fc * t) / (M_PI * t);
    const double u = static_cast<double>(j + half) / static_cast<double>(2 * half);
    const double w = 0.42 - 0.5 * std::cos(2.0 * M_PI * u) + 0.08 * std::cos(4.0 * M_PI * u);
    h[static_cast<std::size_t>(j + half)] = static_cast<float>(sinc * w);
    sum += sinc * w;
  }
  for (float& v : h) v = static_cast<float>(v / sum);  // unit gain at 0 Hz
  const long m = (n + f - 1) / f;
  y->assign(static_cast<std::size_t>(m), 0.0f);
  for (long k = 0; k < m; ++k) {
    const long c = k * f;
    const long j0 = std::max(-half, -c), j1 = std::min(half, n - 1 - c);
    const float* xp = x.data() + c;
    const float* hp = h.data() + half;
    float a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, a3 = 0.0f;
    long j = j0;
    for (; j + 3 <= j1; j += 4) {
      a0 += hp[j] * xp[j];
      a1 += hp[j + 1] * xp[j + 1];
      a2 += hp[j + 2] * xp[j + 2];
      a3 += hp[j + 3] * xp[j + 3];
    }
    for (; j <= j1; ++j) a0 += hp[j] * xp[j];
    (*y)[static_cast<std::size_t>(k)] = (a0 + a1) + (a2 + a3);
  }
}

void FullRateAmplitudes(const std::vector<float>& x, double rate_hz, SignalDetection* d) {
  const long n = static_cast<long>(x.size());
  const long len = static_cast<long>(0.003 * rate_hz) + 1;
  auto peak = [&](Impact& imp) {
    const long i0 = std::clamp(static_cast<long>(std::floor(imp.time_s * rate_hz)), 0L, n);
    double a = 0.0;
    for (long i = i0; i < std::min(n, i0 + len); ++i)
      a = std::max(a, static_cast<double>(std::fabs(x[static_cast<std::size_t>(i)])));
    imp.amplitude = a;
  };
  for (Impact& imp : d->candidates) peak(imp);
  for (Sequence& q : d->sequences) {
    for (Impact& imp : q.impacts) peak(imp);
    for (RemovedImpact& r : q.removed) peak(r.impact);
  }
}

void ShiftTimes(double dt, SignalDetection* d) {
  for (Impact& i : d->candidates) i.time_s += dt;
  for (Sequence& q : d->sequences) {
    for (Impact& i : q.impacts) i.time_s += dt;
    for (RemovedImpact& r : q.removed) r.impact.time_s += dt;
  }
}

SignalDetection ChooseSignal(const std::vector<int>& choices,
                             std::vector<SignalAcrossBlocks>* signals, const std::string& window,
                             DetectionResult* res) {
  const std::string& path = res->audio.path;
  const int nch = res->audio.channels;
  int best = -1;
  SignalDetection chosen;
  std::string failures;
  bool any_sound = false;
  for (std::size_t ci = 0; ci < choices.size(); ++ci) {
    SignalAcrossBlocks& sig = (*signals)[ci];
    SignalDetection& d = sig.merged;
    MarkClipped(ClipPeak(res->clipping, choices[ci], static_cast<std::size_t>(nch)), &d);
    ChannelScore cs;
    cs.channel = choices[ci];
    if (!sig.sound) {
      cs.failure = "silent (peak |x| = " + FormatGeneral(sig.peak, 3) + ")";
    } else {
      any_sound = true;
      if (d.sequences.empty()) {
        d.failure = sig.failure.empty() ? std::string("no bounce sequence") : sig.failure;
      } else {
        d.score =
            SequenceScore(d.sequences[static_cast<std::size_t>(LongestSequence(d.sequences))]);
        const Sequence& m = d.sequences[static_cast<std::size_t>(LongestSequence(d.sequences))];
        cs.impacts = static_cast<int>(m.impacts.size());
        cs.first_impact_s = m.impacts.front().time_s;
      }
      cs.failure = d.failure;
      cs.score = d.score;
      // A later signal (channel 1, ..., then the mix) replaces the one chosen so far only when it
      // is clearly better (kChannelScoreMargin): near ties would otherwise flip with the weak
      // tail of a sequence, i.e. with how much audio surrounds it.
      if (best < 0 || (chosen.sequences.empty() && !d.sequences.empty()) ||
          d.score > (1.0 + kChannelScoreMargin) * chosen.score) {
        best = static_cast<int>(ci);
        chosen = std::move(d);
      }
    }
    if (!cs.failure.empty())
      failures += std::string(failures.empty() ? "" : "; ") +
                  (choices.size() > 1 ? (cs.channel >= 0 ? "channel " + std::to_string(cs.channel)
                                                         : std::string("mix")) +
                                            ": "
                                      : std::string()) +
                  cs.failure;
    res->channel_scores.push_back(cs);
  }
  if (!any_sound)
    throw Error(ErrorCode::kSilence, path + ": recording" +
                                         (!window.empty() ? " window " + window : "") +
                                         " is silent (peak |x| at or below one 16-bit step)");
  if (best < 0 || chosen.sequences.empty())
    throw Error(ErrorCode::kNoBounces, path + ": no bounce sequence found" +
                                           (!window.empty() ? " in the window " + window : "") +
                                           " (" + failures + ")");
  res->channel = choices[static_cast<std::size_t>(best)];
  if (res->channel_scores.size() == 1) res->channel_scores.clear();  // nothing was chosen
  return chosen;
}

// When auto had a real choice and the signals disagree on the main sequence, say which was
// used and why (the scores of all are in DetectionResult::channel_scores).
void ChannelChoiceWarning(const DetectionResult& r, std::vector<Warning>* out) {
  if (r.channel_scores.size() < 2) return;
  auto name = [](int c) {
    return c >= 0 ? "channel " + std::to_string(c) : std::string("the mix");
  };
  const ChannelScore* used = nullptr;
  for (const ChannelScore& c : r.channel_scores)
    if (c.channel == r.channel) used = &c;
  if (!used) return;
  bool disagree = false;
  std::string others;
  for (const ChannelScore& c : r.channel_scores) {
    if (&c == used) continue;
    others += (others.empty() ? "" : ", ") + name(c.channel) + " " + FormatFixed(c.score, 1) +
              " (" + std::to_string(c.impacts) + " impacts)";
    disagree = disagree || c.impacts == 0 ||
               std::fabs(c.first_impact_s - used->first_impact_s) > 0.005 ||
               std::abs(c.impacts - used->impacts) > std::max(2, used->impacts / 10);
  }
  if (!disagree) return;
  out->push_back(
      {"channel_choice",
       "the channels disagree; " + name(r.channel) + " was used: its main sequence scores " +
           FormatFixed(used->score, 1) + " (" + std::to_string(used->impacts) + " impacts from " +
           FormatFixed(used->first_impact_s, 4) + " s), " + others +
           " (score = sum of the members' tracker weights)",
       -1, "listen to each (--channel N --click-track FILE.wav) and choose with --channel N"});
}

}  // namespace bouncecal
