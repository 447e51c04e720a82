// bench_live — what the streaming detector (acoustic/live.hpp) costs and how it agrees with the
// batch detector, fed as a live stream would feed it (2048-sample chunks, 43 ms at 48 kHz):
//
//   build/bench_live                      # the bundled recording and the synth presets
//   build/bench_live --hour 60            # also a 60-minute stream: window and memory
//
// Per recording: the impacts the batch detector finds in its main sequence, the live impacts
// of the same drop after the stream ended, the share of the batch's intervals the live ones
// reproduce (both ends within 1 ms, the length within 3 combined sigmas), the revisions sent,
// the audio latency (audio fed when an impact was reported, less the impact's time: the settle
// time plus the wait for the next run; median and 90th percentile, a sequence's first two
// impacts left out as they wait for the third), and the CPU time per second of audio (this
// thread's user + system time: the share of one core a real-time stream takes). The long
// stream loops the bundled recording with 20 s of room noise between drops and reports the
// largest window held, the process's peak resident memory (VmHWM) and its growth over the
// stream, the CPU share, and that every drop was found. Prints Markdown tables.
#include <sys/resource.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/live.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/synth/synth.hpp"

namespace {

using namespace bouncecal;

double ThreadCpuS() {
  rusage u{};
  getrusage(RUSAGE_THREAD, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double PeakRssMb() {
  std::ifstream in("/proc/self/status");
  for (std::string line; std::getline(in, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0.0;
}

double Quantile(std::vector<double> v, double p) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v[static_cast<std::size_t>(std::min<double>(
      static_cast<double>(v.size() - 1), std::floor(p * static_cast<double>(v.size()))))];
}

struct Row {
  std::string name;
  int batch = 0, live = 0, revisions = 0, runs = 0;
  double reproduced = 0, latency_median = 0, latency_p90 = 0, cpu_share = 0, window_s = 0;
};

// The live sequence sharing most impacts (within 1 ms) with `batch`.
std::vector<Impact> Matching(const std::vector<LiveImpact>& all, const std::vector<Impact>& batch) {
  std::map<int, std::vector<Impact>> by;
  for (const LiveImpact& i : all) by[i.sequence].push_back(i.impact);
  std::vector<Impact> best;
  int best_n = -1;
  for (auto& [id, q] : by) {
    int n = 0;
    for (const Impact& a : q)
      for (const Impact& b : batch) n += std::fabs(a.time_s - b.time_s) < 1e-3 ? 1 : 0;
    if (n > best_n) best_n = n, best = q;
  }
  return best;
}

double Reproduced(const std::vector<Impact>& live, const std::vector<Impact>& batch) {
  int good = 0;
  for (std::size_t k = 0; k + 1 < batch.size(); ++k) {
    for (std::size_t j = 0; j + 1 < live.size(); ++j) {
      if (std::fabs(live[j].time_s - batch[k].time_s) > 1e-3) continue;
      if (std::fabs(live[j + 1].time_s - batch[k + 1].time_s) <= 1e-3 &&
          std::fabs((live[j + 1].time_s - live[j].time_s) -
                    (batch[k + 1].time_s - batch[k].time_s)) <=
              3.0 * std::hypot(batch[k].sigma_s, batch[k + 1].sigma_s) + 1e-6)
        ++good;
      break;
    }
  }
  return batch.size() > 1 ? good / static_cast<double>(batch.size() - 1) : 0.0;
}

Row Measure(const std::string& name, const std::vector<float>& x, double rate) {
  Row r;
  r.name = name;
  Audio a;
  a.info.path = name;
  a.info.sample_rate_hz = rate;
  a.info.channels = 1;
  a.info.frames = static_cast<std::int64_t>(x.size());
  a.channels = {x};
  a.clipping = {AnalyzeClipping(x, 0)};
  std::vector<Impact> batch;
  try {
    batch = DetectImpacts(a, DetectOptions{}).main().impacts;
  } catch (const Error&) {
  }
  LiveDetector live(rate);
  std::vector<double> latency;
  double window = 0;
  const double cpu0 = ThreadCpuS();
  auto take = [&](const LiveUpdate& u) {
    r.revisions += static_cast<int>(u.revisions.size());
    for (const LiveImpact& i : u.impacts)
      if (i.index >= 2)
        latency.push_back(static_cast<double>(live.frames()) / rate - i.impact.time_s);
    window = std::max(window, static_cast<double>(live.window_frames()) / rate);
  };
  for (std::size_t at = 0; at < x.size(); at += 2048)
    take(live.Feed(x.data() + at, std::min<std::size_t>(2048, x.size() - at)));
  take(live.Finish());
  r.cpu_share = (ThreadCpuS() - cpu0) / (static_cast<double>(x.size()) / rate);
  const std::vector<Impact> mine = Matching(live.Impacts(), batch);
  r.batch = static_cast<int>(batch.size());
  r.live = static_cast<int>(mine.size());
  r.reproduced = Reproduced(mine, batch);
  r.latency_median = Quantile(latency, 0.5);
  r.latency_p90 = Quantile(latency, 0.9);
  r.runs = live.detections();
  r.window_s = window;
  return r;
}

void LongStream(const std::vector<float>& drop, double rate, double minutes) {
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 3e-4f);
  std::vector<float> gap(static_cast<std::size_t>(20 * rate));
  for (float& v : gap) v = noise(rng);
  const double period_s = static_cast<double>(drop.size() + gap.size()) / rate;
  const auto drops = static_cast<int>(std::ceil(minutes * 60.0 / period_s));
  LiveDetector live(rate);
  double window = 0, rss_first = 0;
  std::int64_t fed = 0;
  std::map<int, int> members;
  const double cpu0 = ThreadCpuS();
  for (int d = 0; d < drops; ++d) {
    for (const std::vector<float>* part : std::vector<const std::vector<float>*>{&drop, &gap}) {
      for (std::size_t at = 0; at < part->size(); at += 2048) {
        const std::size_t n = std::min<std::size_t>(2048, part->size() - at);
        for (const LiveImpact& i : live.Feed(part->data() + at, n).impacts) ++members[i.sequence];
        fed += static_cast<std::int64_t>(n);
        window = std::max(window, static_cast<double>(live.window_frames()) / rate);
      }
    }
    if (d == 0) rss_first = PeakRssMb();
  }
  live.Finish();
  const double cpu = ThreadCpuS() - cpu0;
  int found = 0;
  for (const auto& [id, n] : members) found += n >= 60 ? 1 : 0;
  std::printf(
      "\n| stream | audio | drops found | largest window | peak RSS after 1st drop | peak RSS at "
      "the end | CPU per s of audio |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  std::printf(
      "| bundled drop + 20 s noise, looped | %.1f min | %d of %d | %.1f s | %.0f MB | %.0f MB | "
      "%.3f s |\n",
      static_cast<double>(fed) / rate / 60.0, found, drops, window, rss_first, PeakRssMb(),
      cpu / (static_cast<double>(fed) / rate));
}

}  // namespace

int main(int argc, char** argv) {
  double hour_minutes = 0;
  for (int i = 1; i < argc; ++i) {
    if (std::strcmp(argv[i], "--hour") == 0 && i + 1 < argc) hour_minutes = std::atof(argv[++i]);
  }
  const Audio bundled =
      ReadAudio(std::string(BOUNCECAL_SOURCE_DIR) + "/data/default_steel_copper.flac");
  std::vector<Row> rows;
  rows.push_back(
      Measure("bundled (steel-copper, 48 kHz)", bundled.channels[0], bundled.info.sample_rate_hz));
  for (const std::string preset : {"glass-glass", "pingpong-wood", "rubber-wood", "phone-16k"}) {
    SynthSpec spec = SynthPreset(preset);
    const Recording rec = Synthesize(spec).recording;
    rows.push_back(Measure(preset + " (synth, " +
                               std::to_string(static_cast<int>(rec.sample_rate_hz / 1000)) +
                               " kHz)",
                           rec.channels[0], rec.sample_rate_hz));
  }
  std::printf(
      "| recording | batch impacts | live impacts | intervals reproduced | revisions | latency "
      "median | latency p90 | runs | largest window | CPU per s of audio |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Row& r : rows)
    std::printf("| %s | %d | %d | %.1f %% | %d | %.0f ms | %.0f ms | %d | %.1f s | %.3f s |\n",
                r.name.c_str(), r.batch, r.live, 100.0 * r.reproduced, r.revisions,
                1e3 * r.latency_median, 1e3 * r.latency_p90, r.runs, r.window_s, r.cpu_share);
  if (hour_minutes > 0) LongStream(bundled.channels[0], bundled.info.sample_rate_hz, hour_minutes);
  return 0;
}
