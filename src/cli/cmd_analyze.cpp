// `bouncecal analyze FILE`: recording -> impacts -> per-bounce speeds, restitution, energy loss.
//
//   bouncecal analyze drop.wav --height 0.2                 # table on stdout
//   bouncecal analyze drop.wav --scene pingpong.toml --json # JSON contract below
//   bouncecal analyze drop.wav --drag quadratic --csv       # one row per bounce
//
// = ReadAudio + DetectImpacts (detect.hpp) + AnalyzeBounces (kinematics.hpp) of the main
// (longest) sequence. The first impact's restitution needs the drop: it is used when the scene
// file has [drop] or --height/--impact-speed is given (the built-in 0.2 m is never assumed).
// Every other value the result depends on and the user did not give is listed as assumed.
// e_sigma includes the ball's scatter from bounce to bounce (bounce_screen.hpp);
// e_timing_sigma is the timing part alone.
//
// --json: schema bouncecal.analysis/1 (docs/schema.md; built by AnalysisJson, io/schema.hpp);
//   several recordings or sequences: an array of them (a failed recording: bouncecal.error/1).
//   Unknown values are null, never "nan"; contact_s is null when the correction is off.
// --csv: header + one row per bounce (sequence, index, ...; a leading file column for several
//   recordings), shortest round-trip numbers, unknown values empty.
// Errors: one line on stderr, exit code from error.hpp, nothing on stdout.
#include <cmath>
#include <cstdio>
#include <iostream>
#include <optional>
#include <sstream>
#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/format.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/fit/scene_checks.hpp"
#include "commands.hpp"
#include "detect_flags.hpp"
#include "output.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {
namespace {

struct AnalyzeFlags {
  std::vector<std::string> files;
  DetectFlags detect;
  SceneFlags scene;
  std::optional<double> contact_time_s;
  bool json = false;
  bool csv = false;
};

// printf's "%*.*f", or "-" right-aligned for a value that is not finite.
std::string FixedOrDash(double v, int decimals, int width = 0) {
  if (!std::isfinite(v)) return std::string(static_cast<size_t>(std::max(width - 1, 0)), ' ') + "-";
  std::string out;
  AppendFixed(&out, v, decimals, width);
  return out;
}

struct Summary {
  int n_with_e = 0;
  double e_min = NAN, e_max = NAN;
};

Summary Summarize(const Analysis& a) {
  Summary s;
  for (const Bounce& b : a.bounces) {
    if (!std::isfinite(b.e)) continue;
    ++s.n_with_e;
    s.e_min = std::isfinite(s.e_min) ? std::min(s.e_min, b.e) : b.e;
    s.e_max = std::isfinite(s.e_max) ? std::max(s.e_max, b.e) : b.e;
  }
  return s;
}

std::string EffectsLine(const GivenScene& gs, const Analysis& a) {
  const Scene& scene = gs.scene;
  std::ostringstream o;
  o << "scene: drag " << DragModelName(scene.effects.drag);
  if (scene.effects.drag != DragModel::kNone) {
    o << " (terminal speed " << FixedOrDash(a.terminal_speed_m_s, 2) << " m/s)";
  }
  o << ", buoyancy " << (scene.effects.buoyancy ? "on" : "off") << ", contact duration "
    << (scene.effects.contact_duration ? "on" : "off") << "; g_eff "
    << FixedOrDash(a.effective_gravity_m_s2, 5) << " m/s^2; ball " << scene.ball.material << " "
    << FixedOrDash(scene.ball.diameter_m * 1000, 2) << " mm";
  if (!gs.drop_given) {
    o << "; drop unknown (first e not computed: give --height or --impact-speed)";
  } else if (scene.drop.height_m) {
    o << "; drop height " << FixedOrDash(*scene.drop.height_m, 4) << " m";
    if (a.height_sigma_m > 0.0) o << " +- " << FixedOrDash(a.height_sigma_m, 4) << " m";
  } else if (scene.drop.impact_speed_m_s) {
    o << "; first impact speed " << FixedOrDash(*scene.drop.impact_speed_m_s, 4) << " m/s";
  }
  return o.str();
}

// One chosen sequence of one recording; JSON goes to *json (when --json), text to stdout.
void RunOne(const AnalyzeFlags& flags, const GivenScene& gs, const AnalysisOptions& aopt,
            const std::string& file, const LoadedRecording& loaded, int chosen, bool csv_header,
            bool with_file, nlohmann::json* json_out) {
  const DetectionResult& det = loaded.result;
  const AudioInfo& info = det.audio;
  const Scene& scene = gs.scene;
  const Sequence& seq = det.sequences.at(static_cast<std::size_t>(chosen));
  Analysis an;
  try {
    an = AnalyzeBounces(seq, scene, aopt);
  } catch (const Error& e) {
    if (e.code() == ErrorCode::kNoBounces) throw Error(e.code(), file + ": " + e.what());
    throw;
  }
  std::vector<Warning> warnings = SceneUnitWarnings(scene, gs.drop_given);
  for (const Warning& w : det.warnings) warnings.push_back(w);
  for (const Warning& w : an.warnings) warnings.push_back(w);
  const std::vector<Assumed> assumed = AssumedValues(gs, false);
  const Summary sum = Summarize(an);

  if (flags.json) {
    json_out->push_back(AnalysisJson(file, det, chosen, scene, an,
                                     {.drop_known = gs.drop_given,
                                      .from_impacts_file = !loaded.impacts_file.empty(),
                                      .assumed = AssumedJson(assumed),
                                      .warnings = warnings}));
    return;
  }

  PrintWarnings(warnings);
  std::ostringstream o;
  if (flags.csv) {
    // contact_s is empty (not applicable) when the contact-duration correction is off.
    const bool contact = scene.effects.contact_duration;
    if (csv_header) {
      o << (with_file ? "file," : "")
        << "sequence,index,time_s,time_sigma_s,interval_s,v_in_m_s,v_in_sigma_m_s,v_out_m_s,"
           "v_out_sigma_m_s,e,e_sigma,e_timing_sigma,eta,eta_sigma,contact_s,irregular\n";
    }
    for (const Bounce& b : an.bounces) {
      if (with_file) o << CsvField(file) << ",";
      o << chosen << "," << b.index << "," << CsvNumber(b.time_s) << ","
        << CsvNumber(b.time_sigma_s) << "," << CsvNumber(b.interval_s) << ","
        << CsvNumber(b.v_in_m_s) << "," << CsvNumber(b.v_in_sigma_m_s) << ","
        << CsvNumber(b.v_out_m_s) << "," << CsvNumber(b.v_out_sigma_m_s) << "," << CsvNumber(b.e)
        << "," << CsvNumber(b.e_total_sigma) << "," << CsvNumber(b.e_sigma) << ","
        << CsvNumber(b.eta) << "," << CsvNumber(b.eta_sigma) << ","
        << (contact && b.contact_s > 0.0 ? CsvNumber(b.contact_s) : "") << ","
        << (b.irregular ? 1 : 0) << "\n";
    }
    std::cout << o.str();
    return;
  }

  o << file << (loaded.chosen.size() > 1 ? " sequence " + std::to_string(chosen) : std::string())
    << ": " << FixedOrDash(info.sample_rate_hz, 0) << " Hz, " << info.channels << " channel(s), "
    << (det.channel >= 0 ? "channel " + std::to_string(det.channel) : std::string("mix"))
    << " used; " << seq.impacts.size() << " impacts in the sequence (of " << det.sequences.size()
    << " sequence(s)), end: " << seq.end_reason << "\n";
  o << EffectsLine(gs, an) << "\n" << AssumedText(assumed) << "\n";
  // "value +- sigma" pairs, "-" where unknown.
  auto pm = [](double v, double sigma, int decimals, int sigma_decimals) {
    if (!std::isfinite(v)) return std::string("-");
    return FixedOrDash(v, decimals) + " +- " + FixedOrDash(sigma, sigma_decimals);
  };
  const bool show_contact = scene.effects.contact_duration;
  char head[256];
  std::snprintf(head, sizeof head, "%4s %11s %8s %11s  %-21s %-21s %-20s %-20s%s\n", "k", "time_s",
                "sigma_us", "interval_s", "v_in_m_s", "v_out_m_s", "e", "eta",
                show_contact ? "  contact_us" : "");
  auto rstrip = [](std::string t) {
    while (t.size() > 1 && t[t.size() - 2] == ' ') t.erase(t.size() - 2, 1);
    return t;
  };
  o << rstrip(head);
  for (const Bounce& b : an.bounces) {
    char line[512];
    std::snprintf(line, sizeof line, "%4d %11.6f %8s %11s  %-21s %-21s %-20s %-20s%s%s\n", b.index,
                  b.time_s, FixedOrDash(b.time_sigma_s * 1e6, 2).c_str(),
                  FixedOrDash(b.interval_s, 6).c_str(),
                  pm(b.v_in_m_s, b.v_in_sigma_m_s, 5, 5).c_str(),
                  pm(b.v_out_m_s, b.v_out_sigma_m_s, 5, 5).c_str(),
                  pm(b.e, b.e_total_sigma, 5, 6).c_str(), pm(b.eta, b.eta_sigma, 5, 5).c_str(),
                  show_contact ? ("  " + FixedOrDash(b.contact_s * 1e6, 1, 10)).c_str() : "",
                  b.irregular ? "  irregular" : "");
    o << rstrip(line);
  }
  o << "\nsummary: " << an.bounces.size() << " impacts, " << sum.n_with_e << " with e";
  if (sum.n_with_e > 0) {
    o << "; e from " << FixedOrDash(sum.e_min, 4) << " to " << FixedOrDash(sum.e_max, 4);
  }
  if (an.first_e) {
    o << "; first impact e = " << FixedOrDash(*an.first_e, 5) << " +- "
      << FixedOrDash(*an.first_e_sigma, 5);
  }
  o << "\n";
  if (an.scatter_e) {
    auto g2 = [](double v) { return FormatGeneral(v, 2); };
    o << "scatter of e from bounce to bounce: ";
    if (*an.scatter_e > 0.0) {
      o << g2(*an.scatter_e) << " +- " << g2(*an.scatter_e_sigma);
    } else {
      o << "0 (< " << g2(*an.scatter_e_sigma) << ", 68 % upper limit)";
    }
    o << " (e sigmas above include it; timing alone: e_timing_sigma in --json)\n";
  }
  if (an.mean_eta_first3) {
    o << "mean eta of the first three (impacts";
    for (int k : an.mean_eta_indices) o << " " << k;
    o << ") = " << FixedOrDash(*an.mean_eta_first3, 5) << " +- "
      << FixedOrDash(*an.mean_eta_first3_sigma, 5);
    // The seed paper's number is for its own experiment only: a steel ball on copper that the
    // user stated (the built-in defaults are the seed's materials; they prove nothing).
    if (gs.Given("ball.material") && gs.Given("surface.material") &&
        scene.ball.material == "steel" && scene.surface.material == "copper") {
      o << "  (seed 002: 0.58 for a steel ball on copper)";
    }
    o << "\n";
  }
  std::cout << o.str();
}

void Run(const AnalyzeFlags& flags) {
  // The scene first: it is cheap and its errors should not wait for the detector.
  GivenScene gs = ResolveGivenScene(flags.scene);
  if (flags.contact_time_s) gs.scene.effects.contact_duration = true;  // a given duration is used
  AnalysisOptions aopt;
  aopt.use_drop = gs.drop_given;
  // Drag off by the user's choice, or no ball to compute it for: no drag check.
  aopt.check_drag = !gs.Given("effects.drag") && gs.ball_given;
  if (flags.contact_time_s) aopt.contact_time_s = *flags.contact_time_s;
  std::string why;
  if (!aopt.IsValid(&why)) throw Error(ErrorCode::kBadParameter, "--contact-time: " + why);
  MakeDetectOptions(flags.detect);  // flag errors before any work
  const auto inputs = PairInputs(flags.files, flags.detect);
  const bool several = inputs.size() > 1;
  nlohmann::json all = nlohmann::json::array();
  bool any_failed = false;
  bool csv_header_done = false;
  for (std::size_t n = 0; n < inputs.size(); ++n) {
    const auto& [rec, imp] = inputs[n];
    const std::string name = rec.empty() ? imp : rec;
    try {
      const LoadedRecording loaded = LoadRecording(rec, nullptr, imp, flags.detect);
      for (int s : loaded.chosen) {
        if (!flags.json && !flags.csv && (n > 0 || s != loaded.chosen.front())) std::cout << "\n";
        RunOne(flags, gs, aopt, name, loaded, s, !csv_header_done, several, &all);
        csv_header_done = true;
      }
    } catch (const Error& e) {
      if (!several) throw;
      any_failed = true;
      std::fprintf(stderr, "bouncecal: %s\n", e.what());
      if (flags.json) all.push_back(FailedInputJson(name, e.code(), e.what()));
    }
  }
  // One recording and one sequence: the object itself (the shape of one analysis).
  if (flags.json) std::cout << DumpJson(all.size() == 1 && !several ? all[0] : all, 2) << "\n";
  if (any_failed)
    throw Error(ErrorCode::kSomeFailed, "some recordings failed (see the messages above)");
}

}  // namespace

void RegisterAnalyze(CLI::App& app) {
  auto flags = std::make_shared<AnalyzeFlags>();
  CLI::App* sub = app.add_subcommand(
      "analyze", "impacts -> per-bounce speeds, restitution e and energy loss eta (with sigmas)");
  sub->add_option(
      "FILE", flags->files,
      "recordings (any format libsndfile or FFmpeg reads; - reads standard input; or none "
      "with --impacts)");
  AddDetectFlags(sub, &flags->detect);
  AddSceneFlags(sub, &flags->scene, /*with_law=*/false);
  sub->add_option(
      "--contact-time", flags->contact_time_s,
      "contact duration (s) used with --contact-duration instead of the Hertz estimate");
  auto* json = sub->add_flag("--json", flags->json, "JSON on stdout");
  auto* csv = sub->add_flag("--csv", flags->csv, "CSV on stdout");
  json->excludes(csv);
  sub->callback([flags]() { Run(*flags); });
}

}  // namespace bouncecal::cli
