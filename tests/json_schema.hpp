// A small JSON Schema validator for the test suite: the subset docs/schema/*.schema.json use
// (type, const, enum, properties, required, additionalProperties, items, anyOf, $ref to
// "#/$defs/X" or "FILE.schema.json#/$defs/X" in the same directory). Unknown keywords are an
// error, so a schema cannot silently use something this validator ignores.
#pragma once

#include <filesystem>
#include <fstream>
#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace bouncecal::testing_util {

class SchemaSet {
 public:
  // Loads every *.schema.json under `dir`.
  explicit SchemaSet(const std::filesystem::path& dir) {
    for (const auto& e : std::filesystem::directory_iterator(dir)) {
      const std::string name = e.path().filename().string();
      if (name.size() < 12 || name.substr(name.size() - 12) != ".schema.json") continue;
      std::ifstream in(e.path());
      docs_[name] = nlohmann::json::parse(in);
    }
  }
  bool Has(const std::string& file) const { return docs_.count(file) > 0; }

  // Errors of `value` against the schema file `file` ("detect.schema.json"); empty = valid.
  std::vector<std::string> Validate(const nlohmann::json& value, const std::string& file) const {
    std::vector<std::string> errors;
    Check(value, docs_.at(file), file, "$", &errors);
    return errors;
  }

 private:
  static std::string TypeOf(const nlohmann::json& v) {
    if (v.is_null()) return "null";
    if (v.is_boolean()) return "boolean";
    if (v.is_number_integer()) return "integer";
    if (v.is_number()) return "number";
    if (v.is_string()) return "string";
    if (v.is_array()) return "array";
    return "object";
  }
  static bool TypeMatches(const nlohmann::json& v, const std::string& t) {
    const std::string got = TypeOf(v);
    return got == t || (t == "number" && got == "integer");
  }

  const nlohmann::json& Resolve(const std::string& ref, std::string* file) const {
    const size_t hash = ref.find('#');
    if (hash != 0) *file = ref.substr(0, hash);
    const nlohmann::json* node = &docs_.at(*file);
    const std::string pointer = hash == std::string::npos ? "" : ref.substr(hash + 1);
    return pointer.empty() ? *node : node->at(nlohmann::json::json_pointer(pointer));
  }

  void Check(const nlohmann::json& v, const nlohmann::json& s, std::string file,
             const std::string& path, std::vector<std::string>* errors) const {
    static const std::set<std::string> known = {
        "$schema", "$id",  "$defs",      "title",    "description",          "type",
        "const",   "enum", "properties", "required", "additionalProperties", "items",
        "anyOf",   "$ref"};
    for (const auto& [k, unused] : s.items())
      if (!known.count(k)) errors->push_back(path + ": schema keyword '" + k + "' not supported");
    if (s.contains("$ref")) {
      const nlohmann::json& target = Resolve(s["$ref"].get<std::string>(), &file);
      Check(v, target, file, path, errors);
    }
    if (s.contains("type")) {
      const nlohmann::json& t = s["type"];
      bool ok = false;
      if (t.is_string()) ok = TypeMatches(v, t.get<std::string>());
      for (const auto& one : t.is_array() ? t : nlohmann::json::array())
        ok = ok || TypeMatches(v, one.get<std::string>());
      if (!ok) {
        errors->push_back(path + ": " + TypeOf(v) + " where the schema says " + t.dump());
        return;
      }
    }
    if (s.contains("const") && v != s["const"])
      errors->push_back(path + ": " + v.dump() + " != " + s["const"].dump());
    if (s.contains("enum")) {
      bool found = false;
      for (const auto& e : s["enum"]) found = found || v == e;
      if (!found) errors->push_back(path + ": " + v.dump() + " not in " + s["enum"].dump());
    }
    if (s.contains("anyOf")) {
      bool any = false;
      std::vector<std::string> all;
      for (const auto& alt : s["anyOf"]) {
        std::vector<std::string> e;
        Check(v, alt, file, path, &e);
        any = any || e.empty();
        all.insert(all.end(), e.begin(), e.end());
      }
      if (!any) {
        errors->push_back(path + ": matches no alternative of anyOf:");
        errors->insert(errors->end(), all.begin(), all.end());
      }
    }
    if (v.is_object()) {
      for (const auto& r : s.value("required", nlohmann::json::array()))
        if (!v.contains(r.get<std::string>()))
          errors->push_back(path + ": missing key '" + r.get<std::string>() + "'");
      const nlohmann::json props = s.value("properties", nlohmann::json::object());
      for (const auto& [k, item] : v.items()) {
        if (props.contains(k)) {
          Check(item, props[k], file, path + "." + k, errors);
        } else if (s.contains("additionalProperties")) {
          const nlohmann::json& ap = s["additionalProperties"];
          if (ap.is_boolean() && !ap.get<bool>()) {
            errors->push_back(path + ": key '" + k + "' is not in the schema");
          } else if (ap.is_object()) {
            Check(item, ap, file, path + "." + k, errors);
          }
        }
      }
    }
    if (v.is_array() && s.contains("items")) {
      for (size_t i = 0; i < v.size(); ++i)
        Check(v[i], s["items"], file, path + "[" + std::to_string(i) + "]", errors);
    }
  }

  std::map<std::string, nlohmann::json> docs_;
};

}  // namespace bouncecal::testing_util
