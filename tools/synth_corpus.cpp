// synth_corpus — renders the benchmark corpus (every synth preset) and prints what is in it.
//
//   build/synth_corpus [OUT_DIR] [--seeds N]
//
// For each preset and seed (preset seed, +1, ...) it prints rate, channels, duration, impact
// counts (all; and "scorable": >= 3 ms from both neighbours and >= 20 dB above the noise in
// channel 0, the recall/precision condition), clipped impacts, distractors and the
// render time (thread CPU time). With OUT_DIR it also writes PRESET-sSEED.wav (PCM_24) and
// PRESET-sSEED.truth.json there, e.g. to run aubioonset on the same files.
#include <time.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <string>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/synth/synth.hpp"

namespace {

double ThreadCpuS() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

}  // namespace

int main(int argc, char** argv) {
  using namespace bouncecal;
  std::string out_dir;
  int seeds = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--seeds" && i + 1 < argc) {
      seeds = std::atoi(argv[++i]);
    } else if (!a.empty() && a[0] != '-') {
      out_dir = a;
    } else {
      std::fprintf(stderr, "usage: synth_corpus [OUT_DIR] [--seeds N]\n");
      return 2;
    }
  }
  if (seeds < 1 || seeds > 1000) {
    std::fprintf(stderr, "synth_corpus: --seeds must be 1..1000\n");
    return 2;
  }
  try {
    if (!out_dir.empty() && !std::filesystem::is_directory(out_dir)) {
      throw Error(ErrorCode::kOutput, out_dir + ": not a directory");
    }
    std::printf("%-14s %6s %6s %4s %8s %7s %8s %7s %6s %9s %10s\n", "preset", "seed", "rate", "ch",
                "dur_s", "impacts", "scorable", "clipped", "distr", "render_s", "x_realtime");
    for (const std::string& name : SynthPresetNames()) {
      for (int k = 0; k < seeds; ++k) {
        SynthSpec spec = SynthPreset(name);
        spec.render.seed += static_cast<std::uint64_t>(k);
        const double t0 = ThreadCpuS();
        const SynthResult r = Synthesize(spec);
        const double cpu_s = ThreadCpuS() - t0;
        int impacts = 0, scorable = 0, clipped = 0;
        for (const auto& d : r.recording.drops) {
          for (std::size_t i = 0; i < d.size(); ++i) {
            ++impacts;
            clipped += d[i].clipped;
            const double prev = i > 0 ? d[i].onset_s - d[i - 1].onset_s : 1e9;
            const double next = i + 1 < d.size() ? d[i + 1].onset_s - d[i].onset_s : 1e9;
            scorable += prev >= 0.003 && next >= 0.003 && d[i].snr_db >= 20.0;
          }
        }
        const double dur = r.recording.duration_s();
        std::printf("%-14s %6llu %5.1fk %4zu %8.2f %7d %8d %7d %6zu %9.3f %10.0f\n", name.c_str(),
                    static_cast<unsigned long long>(spec.render.seed),
                    r.recording.sample_rate_hz / 1000, r.recording.channels.size(), dur, impacts,
                    scorable, clipped, r.recording.distractors.size(), cpu_s, dur / cpu_s);
        if (!out_dir.empty()) {
          const std::string stem = out_dir + "/" + name + "-s" + std::to_string(spec.render.seed);
          WriteAudio(stem + ".wav", r.recording.channels, r.recording.sample_rate_hz,
                     AudioWriteOptions{"PCM_24"});
          WriteFileAtomically(stem + ".truth.json", DumpJson(TruthJson(spec, r), 2) + "\n",
                              WriteOptions{.force = true, .inputs = {}});
        }
      }
    }
  } catch (const Error& e) {
    std::fprintf(stderr, "synth_corpus: %s\n", e.what());
    return e.exit_code();
  }
  return 0;
}
