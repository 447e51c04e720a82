// bouncecal/io/param_file.hpp — the calibrated parameter file, schema "bouncecal.params/2".
//
// What `bouncecal calibrate -o params.json` writes and `calibrate --json` prints: the object
// CalibrationJson builds (schema.hpp; every key in docs/schema.md). Version 2 moved the law
// into one "law" object {"name", "formula", "source", "expression", "parameters"}; version 1
// files are still read.
//
//   nlohmann::json doc = CalibrationJson(calibration, MakeProvenance(paths), OptionsJson(opts));
//   WriteParamFile("params.json", doc, {.force = false, .inputs = paths});
//   ParamFile p = ReadParamFile("params.json");     // p.law: a LawSpec for CreateLaw
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

inline constexpr const char* kParamFileSchema = "bouncecal.params/2";
inline constexpr const char* kParamFileSchemaV1 = "bouncecal.params/1";  // still read

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
// Missing file or a directory: Error(kInputMissing); not JSON (the line and column of the
// syntax error), wrong schema, missing or mistyped keys: Error(kBadParameter) naming the file
// and the key.
ParamFile ReadParamFile(const std::string& path);

}  // namespace bouncecal
