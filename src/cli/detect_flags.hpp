// The user-control flags that detect, analyze and calibrate share, and the one function that
// turns them (and the recordings) into bounce sequences:
//   --channel N|mix|auto   --start S  --end S   --sequence main|all|N   --min-snr-db X
//   --impacts FILE (repeatable: impact times from a file instead of detection, one per
//                   recording in the same order; with no recording, each file is one)
//
//   DetectFlags flags;  AddDetectFlags(sub, &flags);          // declare
//   for (const Drop& d : LoadDrops(files, flags)) ...          // one per chosen sequence
//
// The flags fill DropInputOptions (bouncecal/acoustic/drop_input.hpp), which does the work;
// the flag checks here name the flags, and the library's messages (naming Options fields) are
// mapped to the flags by FlagText (output.hpp).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/acoustic/drop_input.hpp"

namespace bouncecal::cli {

struct DetectFlags {
  std::string channel = "auto";
  std::optional<double> start_s;
  std::optional<double> end_s;
  std::string sequence = "main";
  std::optional<double> min_snr_db;
  std::vector<std::string> impacts;
  int threads = 1;  // DetectOptions::threads (0: one per core; batch workers set 1)
};

// Adds --channel --start --end --sequence --min-snr-db --impacts to a subcommand.
void AddDetectFlags(CLI::App* sub, DetectFlags* flags);

// The library's options from the flags (the other DetectOptions fields keep their defaults).
// Throws Error(kUsage) naming the flag.
DetectOptions MakeDetectOptions(const DetectFlags& flags);
DropInputOptions MakeDropInputOptions(const DetectFlags& flags);

// The library's drop input (bouncecal/acoustic/drop_input.hpp) with the options from the flags
// and its messages in flag names (FlagText).
using Drop = RecordingDrop;
LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DetectFlags& flags);
std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DetectFlags& flags);
std::vector<Drop> LoadDrops(const std::vector<std::string>& recordings, const DetectFlags& flags);
std::vector<Drop> DropsOf(const std::string& recording, const std::string& impacts_file,
                          const DetectFlags& flags);

// Every file a command reads: the recordings, the --impacts files and the scene file ("" =
// none). No output may replace one of them (WriteOptions::inputs), --force or not.
std::vector<std::string> InputFiles(const std::vector<std::string>& recordings,
                                    const DetectFlags& flags, const std::string& scene_file);

}  // namespace bouncecal::cli
