// read_audio, detect, analyze, calibrate: the bindings that read recordings. Each follows its
// command's steps (src/cli/cmd_*.cpp) and returns the library's schema object (io/schema.hpp),
// so a result equals `json.loads` of the command's --json output.
#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <optional>
#include <sstream>
#include <string>
#include <thread>

#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include "bindings.hpp"
#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/fit/scene_checks.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"

namespace bouncecal::python {
namespace {

// The waveform and what the decoder says about it: {"file", "sample_rate_hz", "channels",
// "frames", "duration_s", "format", "codec", "decoder", "lossy", "samples": float32 array
// [channel, frame]}.
py::object ReadAudioBinding(const std::string& path) {
  Audio audio;
  {
    py::gil_scoped_release release;
    audio = ReadAudio(path);
  }
  const auto n_channels = static_cast<py::ssize_t>(audio.channels.size());
  const auto n_frames = static_cast<py::ssize_t>(audio.info.frames);
  py::array_t<float> samples({n_channels, n_frames});
  auto out = samples.mutable_unchecked<2>();
  for (py::ssize_t c = 0; c < n_channels; ++c) {
    const std::vector<float>& ch = audio.channels[static_cast<std::size_t>(c)];
    for (py::ssize_t f = 0; f < n_frames; ++f)
      out(c, f) = f < static_cast<py::ssize_t>(ch.size()) ? ch[static_cast<std::size_t>(f)] : 0.f;
  }
  py::dict d;
  d["file"] = path;
  d["sample_rate_hz"] = audio.info.sample_rate_hz;
  d["channels"] = audio.info.channels;
  d["frames"] = audio.info.frames;
  d["duration_s"] = audio.info.duration_s();
  d["format"] = audio.info.format;
  d["codec"] = audio.info.subtype;
  d["decoder"] = audio.info.decoder;
  d["lossy"] = audio.info.lossy;
  d["samples"] = samples;
  return d;
}

// Several inputs: one result (or failure entry) each in order; one input: its result, and its
// error raised. `one` fills the results of one input (or throws).
template <class One>
nlohmann::json EachInput(const std::vector<std::pair<std::string, std::string>>& inputs,
                         bool unwrap_single, One one) {
  const bool several = inputs.size() > 1;
  nlohmann::json all = nlohmann::json::array();
  bool any_failed = false;
  for (const auto& [rec, imp] : inputs) {
    const std::string name = rec.empty() ? imp : rec;
    try {
      one(rec, imp, name, &all);
    } catch (const Error& e) {
      if (!several) throw;
      any_failed = true;
      all.push_back(FailedInputJson(name, e.code(), e.what()));
    }
  }
  if (any_failed) {
    throw ErrorWithResult(ErrorCode::kSomeFailed,
                          "some recordings failed (see the entries with \"error\")", all);
  }
  return unwrap_single && all.size() == 1 && !several ? all[0] : all;
}

// `bouncecal detect FILE... --json`.
py::object DetectBinding(const std::vector<std::string>& files, const py::dict& options) {
  Options o(options);
  const DropInputOptions flags = TakeDropInputOptions(o);
  const double hop_ms = o.TakeDouble("hop_ms").value_or(0.0);
  const bool no_refine = o.TakeFlag("no_refine");
  o.Finish("detect");
  if (!(hop_ms >= 0.0) || hop_ms > 50.0) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", hop_ms);
    throw Error(ErrorCode::kUsage,
                std::string("hop_ms ") + buf + ": must be in [0, 50] (0 = auto)");
  }
  py::gil_scoped_release release;
  const auto inputs = PairInputs(files, flags);
  const nlohmann::json result = EachInput(
      inputs, /*unwrap_single=*/true,
      [&](const std::string& rec, const std::string& imp, const std::string& name,
          nlohmann::json* out) {
        // The recording is read block by block (memory independent of its length), as the CLI.
        LoadedRecording l;
        if (imp.empty()) {
          DetectOptions d = flags.detect;
          d.hop_s = hop_ms * 1e-3;
          d.refine = !no_refine;
          l.name = name;
          l.result = DetectImpactsInFile(rec, d);
          l.chosen = ChooseSequences(l.result.sequences, flags.sequence, name);
        } else {
          l = LoadRecording(rec, nullptr, imp, flags);
        }
        out->push_back(DetectionJson(
            name, l.result, {.chosen = l.chosen, .from_impacts_file = !l.impacts_file.empty()}));
      });
  py::gil_scoped_acquire acquire;
  return ToPython(result);
}

// `bouncecal analyze FILE... --json`.
py::object AnalyzeBinding(const std::vector<std::string>& files, const py::dict& options) {
  Options o(options);
  const DropInputOptions detect = TakeDropInputOptions(o);
  const SceneOverrides scene_flags = TakeSceneOverrides(o, /*with_law=*/false);
  const std::optional<double> contact_time_s = o.TakeDouble("contact_time");
  o.Finish("analyze");
  // The scene first: it is cheap and its errors should not wait for the detector.
  GivenScene gs = ResolveGivenScene(scene_flags);
  if (contact_time_s) gs.scene.effects.contact_duration = true;  // a given duration is used
  AnalysisOptions aopt;
  aopt.use_drop = gs.drop_given;
  // Drag off by the user's choice, or no ball to compute it for: no drag check.
  aopt.check_drag = !gs.Given("effects.drag") && gs.ball_given;
  if (contact_time_s) aopt.contact_time_s = *contact_time_s;
  std::string why;
  if (!aopt.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "contact_time: " + why);
  py::gil_scoped_release release;
  const auto inputs = PairInputs(files, detect);
  const nlohmann::json assumed = AssumedJson(AssumedValues(gs, false));
  const nlohmann::json result = EachInput(
      inputs, /*unwrap_single=*/true,
      [&](const std::string& rec, const std::string& imp, const std::string& name,
          nlohmann::json* out) {
        const LoadedRecording loaded = LoadRecording(rec, nullptr, imp, detect);
        for (int s : loaded.chosen) {
          const DetectionResult& det = loaded.result;
          Analysis an;
          try {
            an = AnalyzeBounces(det.sequences.at(static_cast<std::size_t>(s)), gs.scene, aopt);
          } catch (const Error& e) {
            if (e.code() == ErrorCode::kNoBounces) throw Error(e.code(), name + ": " + e.what());
            throw;
          }
          std::vector<Warning> warnings = SceneUnitWarnings(gs.scene, gs.drop_given);
          warnings.insert(warnings.end(), det.warnings.begin(), det.warnings.end());
          warnings.insert(warnings.end(), an.warnings.begin(), an.warnings.end());
          out->push_back(AnalysisJson(name, det, s, gs.scene, an,
                                      {.drop_known = gs.drop_given,
                                       .from_impacts_file = !loaded.impacts_file.empty(),
                                       .assumed = assumed,
                                       .warnings = warnings}));
        }
      });
  py::gil_scoped_acquire acquire;
  return ToPython(result);
}

// The calibrate options that are not scene or detection options.
struct CalibrateRun {
  std::vector<std::string> files;
  DropInputOptions detect;
  GivenScene gs;
  CalibrationOptions options;
  bool compare_all = false;  // law = "all"
  bool batch = false;
  int jobs = 1;
  std::string output;
  bool force = false;
  // An array's provenance (its samples' checksum): files have MakeProvenance(files).
  std::optional<Provenance> provenance;
  Provenance Origin() const { return provenance ? *provenance : MakeProvenance(files); }
};

std::string Precision(double v, int digits) {
  if (!std::isfinite(v)) return "";
  std::ostringstream os;
  os.precision(digits);
  os << v;
  return os.str();
}

CalibrateRun TakeCalibrateRun(const std::vector<std::string>& files, Options& o) {
  CalibrateRun r;
  r.files = files;
  r.detect = TakeDropInputOptions(o);
  SceneOverrides sf = TakeSceneOverrides(o, /*with_law=*/true);
  r.compare_all = sf.law == "all";
  if (r.compare_all) sf.law.clear();
  CalibrationOptions& c = r.options;
  c.strategy = ParseFitStrategy(o.TakeString("strategy").value_or("restitution"));
  c.free_parameters = o.TakeStrings("free");
  c.fixed_parameters = o.TakeStrings("fix");
  c.derivatives = ParseDerivativeMode(o.TakeString("derivatives").value_or("auto"));
  c.rel_tolerance = o.TakeDouble("rtol").value_or(1e-9);
  c.loss = ParseRobustLoss(o.TakeString("loss").value_or("none"));
  c.loss_scale_sigma = o.TakeDouble("loss_scale").value_or(3.0);
  c.max_iterations = o.TakeInt("max_iterations").value_or(100);
  c.max_starts = o.TakeInt("starts").value_or(4);
  const bool ignore_drop = o.TakeFlag("ignore_drop");
  c.estimate_scatter = !o.TakeFlag("no_scatter");
  r.batch = o.TakeFlag("batch");
  r.jobs = o.TakeInt("jobs").value_or(1);
  r.output = o.TakeString("output").value_or("");
  r.force = o.TakeFlag("force");
  o.Finish("calibrate");
  if (r.jobs < 1 || r.jobs > 256) {
    throw Error(ErrorCode::kUsage, "jobs " + std::to_string(r.jobs) + ": expected 1..256");
  }
  if (r.compare_all && r.batch) {
    throw Error(ErrorCode::kUsage, "law=\"all\" cannot be combined with batch=True");
  }
  r.gs = ResolveGivenScene(sf);
  if (!r.gs.ball_given) {
    const bool diameter = r.gs.Given("ball.diameter_m");
    throw Error(ErrorCode::kBadScene,
                std::string("calibrate: the ball's ") + (diameter ? "mass" : "size and mass") +
                    " are not given (they enter the contact law, its default stiffness and the "
                    "drag): give scene=FILE with a [ball] table, or diameter=M with mass=KG "
                    "(or density=KG_M3, or material=NAME)");
  }
  c.use_drop = r.gs.drop_given && !ignore_drop;
  c.analysis.check_drag = !r.gs.Given("effects.drag");  // drag off by the user's choice
  std::string err;
  if (!c.IsValid(&err)) throw Error(ErrorCode::kUsage, err);
  return r;
}

std::vector<CalibrationInput> InputsOf(const std::pair<std::string, std::string>& input,
                                       const DropInputOptions& options) {
  std::vector<CalibrationInput> out;
  for (RecordingDrop& d : DropsOf(input.first, input.second, options))
    out.push_back({d.name, std::move(d.sequence)});
  return out;
}

// Runs fn(i) for i in [0, n) on up to `jobs` threads.
template <class Fn>
void Pool(std::size_t n, int jobs, Fn fn) {
  std::atomic<std::size_t> next{0};
  auto worker = [&]() {
    for (std::size_t i = next++; i < n; i = next++) fn(i);
  };
  const int threads = std::max(1, std::min<int>(jobs, static_cast<int>(n)));
  std::vector<std::thread> pool;
  for (int t = 1; t < threads; ++t) pool.emplace_back(worker);
  worker();
  for (auto& t : pool) t.join();
}

// `calibrate --batch --json`: one bouncecal.calibration_row/1 per file.
nlohmann::json CalibrateBatch(const CalibrateRun& r,
                              const std::vector<std::pair<std::string, std::string>>& inputs) {
  const std::size_t n = inputs.size();
  std::vector<std::optional<Calibration>> fits(n);
  std::vector<std::optional<Error>> errors(n);
  Pool(n, r.jobs, [&](std::size_t i) {
    try {
      fits[i] = Calibrate(InputsOf(inputs[i], r.detect), r.gs.scene, r.options);
    } catch (const Error& e) {
      errors[i] = e;
    } catch (const std::exception& e) {
      errors[i] = Error(ErrorCode::kInternal, inputs[i].first + ": " + e.what());
    }
  });
  nlohmann::json rows = nlohmann::json::array();
  std::size_t failed = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const std::string name = inputs[i].first.empty() ? inputs[i].second : inputs[i].first;
    rows.push_back(
        CalibrationRowJson(name, fits[i] ? &*fits[i] : nullptr, errors[i] ? &*errors[i] : nullptr));
    failed += errors[i] || fits[i]->outcome != FitOutcome::kConverged ? 1 : 0;
  }
  if (!r.output.empty()) {
    std::string lines;
    for (const nlohmann::json& row : rows) lines += DumpJson(row) + "\n";
    WriteFileAtomically(r.output, lines, {.force = r.force, .inputs = r.files});
  }
  if (failed > 0) {
    throw ErrorWithResult(
        ErrorCode::kSomeFailed,
        std::to_string(failed) + " of " + std::to_string(n) + " recordings failed", rows);
  }
  return rows;
}

// `calibrate --law all --json` (bouncecal.law_comparison/2).
nlohmann::json CalibrateAll(const CalibrateRun& r, const std::vector<CalibrationInput>& inputs) {
  const std::vector<LawComparisonRow> rows = CompareLaws(inputs, r.gs.scene, r.options, r.jobs);
  const Provenance prov = r.Origin();
  const nlohmann::json options_json = OptionsJson(r.options);
  nlohmann::json doc =
      LawComparisonJson(rows, prov, options_json, AssumedJson(AssumedValues(r.gs, true)));
  if (rows.empty() || !rows.front().adequate) {
    throw ErrorWithResult(
        ErrorCode::kFitFailed,
        "no contact law fits these recordings adequately" +
            (rows.empty() ? "" : ": " + rows.front().fit.law + ": " + rows.front().fit.reason),
        doc);
  }
  if (!r.output.empty()) {
    WriteParamFile(r.output, CalibrationJson(rows.front().fit, prov, options_json),
                   {.force = r.force, .inputs = r.files});
  }
  return doc;
}

// `calibrate --json` of one (joint) fit: the parameter file's object with "assumed".
nlohmann::json CalibrateOne(const CalibrateRun& r, const std::vector<CalibrationInput>& inputs) {
  const Scene& scene = r.gs.scene;
  Calibration c = Calibrate(inputs, scene, r.options);
  const std::vector<Warning> unit = SceneUnitWarnings(scene, r.options.use_drop);
  c.warnings.insert(c.warnings.begin(), unit.begin(), unit.end());
  std::vector<Assumed> assumed = AssumedValues(r.gs, true);
  for (const auto& p : c.parameters) {
    if (p.fixed && !r.gs.Given("law.parameters." + p.name)) {
      assumed.push_back({"law.parameters." + p.name, Precision(p.value, 7) + " " + p.unit,
                         "held at the law's default, not fitted"});
    }
  }
  nlohmann::json doc = CalibrationJson(c, r.Origin(), OptionsJson(r.options));
  doc["assumed"] = AssumedJson(assumed);
  // The parameter file records every outcome; the exception tells scripts.
  if (!r.output.empty()) WriteParamFile(r.output, doc, {.force = r.force, .inputs = r.files});
  if (c.outcome != FitOutcome::kConverged) {
    throw ErrorWithResult(
        FitOutcomeExitCode(c.outcome),
        std::string("calibrate: outcome ") + FitOutcomeName(c.outcome) + ": " + c.reason, doc);
  }
  return doc;
}

py::object CalibrateBinding(const std::vector<std::string>& files, const py::dict& options) {
  Options o(options);
  const CalibrateRun r = TakeCalibrateRun(files, o);
  if (!r.compare_all) CreateLaw(r.gs.scene.law, r.gs.scene);  // unknown law: before any work
  py::gil_scoped_release release;
  const auto pairs = PairInputs(files, r.detect);
  if (!r.output.empty()) CheckOutputPath(r.output, {.force = r.force, .inputs = files});
  nlohmann::json result;
  if (r.batch) {
    result = CalibrateBatch(r, pairs);
  } else {
    // Detection of every input (threads), the first input's error in input order.
    std::vector<std::vector<CalibrationInput>> per(pairs.size());
    std::vector<std::optional<Error>> errors(pairs.size());
    Pool(pairs.size(), r.jobs, [&](std::size_t i) {
      try {
        per[i] = InputsOf(pairs[i], r.detect);
      } catch (const Error& e) {
        errors[i] = e;
      }
    });
    for (const auto& e : errors)
      if (e) throw *e;
    std::vector<CalibrationInput> inputs;
    for (auto& p : per) inputs.insert(inputs.end(), p.begin(), p.end());
    result = r.compare_all ? CalibrateAll(r, inputs) : CalibrateOne(r, inputs);
  }
  py::gil_scoped_acquire acquire;
  return ToPython(result);
}

// `calibrate --json` on an array (one recording; batch does not apply).
py::object CalibrateArrayBinding(
    const py::array_t<float, py::array::c_style | py::array::forcecast>& samples, double rate_hz,
    const py::dict& options) {
  Options o(options);
  const std::string name = o.TakeString("name").value_or("array");
  CalibrateRun r = TakeCalibrateRun({}, o);
  if (r.batch) throw Error(ErrorCode::kUsage, "calibrate: batch=True needs files");
  if (!r.compare_all) CreateLaw(r.gs.scene.law, r.gs.scene);  // unknown law: before any work
  const Audio audio = AudioFromArray(samples, rate_hz, name);
  py::gil_scoped_release release;
  if (!r.output.empty()) CheckOutputPath(r.output, {.force = r.force, .inputs = {}});
  Provenance p;
  std::string bytes;
  for (const auto& c : audio.channels)
    bytes.append(reinterpret_cast<const char*>(c.data()), c.size() * sizeof(float));
  p.inputs.push_back({name, Sha256OfString(bytes)});
  p.bouncecal_version = BouncecalVersion();
  p.date_utc = NowIsoDateUtc();
  r.provenance = p;
  const LoadedRecording l = LoadRecording(name, &audio, "", r.detect);
  std::vector<CalibrationInput> inputs;
  for (int s : l.chosen) {
    const std::string drop = l.chosen.size() > 1 ? name + "#" + std::to_string(s) : name;
    inputs.push_back({drop, l.result.sequences.at(static_cast<std::size_t>(s))});
  }
  const nlohmann::json result = r.compare_all ? CalibrateAll(r, inputs) : CalibrateOne(r, inputs);
  py::gil_scoped_acquire acquire;
  return ToPython(result);
}

}  // namespace

void BindRecordings(py::module_& m) {
  m.def("calibrate_array", &CalibrateArrayBinding, py::arg("samples"), py::arg("rate"),
        py::arg("options"));
  m.def("read_audio", &ReadAudioBinding, py::arg("path"));
  m.def("detect", &DetectBinding, py::arg("files"), py::arg("options"));
  m.def("analyze", &AnalyzeBinding, py::arg("files"), py::arg("options"));
  m.def("calibrate", &CalibrateBinding, py::arg("files"), py::arg("options"));
}

}  // namespace bouncecal::python
