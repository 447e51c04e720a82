// The user-control flags that detect, analyze and calibrate share, and the one function that
// turns them (and the recordings) into bounce sequences:
//   --channel N|mix|auto   --start S  --end S   --sequence main|all|N   --min-snr-db X
//   --impacts FILE (repeatable: impact times from a file instead of detection, one per
//                   recording in the same order; with no recording, each file is one)
//
//   DetectFlags flags;  AddDetectFlags(sub, &flags);          // declare
//   for (const Drop& d : LoadDrops(files, flags)) ...          // one per chosen sequence
//
// Library messages name Options fields; the flag checks here name the flags.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"

namespace bouncecal::cli {

struct DetectFlags {
  std::string channel = "auto";
  std::optional<double> start_s;
  std::optional<double> end_s;
  std::string sequence = "main";
  std::optional<double> min_snr_db;
  std::vector<std::string> impacts;
};

// Adds --channel --start --end --sequence --min-snr-db --impacts to a subcommand.
void AddDetectFlags(CLI::App* sub, DetectFlags* flags);

// The detector's options from the flags (the other DetectOptions fields keep their defaults).
// Throws Error(kUsage) naming the flag.
DetectOptions MakeDetectOptions(const DetectFlags& flags);

// One recording's sequences: detected, or read from its --impacts file.
struct LoadedRecording {
  std::string name;          // the recording (or the impacts file when there is none)
  DetectionResult result;    // sequences (detected or from the file), audio info, warnings
  std::vector<int> chosen;   // --sequence: indices into result.sequences
  std::string impacts_file;  // non-empty when the times came from a file
};

// `audio`: the recording already read (or null: read here when needed). Throws Error.
LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DetectFlags& flags);

// Pairs the recordings with the --impacts files (see above) and loads each. Throws Error(kUsage)
// when the counts do not pair up.
std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DetectFlags& flags);

// One drop for analyze/calibrate: a chosen sequence of a recording, named "FILE" or, when
// --sequence gives several of one recording, "FILE#N" (N its sequence index).
struct Drop {
  std::string name;
  Sequence sequence;
  std::vector<Warning> warnings;  // the recording's detection warnings (on its first drop only)
};
std::vector<Drop> LoadDrops(const std::vector<std::string>& recordings, const DetectFlags& flags);
// The drops of one recording / --impacts pair (an element of PairInputs).
std::vector<Drop> DropsOf(const std::string& recording, const std::string& impacts_file,
                          const DetectFlags& flags);

}  // namespace bouncecal::cli
