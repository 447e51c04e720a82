// bouncecal/acoustic/drop_input.hpp — recordings (or impact-time files) -> the drops a user
// chose: the bounce sequences that analyze and calibrate work on.
//
// Each recording is detected (DetectImpacts), or its impact times are read from a file
// (ReadImpactsFile: detect --json output, CSV with a time_s column, Audacity labels, one time
// per line); the window [detect.start_s, detect.end_s) applies to both; `sequence` picks the
// sequences. The command line fills the options from its flags (src/cli/detect_flags.cpp), the
// Python bindings from their keywords; messages here name the Options fields.
//
//   DropInputOptions o;  o.sequence = ParseSequenceChoice("all");
//   for (const RecordingDrop& d : LoadDrops({"a.wav", "b.wav"}, o)) Analyze(d.sequence, ...);
#pragma once

#include <string>
#include <utility>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"

namespace bouncecal {

struct DropInputOptions {
  DetectOptions detect;     // detection, and the time window (applied to times from files too)
  SequenceChoice sequence;  // which sequences of each recording become drops
  // Impact times from files instead of detection: one per recording, in the same order; with
  // no recording, each file is one input.
  std::vector<std::string> impacts_files;
  bool IsValid(std::string* error) const { return detect.IsValid(error); }
};

// The inputs as (recording, impacts file) pairs, either may be "" (see impacts_files); a
// recording "-" is standard input. Throws Error(kUsage) when the counts do not pair up, there is
// no input, or standard input is named more than once.
std::vector<std::pair<std::string, std::string>> PairInputs(
    const std::vector<std::string>& recordings, const DropInputOptions& options);

// One recording's sequences: detected, or read from its impacts file.
struct LoadedRecording {
  std::string name;          // the recording (or the impacts file when there is none)
  DetectionResult result;    // sequences (detected or from the file), audio info, warnings
  std::vector<int> chosen;   // options.sequence: indices into result.sequences
  std::string impacts_file;  // non-empty when the times came from a file
};
// `audio`: the recording already read (or null: read here when needed). Throws Error
// (kBadParameter for invalid options, the readers' and the detector's errors).
LoadedRecording LoadRecording(const std::string& recording, const Audio* audio,
                              const std::string& impacts_file, const DropInputOptions& options);

// One drop: a chosen sequence of a recording, named "FILE" or, when several sequences of one
// recording are chosen, "FILE#N" (N its sequence index).
struct RecordingDrop {
  std::string name;
  Sequence sequence;
  std::vector<Warning> warnings;  // the recording's detection warnings (on its first drop only)
};
// The drops of one (recording, impacts file) pair (an element of PairInputs).
std::vector<RecordingDrop> DropsOf(const std::string& recording, const std::string& impacts_file,
                                   const DropInputOptions& options);
// The drops of every input, in order.
std::vector<RecordingDrop> LoadDrops(const std::vector<std::string>& recordings,
                                     const DropInputOptions& options);

}  // namespace bouncecal
