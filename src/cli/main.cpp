// bouncecal — calibrate contact-law damping from the sound of a bouncing ball.
#include <malloc.h>

#include <cstdio>
#include <cstring>
#include <exception>

#include <glog/logging.h>
#include <CLI/CLI.hpp>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "commands.hpp"
#include "output.hpp"

namespace {

// Ceres logs through glog: without initialisation every failed fit printed "WARNING: Logging
// before InitGoogleLogging() is written to STDERR" and its own "E... trust_region_minimizer.cc"
// lines. The solver's outcome and message already reach the user through our own messages
// (calibrate.hpp: FitOutcome, Calibration::message), so glog keeps only FATAL (which aborts
// anyway) and writes no log files. Done here, once: the library holds no global state.
void QuietThirdPartyLogging(const char* argv0) {
  FLAGS_logtostderr = true;  // no files under /tmp
  FLAGS_minloglevel = google::GLOG_FATAL;
  google::InitGoogleLogging(argv0);
}

// Detection allocates a few buffers of one block's length (up to 2 minutes of audio, ~23 MB
// each at 48 kHz) per block and candidate signal. glibc maps such sizes freshly (mmap) and
// returns freed heap tops to the kernel, so every block paid its page faults again: on a
// 10-minute recording 0.9 s of system time, mostly faults, against 0.4 s with the heap kept.
// Allocations up to glibc's largest mmap threshold (32 MB on 64-bit) come from the heap and
// freed memory stays mapped for the next block; the peak is unchanged. Process-wide malloc
// tuning belongs to the program, not the library.
void KeepLargeBuffersMapped() {
  mallopt(M_MMAP_THRESHOLD, 32 * 1024 * 1024);
  mallopt(M_TRIM_THRESHOLD, 1024 * 1024 * 1024);
}

}  // namespace

int main(int argc, char** argv) {
  KeepLargeBuffersMapped();
  QuietThirdPartyLogging(argv[0]);
  // A SIGINT/SIGTERM mid-write removes the temporary file; finished outputs stay complete.
  bouncecal::InstallTempFileCleanupOnSignals();
  CLI::App app{"bouncecal " BOUNCECAL_VERSION
               " — calibrate contact-law damping from the sound of a bouncing ball"};
  app.set_version_flag("--version", std::string("bouncecal ") + BOUNCECAL_VERSION);
  app.require_subcommand(1);
  // The subcommand named first on the command line is the only one registered (building every
  // subcommand's options took ~0.7 ms of each run, a tenth of the program's start); anything
  // else (--help, --version, a misspelt name) gets them all, listed as before.
  struct Subcommand {
    const char* name;
    void (*add)(CLI::App&);
  };
  static constexpr Subcommand kSubcommands[] = {{"detect", bouncecal::cli::RegisterDetect},
                                                {"analyze", bouncecal::cli::RegisterAnalyze},
                                                {"synth", bouncecal::cli::RegisterSynth},
                                                {"laws", bouncecal::cli::RegisterLaws},
                                                {"simulate", bouncecal::cli::RegisterSimulate},
                                                {"calibrate", bouncecal::cli::RegisterCalibrate},
                                                {"export", bouncecal::cli::RegisterExport},
                                                {"report", bouncecal::cli::RegisterReport},
                                                {"serve", bouncecal::cli::RegisterServe},
                                                {"listen", bouncecal::cli::RegisterListen}};
  const Subcommand* named = nullptr;
  for (const Subcommand& s : kSubcommands)
    if (argc > 1 && std::strcmp(argv[1], s.name) == 0) named = &s;
  if (named != nullptr) {
    named->add(app);
  } else {
    for (const Subcommand& s : kSubcommands) s.add(app);
  }
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are "errors" with exit code 0: let CLI11 print them.
    if (e.get_exit_code() == 0) return app.exit(e);
    // Everything else: one line on stderr, like every other bouncecal error.
    std::fprintf(stderr, "bouncecal: %s (see --help)\n", e.what());
    return static_cast<int>(bouncecal::ErrorCode::kUsage);
  } catch (const bouncecal::Error& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "bouncecal: %s\n", bouncecal::cli::FlagText(e.what()).c_str());
    return e.exit_code();
  } catch (const std::exception& e) {
    std::fflush(stdout);
    std::fprintf(stderr, "bouncecal: internal error: %s\n", e.what());
    return static_cast<int>(bouncecal::ErrorCode::kInternal);
  }
  return 0;
}
