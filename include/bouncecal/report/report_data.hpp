// bouncecal/report/report_data.hpp — the one adapter from the library's result structs to the
// report: DetectionResult + Analysis + Calibration(s) + law-comparison rows -> one JSON object
// (schema "bouncecal.report/2") that the HTML page draws and the static figures plot.
//
// Everything the report shows passes through ReportDataJson, so a new field in a result struct
// reaches the page by one edit here. The JSON follows the project's output conventions: keys in
// snake_case with a unit suffix, null for absent or unknown values, a "warnings" array on every
// recording, times in seconds from the start of the file.
//
//   ReportRecording r = LoadReportRecording("drop.wav", detect_options, scene, analysis_options);
//   ReportInput in;
//   in.recordings.push_back(std::move(r));
//   in.calibration = &fit;                       // optional
//   nlohmann::json data = ReportDataJson(in, ReportDataOptions{});
//   std::string html = RenderHtmlReport(data);   // html_report.hpp
//
// A recording in which the detector finds no bounce sequence (or that is silent) still gets a
// waveform: LoadReportRecording keeps the reason (the detector's message) instead of throwing,
// and the report says it. Unreadable files (missing, not audio, NaN) still throw.
//
// Common mistake: the waveform is decimated (a min/max envelope over the whole file plus full
// resolution around every candidate onset), so a long recording costs a few hundred kB, not its
// full sample count; ReportDataOptions says how much.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/fit/kinematics.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/scene.hpp"

namespace bouncecal {

inline constexpr const char* kReportSchema = "bouncecal.report/2";

struct ReportDataOptions {
  // Min/max envelope bins over the whole recording (each bin one min and one max value).
  int envelope_bins = 4000;
  // Full-resolution windows around every detected impact and rejected candidate.
  double window_before_s = 0.002;
  double window_after_s = 0.008;
  // Upper bound on the full-resolution samples kept per recording (windows beyond it are
  // dropped, latest first; the envelope still covers them).
  long max_window_samples = 400000;
  // Waveform samples are stored as integers in [-levels, levels] times a scale (peak / levels):
  // 32767 keeps 16-bit recordings exact and the JSON compact.
  int quantization_levels = 32767;
  bool IsValid(std::string* error) const;
};

// One recording as the report needs it. `detection` and `analysis` are empty when the detector
// or the kinematics could not produce them; `no_impacts_reason` then says why.
struct ReportRecording {
  std::string path;
  AudioInfo audio;
  int channel = -1;            // the channel shown (the detector's), -1 = mix
  std::vector<float> samples;  // that channel (or the mix)
  std::optional<DetectionResult> detection;
  std::vector<Impact> candidates;  // every onset found (also when no sequence was found)
  std::optional<Analysis> analysis;
  std::string no_impacts_reason;  // why there are no impacts / bounces ("" if there are)
};

// Reads and detects one recording for the report. Throws what ReadAudio throws (missing file,
// not audio, NaN samples) and Error(kBadParameter) for invalid options; a silent recording or
// one without a bounce sequence returns with no_impacts_reason set.
ReportRecording LoadReportRecording(const std::string& path, const DetectOptions& detect_options,
                                    const Scene& scene, const AnalysisOptions& analysis_options);

struct ReportInput {
  std::vector<ReportRecording> recordings;
  // The fit (the best law when several were compared); null when none was made.
  const Calibration* calibration = nullptr;
  // Every law of `--law all`, ranked by AIC (rows[0].fit is the same law as `calibration`).
  const std::vector<LawComparisonRow>* law_comparison = nullptr;
  // Why there is no fit (set when calibration is null but a fit was attempted).
  std::string fit_failure;
  std::optional<Provenance> provenance;
  nlohmann::json options = nlohmann::json::object();  // the options the results ran with
  std::string command;                                // the command line, for provenance
};

// The report object (schema kReportSchema). Simulates the fitted law at the fitted parameters
// for the energy ledger (the first recording's fitted first impact speed and time origin).
// Throws Error(kBadParameter) for invalid options.
nlohmann::json ReportDataJson(const ReportInput& input, const ReportDataOptions& options = {});

// Waveform decimation (exposed for tests): min/max envelope of `samples` in `bins` equal bins,
// plus full-resolution windows [t - before, t + after] around each time in `times_s` (merged
// where they overlap), at most max_window_samples samples in all.
nlohmann::json WaveformJson(const std::vector<float>& samples, double rate_hz,
                            const std::vector<double>& times_s, const ReportDataOptions& options);

}  // namespace bouncecal
