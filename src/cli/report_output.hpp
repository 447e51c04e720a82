// Report outputs shared by `report` and `calibrate --report/--plot`: the HTML report and the
// static figure of the same results (src/report). Flags -> library calls only.
#pragma once

#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/acoustic/detect.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/physics/scene.hpp"
#include "bouncecal/report/report_data.hpp"
#include "progress.hpp"
#include "scene_flags.hpp"

namespace bouncecal::cli {

struct ReportPaths {
  std::string html;  // --report / -o: the HTML report ("" = none)
  std::string plot;  // --plot: FILE.svg or FILE.png ("" = none)
  bool force = false;
  bool any() const { return !html.empty() || !plot.empty(); }
};

// Before any work: each path usable (not existing without --force, not an input, directory
// present) and the figure's extension known. Throws Error(kOutput / kUsage).
void CheckReportPaths(const ReportPaths& paths, const std::vector<std::string>& inputs);

// The command line as one string, for the provenance block.
std::string CommandLine(const std::string& command, const std::vector<std::string>& args);

// The analysis options of `analyze` for this scene: the first impact's e only when the user gave
// the drop; the drag check only when the user gave the ball and left the drag open.
AnalysisOptions ReportAnalysisOptions(const GivenScene& gs);

// What one report needs besides the recordings (read and detected again here: the fit keeps
// only the main sequences).
struct ReportResults {
  const Calibration* calibration = nullptr;
  const std::vector<LawComparisonRow>* law_comparison = nullptr;
  std::string fit_failure;
  Provenance provenance;
  nlohmann::json options = nlohmann::json::object();
  std::string command;
};

// Reads and detects every file for the report (a recording without impacts keeps its reason).
std::vector<ReportRecording> LoadRecordings(const std::vector<std::string>& files,
                                            const DetectOptions& detect, const Scene& scene,
                                            const AnalysisOptions& analysis, Progress* progress);

// Builds the report object and writes the requested outputs.
void WriteReportOutputs(const ReportPaths& paths, std::vector<ReportRecording> recordings,
                        const ReportResults& results, Progress* progress);

// LoadRecordings + WriteReportOutputs, for `calibrate --report` (its fit keeps only the main
// sequences, so the recordings are read and detected again).
void WriteReports(const ReportPaths& paths, const std::vector<std::string>& files,
                  const DetectOptions& detect, const Scene& scene, const AnalysisOptions& analysis,
                  const ReportResults& results, Progress* progress);

}  // namespace bouncecal::cli
