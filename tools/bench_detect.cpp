// bench_detect — detection accuracy and speed on a rendered corpus, side by side with aubioonset.
//
//   build/bench_detect                 # default: 6 presets x 5 seeds, aubio if installed
//   build/bench_detect --seeds 5 --no-aubio --keep /tmp/corpus
//
// Corpus: the synth presets (synth.hpp) "steel-copper", "glass-glass", "pingpong-wood",
// "rubber-wood", "phone-16k", "two-drops", each rendered with several seeds, written as 24-bit
// WAV to a temporary folder and read back with ReadAudio (the path a user's file takes).
//
// Matching rule (the same for bouncecal and aubio; tools/detect_matching.hpp, shared with the
// scoreboard): one constant offset per file is allowed (no detector knows the microphone
// distance; aubio also reports onsets shifted by its latency): the offset is the median of
// (nearest detection - truth onset) over eligible impacts, within +-20 ms. After removing it,
// truth and detections are matched one-to-one, nearest first, within +-1 ms. Eligible impacts: >= 3
// ms from both neighbours of their drop and SNR >= 20 dB (the renderer's per-impact SNR). Recall =
// matched eligible / eligible. Precision = detections matched to any true impact / detections
// (distractor clicks and echoes count as false). Interval error: (t_det[k+1] - t_det[k]) -
// (t_true[k+1] - t_true[k]) over consecutive impacts of one drop, both eligible and matched.
// Restitution error: e_k = dt_k / dt_{k-1} from detected minus from true onsets (the part of the
// restitution error that detection causes). Calibration, on intervals (what sigma_s promises,
// timing.hpp): pull = interval error / hypot(sigma_k, sigma_k+1); RMS(pull) should be ~1. Speed:
// CPU time of DetectImpacts only (file already in memory), best of 3 runs, one thread; aubioonset's
// time is the CPU time of its process on the same file (decode and process start included). CPU
// time, not wall time: the benchmark machine may be shared.
#include <sys/resource.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <map>
#include <memory>
#include <numeric>
#include <sstream>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/timing.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/synth/synth.hpp"
#include "detect_matching.hpp"

namespace fs = std::filesystem;
using namespace bouncecal;
using bench::MatchOnsets;
using bench::OnsetMatch;
using bench::Quantile;
using bench::TruthOnset;

namespace {

// CPU time of this thread (s): the machine may be shared, wall time would count the others.
double ThreadCpuS() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}
// CPU time (user + system) of all waited-for children (s).
double ChildrenCpuS() {
  rusage ru{};
  getrusage(RUSAGE_CHILDREN, &ru);
  return static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
}

struct Metrics {
  int eligible = 0, matched_eligible = 0, detections = 0, matched_detections = 0;
  std::vector<double> interval_err_us;
  std::vector<double> e_err;
  std::vector<double> e_err_long;  // both intervals >= 50 ms
  std::vector<double> z;           // interval pulls: error / hypot(sigma_k, sigma_k+1)
  std::vector<std::pair<double, double>> amp_err;  // (amplitude, error s) of matched impacts
  double time_s = 0.0;
  double audio_s = 0.0;
  void Add(const Metrics& o) {
    eligible += o.eligible;
    matched_eligible += o.matched_eligible;
    detections += o.detections;
    matched_detections += o.matched_detections;
    interval_err_us.insert(interval_err_us.end(), o.interval_err_us.begin(),
                           o.interval_err_us.end());
    e_err.insert(e_err.end(), o.e_err.begin(), o.e_err.end());
    e_err_long.insert(e_err_long.end(), o.e_err_long.begin(), o.e_err_long.end());
    z.insert(z.end(), o.z.begin(), o.z.end());
    amp_err.insert(amp_err.end(), o.amp_err.begin(), o.amp_err.end());
    time_s += o.time_s;
    audio_s += o.audio_s;
  }
};

double Rms(const std::vector<double>& v) {
  if (v.empty()) return NAN;
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s / static_cast<double>(v.size()));
}

// det: detection times; sigma: per detection (0 = unknown).
Metrics Score(const std::vector<TruthOnset>& truth, const std::vector<double>& det,
              const std::vector<double>& sigma) {
  Metrics m;
  m.detections = static_cast<int>(det.size());
  const OnsetMatch match = MatchOnsets(truth, det);
  const double offset = match.offset_s;
  const std::vector<int>& t2d = match.truth_to_det;
  const std::vector<int>& d2t = match.det_to_truth;
  for (std::size_t i = 0; i < truth.size(); ++i) {
    if (truth[i].eligible) {
      ++m.eligible;
      if (t2d[i] >= 0) {
        ++m.matched_eligible;
        const std::size_t di = static_cast<std::size_t>(t2d[i]);
        const double err = det[di] - offset - truth[i].t;
        m.amp_err.push_back({truth[i].amplitude, err});
      }
    }
  }
  for (int v : d2t)
    if (v >= 0) ++m.matched_detections;
  auto ok = [&](std::size_t i) { return truth[i].eligible && t2d[i] >= 0; };
  auto dt = [&](std::size_t i) {  // detected time of truth i
    return det[static_cast<std::size_t>(t2d[i])];
  };
  for (std::size_t i = 0; i + 1 < truth.size(); ++i) {
    if (truth[i].drop != truth[i + 1].drop || !ok(i) || !ok(i + 1)) continue;
    const double ivl_err = (dt(i + 1) - dt(i)) - (truth[i + 1].t - truth[i].t);
    m.interval_err_us.push_back(ivl_err * 1e6);
    if (!sigma.empty()) {
      const double s = std::hypot(sigma[static_cast<std::size_t>(t2d[i])],
                                  sigma[static_cast<std::size_t>(t2d[i + 1])]);
      if (s > 0) m.z.push_back(ivl_err / s);
    }
    if (i >= 1 && truth[i - 1].drop == truth[i].drop && ok(i - 1)) {
      const double e_det = (dt(i + 1) - dt(i)) / (dt(i) - dt(i - 1));
      const double e_true = (truth[i + 1].t - truth[i].t) / (truth[i].t - truth[i - 1].t);
      m.e_err.push_back(e_det - e_true);
      if (truth[i].t - truth[i - 1].t >= 0.05 && truth[i + 1].t - truth[i].t >= 0.05)
        m.e_err_long.push_back(e_det - e_true);
    }
  }
  return m;
}

struct Corpus {
  std::string preset;
  int seed = 0;
  std::string path;
  Audio audio;
  std::vector<std::vector<TruthOnset>> truth_per_channel;
};

std::vector<TruthOnset> TruthFor(const SynthSpec& spec, const Recording& rec, int channel) {
  std::vector<TruthOnset> out;
  const double d0 = spec.render.channels.front().delay_s;
  const double dc = spec.render.channels[static_cast<std::size_t>(std::max(channel, 0))].delay_s;
  for (std::size_t d = 0; d < rec.drops.size(); ++d) {
    const auto& imps = rec.drops[d];
    for (std::size_t k = 0; k < imps.size(); ++k) {
      TruthOnset t;
      t.t = imps[k].onset_s + (dc - d0);
      t.drop = static_cast<int>(d);
      t.index = static_cast<int>(k);
      t.amplitude = imps[k].amplitude;
      const double prev = k > 0 ? imps[k].onset_s - imps[k - 1].onset_s : 1e9;
      const double next = k + 1 < imps.size() ? imps[k + 1].onset_s - imps[k].onset_s : 1e9;
      t.eligible = prev >= 0.003 && next >= 0.003 && imps[k].snr_db >= 20.0;
      out.push_back(t);
    }
  }
  std::sort(out.begin(), out.end(), [](const TruthOnset& a, const TruthOnset& b) {
    return a.drop != b.drop ? a.drop < b.drop : a.t < b.t;
  });
  return out;
}

struct RunOut {
  std::vector<double> t, sigma;
  std::vector<Sequence> sequences;
  double time_s = 0;
  int channel = 0;
  bool failed = false;
};

RunOut RunBouncecal(const Audio& a, const DetectOptions& o, int reps) {
  RunOut r;
  double best = 1e9;
  for (int k = 0; k < reps; ++k) {
    const double t0 = ThreadCpuS();
    try {
      DetectionResult res = DetectImpacts(a, o);
      best = std::min(best, ThreadCpuS() - t0);
      if (k == 0) {
        r.channel = std::max(res.channel, 0);
        r.sequences = res.sequences;
        for (const Sequence& s : res.sequences)
          for (const Impact& i : s.impacts) {
            r.t.push_back(i.time_s);
            r.sigma.push_back(i.sigma_s);
          }
      }
    } catch (const Error& e) {
      std::fprintf(stderr, "bench_detect: %s\n", e.what());
      r.failed = true;
      best = std::min(best, ThreadCpuS() - t0);
    }
  }
  r.time_s = best;
  return r;
}

// Per-impact timing diagnostics (--dump): each sequence re-timed on the channel it came from,
// the model's parts beside the raw error against the nearest true onset (within 1 ms).
void DumpTiming(const std::string& path, const Corpus& c, const RunOut& r) {
  std::FILE* f = std::fopen(path.c_str(), "a");
  if (!f) return;
  const auto& x = c.audio.channels[static_cast<std::size_t>(r.channel)];
  const auto& truth = c.truth_per_channel[static_cast<std::size_t>(r.channel)];
  for (std::size_t q = 0; q < r.sequences.size(); ++q) {
    Sequence s = r.sequences[q];
    const TimingResult tr = TimeSequence(x, c.audio.info.sample_rate_hz, &s);
    for (std::size_t k = 0; k < s.impacts.size(); ++k) {
      const Impact& im = s.impacts[k];
      const TruthOnset* best = nullptr;
      for (const TruthOnset& t : truth)
        if (!best || std::fabs(t.t - im.time_s) < std::fabs(best->t - im.time_s)) best = &t;
      const bool matched = best && std::fabs(best->t - im.time_s) <= 1e-3;
      const TimingDetail& d = tr.detail[k];
      std::fprintf(
          f,
          "%s,%d,%zu,%zu,%.9e,%.4e,%d,%.4f,%.4e,%.4e,%.4e,%.4e,%.4e,%.4e,%.2f,%d,%.0f,%.3f,%.4e\n",
          c.preset.c_str(), c.seed, q, k, matched ? im.time_s - best->t : NAN, im.sigma_s,
          d.by_template ? 1 : 0, d.ncc, d.sigma_noise, d.shape_drift, d.sigma_slip, d.level_ratio,
          d.noise_rms, im.amplitude, im.snr_db, matched ? (best->eligible ? 1 : 0) : -1,
          c.audio.info.sample_rate_hz, d.aic_residual, d.sigma_ambiguity);
    }
  }
  std::fclose(f);
}

bool HaveAubio() { return std::system("command -v aubioonset > /dev/null 2>&1") == 0; }

RunOut RunAubio(const std::string& path, const std::string& method, bool short_hop) {
  RunOut r;
  const std::string cmd = "aubioonset -i '" + path + "' -O " + method +
                          (short_hop ? " -B 512 -H 64" : "") + " 2>/dev/null";
  const double t0 = ChildrenCpuS();
  std::unique_ptr<FILE, int (*)(FILE*)> p(popen(cmd.c_str(), "r"), pclose);
  if (!p) {
    r.failed = true;
    return r;
  }
  char line[256];
  while (std::fgets(line, sizeof line, p.get())) {
    char* end = nullptr;
    const double v = std::strtod(line, &end);
    if (end != line) r.t.push_back(v);
  }
  r.failed = pclose(p.release()) != 0;
  r.time_s = ChildrenCpuS() - t0;  // includes the shell popen starts
  return r;
}

std::string F(const char* fmt, double v) {
  if (!std::isfinite(v)) return "–";
  char b[64];
  std::snprintf(b, sizeof b, fmt, v);
  return b;
}

void PrintAccuracyRow(const std::string& preset, const std::string& who, const Metrics& m) {
  const double recall = m.eligible ? double(m.matched_eligible) / m.eligible : NAN;
  const double precision = m.detections ? double(m.matched_detections) / m.detections : NAN;
  std::vector<double> abs_err;
  for (double v : m.interval_err_us) abs_err.push_back(std::fabs(v));
  std::printf("| %s | %s | %d | %s | %s | %s | %s | %s | %s |\n", preset.c_str(), who.c_str(),
              m.eligible, F("%.3f", recall).c_str(), F("%.3f", precision).c_str(),
              F("%.1f", Quantile(abs_err, 0.5)).c_str(), F("%.1f", Quantile(abs_err, 0.95)).c_str(),
              F("%.2e", Rms(m.e_err)).c_str(), F("%.2e", Rms(m.e_err_long)).c_str());
}

// --- Real recordings ------------------------------------------------------------------------
// ../shared/recordings: hand-annotated onsets (NAME.impacts.csv: k, t_impact_s, confidence H/M/L).
// Rule (as /work/scratch/cmp.py of the issue): each annotation takes the nearest detection of
// the main sequence within 5 ms; one constant offset per file (the median of those errors);
// detections of the main sequence not matched, inside the annotated span (+-5 ms), count as
// extra; before/after the span are counted apart (after: the annotators stopped where they were
// unsure; many are real tail bounces). Start invariance: the file with its first 40 % of the
// time before the first annotated impact cut off (a whole number of samples), every impact of
// every sequence matched within 5 ms: how many agree within max(3 sigma, 2 us), and the largest
// |dt| among those that do not.
struct Annotation {
  double t = 0.0;
  char confidence = 'L';
};

std::vector<Annotation> ReadAnnotations(const std::string& path) {
  std::vector<Annotation> out;
  std::FILE* f = std::fopen(path.c_str(), "r");
  if (!f) return out;
  char line[512];
  bool header = true;
  while (std::fgets(line, sizeof line, f)) {
    if (header) {
      header = false;
      continue;
    }
    char* p = std::strchr(line, ',');
    if (!p) continue;
    char* end = nullptr;
    const double t = std::strtod(p + 1, &end);
    if (end == p + 1 || *end != ',') continue;
    out.push_back({t, end[1]});
  }
  std::fclose(f);
  return out;
}

void RealRecordingsBlock(const std::string& dir) {
  std::printf(
      "\n## Real recordings (%s; rule: see RealRecordingsBlock in tools/bench_detect.cpp)\n\n",
      dir.c_str());
  std::printf(
      "| file | channel | sequences | main | H found | M found | L found | extra inside | before "
      "| after | removed (codes) | start invariance: agree / matched, worst disagreement |\n"
      "|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  std::vector<fs::path> wavs;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(dir, ec))
    if (e.path().extension() == ".wav") wavs.push_back(e.path());
  std::sort(wavs.begin(), wavs.end());
  if (wavs.empty()) std::printf("| (no recordings in %s) |||||||||||\n", dir.c_str());
  for (const fs::path& w : wavs) {
    const std::vector<Annotation> ann =
        ReadAnnotations((w.parent_path() / (w.stem().string() + ".impacts.csv")).string());
    if (ann.size() < 2) continue;
    Audio audio;
    DetectionResult r;
    try {
      audio = ReadAudio(w.string());
      r = DetectImpacts(audio, DetectOptions{});
    } catch (const Error& e) {
      std::printf("| %s | failed: %s |||||||||||\n", w.filename().c_str(), e.what());
      continue;
    }
    const auto& imps = r.main().impacts;
    std::map<char, int> found, total;
    std::vector<double> errs;
    std::vector<bool> matched(imps.size(), false);
    for (const Annotation& a : ann) {
      ++total[a.confidence];
      std::size_t best = imps.size();
      for (std::size_t j = 0; j < imps.size(); ++j)
        if (best == imps.size() ||
            std::fabs(imps[j].time_s - a.t) < std::fabs(imps[best].time_s - a.t))
          best = j;
      if (best < imps.size() && std::fabs(imps[best].time_s - a.t) < 0.005) {
        ++found[a.confidence];
        matched[best] = true;
        errs.push_back(imps[best].time_s - a.t);
      }
    }
    const double lo = ann.front().t - 0.005, hi = ann.back().t + 0.005;
    int extra = 0, before = 0, after = 0;
    for (std::size_t j = 0; j < imps.size(); ++j) {
      if (imps[j].time_s < lo)
        ++before;
      else if (imps[j].time_s > hi)
        ++after;
      else if (!matched[j])
        ++extra;
    }
    std::map<std::string, int> removed;
    for (const Sequence& q : r.sequences)
      for (const RemovedImpact& x : q.removed) ++removed[x.code];
    for (const Warning& wn : r.warnings)
      if (wn.code == "phantom_removed" && wn.message.find("impacts removed") != std::string::npos)
        ++removed["phantom_sequence"];
    std::string rem;
    for (const auto& [code, n] : removed)
      rem += (rem.empty() ? "" : ", ") + std::to_string(n) + " " + code;
    // Start invariance.
    Audio cut = audio;
    const double rate = audio.info.sample_rate_hz;
    const std::size_t k = static_cast<std::size_t>(std::floor(0.4 * ann.front().t * rate));
    for (auto& c : cut.channels) c.erase(c.begin(), c.begin() + static_cast<std::ptrdiff_t>(k));
    cut.info.frames -= static_cast<std::int64_t>(k);
    int agree = 0, compared = 0;
    double worst = 0.0;
    try {
      const DetectionResult rc = DetectImpacts(cut, DetectOptions{});
      const double shift = static_cast<double>(k) / rate;
      for (const Sequence& qa : r.sequences)
        for (const Impact& a : qa.impacts) {
          const Impact* b = nullptr;
          for (const Sequence& qb : rc.sequences)
            for (const Impact& i : qb.impacts)
              if (!b ||
                  std::fabs(i.time_s + shift - a.time_s) < std::fabs(b->time_s + shift - a.time_s))
                b = &i;
          if (!b || std::fabs(b->time_s + shift - a.time_s) > 0.005) continue;
          ++compared;
          const double d = std::fabs(b->time_s + shift - a.time_s);
          if (d <= std::max(3.0 * std::max(a.sigma_s, b->sigma_s), 2e-6))
            ++agree;
          else
            worst = std::max(worst, d);
        }
    } catch (const Error&) {
    }
    auto frac = [&](char c) { return std::to_string(found[c]) + "/" + std::to_string(total[c]); };
    std::printf(
        "| %s | %s | %zu | %zu | %s | %s | %s | %d | %d | %d | %s | %d / %d cut %.3f s, worst %s "
        "|\n",
        w.filename().c_str(), r.channel >= 0 ? std::to_string(r.channel).c_str() : "mix",
        r.sequences.size(), imps.size(), frac('H').c_str(), frac('M').c_str(), frac('L').c_str(),
        extra, before, after, rem.empty() ? "-" : rem.c_str(), agree, compared,
        static_cast<double>(k) / rate, worst > 0 ? (F("%.1f", worst * 1e6) + " µs").c_str() : "-");
  }
}
// Renders every preset with `seeds` seeds as 24-bit WAV into dir and reads them back (the path a
// user's file takes); with keep, the truth JSON is written beside each.
std::vector<Corpus> RenderCorpus(const std::vector<std::string>& presets, int seeds,
                                 const fs::path& dir, bool keep) {
  std::vector<Corpus> corpus;
  std::fprintf(stderr, "rendering %zu files...\n", presets.size() * seeds);
  for (const std::string& p : presets)
    for (int s = 0; s < seeds; ++s) {
      SynthSpec spec = SynthPreset(p);
      spec.render.seed = spec.render.seed + 1000ull * static_cast<unsigned>(s);
      const SynthResult res = Synthesize(spec);
      Corpus c;
      c.preset = p;
      c.seed = static_cast<int>(spec.render.seed);
      c.path = (dir / (p + "_" + std::to_string(c.seed) + ".wav")).string();
      WriteAudio(c.path, res.recording.channels, res.recording.sample_rate_hz,
                 AudioWriteOptions{"PCM_24"});
      c.audio = ReadAudio(c.path);
      if (keep) {
        std::FILE* tf = std::fopen((c.path + ".truth.json").c_str(), "w");
        if (tf) {
          std::fputs(DumpJson(TruthJson(spec, res), 1).c_str(), tf);
          std::fclose(tf);
        }
      }
      for (std::size_t ch = 0; ch < res.recording.channels.size(); ++ch)
        c.truth_per_channel.push_back(TruthFor(spec, res.recording, static_cast<int>(ch)));
      corpus.push_back(std::move(c));
    }
  return corpus;
}

// Table 2: RMS of the interval pulls per preset, and the level bias of the (absolute) errors.
void PrintCalibrationTable(const std::vector<std::string>& presets,
                           std::map<std::string, Metrics>& bc) {
  // 2. Timing calibration and level bias.
  std::printf("\n## Timing uncertainty calibration (intervals) and level bias (bouncecal)\n\n");
  std::printf(
      "| preset | interval pull RMS | 1.4826 median(|pull|) | median |err| (µs) | mean err loud "
      "half (µs) | "
      "mean err quiet half (µs) | quiet/loud amplitude (dB) |\n|---|---|---|---|---|---|---|\n");
  for (const std::string& p : presets) {
    auto ae = bc[p].amp_err;
    std::sort(ae.begin(), ae.end());
    std::vector<double> abs_e;
    double quiet = 0, loud = 0, qa = 0, la = 0;
    const std::size_t h = ae.size() / 2;
    for (std::size_t i = 0; i < ae.size(); ++i) {
      abs_e.push_back(std::fabs(ae[i].second) * 1e6);
      if (i < h) {
        quiet += ae[i].second;
        qa += std::log10(std::max(ae[i].first, 1e-9));
      } else {
        loud += ae[i].second;
        la += std::log10(std::max(ae[i].first, 1e-9));
      }
    }
    const double nq = static_cast<double>(h), nl = static_cast<double>(ae.size() - h);
    std::vector<double> abs_z;
    for (double v : bc[p].z) abs_z.push_back(std::fabs(v));
    std::printf("| %s | %s | %s | %s | %s | %s | %s |\n", p.c_str(),
                F("%.2f", Rms(bc[p].z)).c_str(), F("%.2f", 1.4826 * Quantile(abs_z, 0.5)).c_str(),
                F("%.1f", Quantile(abs_e, 0.5)).c_str(), F("%+.1f", 1e6 * loud / nl).c_str(),
                F("%+.1f", 1e6 * quiet / nq).c_str(), F("%.1f", 20 * (qa / nq - la / nl)).c_str());
  }
}

// Table 4: accuracy vs cost of the detection settings (first seed of every preset).
void SettingsTable(const std::vector<Corpus>& corpus) {
  // 4. Accuracy vs cost of the detection settings (first seed of every preset).
  std::printf("\n## Accuracy vs cost of detection settings (1 seed per preset)\n\n");
  std::printf(
      "| hop (ms) | refine | LPC order | guided search | recall | precision | interval err median "
      "(µs) | "
      "p95 (µs) | × real time |\n|---|---|---|---|---|---|---|---|---|\n");
  struct Setting {
    double hop_ms;
    bool refine;
    int lpc;
    bool guided;
  };
  const std::vector<Setting> settings = {{0.17, true, 48, true},  {0.33, true, 48, true},
                                         {0.67, true, 48, true},  {1.33, true, 48, true},
                                         {0.33, false, 48, true}, {0.67, false, 48, true},
                                         {0.33, true, 48, false}, {0.33, true, 16, true},
                                         {0.33, true, 32, true},  {0.33, true, 0, true}};
  for (const Setting& s : settings) {
    Metrics tot;
    DetectOptions o;
    o.hop_s = s.hop_ms * 1e-3;
    o.refine = s.refine;
    o.lpc_order = s.lpc;
    o.guided_search = s.guided;
    for (const Corpus& c : corpus) {
      if (c.seed != static_cast<int>(SynthPreset(c.preset).render.seed)) continue;
      const RunOut r = RunBouncecal(c.audio, o, 2);
      Metrics m = Score(c.truth_per_channel[static_cast<std::size_t>(r.channel)], r.t, r.sigma);
      m.time_s = r.time_s;
      m.audio_s = c.audio.info.duration_s();
      tot.Add(m);
    }
    std::vector<double> abs_err;
    for (double v : tot.interval_err_us) abs_err.push_back(std::fabs(v));
    std::printf(
        "| %.2f | %s | %d | %s | %s | %s | %s | %s | %.0f× |\n", s.hop_ms, s.refine ? "on" : "off",
        s.lpc, s.guided ? "on" : "off",
        F("%.3f", tot.eligible ? double(tot.matched_eligible) / tot.eligible : NAN).c_str(),
        F("%.3f", tot.detections ? double(tot.matched_detections) / tot.detections : NAN).c_str(),
        F("%.1f", Quantile(abs_err, 0.5)).c_str(), F("%.1f", Quantile(abs_err, 0.95)).c_str(),
        tot.audio_s / tot.time_s);
  }
}

}  // namespace

int main(int argc, char** argv) {
  int seeds = 5;
  bool use_aubio = true;
  bool quick = false, real_only = false;
  std::string keep, dump, recordings = "../shared/recordings";
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--seeds" && i + 1 < argc) {
      seeds = std::atoi(argv[++i]);
    } else if (a == "--no-aubio") {
      use_aubio = false;
    } else if (a == "--keep" && i + 1 < argc) {
      keep = argv[++i];
    } else if (a == "--quick") {
      quick = true;
      use_aubio = false;
    } else if (a == "--dump" && i + 1 < argc) {
      dump = argv[++i];
    } else if (a == "--recordings" && i + 1 < argc) {
      recordings = argv[++i];
    } else if (a == "--real-only") {
      real_only = true;
    } else {
      std::fprintf(stderr,
                   "usage: bench_detect [--seeds N] [--no-aubio] [--quick] [--keep DIR] [--dump "
                   "CSV] [--recordings DIR] [--real-only]\n");
      return 2;
    }
  }
  if (seeds < 1 || seeds > 50) {
    std::fprintf(stderr, "bench_detect: --seeds must be 1..50\n");
    return 2;
  }
  if (real_only) {
    RealRecordingsBlock(recordings);
    return 0;
  }
  const bool aubio = use_aubio && HaveAubio();
  if (use_aubio && !aubio) std::fprintf(stderr, "bench_detect: aubioonset not found; skipping\n");
  fs::path dir = keep.empty()
                     ? fs::temp_directory_path() / ("bench_detect_" + std::to_string(::getpid()))
                     : fs::path(keep);
  fs::create_directories(dir);
  if (!dump.empty()) {
    std::FILE* f = std::fopen(dump.c_str(), "w");
    if (!f) {
      std::fprintf(stderr, "bench_detect: cannot write %s\n", dump.c_str());
      return 2;
    }
    std::fputs(
        "preset,seed,sequence,k,err_s,sigma_s,by_template,ncc,sigma_noise,shape_drift,"
        "sigma_slip,level_ratio,noise_rms,amplitude,snr_db,eligible,rate_hz,aic_residual,sigma_"
        "ambiguity\n",
        f);
    std::fclose(f);
  }
  const std::string& dump_file = dump;

  const std::vector<std::string> presets = SynthPresetNames();
  const std::vector<Corpus> corpus = RenderCorpus(presets, seeds, dir, !keep.empty());

  // 1. Accuracy per preset, bouncecal vs aubio.
  const std::vector<std::pair<std::string, bool>> aubio_runs = {
      {"hfc", false}, {"hfc", true}, {"specflux", false}, {"specflux", true}};
  std::map<std::string, Metrics> bc, au[4];
  double bc_time = 0, au_time = 0, audio_total = 0;
  std::vector<double> au_ratio;
  for (const Corpus& c : corpus) {
    const RunOut r = RunBouncecal(c.audio, DetectOptions{}, 3);
    Metrics m = Score(c.truth_per_channel[static_cast<std::size_t>(r.channel)], r.t, r.sigma);
    m.time_s = r.time_s;
    m.audio_s = c.audio.info.duration_s();
    bc[c.preset].Add(m);
    if (!dump_file.empty()) DumpTiming(dump_file, c, r);
    bc_time += r.time_s;
    audio_total += m.audio_s;
    if (aubio) {
      double file_au = 0;
      for (std::size_t k = 0; k < aubio_runs.size(); ++k) {
        const RunOut ra = RunAubio(c.path, aubio_runs[k].first, aubio_runs[k].second);
        Metrics ma = Score(c.truth_per_channel[0], ra.t, {});
        ma.time_s = ra.time_s;
        ma.audio_s = m.audio_s;
        au[k][c.preset].Add(ma);
        if (k == 0) file_au = ra.time_s;
      }
      au_time += file_au;
      au_ratio.push_back(file_au / r.time_s);
    }
  }
  std::printf(
      "## Detection accuracy (%d seeds per preset; rule: see the header of "
      "tools/bench_detect.cpp)\n\n",
      seeds);
  std::printf(
      "| preset | detector | eligible | recall | precision | interval err median (µs) | "
      "p95 (µs) | e RMS err | e RMS err, dt >= 50 ms |\n|---|---|---|---|---|---|---|---|---|\n");
  Metrics all_bc;
  for (const std::string& p : presets) {
    PrintAccuracyRow(p, "bouncecal", bc[p]);
    all_bc.Add(bc[p]);
    if (aubio)
      for (std::size_t k = 0; k < aubio_runs.size(); ++k)
        PrintAccuracyRow(
            p,
            "aubio " + aubio_runs[k].first + (aubio_runs[k].second ? " -B512 -H64" : " (default)"),
            au[k][p]);
  }
  PrintAccuracyRow("all", "bouncecal", all_bc);

  PrintCalibrationTable(presets, bc);
  RealRecordingsBlock(recordings);

  // 3. Speed.
  std::printf("\n## Speed (one thread)\n\n");
  std::printf("| what | value |\n|---|---|\n");
  std::printf("| audio in corpus | %.1f s in %zu files |\n", audio_total, corpus.size());
  std::printf("| bouncecal DetectImpacts total | %.1f ms |\n", bc_time * 1e3);
  std::printf("| bouncecal × real time | %.0f× |\n", audio_total / bc_time);
  for (const std::string& p : presets)
    std::printf("| × real time, %s | %.0f× |\n", p.c_str(), bc[p].audio_s / bc[p].time_s);
  if (aubio) {
    std::printf("| aubioonset hfc (default hop), process CPU time total | %.1f ms |\n",
                au_time * 1e3);
    std::printf("| aubioonset time / bouncecal time (median over files) | %.2f |\n",
                Quantile(au_ratio, 0.5));
  }

  if (quick) {
    if (keep.empty()) fs::remove_all(dir);
    return 0;
  }
  SettingsTable(corpus);
  if (keep.empty()) fs::remove_all(dir);
  return 0;
}
