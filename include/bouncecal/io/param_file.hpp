// bouncecal/io/param_file.hpp — the calibrated parameter file, schema "bouncecal.params/1".
//
// What `bouncecal calibrate -o params.json` writes and `calibrate --json` prints: one JSON
// object with stable keys, for DEM codes and lab scripts.
//
//   {"schema": "bouncecal.params/1",
//    "law": "walton-braun", "formula": "...", "source": "...",
//    "parameters": {"gamma": {"value", "sigma", "unit", "fixed", "determined", "lower", "upper"}},
//    "e_of_v": [{"v_m_s", "e", "sigma"}, ...],          // over the measured speed range
//    "fit": {"strategy", "derivatives", "outcome" (converged | iteration_limit | poor_fit |
//            not_determinable | failed), "exit_code", "reason" (one line), "message",
//            "scatter_e", "scatter_e_sigma", "scatter_e_is_upper_limit",
//            "rms_residual_s" (trajectory) or "rms_residual_e" (restitution), "chi2",
//            "chi2_dof" (full model: timing + scatter), "dof", "num_residuals", "num_free",
//            "trend_chi2", "trend_dof", "neg_log_likelihood", "aic", "bic", "starts",
//            "starts_reached_best", "iterations", "simulations", "v_min_m_s", "v_max_m_s",
//            "determined": [...], "undetermined": [...]},
//    "warnings": [{"code", "message", "impact"}],       // coded diagnostics (README)
//    "assumed": [{"key", "value", "note"}],            // added by the CLI: defaults used
//    "recordings": [{"path", "impacts", "simulated_impacts", "impact_speed_m_s",
//                    "impact_speed_sigma_m_s", "impact_speed_fixed", "time_origin_s",
//                    "time_origin_sigma_s", "rms_residual_s" | "rms_residual_e"}],
//    "scene": {"ball": {...}, "surface": {...}, "environment": {...}, "drop": {...},
//              "effects": {...}, "law": {"name", "parameters", "expression"}},
//    "scene_toml": "...",                               // the same scene as a scene file
//    "resolved": {...},        // every physical value as a number (param_resolved.hpp)
//    "provenance": {"inputs": [{"path", "sha256"}], "bouncecal_version", "options",
//                   "date_utc"}}
// Units are in the key names or in "unit"; a sigma that does not exist (held or undetermined
// parameter) is null. New keys may be added within version 1; renaming or removing one bumps
// the version.
//
//   nlohmann::json doc = ParamFileJson(calibration, MakeProvenance(paths), OptionsJson(opts));
//   WriteParamFile("params.json", doc, {.force = false, .inputs = paths});
//   ParamFile p = ReadParamFile("params.json");     // p.law: a LawSpec for CreateLaw
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

inline constexpr const char* kParamFileSchema = "bouncecal.params/1";

// The scene as JSON (ball, surface, environment, drop, effects, law).
nlohmann::json SceneJson(const Scene& scene);
// The options a fit ran with, for provenance.
nlohmann::json OptionsJson(const CalibrationOptions& options);
// The whole parameter-file object.
nlohmann::json ParamFileJson(const Calibration& calibration, const Provenance& provenance,
                             const nlohmann::json& options);
// Writes the object (2-space indented, trailing newline) atomically; refuses to overwrite an
// input or an existing file without options.force. Throws Error(kOutput).
void WriteParamFile(const std::string& path, const nlohmann::json& doc,
                    const WriteOptions& options);

// What a script or simulator needs back from a parameter file.
struct ParamFile {
  std::string schema;
  LawSpec law;                          // name + fitted/held parameter values (+ expression)
  std::map<std::string, double> sigma;  // per parameter; absent when null
  std::string outcome;
  std::vector<std::string> warnings;  // warning codes
  nlohmann::json doc;                 // the whole object
};
// Reads and checks a parameter file: schema version, law, parameter values.
// Missing file: Error(kInputMissing); not JSON, wrong schema, missing or mistyped keys:
// Error(kBadParameter) naming the file and the key.
ParamFile ReadParamFile(const std::string& path);

}  // namespace bouncecal
