// A progress line on stderr for work longer than about a second (detection of long recordings,
// `--law all`, batches): shown only when stderr is a terminal, never with --quiet, so scripts
// and logs see nothing. Each Stage() rewrites the line in place; Done() (or the destructor)
// clears it.
//
//   Progress progress(flags.quiet);
//   progress.Stage("detecting impacts in drop.wav");
#pragma once

#include <string>

namespace bouncecal::cli {

class Progress {
 public:
  // Enabled when !quiet and stderr is a terminal (isatty).
  explicit Progress(bool quiet);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  bool enabled() const { return enabled_; }
  // "bouncecal: <text> ..." on the progress line (nothing when disabled).
  void Stage(const std::string& text);
  // Clears the line (before a result or a message is printed).
  void Done();

 private:
  bool enabled_ = false;
  bool shown_ = false;
};

}  // namespace bouncecal::cli
