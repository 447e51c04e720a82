// `bouncecal report FILE... -o report.html [--plot fig.svg|fig.png]`: detect, analyze and fit
// the recordings as `calibrate` does, and write one self-contained HTML report (report_data.hpp,
// html_report.hpp) and/or a static figure (figures.hpp).
//
// The report is written whenever the recordings can be read: a recording without impacts (or
// silent) still gets its waveform and the reason, a failed fit its message. The exit code then
// says what is missing: kNoBounces when a recording has no bounce sequence, kFitFailed when the
// fit failed or did not converge (the report is written first, and the message names it).
// Progress on stderr only when it is a terminal (--quiet: never).
#include <cmath>
#include <filesystem>
#include <iostream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "commands.hpp"
#include "detect_flags.hpp"
#include "output.hpp"
#include "progress.hpp"
#include "report_output.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {

struct ReportArgs {
  std::vector<std::string> files;
  SceneFlags scene;
  ReportPaths paths;
  std::string strategy = "restitution";
  std::vector<std::string> free;
  std::vector<std::string> fix;
  bool ignore_drop = false;
  DetectFlags detect;
  int jobs = DefaultJobs();
  bool quiet = false;
  // Points of the fitted e(v) curve and band in the report (CalibrationOptions::e_of_v_points):
  // more than calibrate's table so that the curve is smooth on a log axis.
  int e_of_v_points = 24;
  std::vector<std::string> argv;  // for the provenance block
};

// What the fit stage produced: one fit, or a ranked comparison, or why there is none.
struct FitStage {
  std::optional<Calibration> fit;
  std::vector<LawComparisonRow> rows;
  std::optional<Error> error;
  const Calibration* best() const {
    if (!rows.empty())
      return rows.front().fit.outcome == FitOutcome::kFailed ? nullptr : &rows[0].fit;
    return fit ? &*fit : nullptr;
  }
};

FitStage Fit(const std::vector<ReportRecording>& recordings, const Scene& scene,
             const CalibrationOptions& opts, bool all, int jobs, Progress* progress) {
  FitStage out;
  std::vector<CalibrationInput> inputs;
  for (const ReportRecording& r : recordings)
    if (r.detection && r.analysis) inputs.push_back({r.path, r.detection->main()});
  if (inputs.empty()) {
    out.error = Error(ErrorCode::kNoBounces, "no recording has a bounce sequence to fit");
    return out;
  }
  try {
    if (all) {
      progress->Stage("fitting every law (--law all) to " + std::to_string(inputs.size()) +
                      " recording(s)");
      out.rows = CompareLaws(inputs, scene, opts, jobs);
      if (out.rows.empty() || out.rows.front().fit.outcome == FitOutcome::kFailed) {
        out.error = Error(ErrorCode::kFitFailed,
                          "no contact law could be fitted" +
                              (out.rows.empty() ? "" : ": " + out.rows.front().fit.message));
      }
    } else {
      progress->Stage("fitting " + scene.law.name + " to " + std::to_string(inputs.size()) +
                      " recording(s)");
      out.fit = Calibrate(inputs, scene, opts);
    }
  } catch (const Error& e) {
    out.error = e;
  }
  const Calibration* best = out.best();
  if (!out.error && best != nullptr && best->outcome != FitOutcome::kConverged) {
    out.error = Error(FitOutcomeExitCode(best->outcome),
                      std::string("fit ") + FitOutcomeName(best->outcome) + ": " + best->reason);
  }
  return out;
}

void Run(const ReportArgs& a) {
  if (!a.paths.any()) {
    throw Error(ErrorCode::kUsage, "nothing to write: give -o report.html and/or --plot FILE");
  }
  CalibrationOptions opts;
  opts.strategy = ParseFitStrategy(a.strategy);
  opts.free_parameters = a.free;
  opts.fixed_parameters = a.fix;
  opts.e_of_v_points = a.e_of_v_points;
  std::string why;
  if (!opts.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  if (a.jobs < 1 || a.jobs > 256) {
    throw Error(ErrorCode::kUsage, "--jobs " + std::to_string(a.jobs) + ": expected 1..256");
  }
  const bool all = a.scene.law == "all";
  SceneFlags sf = a.scene;
  if (all) sf.law.clear();
  const GivenScene gs = ResolveGivenScene(sf);
  const Scene& scene = gs.scene;
  // As calibrate: the stated drop is used unless --ignore-drop; no drag check when the user
  // chose the drag.
  opts.use_drop = gs.drop_given && !a.ignore_drop;
  opts.analysis = ReportAnalysisOptions(gs);
  opts.threads = a.jobs;  // one law's simulated contacts on the threads, as calibrate does
  if (!opts.IsValid(&why)) throw Error(ErrorCode::kUsage, why);
  if (!all) CreateLaw(scene.law, scene);  // unknown law or parameter: fail before any work
  const DetectOptions detect = MakeDetectOptions(a.detect);
  CheckReportPaths(a.paths, InputFiles(a.files, a.detect, a.scene.scene_file));

  Progress progress(a.quiet);
  std::vector<ReportRecording> recordings =
      LoadRecordings(a.files, detect, scene, ReportAnalysisOptions(gs), &progress);
  const FitStage fit = Fit(recordings, scene, opts, all, a.jobs, &progress);

  std::vector<std::string> no_impacts;
  std::vector<Warning> warnings;
  for (const ReportRecording& r : recordings) {
    if (!r.no_impacts_reason.empty()) no_impacts.push_back(r.no_impacts_reason);
    if (r.detection)
      warnings.insert(warnings.end(), r.detection->warnings.begin(), r.detection->warnings.end());
    if (r.analysis)
      warnings.insert(warnings.end(), r.analysis->warnings.begin(), r.analysis->warnings.end());
  }
  const int n_recordings = static_cast<int>(recordings.size());
  ReportResults results;
  results.calibration = fit.best();
  results.law_comparison = fit.rows.empty() ? nullptr : &fit.rows;
  if (fit.error && fit.best() == nullptr) results.fit_failure = fit.error->what();
  results.provenance = MakeProvenance(a.files);
  results.options = OptionsJson(opts);
  results.command = CommandLine("report", a.argv);
  WriteReportOutputs(a.paths, std::move(recordings), results, &progress);

  progress.Done();
  PrintWarnings(warnings);
  for (const std::string* p : {&a.paths.html, &a.paths.plot}) {
    if (p->empty()) continue;
    std::cout << "wrote " << *p << " (" << std::filesystem::file_size(*p) / 1024
              << " kB): " << n_recordings << " recording(s)";
    if (fit.best() != nullptr) std::cout << "; " << fit.best()->BriefReport();
    std::cout << "\n";
  }
  std::cout << std::flush;
  const std::string written =
      "; the report was written (" + (a.paths.html.empty() ? a.paths.plot : a.paths.html) + ")";
  if (!no_impacts.empty()) {
    std::string msg = no_impacts.front();
    if (no_impacts.size() > 1) msg += " (and " + std::to_string(no_impacts.size() - 1) + " more)";
    throw Error(ErrorCode::kNoBounces, msg + written);
  }
  if (fit.error) throw Error(fit.error->code(), std::string(fit.error->what()) + written);
}

}  // namespace

void RegisterReport(CLI::App& app) {
  auto args = std::make_shared<ReportArgs>();
  CLI::App* sub = app.add_subcommand(
      "report",
      "detect, analyze and fit recordings; write a self-contained HTML report and/or "
      "a static figure");
  sub->add_option("files", args->files,
                  "recordings (several: one joint fit; - reads standard input)")
      ->required();
  AddOutputOption(sub, "-o,--output", &args->paths.html, "write the HTML report here");
  AddOutputOption(sub, "--plot", &args->paths.plot,
                  "write the same charts as a static figure, FILE.svg or FILE.png (gnuplot)");
  sub->add_flag("--force", args->paths.force, "replace existing output files");
  sub->add_flag("--quiet", args->quiet, "no progress line on stderr (shown only on a terminal)");
  AddSceneFlags(sub, &args->scene, true);
  sub->add_option("--strategy", args->strategy, "trajectory or restitution (as calibrate)");
  sub->add_option("--free", args->free, "also fit this held parameter, e.g. k (repeatable)")
      ->allow_extra_args(false);
  sub->add_option("--fix", args->fix, "hold this damping parameter at its scene value")
      ->allow_extra_args(false);
  sub->add_flag("--ignore-drop", args->ignore_drop,
                "do not use the scene's drop height/speed for the first impact (as calibrate)");
  AddDetectFlags(sub, &args->detect);
  sub->add_option("--jobs", args->jobs,
                  "worker threads (--law all, one law's simulated contacts); default: the "
                  "machine's cores, at most 8 (results do not depend on it)");
  sub->callback([args, sub]() {
    args->argv.clear();
    for (const std::string& f : args->files) args->argv.push_back(f);
    for (const CLI::Option* o : sub->get_options()) {
      if (o->get_lnames().empty() || o->count() == 0) continue;
      const std::string name = "--" + o->get_lnames().front();
      if (o->get_expected_min() == 0) {
        args->argv.push_back(name);  // a flag
        continue;
      }
      for (const std::string& v : o->results()) args->argv.push_back(name + " " + v);
    }
    Run(*args);
  });
}

}  // namespace bouncecal::cli
