#include "progress.hpp"

#include <unistd.h>

#include <cstdio>

namespace bouncecal::cli {

Progress::Progress(bool quiet) : enabled_(!quiet && ::isatty(STDERR_FILENO) == 1) {}

Progress::~Progress() { Done(); }

void Progress::Stage(const std::string& text) {
  if (!enabled_) return;
  // \r and "erase to end of line" (ANSI EL) rewrite the line in place.
  std::fprintf(stderr, "\r\033[Kbouncecal: %s ...", text.c_str());
  std::fflush(stderr);
  shown_ = true;
}

void Progress::Done() {
  if (!shown_) return;
  std::fputs("\r\033[K", stderr);
  std::fflush(stderr);
  shown_ = false;
}

}  // namespace bouncecal::cli
