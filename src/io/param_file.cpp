#include "bouncecal/io/param_file.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/param_resolved.hpp"

namespace bouncecal {
using nlohmann::json;

void WriteParamFile(const std::string& path, const json& doc, const WriteOptions& options) {
  WriteFileAtomically(path, DumpJson(doc, 2) + "\n", options);
}

namespace {

// The file's text. A missing file or a directory is kInputMissing, as for recordings and scenes
// (std::ifstream opens a directory on Linux and reads nothing).
std::string ReadParamText(const std::string& path) {
  std::error_code ec;
  const auto status = std::filesystem::status(path, ec);
  if (ec || !std::filesystem::exists(status)) {
    throw Error(ErrorCode::kInputMissing, path + ": parameter file does not exist");
  }
  if (std::filesystem::is_directory(status)) {
    throw Error(ErrorCode::kInputMissing, path + ": is a directory, expected a parameter file");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) throw Error(ErrorCode::kInputMissing, path + ": cannot open parameter file");
  std::stringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw Error(ErrorCode::kInputMissing, path + ": cannot read parameter file");
  return ss.str();
}

// The JSON document; a syntax error names the line and column where parsing stopped.
json ParseParamJson(const std::string& path, const std::string& text) {
  if (text.empty()) {
    throw Error(ErrorCode::kBadParameter, path +
                                              ": empty file (0 bytes), expected a JSON "
                                              "parameter file (calibrate -o)");
  }
  try {
    return json::parse(text);
  } catch (const json::parse_error& e) {
    // e.byte: 1-based index of the character the parser stopped at.
    const size_t at = std::min<size_t>(e.byte == 0 ? 0 : e.byte - 1, text.size());
    const size_t line = 1 + static_cast<size_t>(std::count(text.begin(), text.begin() + at, '\n'));
    const size_t newline = at == 0 ? std::string::npos : text.rfind('\n', at - 1);
    const size_t column = at - (newline == std::string::npos ? 0 : newline + 1) + 1;
    throw Error(ErrorCode::kBadParameter,
                path + ": not a JSON parameter file: syntax error at line " + std::to_string(line) +
                    ", column " + std::to_string(column) +
                    (at >= text.size() ? " (the text ends early)" : ""));
  } catch (const json::out_of_range& e) {
    // A number beyond a double's range ("2e421") is valid JSON syntax that nlohmann rejects as
    // out_of_range (found by the CI fuzz stage: it escaped the reader and aborted).
    throw Error(ErrorCode::kBadParameter,
                path + ": not a usable parameter file: a number is beyond a double's range (" +
                    std::string(e.what()).substr(0, 120) + ")");
  }
}

}  // namespace

ParamFile ReadParamFile(const std::string& path) {
  auto bad = [&](const std::string& m) { return Error(ErrorCode::kBadParameter, path + ": " + m); };
  json doc = ParseParamJson(path, ReadParamText(path));
  if (!doc.is_object()) throw bad("not a JSON object");
  ParamFile pf;
  if (!doc.contains("schema") || !doc["schema"].is_string()) throw bad("missing key 'schema'");
  pf.schema = doc["schema"].get<std::string>();
  const bool v1 = pf.schema == kParamFileSchemaV1;
  if (pf.schema != kParamFileSchema && !v1) {
    const std::string family = "bouncecal.params/";
    const bool newer = pf.schema.rfind(family, 0) == 0 && pf.schema > kParamFileSchema;
    throw bad("schema '" + pf.schema + "' is " +
              (newer ? "newer than this bouncecal reads (" + std::string(kParamFileSchema) +
                           "): upgrade bouncecal"
                     : "unknown (expected " + std::string(kParamFileSchema) + ")"));
  }
  // Version 2: "law": {"name", "expression", "parameters"}; version 1: "law" a name, the
  // parameters at the top level and the expression in scene.law.
  const json* law = v1 ? &doc : (doc.contains("law") ? &doc["law"] : nullptr);
  const char* name_key = v1 ? "law" : "name";
  const std::string where = v1 ? "" : "law.";
  if (law == nullptr || !law->is_object() || !law->contains(name_key) ||
      !(*law)[name_key].is_string()) {
    throw bad("missing key '" + (v1 ? std::string("law") : where + "name") + "'");
  }
  pf.law.name = (*law)[name_key].get<std::string>();
  if (!law->contains("parameters") || !(*law)["parameters"].is_object()) {
    throw bad("missing key '" + where + "parameters'");
  }
  for (const auto& [name, p] : (*law)["parameters"].items()) {
    if (!p.is_object() || !p.contains("value") || !p["value"].is_number()) {
      throw bad(where + "parameters." + name + ".value: expected a number");
    }
    pf.law.parameters[name] = p["value"].get<double>();
    if (p.contains("sigma") && p["sigma"].is_number()) pf.sigma[name] = p["sigma"].get<double>();
  }
  const json* expr_holder =
      v1 ? (doc.contains("scene") && doc["scene"].contains("law") ? &doc["scene"]["law"] : nullptr)
         : law;
  if (expr_holder != nullptr && expr_holder->contains("expression") &&
      (*expr_holder)["expression"].is_string()) {
    pf.law.expression = (*expr_holder)["expression"].get<std::string>();
  }
  if (doc.contains("fit") && doc["fit"].contains("outcome") && doc["fit"]["outcome"].is_string()) {
    pf.outcome = doc["fit"]["outcome"].get<std::string>();
  }
  if (doc.contains("warnings") && doc["warnings"].is_array()) {
    for (const auto& w : doc["warnings"]) {
      if (w.is_object() && w.contains("code") && w["code"].is_string()) {
        pf.warnings.push_back(w["code"].get<std::string>());
      }
    }
  }
  pf.doc = std::move(doc);
  return pf;
}

}  // namespace bouncecal
