// The routes that do the work (api_routes.hpp): each makes the library calls of its command
// (src/cli/cmd_analyze.cpp, cmd_calibrate.cpp, cmd_report.cpp, cmd_export.cpp), on the request's
// recording, and answers with what the command prints with --json (or writes with -o).
#include "api_routes.hpp"

#include <filesystem>
#include <fstream>

#include "bouncecal/acoustic/drop_input.hpp"
#include "bouncecal/export/export.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/scene_checks.hpp"
#include "bouncecal/io/analysis_document.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/report/html_report.hpp"
#include "bouncecal/report/report_data.hpp"
#include "bouncecal/serve/query_options.hpp"
#include "bouncecal/serve/zip.hpp"

namespace bouncecal::serve {
namespace {

// Runs `f` on the recording; its errors name the recording, not the server's file.
template <class F>
auto OnRecording(const Recording& rec, F&& f) -> decltype(f()) {
  try {
    return f();
  } catch (const Error& e) {
    throw Named(e, rec);
  }
}

// calibrate refuses a fit without a ball: its mass and size enter every contact law.
void RequireBall(const GivenScene& gs) {
  if (gs.ball_given) return;
  throw Error(ErrorCode::kBadScene,
              std::string("calibrate: the ball's ") +
                  (gs.Given("ball.diameter_m") ? "mass" : "size and mass") +
                  " are not given (they enter the contact law, its default stiffness and the "
                  "drag): give diameter with mass (or density, or material), or scene=NAME");
}

// The values the fit depends on that were not given: the scene's and the law's held parameters.
nlohmann::json AssumedFor(const GivenScene& gs, const Calibration& c) {
  std::vector<Assumed> out = AssumedValues(gs, true);
  for (const auto& p : c.parameters) {
    if (p.fixed && !gs.Given("law.parameters." + p.name)) {
      char value[64];
      std::snprintf(value, sizeof value, "%.7g", p.value);
      out.push_back({"law.parameters." + p.name, std::string(value) + " " + p.unit,
                     "held at the law's default, not fitted"});
    }
  }
  return AssumedJson(out);
}

Provenance NamedProvenance(const Recording& rec) {
  Provenance p = MakeProvenance({rec.path});
  p.inputs[0].path = rec.name;
  return p;
}

// The drops of the recording as calibration inputs, named as the recording is.
std::vector<CalibrationInput> Inputs(const Recording& rec, const DropInputOptions& drops) {
  std::vector<CalibrationInput> out;
  for (RecordingDrop& d : DropsOf(rec.path, "", drops)) {
    std::string name = d.name;
    if (name.rfind(rec.path, 0) == 0) name = rec.name + name.substr(rec.path.size());
    out.push_back({name, std::move(d.sequence)});
  }
  return out;
}

}  // namespace

ApiResponse AnalyzeRoute(Query q, const RouteContext& c) {
  const SceneOverrides scene = TakeSceneQuery(q, /*with_law=*/false);
  const DropInputOptions drops = TakeDropQuery(q);
  const std::optional<double> contact_time_s = q.TakeDouble("contact_time");
  const SourceQuery source = TakeSourceQuery(q);
  q.Finish(c.route);
  GivenScene gs = ResolveGivenScene(scene);  // the scene's errors before the upload's
  const AnalysisOptions options = AnalyzeOptionsFor(&gs, contact_time_s);
  const Recording rec = OpenSource(source, c);
  return OnRecording(rec, [&] {
    const LoadedRecording l = LoadRecording(rec.path, nullptr, "", drops);
    const std::vector<nlohmann::json> docs = AnalysisDocuments(rec.name, l, gs, options);
    return JsonResponse(docs.size() == 1 ? docs.front() : nlohmann::json(docs));
  });
}

ApiResponse CalibrateRoute(Query q, const RouteContext& c) {
  SceneOverrides scene = TakeSceneQuery(q, /*with_law=*/true);
  const DropInputOptions drops = TakeDropQuery(q);
  const bool all = scene.law == "all";
  if (all) scene.law.clear();
  const GivenScene gs = ResolveGivenScene(scene);
  const CalibrationOptions options = TakeCalibrationQuery(q, gs, c.options.jobs);
  const SourceQuery source = TakeSourceQuery(q);
  q.Finish(c.route);
  RequireBall(gs);
  if (!all) CreateLaw(gs.scene.law, gs.scene);  // an unknown law or parameter before any work
  const Recording rec = OpenSource(source, c);
  return OnRecording(rec, [&] {
    const std::vector<CalibrationInput> inputs = Inputs(rec, drops);
    const Provenance prov = NamedProvenance(rec);
    if (all) {
      const std::vector<LawComparisonRow> rows =
          CompareLaws(inputs, gs.scene, options, c.options.jobs);
      const nlohmann::json doc =
          LawComparisonJson(rows, prov, OptionsJson(options), AssumedJson(AssumedValues(gs, true)));
      const bool any = !rows.empty() && rows.front().adequate;
      return JsonResponse(doc, any ? 0 : static_cast<int>(ErrorCode::kFitFailed));
    }
    Calibration fit = Calibrate(inputs, gs.scene, options);
    const std::vector<Warning> unit = SceneUnitWarnings(gs.scene, options.use_drop);
    fit.warnings.insert(fit.warnings.begin(), unit.begin(), unit.end());
    nlohmann::json doc = CalibrationJson(fit, prov, OptionsJson(options));
    doc["assumed"] = AssumedFor(gs, fit);
    return JsonResponse(doc, fit.outcome == FitOutcome::kConverged
                                 ? 0
                                 : static_cast<int>(FitOutcomeExitCode(fit.outcome)));
  });
}

ApiResponse ReportRoute(Query q, const RouteContext& c) {
  SceneOverrides scene = TakeSceneQuery(q, /*with_law=*/true);
  const DropInputOptions drops = TakeDropQuery(q);
  const bool all = scene.law == "all";
  if (all) scene.law.clear();
  const GivenScene gs = ResolveGivenScene(scene);
  CalibrationOptions options = TakeCalibrationQuery(q, gs, c.options.jobs);
  const SourceQuery source = TakeSourceQuery(q);
  q.Finish(c.route);
  // As `report`: a smooth e(v) curve, the analysis of `analyze` for the scene.
  options.e_of_v_points = 24;
  GivenScene analysed = gs;
  options.analysis = AnalyzeOptionsFor(&analysed, std::nullopt);
  if (!all) CreateLaw(gs.scene.law, gs.scene);
  const Recording rec = OpenSource(source, c);
  return OnRecording(rec, [&] {
    ReportInput in;
    in.recordings.push_back(
        LoadReportRecording(rec.path, drops.detect, gs.scene, options.analysis));
    ReportRecording& r = in.recordings.back();
    r.path = rec.name;
    r.audio.path = rec.name;
    std::optional<Calibration> fit;
    std::vector<LawComparisonRow> rows;
    int exit_code = 0;
    if (!r.detection || !r.analysis) {
      exit_code = static_cast<int>(ErrorCode::kNoBounces);
    } else if (!gs.ball_given) {
      in.fit_failure = "no fit: the ball's size and mass are not given";
    } else {
      try {
        const std::vector<CalibrationInput> inputs = {{rec.name, r.detection->main()}};
        if (all) {
          rows = CompareLaws(inputs, gs.scene, options, c.options.jobs);
          if (!rows.empty() && rows.front().fit.outcome != FitOutcome::kFailed)
            in.calibration = &rows.front().fit;
          in.law_comparison = &rows;
        } else {
          fit = Calibrate(inputs, gs.scene, options);
          in.calibration = &*fit;
        }
        if (in.calibration != nullptr && in.calibration->outcome != FitOutcome::kConverged)
          exit_code = static_cast<int>(FitOutcomeExitCode(in.calibration->outcome));
      } catch (const Error& e) {
        in.fit_failure = Named(e, rec).what();
        exit_code = e.exit_code();
      }
    }
    in.provenance = NamedProvenance(rec);
    in.options = OptionsJson(options);
    in.command = "bouncecal serve: POST " + c.request.target;
    ApiResponse out;
    out.content_type = "text/html; charset=utf-8";
    out.body = RenderHtmlReport(ReportDataJson(in));
    out.download_name = "report.html";
    out.exit_code = exit_code;
    return out;
  });
}

ApiResponse ExportRoute(Query q, const RouteContext& c) {
  ExportOptions o;
  const std::string to = q.TakeString("to").value_or("");
  if (!ParseExportTarget(to, &o.target))
    throw Error(ErrorCode::kUsage, "to=" + to + ": expected lammps, liggghts or yade");
  const std::string scene = q.TakeString("scene").value_or("bounce");
  if (!ParseExportScene(scene, &o.scene))
    throw Error(ErrorCode::kUsage, "scene=" + scene + ": expected bounce or packing");
  o.force = q.TakeFlag("force");
  o.allow_approximation = q.TakeFlag("allow_approximation");
  if (auto v = q.TakeInt("impacts")) o.impacts = *v;
  if (auto v = q.TakeDouble("dt_e_error")) o.time_step_e_error = *v;
  if (auto v = q.TakeDouble("packing_time")) o.packing_time_s = *v;
  if (auto v = q.TakeInt("particles")) o.packing_particles = *v;
  if (auto v = q.TakeDouble("packing_restitution")) o.packing_restitution = *v;
  q.Finish(c.route);
  std::string why;
  if (!o.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  if (c.request.body_path.empty() || c.request.body_bytes == 0)
    throw Error(ErrorCode::kInputMissing,
                c.route + ": no parameter file: send it (calibrate's params.json) as the body");
  const Recording params{c.dir + "/params.json", "params.json"};
  std::filesystem::rename(c.request.body_path, params.path);
  const std::string deck = std::string(ExportSceneName(o.scene)) + "_" + to;
  const std::string out_dir = c.dir + "/" + deck;
  return OnRecording(params, [&] {
    try {
      ExportDeck(params.path, out_dir, o);
    } catch (const Error& e) {
      std::string m = e.what();
      for (std::size_t at; (at = m.find(out_dir)) != std::string::npos;)
        m.replace(at, out_dir.size(), deck);
      throw Error(e.code(), m);
    }
    ApiResponse out;
    out.content_type = "application/zip";
    out.body = ZipDirectory(out_dir, deck);
    out.download_name = deck + ".zip";
    return out;
  });
}

}  // namespace bouncecal::serve
