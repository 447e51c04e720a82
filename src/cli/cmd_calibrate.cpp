// `bouncecal calibrate FILE...`: detect the impacts of each recording and fit the contact law's
// damping (calibrate.hpp); write the parameter file (param_file.hpp).
//
// One file -> one fit; several files -> one joint fit (shared law parameters, per-file
// nuisances) unless --batch, which fits each file separately on a worker pool (--jobs N) and
// prints one summary line per file (text, --csv or --json lines), reporting per-file failures
// on stderr without stopping the others (exit code kSomeFailed if any failed).
// --law all fits every registered law and prints a ranked table.
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <sstream>
#include <thread>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "commands.hpp"
#include "report_output.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {

struct CalibrateArgs {
  std::vector<std::string> files;
  SceneFlags scene;
  std::string strategy = "trajectory";
  std::vector<std::string> free;
  std::vector<std::string> fix;
  std::string derivatives = "auto";
  double rtol = 1e-9;
  std::string loss = "huber";
  double loss_scale = 3.0;
  int max_iterations = 60;
  bool use_drop = false;
  std::string channel = "auto";
  std::string output;
  bool force = false;
  bool json = false;
  bool csv = false;
  int jobs = 1;
  bool batch = false;
  ReportPaths report;  // --report FILE.html, --plot FILE.svg|png (report_output.hpp)
  bool quiet = false;  // no progress line
};

std::string Num(double v, int prec = 10) {
  if (!std::isfinite(v)) return "";
  std::ostringstream os;
  os.precision(prec);
  os << v;
  return os.str();
}

std::string CsvField(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string out = "\"";
  for (char c : s) {
    if (c == '"') out += '"';
    out += c;
  }
  return out + "\"";
}

CalibrationInput Detect(const std::string& path, const ChannelSelection& channel) {
  const Audio audio = ReadAudio(path);
  DetectOptions d;
  d.channel = channel;
  const DetectionResult r = DetectImpacts(audio, d);
  return {path, r.main()};
}

// Detects every file on up to `jobs` threads; throws the first file's error in input order.
std::vector<CalibrationInput> DetectAll(const std::vector<std::string>& files,
                                        const ChannelSelection& channel, int jobs) {
  std::vector<CalibrationInput> out(files.size());
  std::vector<std::optional<Error>> errors(files.size());
  std::atomic<size_t> next{0};
  auto worker = [&]() {
    for (size_t i = next++; i < files.size(); i = next++) {
      try {
        out[i] = Detect(files[i], channel);
      } catch (const Error& e) {
        errors[i] = e;
      } catch (const std::exception& e) {
        errors[i] = Error(ErrorCode::kInternal, files[i] + ": " + e.what());
      }
    }
  };
  const int n = std::max(1, std::min<int>(jobs, static_cast<int>(files.size())));
  std::vector<std::thread> pool;
  for (int t = 1; t < n; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  for (auto& e : errors) {
    if (e) throw *e;
  }
  return out;
}

std::string CsvHeader(const std::vector<ParameterSpec>& specs) {
  std::string h = "file,status,error,law,outcome,impacts";
  for (const auto& s : specs) h += "," + s.name + "," + s.name + "_sigma";
  return h + ",rms_residual,residual_unit,chi2_dof";
}

std::string CsvRow(const std::string& file, const std::vector<ParameterSpec>& specs,
                   const Calibration* c, const Error* err) {
  std::string row = CsvField(file) + ",";
  if (err) {
    row += std::string(ErrorCodeName(err->code())) + "," + CsvField(err->what()) + ",,,";
    for (size_t i = 0; i < specs.size(); ++i) row += ",,";
    return row + ",,";
  }
  row += "ok,," + c->law + "," + FitOutcomeName(c->outcome) + ",";
  int impacts = 0;
  for (const auto& r : c->recordings) impacts += r.impacts;
  row += std::to_string(impacts);
  for (const auto& p : c->parameters) row += "," + Num(p.value) + "," + Num(p.sigma, 4);
  return row + "," + Num(c->rms_residual, 6) + "," + c->residual_unit + "," + Num(c->chi2_dof, 6);
}

nlohmann::json JsonRow(const std::string& file, const Calibration* c, const Error* err) {
  nlohmann::json j = {{"file", file}};
  if (err) {
    j["status"] = ErrorCodeName(err->code());
    j["error"] = err->what();
    return j;
  }
  j["status"] = "ok";
  j["law"] = c->law;
  j["outcome"] = FitOutcomeName(c->outcome);
  nlohmann::json params = nlohmann::json::object();
  for (const auto& p : c->parameters) {
    params[p.name] = {{"value", std::isfinite(p.value) ? nlohmann::json(p.value) : nullptr},
                      {"sigma", std::isfinite(p.sigma) ? nlohmann::json(p.sigma) : nullptr},
                      {"unit", p.unit},
                      {"fixed", p.fixed}};
  }
  j["parameters"] = params;
  int impacts = 0;
  for (const auto& r : c->recordings) impacts += r.impacts;
  j["impacts"] = impacts;
  j[c->strategy == FitStrategy::kTrajectory ? "rms_residual_s" : "rms_residual_e"] =
      c->rms_residual;
  j["chi2_dof"] = c->chi2_dof;
  return j;
}

int RunBatch(const CalibrateArgs& a, const Scene& scene, const CalibrationOptions& opts,
             const ChannelSelection& channel) {
  const auto law = CreateLaw(scene.law, scene);
  const std::vector<ParameterSpec> specs = law->Parameters();
  const size_t n = a.files.size();
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
  auto line_for = [&](size_t i) {
    const Calibration* c = fits[i] ? &*fits[i] : nullptr;
    const Error* e = errors[i] ? &*errors[i] : nullptr;
    if (a.csv) return CsvRow(a.files[i], specs, c, e);
    if (a.json) return JsonRow(a.files[i], c, e).dump();
    return a.files[i] + ": " +
           (e ? std::string("FAILED (") + ErrorCodeName(e->code()) + "): " + e->what()
              : c->BriefReport());
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
  auto worker = [&]() {
    for (size_t i = next++; i < n; i = next++) {
      std::optional<Calibration> fit;
      std::optional<Error> err;
      try {
        fit = Calibrate({Detect(a.files[i], channel)}, scene, opts);
        if (fit->outcome != FitOutcome::kConverged) {
          err = Error(ErrorCode::kFitFailed, a.files[i] + ": " + fit->message);
          fit.reset();
        }
      } catch (const Error& e) {
        err = e;
      } catch (const std::exception& e) {
        err = Error(ErrorCode::kInternal, a.files[i] + ": " + e.what());
      }
      std::lock_guard<std::mutex> lock(mu);
      fits[i] = std::move(fit);
      errors[i] = std::move(err);
      if (errors[i]) {
        std::string msg = errors[i]->what();
        if (msg.rfind(a.files[i], 0) != 0) msg = a.files[i] + ": " + msg;
        std::cerr << (progress ? "\r\033[K" : "") << "bouncecal: " << msg << "\n";
      }
      done[i] = true;
      ++finished;
      flush_ready();
      if (progress) {
        std::cerr << "\r\033[K[" << finished << "/" << n << "] " << a.files[i] << std::flush;
      }
    }
  };
  const int nthreads = std::max(1, std::min<int>(a.jobs, static_cast<int>(n)));
  std::vector<std::thread> pool;
  for (int t = 1; t < nthreads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
  if (progress) std::cerr << "\r\033[K" << std::flush;
  if (!a.output.empty()) {
    WriteFileAtomically(a.output, summary, {.force = a.force, .inputs = a.files});
  }
  const size_t failed = static_cast<size_t>(
      std::count_if(errors.begin(), errors.end(), [](const auto& e) { return e.has_value(); }));
  if (failed > 0) {
    throw Error(ErrorCode::kSomeFailed,
                std::to_string(failed) + " of " + std::to_string(n) + " recordings failed");
  }
  return 0;
}

void Run(const CalibrateArgs& a) {
  CalibrationOptions opts;
  opts.strategy = ParseFitStrategy(a.strategy);
  opts.free_parameters = a.free;
  opts.fixed_parameters = a.fix;
  opts.derivatives = ParseDerivativeMode(a.derivatives);
  opts.rel_tolerance = a.rtol;
  opts.loss = ParseRobustLoss(a.loss);
  opts.loss_scale_sigma = a.loss_scale;
  opts.max_iterations = a.max_iterations;
  opts.use_drop = a.use_drop;
  std::string err;
  if (!opts.IsValid(&err)) throw Error(ErrorCode::kUsage, err);
  if (a.json && a.csv) throw Error(ErrorCode::kUsage, "--json and --csv: choose one");
  if (a.jobs < 1 || a.jobs > 256) {
    throw Error(ErrorCode::kUsage, "--jobs " + std::to_string(a.jobs) + ": expected 1..256");
  }
  const bool all = a.scene.law == "all";
  if (all && a.batch) throw Error(ErrorCode::kUsage, "--law all cannot be combined with --batch");
  SceneFlags sf = a.scene;
  if (all) sf.law.clear();
  const Scene scene = ResolveScene(sf);
  if (!all) CreateLaw(scene.law, scene);  // unknown law or parameter: fail before any work
  const ChannelSelection channel = ParseChannelSelection(a.channel);
  // The output path must be usable before the expensive work.
  if (!a.output.empty()) CheckOutputPath(a.output, {.force = a.force, .inputs = a.files});
  if (a.report.any() && a.batch) {
    throw Error(ErrorCode::kUsage,
                "--report/--plot show one fit: not with --batch (run "
                "`bouncecal report FILE` per file)");
  }
  ReportPaths report = a.report;
  report.force = a.force;
  CheckReportPaths(report, a.files);
  Progress progress(a.quiet);
  auto write_report = [&](const Calibration* fit, const std::vector<LawComparisonRow>* rows) {
    WriteReports(report, a.files, channel, scene, DropGiven(a.scene),
                 {fit, rows, "", MakeProvenance(a.files), OptionsJson(opts), ""}, &progress);
  };

  if (a.batch) {
    const int rc = RunBatch(a, scene, opts, channel);
    if (rc != 0) throw Error(ErrorCode::kSomeFailed, "some recordings failed");
    return;
  }

  const std::vector<CalibrationInput> inputs = DetectAll(a.files, channel, a.jobs);
  const Provenance prov = MakeProvenance(a.files);
  const nlohmann::json options_json = OptionsJson(opts);

  if (all) {
    progress.Stage("fitting every law (--law all)");
    auto rows = CompareLaws(inputs, scene, opts, a.jobs);
    progress.Done();
    if (!rows.empty()) {
      const bool failed = rows.front().fit.outcome == FitOutcome::kFailed;
      write_report(failed ? nullptr : &rows.front().fit, &rows);
    }
    if (rows.empty() || rows.front().fit.outcome == FitOutcome::kFailed) {
      throw Error(ErrorCode::kFitFailed, "no contact law could be fitted to these recordings" +
                                             (rows.empty() ? "" : ": " + rows.front().fit.message));
    }
    const Calibration& best = rows.front().fit;
    std::vector<double> speeds;
    if (best.v_max_m_s > 0) {
      speeds = {best.v_min_m_s, std::sqrt(best.v_min_m_s * best.v_max_m_s), best.v_max_m_s};
    }
    if (a.json) {
      nlohmann::json j = {{"schema", "bouncecal.law_comparison/1"}};
      nlohmann::json laws = nlohmann::json::array();
      int rank = 0;
      for (const auto& r : rows) {
        nlohmann::json l;
        if (r.fit.outcome == FitOutcome::kFailed) {
          l = {{"law", r.fit.law}, {"fit", {{"outcome", "failed"}, {"message", r.fit.message}}}};
        } else {
          l = ParamFileJson(r.fit, prov, options_json);
          l["delta_aic"] = r.delta_aic;
        }
        l["rank"] = ++rank;
        laws.push_back(l);
      }
      j["laws"] = laws;
      std::cout << j.dump(2) << "\n";
    } else if (a.csv) {
      std::cout << "rank,law,outcome,rms_residual,residual_unit,chi2_dof,aic,delta_aic,bic\n";
      int rank = 0;
      for (const auto& r : rows) {
        const auto& c = r.fit;
        std::cout << ++rank << "," << c.law << "," << FitOutcomeName(c.outcome) << ","
                  << (c.outcome == FitOutcome::kFailed
                          ? ",,,,,"
                          : Num(c.rms_residual, 6) + "," + c.residual_unit + "," +
                                Num(c.chi2_dof, 6) + "," + Num(c.aic, 8) + "," +
                                Num(r.delta_aic, 6) + "," + Num(c.bic, 8))
                  << "\n";
      }
    } else {
      std::cout << "law comparison (" << FitStrategyName(opts.strategy)
                << " fit, ranked by AIC at rtol " << opts.comparison_rel_tolerance
                << ", best law refitted at rtol " << opts.rel_tolerance
                << "; e(v) at the lowest, middle and highest measured speed)\n"
                << LawComparisonTable(rows, speeds) << "\nbest: " << best.BriefReport() << "\n";
    }
    if (!a.output.empty() && best.outcome == FitOutcome::kConverged) {
      WriteParamFile(a.output, ParamFileJson(best, prov, options_json),
                     {.force = a.force, .inputs = a.files});
    }
    return;
  }

  const Calibration c = Calibrate(inputs, scene, opts);
  write_report(&c, nullptr);
  const nlohmann::json doc = ParamFileJson(c, prov, options_json);
  if (a.json) {
    std::cout << doc.dump(2) << "\n";
  } else if (a.csv) {
    std::cout << CsvHeader(CreateLaw(scene.law, scene)->Parameters()) << "\n"
              << CsvRow(a.files.size() == 1 ? a.files[0] : "joint",
                        CreateLaw(scene.law, scene)->Parameters(), &c, nullptr)
              << "\n";
  } else {
    std::cout << c.FullReport();
  }
  std::cout << std::flush;
  if (c.outcome != FitOutcome::kConverged) {
    throw Error(ErrorCode::kFitFailed, c.message + "; no parameter file written");
  }
  if (!a.output.empty()) {
    WriteParamFile(a.output, doc, {.force = a.force, .inputs = a.files});
    if (!a.json && !a.csv) std::cout << "wrote " << a.output << "\n";
  }
}

}  // namespace

void RegisterCalibrate(CLI::App& app) {
  auto args = std::make_shared<CalibrateArgs>();
  CLI::App* sub = app.add_subcommand(
      "calibrate", "fit a contact law's damping to recordings and write the parameter file");
  sub->add_option("files", args->files, "recordings (several: one joint fit, or --batch)")
      ->required();
  AddSceneFlags(sub, &args->scene, true);
  sub->add_option("--strategy", args->strategy,
                  "trajectory (fit simulated impact times) or restitution (fit e(v) points)");
  // One value per occurrence, so `--free k drop.wav` does not swallow the recording.
  sub->add_option("--free", args->free, "also fit this held parameter, e.g. k (repeatable)")
      ->allow_extra_args(false);
  sub->add_option("--fix", args->fix, "hold this damping parameter at its scene value")
      ->allow_extra_args(false);
  sub->add_option("--derivatives", args->derivatives, "auto (analytic where possible) or numeric");
  sub->add_option("--rtol", args->rtol, "simulator relative tolerance inside the fit");
  sub->add_option("--loss", args->loss, "robust loss: huber, cauchy or none");
  sub->add_option("--loss-scale", args->loss_scale, "robust loss scale, in sigmas");
  sub->add_option("--max-iterations", args->max_iterations, "solver iteration limit");
  sub->add_flag(
      "--use-drop", args->use_drop,
      "hold the first impact speed at the scene's drop height/speed instead of fitting it");
  sub->add_option("--channel", args->channel, "channel: 0, 1, ..., mix or auto");
  sub->add_option("-o,--output", args->output, "write the parameter file (JSON) here");
  sub->add_flag("--force", args->force, "replace an existing output file");
  sub->add_flag("--json", args->json, "print the parameter-file object to stdout");
  sub->add_flag("--csv", args->csv, "print CSV");
  sub->add_option("--jobs", args->jobs, "worker threads (detection; --batch fits)");
  sub->add_flag("--batch", args->batch, "fit each file separately, one summary line per file");
  sub->add_option("--report", args->report.html, "also write the HTML report of this fit");
  sub->add_option("--plot", args->report.plot, "also write its figures: FILE.svg or FILE.png");
  sub->add_flag("--quiet", args->quiet, "no progress line on stderr (shown only on a terminal)");
  sub->callback([args]() { Run(*args); });
}

}  // namespace bouncecal::cli
