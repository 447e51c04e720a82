// bouncecal/core/error.hpp — the one error type of the library and the CLI's exit codes.
//
// Every stage validates its inputs at the boundary (files, scene files, CLI values, parameter
// vectors) and throws bouncecal::Error with a message that names the input, the value and what
// was expected. The CLI prints "bouncecal: <message>" on one line and exits with code().
//
//   throw Error(ErrorCode::kNotAudio, path + ": not an audio file libsndfile can read (...)");
//
// Inside the library, broken invariants are assertions, not Errors.
#pragma once

#include <stdexcept>
#include <string>

namespace bouncecal {

// Process exit codes. Stable: scripts test them. Documented in docs/cli.md.
enum class ErrorCode : int {
  kOk = 0,
  kInternal = 1,      // a bug: please report
  kUsage = 2,         // bad command line (CLI11 parse errors use this too)
  kInputMissing = 3,  // file does not exist, is a directory, or cannot be opened
  kNotAudio = 4,      // not audio, unsupported, truncated or zero-length file
  kBadSamples = 5,    // NaN or Inf samples
  kSilence = 6,       // the recording is silent (all samples at or below the noise floor)
  kNoBounces = 7,     // no usable bounce sequence (noise only, a single impact, ...)
  kBadScene = 8,      // malformed scene or impacts file, unknown key, bad or conflicting values
  kBadParameter = 9,  // unknown law/parameter, out-of-range or non-finite value
  kFitFailed = 10,    // the fit failed: no usable result (fit outcome "failed")
  kOutput = 11,       // output path unusable (missing directory, exists without force, ...)
  kSomeFailed = 12,   // batch mode: at least one input failed, the others were processed
  // Fit outcomes other than "converged" (calibrate.hpp). The parameter file is still written
  // and records the outcome; these codes keep scripts from taking it for a success.
  kFitIterationLimit = 13,   // "iteration_limit": the solver stopped before an optimum
  kFitPoorFit = 14,          // "poor_fit": the law is rejected by its own goodness of fit
  kFitNotDeterminable = 15,  // "not_determinable": the data cannot pin a damping parameter
};

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const { return code_; }
  int exit_code() const { return static_cast<int>(code_); }

 private:
  ErrorCode code_;
};

// Short stable name of an error code ("no_bounces"), for JSON/CSV batch summaries.
const char* ErrorCodeName(ErrorCode code);

}  // namespace bouncecal
