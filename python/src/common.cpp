// JSON -> Python, the error translator and the option readers of the bindings (bindings.hpp).
#include <exception>
#include <string>

#include <Python.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"

namespace bouncecal::python {

py::object ToPython(const nlohmann::json& j) {
  switch (j.type()) {
    case nlohmann::json::value_t::null:
    case nlohmann::json::value_t::discarded:
      return py::none();
    case nlohmann::json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(j.get<std::int64_t>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(j.get<std::uint64_t>());
    case nlohmann::json::value_t::number_float:
      return py::float_(j.get<double>());
    case nlohmann::json::value_t::string:
      return py::str(j.get_ref<const std::string&>());
    case nlohmann::json::value_t::array: {
      py::list out;
      for (const nlohmann::json& v : j) out.append(ToPython(v));
      return out;
    }
    case nlohmann::json::value_t::object: {
      py::dict out;
      for (auto it = j.begin(); it != j.end(); ++it) out[py::str(it.key())] = ToPython(it.value());
      return out;
    }
    case nlohmann::json::value_t::binary:
      break;
  }
  throw Error(ErrorCode::kInternal, "JSON value of an unexpected type (binary)");
}

namespace {

// The exception object is made by the package (one class per code) and raised as it is.
void Raise(const Error& e, const py::object& result) {
  py::object make = py::module_::import("bouncecal._errors").attr("_make_error");
  py::object exc = make(ErrorCodeName(e.code()), e.exit_code(), KeywordText(e.what()), result);
  PyErr_SetObject(reinterpret_cast<PyObject*>(Py_TYPE(exc.ptr())), exc.ptr());
}

}  // namespace

void RegisterErrorTranslator() {
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const ErrorWithResult& e) {
      Raise(e, ToPython(e.result()));
    } catch (const Error& e) {
      Raise(e, py::none());
    }
  });
}

// A copy (reading removes keys; the caller's dict stays as it is).
Options::Options(const py::dict& d) : d_(py::reinterpret_steal<py::dict>(PyDict_Copy(d.ptr()))) {
  if (!d_) throw py::error_already_set();
}

std::optional<double> Options::TakeDouble(const char* name) {
  if (!d_.contains(name)) return std::nullopt;
  const double v = py::cast<double>(d_[name]);
  PyDict_DelItemString(d_.ptr(), name);
  return v;
}

std::optional<int> Options::TakeInt(const char* name) {
  if (!d_.contains(name)) return std::nullopt;
  const int v = py::cast<int>(d_[name]);
  PyDict_DelItemString(d_.ptr(), name);
  return v;
}

std::optional<std::string> Options::TakeString(const char* name) {
  if (!d_.contains(name)) return std::nullopt;
  std::string v = py::cast<std::string>(d_[name]);
  PyDict_DelItemString(d_.ptr(), name);
  return v;
}

std::vector<std::string> Options::TakeStrings(const char* name) {
  if (!d_.contains(name)) return {};
  std::vector<std::string> v = py::cast<std::vector<std::string>>(d_[name]);
  PyDict_DelItemString(d_.ptr(), name);
  return v;
}

bool Options::TakeFlag(const char* name) {
  if (!d_.contains(name)) return false;
  const bool v = py::cast<bool>(d_[name]);
  PyDict_DelItemString(d_.ptr(), name);
  return v;
}

void Options::Finish(const char* function) {
  if (d_.empty()) return;
  std::string names;
  for (const auto& item : d_)
    names += (names.empty() ? "" : ", ") + py::str(item.first).cast<std::string>();
  throw Error(ErrorCode::kUsage, std::string(function) + ": unknown option(s) " + names);
}

SceneOverrides TakeSceneOverrides(Options& o, bool with_law) {
  SceneOverrides f;
  if (auto v = o.TakeString("scene")) f.scene_file = *v;
  if (auto v = o.TakeString("scene_text")) f.scene_text = *v;
  f.height_m = o.TakeDouble("height");
  f.height_sigma_m = o.TakeDouble("height_sigma");
  f.impact_speed_m_s = o.TakeDouble("impact_speed");
  f.diameter_m = o.TakeDouble("diameter");
  f.density_kg_m3 = o.TakeDouble("density");
  f.mass_kg = o.TakeDouble("mass");
  if (auto v = o.TakeString("material")) f.material = *v;
  if (auto v = o.TakeString("drag")) f.drag = *v;
  f.buoyancy = o.TakeFlag("buoyancy");
  f.contact_duration = o.TakeFlag("contact_duration");
  f.g_m_s2 = o.TakeDouble("g");
  if (with_law) {
    if (auto v = o.TakeString("law")) f.law = *v;
    f.law_sets = o.TakeStrings("set");
    if (auto v = o.TakeString("expression")) f.expression = *v;
  }
  return f;
}

DropInputOptions TakeDropInputOptions(Options& o) {
  DropInputOptions f;
  f.detect.channel = ParseChannelSelection(o.TakeString("channel").value_or("auto"));
  if (auto v = o.TakeDouble("start")) f.detect.start_s = *v;
  f.detect.end_s = o.TakeDouble("end");
  if (auto v = o.TakeDouble("min_snr_db")) f.detect.min_snr_db = *v;
  f.sequence = ParseSequenceChoice(o.TakeString("sequence").value_or("main"));
  f.impacts_files = o.TakeStrings("impacts");
  std::string why;
  if (!f.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  return f;
}

namespace {

// Field names -> keywords, each replaced as a whole name (SceneOverrides::law is not
// SceneOverrides::law_sets).
constexpr NameInFrontEnd kKeywords[] = {
    {"SceneOverrides::height_m", "height"},
    {"SceneOverrides::height_sigma_m", "height_sigma"},
    {"SceneOverrides::impact_speed_m_s", "impact_speed"},
    {"SceneOverrides::diameter_m", "diameter"},
    {"SceneOverrides::density_kg_m3", "density"},
    {"SceneOverrides::mass_kg", "mass"},
    {"SceneOverrides::material", "material"},
    {"SceneOverrides::drag", "drag"},
    {"SceneOverrides::g_m_s2", "g"},
    {"SceneOverrides::law", "law"},
    {"SceneOverrides::law_sets", "set"},
    {"SceneOverrides::expression", "expression"},
    {"DropInputOptions::impacts_files", "impacts"},
    {"DetectOptions::start_s/end_s", "start/end"},
    {"DetectOptions::start_s", "start"},
    {"DetectOptions::end_s", "end"},
    {"DetectOptions::min_snr_db", "min_snr_db"},
    {"ExportOptions::force", "force"},
    {"ExportOptions::allow_approximation", "allow_approximation"},
    {"WriteOptions::force", "force"},
};

}  // namespace

std::string KeywordText(const std::string& message) { return RenameFields(message, kKeywords); }

}  // namespace bouncecal::python
