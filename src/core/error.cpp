#include "bouncecal/core/error.hpp"

namespace bouncecal {

const char* ErrorCodeName(ErrorCode code) {
  switch (code) {
    case ErrorCode::kOk:
      return "ok";
    case ErrorCode::kInternal:
      return "internal";
    case ErrorCode::kUsage:
      return "usage";
    case ErrorCode::kInputMissing:
      return "input_missing";
    case ErrorCode::kNotAudio:
      return "not_audio";
    case ErrorCode::kBadSamples:
      return "bad_samples";
    case ErrorCode::kSilence:
      return "silence";
    case ErrorCode::kNoBounces:
      return "no_bounces";
    case ErrorCode::kBadScene:
      return "bad_scene";
    case ErrorCode::kBadParameter:
      return "bad_parameter";
    case ErrorCode::kFitFailed:
      return "fit_failed";
    case ErrorCode::kOutput:
      return "output";
    case ErrorCode::kSomeFailed:
      return "some_failed";
    case ErrorCode::kFitIterationLimit:
      return "iteration_limit";
    case ErrorCode::kFitPoorFit:
      return "poor_fit";
    case ErrorCode::kFitNotDeterminable:
      return "not_determinable";
  }
  return "unknown";
}

}  // namespace bouncecal
