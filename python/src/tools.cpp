// laws, simulate, export: the bindings of the commands that need no recording.
#include <cmath>
#include <memory>
#include <string>

#include "bindings.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/export/export.hpp"
#include "bouncecal/io/param_resolved.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"

namespace bouncecal::python {
namespace {

// `bouncecal laws --json` (bouncecal.laws/1).
nlohmann::json LawsListing(const std::string& name, const Scene& scene) {
  std::vector<LawInfo> infos = RegisteredLaws();
  if (!name.empty()) {
    std::vector<LawInfo> one;
    for (const LawInfo& i : infos)
      if (i.name == name) one.push_back(i);
    if (one.empty()) CreateLaw(ExampleLawSpec(name), scene);  // throws the "unknown law" error
    infos = one;
  }
  std::vector<nlohmann::json> laws;
  for (const LawInfo& info : infos) {
    const std::unique_ptr<ContactLaw> law = CreateLaw(ExampleLawSpec(info.name), scene);
    laws.push_back(LawListingJson(*law, info.summary, ExampleLawSpec(info.name).expression));
  }
  return LawsJson(laws);
}

py::object Laws(const py::dict& options) {
  Options o(options);
  const std::string name = o.TakeString("name").value_or("");
  const std::string scene_file = o.TakeString("scene").value_or("");
  o.Finish("laws");
  const Scene scene = scene_file.empty() ? Scene{} : LoadSceneFile(scene_file);
  return ToPython(LawsListing(name, scene));
}

// The scene of simulate: the scene flags, or a parameter file's replay (then no scene flag).
Scene SimulateScene(Options& o) {
  const std::string params = o.TakeString("params").value_or("");
  const SceneOverrides flags = TakeSceneOverrides(o, true);
  if (params.empty()) return ResolveScene(flags);
  const bool any_scene_option =
      !flags.scene_file.empty() || flags.height_m || flags.height_sigma_m ||
      flags.impact_speed_m_s || flags.diameter_m || flags.density_kg_m3 || flags.mass_kg ||
      !flags.material.empty() || !flags.drag.empty() || flags.buoyancy || flags.contact_duration ||
      flags.g_m_s2 || !flags.law.empty() || !flags.law_sets.empty() || !flags.expression.empty();
  if (any_scene_option) {
    throw Error(ErrorCode::kUsage,
                "params " + params +
                    ": the file is the whole scene and law; scene and law options cannot be "
                    "combined with it (use max_impacts/horizon to shorten the run)");
  }
  return ReplayFromParamFile(ReadParamFile(params), params).scene;
}

py::object SimulateBinding(const py::dict& options) {
  Options o(options);
  Scene scene = SimulateScene(o);
  const std::optional<double> rtol = o.TakeDouble("rtol");
  const std::optional<double> horizon_s = o.TakeDouble("horizon");
  const std::optional<int> max_impacts = o.TakeInt("max_impacts");
  const bool integrate = o.TakeFlag("integrate");
  o.Finish("simulate");
  if (horizon_s) {
    if (!(*horizon_s > 0.0) || !std::isfinite(*horizon_s)) {
      throw Error(ErrorCode::kUsage, "horizon: must be a positive number of seconds");
    }
    scene.limits.horizon_s = *horizon_s;
  }
  if (max_impacts) {
    if (*max_impacts < 1) throw Error(ErrorCode::kUsage, "max_impacts: must be >= 1");
    scene.limits.max_impacts = *max_impacts;
  }
  SimulatorOptions sim_options;
  if (rtol) sim_options.rel_tolerance = *rtol;
  sim_options.use_closed_form = !integrate;
  std::string why;
  if (!sim_options.IsValid(&why)) throw Error(ErrorCode::kUsage, "rtol: " + why);
  const std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);
  const std::vector<double> p = law->ParameterValues();
  Simulation sim;
  {
    py::gil_scoped_release release;
    sim = Simulate(scene, *law, p, sim_options);
  }
  return ToPython(SimulationJson(scene, *law, p, sim));
}

py::object ExportBinding(const std::string& params, const std::string& output,
                         const py::dict& options) {
  Options o(options);
  ExportOptions e;
  const std::string to = o.TakeString("to").value_or("");
  const std::string scene = o.TakeString("scene").value_or("bounce");
  if (!ParseExportTarget(to, &e.target)) {
    throw Error(ErrorCode::kUsage, "to " + to + ": expected lammps, liggghts or yade");
  }
  if (!ParseExportScene(scene, &e.scene)) {
    throw Error(ErrorCode::kUsage, "scene " + scene + ": expected bounce or packing");
  }
  e.force = o.TakeFlag("force");
  e.allow_approximation = o.TakeFlag("allow_approximation");
  e.impacts = o.TakeInt("impacts").value_or(e.impacts);
  e.time_step_e_error = o.TakeDouble("dt_e_error").value_or(e.time_step_e_error);
  e.packing_time_s = o.TakeDouble("packing_time").value_or(e.packing_time_s);
  e.packing_particles = o.TakeInt("particles").value_or(e.packing_particles);
  e.packing_restitution = o.TakeDouble("packing_restitution").value_or(e.packing_restitution);
  o.Finish("export");
  std::string why;
  if (!e.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  ExportResult r;
  {
    py::gil_scoped_release release;
    r = ExportDeck(params, output, e);
  }
  return ToPython(ExportResultJson(r));
}

}  // namespace

void BindTools(py::module_& m) {
  m.def("laws", &Laws, py::arg("options"));
  m.def("simulate", &SimulateBinding, py::arg("options"));
  m.def("export", &ExportBinding, py::arg("params"), py::arg("output"), py::arg("options"));
}

}  // namespace bouncecal::python
