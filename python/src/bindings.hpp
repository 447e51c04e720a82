// Shared pieces of the Python bindings (module.cpp).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/io/given_scene.hpp"

namespace bouncecal::python {

namespace py = pybind11;

// JSON -> Python: objects -> dict (key order kept), arrays -> list, numbers -> int/float,
// null -> None.
py::object ToPython(const nlohmann::json& j);

// An Error after which the CLI still prints a result (several inputs with failures, a fit whose
// outcome is not "converged"): the exception's .result holds that result.
class ErrorWithResult : public Error {
 public:
  ErrorWithResult(ErrorCode code, const std::string& message, nlohmann::json result)
      : Error(code, message), result_(std::move(result)) {}
  const nlohmann::json& result() const { return result_; }

 private:
  nlohmann::json result_;
};

// bouncecal::Error -> the bouncecal.Error subclass of its code (python/bouncecal/_errors.py).
void RegisterErrorTranslator();

// The options the caller set, by name (the CLI's flag in snake_case). Each Take* reads and
// removes one; Finish() refuses names nobody read (a misspelled option is an error, not ignored).
class Options {
 public:
  explicit Options(const py::dict& d);
  std::optional<double> TakeDouble(const char* name);
  std::optional<int> TakeInt(const char* name);
  std::optional<std::string> TakeString(const char* name);
  std::vector<std::string> TakeStrings(const char* name);
  bool TakeFlag(const char* name);
  void Finish(const char* function);

 private:
  py::dict d_;
};

// scene (a file, or the TOML text of a scene dict) and the scene keywords (height, mass, ...:
// the SceneOverrides fields); with_law adds law, set, expression.
SceneOverrides TakeSceneOverrides(Options& o, bool with_law);
// channel, start, end, sequence, min_snr_db, impacts -> the drop input's options. Throws
// Error(kUsage) for an invalid value (before any work).
DropInputOptions TakeDropInputOptions(Options& o);
// A library message with the keyword names of this module ("SceneOverrides::height_m" ->
// "height", "WriteOptions::force" -> "force").
std::string KeywordText(const std::string& message);

// laws, simulate, export.
void BindTools(py::module_& m);
// detect, analyze, calibrate, read_audio.
void BindRecordings(py::module_& m);
// detect_array, analyze_array, Listener.
void BindLive(py::module_& m);

// A NumPy array (1-D mono or 2-D [channel, frame], any float or integer dtype converted to
// float32) with its rate as a recording named `name`, every sample checked as a file's are.
// Throws Error(kUsage) for a bad shape or rate, Error(kBadSamples) for NaN/Inf or beyond
// kMaxSampleMagnitude.
Audio AudioFromArray(const py::array_t<float, py::array::c_style | py::array::forcecast>& samples,
                     double rate_hz, const std::string& name);

}  // namespace bouncecal::python
