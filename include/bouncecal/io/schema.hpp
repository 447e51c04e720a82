// bouncecal/io/schema.hpp — the one JSON output schema of every command (docs/schema.md).
//
// Each builder returns the object a command prints with --json (and the Python bindings
// return as a dict), from library types only: no command-line flags. Every top-level object
// carries "schema": "bouncecal.<name>/<version>"; the same concept has the same key everywhere
// (time_s / time_sigma_s of an impact, channel: int or null = mix, one "scene" object, one
// "law" object); absent or not-applicable values are null, never NaN or a fake 0.
//
//   nlohmann::json d = DetectionJson("drop.wav", result, {.chosen = {0}});
//   nlohmann::json a = AnalysisJson("drop.wav", result, 0, scene, analysis, {});
//   nlohmann::json s = SimulationJson(scene, *law, values, simulation);
//   nlohmann::json c = CalibrationJson(calibration, provenance, OptionsJson(options));
//
// Versions: adding a key keeps the version; renaming, removing, retyping a key or making a
// non-null key nullable bumps it (docs/schema.md).
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/warning.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/contact_law.hpp"
#include "bouncecal/physics/scene.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal {

inline constexpr const char* kDetectSchema = "bouncecal.detect/2";
inline constexpr const char* kAnalysisSchema = "bouncecal.analysis/1";
inline constexpr const char* kSimulationSchema = "bouncecal.simulation/1";
inline constexpr const char* kLawsSchema = "bouncecal.laws/1";
inline constexpr const char* kCalibrationRowSchema = "bouncecal.calibration_row/1";
inline constexpr const char* kLawComparisonSchema = "bouncecal.law_comparison/2";
inline constexpr const char* kSynthSchema = "bouncecal.synth/1";
inline constexpr const char* kErrorSchema = "bouncecal.error/1";
// `export --json` and DIR/mapping.json (built in the export wing: ExportResultJson).
inline constexpr const char* kExportSchema = "bouncecal.export/2";

// ---- building blocks -------------------------------------------------------------------

// A finite number, or null (JSON has no NaN/Inf).
nlohmann::json JsonNumber(double v);
nlohmann::json JsonNumber(const std::optional<double>& v);
// [{"code", "message", "impact": int|null}, ...]
nlohmann::json WarningsJson(const std::vector<Warning>& warnings);
// {"code" (ErrorCodeName), "exit_code", "message"}
nlohmann::json ErrorJson(ErrorCode code, const std::string& message);
// {"schema": "bouncecal.error/1", "file", "error": ErrorJson}: one failed input of several.
nlohmann::json FailedInputJson(const std::string& file, ErrorCode code, const std::string& message);

// {"time_s", "time_sigma_s", "amplitude", "snr_db", "score", "clipped"}
nlohmann::json ImpactJson(const Impact& impact);
// One bounce of an analysis: {"index", "time_s", "time_sigma_s", "interval_s", "v_in_m_s",
// "v_in_sigma_m_s", "v_out_m_s", "v_out_sigma_m_s", "e", "e_sigma" (with the scatter),
// "e_timing_sigma", "eta", "eta_sigma", "contact_s" (null when the contact-duration correction
// is off), "e_next_correlation", "irregular"}.
nlohmann::json BounceJson(const Bounce& bounce);

struct SceneJsonOptions {
  // The drop (height or first impact speed) was given; false: every drop value is null.
  bool drop_known = true;
};
// The one scene shape: {"source", "ball", "surface", "environment", "drop", "effects"}.
// The law is not part of it: it is the "law" object next to it.
nlohmann::json SceneJson(const Scene& scene, const SceneJsonOptions& options = {});

// The one law shape: {"name", "formula", "source", "expression" (null unless the expression
// law), "parameters": {NAME: {"value", "sigma", "unit", "lower", "upper", "damping", "fixed",
// "determined", "at_bound", "description"}}}. For a law with given values (simulate, the laws
// listing) sigma, fixed, determined and at_bound are null.
nlohmann::json LawJson(const ContactLaw& law, const std::vector<double>& values,
                       const std::string& expression = "");
// A fitted law: sigma and the fit flags from the calibration.
nlohmann::json LawJson(const Calibration& calibration);

// ---- one object per command ------------------------------------------------------------

struct DetectionJsonOptions {
  std::vector<int> chosen;  // chosen sequences (indices into result.sequences)
  bool from_impacts_file = false;
};
// bouncecal.detect/2 (`detect --json`): each impact once, in its sequence.
nlohmann::json DetectionJson(const std::string& file, const DetectionResult& result,
                             const DetectionJsonOptions& options);

struct AnalysisJsonOptions {
  bool drop_known = true;  // the user gave the drop (else drop values are null)
  bool from_impacts_file = false;
  // Values the result depends on that the user did not give: [{"key","value","note"}].
  nlohmann::json assumed = nlohmann::json::array();
  std::vector<Warning> warnings;  // every warning of the run (detection + scene + analysis)
};
// bouncecal.analysis/1 (`analyze --json`), of one chosen sequence.
nlohmann::json AnalysisJson(const std::string& file, const DetectionResult& detection, int sequence,
                            const Scene& scene, const Analysis& analysis,
                            const AnalysisJsonOptions& options);

// bouncecal.simulation/1 (`simulate --json`).
nlohmann::json SimulationJson(const Scene& scene, const ContactLaw& law,
                              const std::vector<double>& values, const Simulation& simulation);

// One entry of bouncecal.laws/1: the law object plus "summary", "end_rule", "state_size",
// "closed_forms".
nlohmann::json LawListingJson(const ContactLaw& law, const std::string& summary,
                              const std::string& expression = "");
// bouncecal.laws/1 (`laws --json`): {"schema", "laws": [entries]}.
nlohmann::json LawsJson(const std::vector<nlohmann::json>& entries);

// The options a fit ran with, for provenance.
nlohmann::json OptionsJson(const CalibrationOptions& options);
// bouncecal.params/2: the parameter file, `calibrate --json` (param_file.hpp).
nlohmann::json CalibrationJson(const Calibration& calibration, const Provenance& provenance,
                               const nlohmann::json& options);
// bouncecal.law_comparison/2 (`calibrate --law all --json`).
nlohmann::json LawComparisonJson(const std::vector<LawComparisonRow>& rows,
                                 const Provenance& provenance, const nlohmann::json& options,
                                 const nlohmann::json& assumed);
// bouncecal.calibration_row/1: one line of `calibrate --batch --json` (a fit or a failure:
// exactly one of calibration/error is non-null).
nlohmann::json CalibrationRowJson(const std::string& file, const Calibration* calibration,
                                  const Error* error);

// ---- CSV --------------------------------------------------------------------------------

// Shortest text that reads back to the same double; "" for NaN/Inf (absent).
std::string CsvNumber(double v);
std::string CsvNumber(const std::optional<double>& v);
// A field quoted when it holds a comma, quote or newline.
std::string CsvField(const std::string& s);

}  // namespace bouncecal
