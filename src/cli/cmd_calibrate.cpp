// `bouncecal calibrate FILE...`: detect the impacts of each recording and fit the contact law's
// damping (calibrate.hpp); write the parameter file (param_file.hpp).
//
// One file -> one fit; several files -> one joint fit (shared law parameters, per-file
// nuisances) unless --batch, which fits each file separately on a worker pool (--jobs N) and
// prints one summary line per file (text, --csv or --json lines), reporting per-file failures
// on stderr without stopping the others (exit code kSomeFailed if any failed).
// --law all fits every registered law as a single run would and prints the adequate ones
// ranked, the others with their outcome. Every fit outcome other than converged exits with its
// own code (error.hpp) after the output and the parameter file are written.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <functional>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/scene_checks.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "commands.hpp"
#include "detect_flags.hpp"
#include "output.hpp"
#include "report_output.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {

struct CalibrateArgs {
  std::vector<std::string> files;
  SceneFlags scene;
  std::string strategy = "restitution";
  std::vector<std::string> free;
  std::vector<std::string> fix;
  std::string derivatives = "auto";
  double rtol = 1e-9;
  std::string loss = "none";
  double loss_scale = 3.0;
  int max_iterations = 100;
  int starts = 4;
  bool ignore_drop = false;
  bool no_scatter = false;
  DetectFlags detect;
  std::string output;
  bool force = false;
  bool json = false;
  bool csv = false;
  int jobs = DefaultJobs();
  bool batch = false;
  ReportPaths report;  // --report FILE.html, --plot FILE.svg|png (report_output.hpp)
  bool quiet = false;  // no progress line
};

// The files no output may replace: recordings, --impacts files, the scene file.
std::vector<std::string> Inputs(const CalibrateArgs& a) {
  return InputFiles(a.files, a.detect, a.scene.scene_file);
}

// A number as printed in text (assumed values): `prec` significant digits, "" if unknown.
// The drops (chosen sequences) of one recording / --impacts pair, as calibration inputs.
std::vector<CalibrationInput> Detect(const std::pair<std::string, std::string>& input,
                                     const DetectFlags& flags) {
  std::vector<CalibrationInput> out;
  for (Drop& d : DropsOf(input.first, input.second, flags))
    out.push_back({d.name, std::move(d.sequence)});
  return out;
}

// The exception in flight as an Error naming `input`: bouncecal errors as they are, anything
// else as kInternal. Worker threads call it from catch (...) so nothing escapes a thread
// (std::terminate would end the whole batch without its per-file lines).
Error CurrentError(const std::string& input) {
  try {
    throw;
  } catch (const Error& e) {
    return e;
  } catch (const std::exception& e) {
    return Error(ErrorCode::kInternal, input + ": " + e.what());
  } catch (...) {
    return Error(ErrorCode::kInternal, input + ": unknown exception");
  }
}

// Detects every input on up to `jobs` threads; throws the first input's error in input order.
std::vector<CalibrationInput> DetectAll(const std::vector<std::pair<std::string, std::string>>& in,
                                        const DetectFlags& flags, int jobs) {
  std::vector<std::vector<CalibrationInput>> per(in.size());
  std::vector<std::optional<Error>> errors(in.size());
  std::atomic<size_t> next{0};
  const int n = std::max(1, std::min<int>(jobs, static_cast<int>(in.size())));
  // Several workers: one thread each for detection (DetectOptions::threads), not one per core
  // each on top of the workers.
  DetectFlags per_worker = flags;
  if (n > 1) per_worker.threads = 1;
  auto worker = [&]() {
    for (size_t i = next++; i < in.size(); i = next++) {
      try {
        per[i] = Detect(in[i], per_worker);
      } catch (...) {
        errors[i] = CurrentError(in[i].first);
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  for (auto& e : errors) {
    if (e) throw *e;
  }
  std::vector<CalibrationInput> out;
  for (auto& p : per) out.insert(out.end(), p.begin(), p.end());
  return out;
}

std::string CsvHeader(const std::vector<ParameterSpec>& specs) {
  std::string h = "file,status,error,law,outcome,impacts";
  for (const auto& s : specs) h += "," + s.name + "," + s.name + "_sigma";
  return h + ",scatter_e,scatter_e_sigma,rms_residual,residual_unit,chi2_dof,reason";
}

// One row: numbers in shortest round-trip form, empty when unknown or not applicable.
std::string CsvRow(const std::string& file, const std::vector<ParameterSpec>& specs,
                   const Calibration* c, const Error* err) {
  std::string row = CsvField(file) + ",";
  if (err) {
    row += std::string(ErrorCodeName(err->code())) + "," + CsvField(err->what()) + ",,,";
    for (size_t i = 0; i < specs.size(); ++i) row += ",,";
    return row + ",,,,,,";
  }
  row += std::string(c->outcome == FitOutcome::kConverged ? "ok" : "fit") + ",," + c->law + "," +
         FitOutcomeName(c->outcome) + ",";
  int impacts = 0;
  for (const auto& r : c->recordings) impacts += r.impacts;
  row += std::to_string(impacts);
  for (const auto& p : c->parameters) row += "," + CsvNumber(p.value) + "," + CsvNumber(p.sigma);
  return row + "," + CsvNumber(c->scatter_e) + "," + CsvNumber(c->scatter_e_sigma) + "," +
         CsvNumber(c->rms_residual) + "," + c->residual_unit + "," + CsvNumber(c->chi2_dof) + "," +
         CsvField(c->outcome == FitOutcome::kConverged ? "" : c->reason);
}

int RunBatch(const CalibrateArgs& a, const Scene& scene, const CalibrationOptions& opts,
             const std::vector<std::pair<std::string, std::string>>& inputs) {
  const auto law = CreateLaw(scene.law, scene);
  const std::vector<ParameterSpec> specs = law->Parameters();
  std::vector<std::string> names;
  for (const auto& p : inputs) names.push_back(p.first.empty() ? p.second : p.first);
  const size_t n = names.size();
  std::vector<std::optional<Calibration>> fits(n);
  std::vector<std::optional<Error>> errors(n);
  std::vector<bool> done(n, false);
  std::mutex mu;
  size_t printed = 0, finished = 0;
  const bool progress = !a.quiet && ::isatty(STDERR_FILENO) != 0;
  std::string summary;  // for -o
  if (a.csv) {
    summary += CsvHeader(specs) + "\n";
    if (a.output.empty()) std::cout << CsvHeader(specs) << "\n" << std::flush;
  }
  auto format_line = [&](size_t i, const Calibration* c, const Error* e) {
    if (a.csv) return CsvRow(names[i], specs, c, e);
    if (a.json) return DumpJson(CalibrationRowJson(names[i], c, e));
    return names[i] + ": " +
           (e ? std::string("FAILED (") + ErrorCodeName(e->code()) + "): " + e->what()
              : c->BriefReport() + (c->outcome == FitOutcome::kConverged
                                        ? ""
                                        : " — " + c->reason + "; next: " + c->hint));
  };
  // Every file gets its line: a failure while formatting one becomes that file's error line.
  auto line_for = [&](size_t i) {
    try {
      return format_line(i, fits[i] ? &*fits[i] : nullptr, errors[i] ? &*errors[i] : nullptr);
    } catch (...) {
      fits[i].reset();
      errors[i] = CurrentError(names[i]);
      return format_line(i, nullptr, &*errors[i]);
    }
  };
  // Lines come out in input order as soon as every earlier file is done.
  auto flush_ready = [&]() {
    while (printed < n && done[printed]) {
      const std::string line = line_for(printed);
      summary += line + "\n";
      if (a.output.empty()) std::cout << line << "\n" << std::flush;
      ++printed;
    }
  };
  std::atomic<size_t> next{0};
  const int nthreads = std::max(1, std::min<int>(a.jobs, static_cast<int>(n)));
  // One detection thread per worker (DetectOptions::threads) when several workers run.
  DetectFlags per_worker = a.detect;
  if (nthreads > 1) per_worker.threads = 1;
  auto worker = [&]() {
    for (size_t i = next++; i < n; i = next++) {
      std::optional<Calibration> fit;
      std::optional<Error> err;
      try {
        fit = Calibrate(Detect(inputs[i], per_worker), scene, opts);
      } catch (...) {
        err = CurrentError(names[i]);
      }
      std::lock_guard<std::mutex> lock(mu);
      fits[i] = std::move(fit);
      errors[i] = std::move(err);
      std::string msg;
      if (errors[i]) {
        msg = errors[i]->what();
      } else if (fits[i]->outcome != FitOutcome::kConverged) {
        msg = std::string(FitOutcomeName(fits[i]->outcome)) + ": " + fits[i]->reason;
      }
      if (!msg.empty()) {
        if (msg.rfind(names[i], 0) != 0) msg = names[i] + ": " + msg;
        std::cerr << (progress ? "\r\033[K" : "") << "bouncecal: " << msg << "\n";
      }
      done[i] = true;
      ++finished;
      flush_ready();
      if (progress) {
        std::cerr << "\r\033[K[" << finished << "/" << n << "] " << names[i] << std::flush;
      }
    }
  };
  std::vector<std::thread> pool;
  for (int t = 1; t < nthreads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (progress) std::cerr << "\r\033[K" << std::flush;
  if (!a.output.empty()) {
    WriteFileAtomically(a.output, summary, {.force = a.force, .inputs = Inputs(a)});
  }
  size_t failed = 0;
  for (size_t i = 0; i < n; ++i) {
    failed += errors[i] || fits[i]->outcome != FitOutcome::kConverged ? 1 : 0;
  }
  if (failed > 0) {
    throw Error(ErrorCode::kSomeFailed,
                std::to_string(failed) + " of " + std::to_string(n) + " recordings failed");
  }
  return 0;
}

// Refuses a fit without a ball: its mass and size enter every contact law.
void RequireBall(const GivenScene& gs) {
  if (gs.ball_given) return;
  const bool diameter = gs.Given("ball.diameter_m");
  throw Error(ErrorCode::kBadScene,
              std::string("calibrate: the ball's ") + (diameter ? "mass" : "size and mass") +
                  " are not given (they enter the contact law, its default stiffness and the "
                  "drag): give --scene FILE with a [ball] table, or --diameter M with --mass KG "
                  "(or --density KG_M3, or --material NAME)");
}

CalibrationOptions Options(const CalibrateArgs& a, const GivenScene& gs) {
  CalibrationOptions opts;
  opts.strategy = ParseFitStrategy(a.strategy);
  opts.free_parameters = a.free;
  opts.fixed_parameters = a.fix;
  opts.derivatives = ParseDerivativeMode(a.derivatives);
  opts.rel_tolerance = a.rtol;
  opts.loss = ParseRobustLoss(a.loss);
  opts.loss_scale_sigma = a.loss_scale;
  opts.max_iterations = a.max_iterations;
  opts.max_starts = a.starts;
  // One law's simulated contacts on the --jobs threads (with --law all as well, alongside the
  // laws run concurrently); --batch runs whole fits on them instead.
  opts.threads = a.batch ? 1 : a.jobs;
  opts.estimate_scatter = !a.no_scatter;
  opts.use_drop = gs.drop_given && !a.ignore_drop;
  // Drag off by the user's explicit choice: no drag check.
  opts.analysis.check_drag = !gs.Given("effects.drag");
  std::string err;
  if (!opts.IsValid(&err)) throw Error(ErrorCode::kUsage, err);
  return opts;
}

// Defaults the result depends on: the scene's (AssumedValues) and the law's held parameters.
std::vector<Assumed> AssumedFor(const GivenScene& gs, const Calibration& c) {
  std::vector<Assumed> out = AssumedValues(gs, true);
  for (const auto& p : c.parameters) {
    if (p.fixed && !gs.Given("law.parameters." + p.name)) {
      out.push_back({"law.parameters." + p.name,
                     (std::isfinite(p.value) ? FormatGeneral(p.value, 7) : "") + " " + p.unit,
                     "held at the law's default, not fitted"});
    }
  }
  return out;
}

// The outcome as the exit code (the parameter file is written before).
void ExitWithOutcome(const Calibration& c) {
  if (c.outcome == FitOutcome::kConverged) return;
  throw Error(FitOutcomeExitCode(c.outcome), std::string("calibrate: outcome ") +
                                                 FitOutcomeName(c.outcome) + ": " + c.reason +
                                                 (c.hint.empty() ? "" : "; next: " + c.hint));
}

// What to try when no law is adequate: the hint of the law that missed by least (the smallest
// misfit, else the first row with a hint), without its advice to try the other laws (every
// one was tried).
std::string NoLawHint(const std::vector<LawComparisonRow>& rows) {
  const LawComparisonRow* best = nullptr;
  for (const auto& r : rows) {
    if (r.fit.hint.empty()) continue;
    if (best == nullptr ||
        (std::isfinite(r.fit.misfit_e) && !(best->fit.misfit_e <= r.fit.misfit_e)))
      best = &r;
  }
  if (best == nullptr) return "";
  std::string kept;
  std::istringstream steps(best->fit.hint);
  for (std::string step; std::getline(steps, step, ';');) {
    if (!step.empty() && step.front() == ' ') step.erase(0, 1);
    if (step.find("--law all") != std::string::npos ||
        step.find("e changes with speed") != std::string::npos)
      continue;
    kept += (kept.empty() ? "" : "; ") + step;
  }
  return kept.empty() ? "check the scene (the ball, --drag, --height) and the impacts used "
                        "(detect --click-track FILE.wav)"
                      : kept;
}

void RunComparison(const CalibrateArgs& a, const GivenScene& gs, const CalibrationOptions& opts,
                   const std::vector<CalibrationInput>& inputs, const Provenance& prov,
                   const nlohmann::json& options_json, Progress* progress,
                   const std::function<void(const Calibration*,
                                            const std::vector<LawComparisonRow>*)>& write_report) {
  progress->Stage("fitting every law (--law all)");
  auto rows = CompareLaws(inputs, gs.scene, opts, a.jobs);
  progress->Done();
  if (!rows.empty()) write_report(rows.front().adequate ? &rows.front().fit : nullptr, &rows);
  const bool any = !rows.empty() && rows.front().adequate;
  std::vector<double> speeds;
  for (const auto& r : rows) {
    if (r.fit.v_max_m_s > 0 && speeds.empty()) {
      const Calibration& f = r.fit;
      speeds = {f.v_min_m_s, std::sqrt(f.v_min_m_s * f.v_max_m_s), f.v_max_m_s};
    }
  }
  std::vector<std::string> inadequate;
  for (const auto& r : rows) {
    if (!r.adequate) inadequate.push_back(r.fit.law + " (" + FitOutcomeName(r.fit.outcome) + ")");
  }
  if (a.json) {
    std::cout << DumpJson(LawComparisonJson(rows, prov, options_json,
                                            AssumedJson(AssumedValues(gs, true))),
                          2)
              << "\n";
  } else if (a.csv) {
    std::cout << "rank,law,outcome,adequate,scatter_e,chi2_dof,aic,delta_aic,reason\n";
    int rank = 0;
    for (const auto& r : rows) {
      const auto& c = r.fit;
      std::cout << (r.adequate ? std::to_string(++rank) : "") << "," << c.law << ","
                << FitOutcomeName(c.outcome) << "," << (r.adequate ? 1 : 0) << ","
                << CsvNumber(c.scatter_e) << "," << CsvNumber(c.chi2_dof) << "," << CsvNumber(c.aic)
                << "," << CsvNumber(r.delta_aic) << "," << CsvField(r.adequate ? "" : c.reason)
                << "\n";
    }
  } else {
    std::cout << AssumedText(AssumedValues(gs, true)) << "law comparison ("
              << FitStrategyName(opts.strategy)
              << " fit of every law, full convergence; adequate fits ranked by AIC, the others "
                 "listed with their outcome; e(v) at the lowest, middle and highest measured "
                 "speed)\n"
              << LawComparisonTable(rows, speeds) << "\n";
    if (any) std::cout << "best: " << rows.front().fit.BriefReport() << "\n";
    if (!inadequate.empty()) {
      std::string list;
      for (const auto& s : inadequate) list += (list.empty() ? "" : ", ") + s;
      std::cout << "not adequate (not ranked): " << list << "\n";
    }
    if (any) std::cout << "next: " << rows.front().fit.hint << "\n";
  }
  std::cout << std::flush;
  if (!any) {
    const std::string hint = NoLawHint(rows);
    throw Error(
        ErrorCode::kFitFailed,
        "no contact law fits these recordings adequately" +
            (rows.empty() ? "" : ": " + rows.front().fit.law + ": " + rows.front().fit.reason) +
            (hint.empty() ? "" : "; next: " + hint));
  }
  if (!a.output.empty()) {
    WriteParamFile(a.output, CalibrationJson(rows.front().fit, prov, options_json),
                   {.force = a.force, .inputs = Inputs(a)});
  }
}

void Run(const CalibrateArgs& a) {
  if (a.json && a.csv) throw Error(ErrorCode::kUsage, "--json and --csv: choose one");
  if (a.jobs < 1 || a.jobs > 256) {
    throw Error(ErrorCode::kUsage, "--jobs " + std::to_string(a.jobs) + ": expected 1..256");
  }
  const bool all = a.scene.law == "all";
  if (all && a.batch) throw Error(ErrorCode::kUsage, "--law all cannot be combined with --batch");
  SceneFlags sf = a.scene;
  if (all) sf.law.clear();
  const GivenScene gs = ResolveGivenScene(sf);
  RequireBall(gs);
  const CalibrationOptions opts = Options(a, gs);
  const Scene& scene = gs.scene;
  if (!all) CreateLaw(scene.law, scene);  // unknown law or parameter: fail before any work
  MakeDetectOptions(a.detect);            // flag errors before any work
  const auto pairs = PairInputs(a.files, a.detect);
  // The output path must be usable before the expensive work.
  if (!a.output.empty()) CheckOutputPath(a.output, {.force = a.force, .inputs = Inputs(a)});
  const std::vector<Warning> unit_warnings = SceneUnitWarnings(scene, opts.use_drop);
  if (a.report.any() && a.batch) {
    throw Error(ErrorCode::kUsage,
                "--report/--plot show one fit: not with --batch (run "
                "`bouncecal report FILE` per file)");
  }
  if (a.report.any() && std::find(a.files.begin(), a.files.end(), "-") != a.files.end()) {
    throw Error(ErrorCode::kUsage,
                "--report/--plot read the recordings again: not with standard input (-), which "
                "is read once; save it to a file, or run `bouncecal report -`");
  }
  ReportPaths report = a.report;
  report.force = a.force;
  CheckReportPaths(report, Inputs(a));
  Progress progress(a.quiet);
  auto write_report = [&](const Calibration* fit, const std::vector<LawComparisonRow>* rows) {
    WriteReports(report, a.files, MakeDetectOptions(a.detect), scene, ReportAnalysisOptions(gs),
                 {fit, rows, "", MakeProvenance(a.files), OptionsJson(opts), ""}, &progress);
  };

  if (a.batch) {
    PrintWarnings(unit_warnings);
    const int rc = RunBatch(a, scene, opts, pairs);
    if (rc != 0) throw Error(ErrorCode::kSomeFailed, "some recordings failed");
    return;
  }

  const std::vector<CalibrationInput> inputs = DetectAll(pairs, a.detect, a.jobs);
  const Provenance prov = MakeProvenance(a.files);
  const nlohmann::json options_json = OptionsJson(opts);
  if (all) {
    PrintWarnings(unit_warnings);
    return RunComparison(a, gs, opts, inputs, prov, options_json, &progress, write_report);
  }

  progress.Stage("fitting " + scene.law.name);
  Calibration c = Calibrate(inputs, scene, opts);
  progress.Done();
  write_report(&c, nullptr);
  c.warnings.insert(c.warnings.begin(), unit_warnings.begin(), unit_warnings.end());
  const std::vector<Assumed> assumed = AssumedFor(gs, c);
  nlohmann::json doc = CalibrationJson(c, prov, options_json);
  doc["assumed"] = AssumedJson(assumed);
  if (a.json) {
    std::cout << DumpJson(doc, 2) << "\n";
  } else if (a.csv) {
    PrintWarnings(c.warnings);
    const auto specs = CreateLaw(scene.law, scene)->Parameters();
    std::cout << CsvHeader(specs) << "\n"
              << CsvRow(a.files.size() == 1 ? a.files[0] : "joint", specs, &c, nullptr) << "\n";
  } else {
    PrintWarnings(c.warnings);
    std::cout << AssumedText(assumed) << c.FullReport();
  }
  std::cout << std::flush;
  // The parameter file records every outcome (nothing is lost); the exit code tells scripts.
  if (!a.output.empty()) {
    WriteParamFile(a.output, doc, {.force = a.force, .inputs = Inputs(a)});
    if (!a.json && !a.csv) std::cout << "wrote " << a.output << "\n" << std::flush;
  }
  ExitWithOutcome(c);
}

}  // namespace

void RegisterCalibrate(CLI::App& app) {
  auto args = std::make_shared<CalibrateArgs>();
  CLI::App* sub = app.add_subcommand(
      "calibrate", "fit a contact law's damping to recordings and write the parameter file");
  sub->add_option("files", args->files,
                  "recordings (several: one joint fit, or --batch; - reads standard input)")
      ->required();
  AddSceneFlags(sub, &args->scene, true);
  sub->add_option("--strategy", args->strategy,
                  "restitution (per-bounce e with scatter; default) or trajectory (simulated "
                  "impact times with the scatter propagated)");
  // One value per occurrence, so `--free k drop.wav` does not swallow the recording.
  sub->add_option("--free", args->free, "also fit this held parameter, e.g. k (repeatable)")
      ->allow_extra_args(false);
  sub->add_option("--fix", args->fix, "hold this damping parameter at its scene value")
      ->allow_extra_args(false);
  sub->add_option("--derivatives", args->derivatives, "auto (analytic where possible) or numeric");
  sub->add_option("--rtol", args->rtol, "simulator relative tolerance inside the fit");
  sub->add_option("--loss", args->loss, "robust loss on whitened residuals: none, huber, cauchy");
  sub->add_option("--loss-scale", args->loss_scale, "robust loss scale, in sigmas");
  sub->add_option("--max-iterations", args->max_iterations, "solver iteration limit per solve");
  sub->add_option("--starts", args->starts, "start points tried (1 = the best guess only)");
  sub->add_flag("--ignore-drop", args->ignore_drop,
                "do not use the drop height/impact speed even when given");
  sub->add_flag("--no-scatter", args->no_scatter,
                "no per-bounce scatter: timing noise only (synthetic recordings)");
  AddDetectFlags(sub, &args->detect);
  AddOutputOption(sub, "-o,--output", &args->output, "write the parameter file (JSON) here");
  sub->add_flag("--force", args->force, "replace an existing output file");
  sub->add_flag("--json", args->json, "print the parameter-file object to stdout");
  sub->add_flag("--csv", args->csv, "print CSV");
  sub->add_option("--jobs", args->jobs,
                  "worker threads (detection, --batch fits, --law all, one law's simulated "
                  "contacts); default: the machine's cores, at most 8 (results do not depend on "
                  "it)");
  sub->add_flag("--batch", args->batch, "fit each file separately, one summary line per file");
  AddOutputOption(sub, "--report", &args->report.html, "also write the HTML report of this fit");
  AddOutputOption(sub, "--plot", &args->report.plot,
                  "also write its figures: FILE.svg or FILE.png");
  sub->add_flag("--quiet", args->quiet, "no progress line on stderr (shown only on a terminal)");
  sub->callback([args]() { Run(*args); });
}

}  // namespace bouncecal::cli
