"""Exceptions of the bouncecal package: one class per exit code of the CLI (docs/cli.md: exit codes).

Every error the library raises is a `bouncecal.Error` with
  .message    the CLI's message (what `bouncecal` prints after "bouncecal: ")
  .code       the code's stable name ("input_missing", "bad_parameter", ...)
  .exit_code  the CLI's exit code for it (3, 9, ...)
and, when the CLI would also have printed a result (a batch where some inputs failed, a fit
whose outcome is not "converged"), .result holds it.
"""


class Error(Exception):
    """A bouncecal error: .message, .code (name), .exit_code (the CLI's), .result (or None)."""

    code = "internal"
    exit_code = 1

    def __init__(self, message, code=None, exit_code=None, result=None):
        super().__init__(message)
        self.message = message
        if code is not None:
            self.code = code
        if exit_code is not None:
            self.exit_code = exit_code
        self.result = result

    def __repr__(self):
        return f"{type(self).__name__}({self.message!r}, code={self.code!r}, exit_code={self.exit_code})"


def _define(name, code, exit_code, doc):
    return type(name, (Error,), {"code": code, "exit_code": exit_code, "__doc__": doc})


InternalError = _define("InternalError", "internal", 1, "A bug: please report it.")
UsageError = _define("UsageError", "usage", 2, "A bad option value or combination.")
InputMissingError = _define(
    "InputMissingError", "input_missing", 3, "A file does not exist, is a directory or cannot be opened.")
NotAudioError = _define("NotAudioError", "not_audio", 4, "Not audio, unsupported, truncated or empty.")
BadSamplesError = _define("BadSamplesError", "bad_samples", 5, "NaN or Inf samples.")
SilenceError = _define("SilenceError", "silence", 6, "The recording is silent.")
NoBouncesError = _define("NoBouncesError", "no_bounces", 7, "No usable bounce sequence.")
BadSceneError = _define("BadSceneError", "bad_scene", 8, "A malformed scene or impacts file.")
BadParameterError = _define(
    "BadParameterError", "bad_parameter", 9, "An unknown law or parameter, an out-of-range value.")
FitFailedError = _define("FitFailedError", "fit_failed", 10, "The fit failed: no usable result.")
OutputError = _define("OutputError", "output", 11, "An unusable output path.")
SomeFailedError = _define(
    "SomeFailedError", "some_failed", 12,
    "Several inputs: at least one failed; .result holds every result and error entry.")
FitOutcomeError = _define(
    "FitOutcomeError", "fit_outcome", 13,
    "The fit's outcome is not \"converged\" (iteration_limit 13, poor_fit 14, not_determinable "
    "15); .result holds the calibration, as the CLI still prints and writes it.")

_BY_CODE = {c.code: c for c in (InternalError, UsageError, InputMissingError, NotAudioError,
                                BadSamplesError, SilenceError, NoBouncesError, BadSceneError,
                                BadParameterError, FitFailedError, OutputError, SomeFailedError)}
_FIT_OUTCOMES = {"iteration_limit", "poor_fit", "not_determinable"}


def _make_error(code, exit_code, message, result=None):
    """The exception for an error of the library (called by the compiled module)."""
    if code in _FIT_OUTCOMES:
        cls = FitOutcomeError
    else:
        cls = _BY_CODE.get(code, Error)
    return cls(message, code=code, exit_code=exit_code, result=result)
