#include "report_output.hpp"

#include <filesystem>
#include <utility>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/report/figures.hpp"
#include "bouncecal/report/html_report.hpp"

namespace bouncecal::cli {

void CheckReportPaths(const ReportPaths& paths, const std::vector<std::string>& inputs) {
  if (!paths.plot.empty()) {
    const std::string ext = std::filesystem::path(paths.plot).extension().string();
    if (ext != ".svg" && ext != ".png") {
      throw Error(ErrorCode::kUsage, "--plot " + paths.plot +
                                         ": the figure's format comes from its extension, "
                                         "expected .svg or .png");
    }
  }
  if (!paths.html.empty() && paths.html == paths.plot) {
    throw Error(ErrorCode::kUsage, paths.html + ": the report and the figure need two paths");
  }
  for (const std::string* p : {&paths.html, &paths.plot}) {
    if (!p->empty()) CheckOutputPath(*p, {.force = paths.force, .inputs = inputs});
  }
}

std::string CommandLine(const std::string& command, const std::vector<std::string>& args) {
  std::string out = "bouncecal " + command;
  for (const std::string& a : args) out += " " + a;
  return out;
}

AnalysisOptions ReportAnalysisOptions(const GivenScene& gs) {
  AnalysisOptions o;
  o.use_drop = gs.drop_given;
  o.check_drag = !gs.Given("effects.drag") && gs.ball_given;
  return o;
}

std::vector<ReportRecording> LoadRecordings(const std::vector<std::string>& files,
                                            const DetectOptions& detect, const Scene& scene,
                                            const AnalysisOptions& analysis, Progress* progress) {
  std::vector<ReportRecording> out;
  for (size_t i = 0; i < files.size(); ++i) {
    if (progress != nullptr) {
      progress->Stage("[" + std::to_string(i + 1) + "/" + std::to_string(files.size()) +
                      "] reading and detecting " + files[i]);
    }
    out.push_back(LoadReportRecording(files[i], detect, scene, analysis));
  }
  return out;
}

void WriteReportOutputs(const ReportPaths& paths, std::vector<ReportRecording> recordings,
                        const ReportResults& results, Progress* progress) {
  if (progress != nullptr) progress->Stage("building the report (energy ledger, waveforms)");
  ReportInput in;
  in.recordings = std::move(recordings);
  in.calibration = results.calibration;
  in.law_comparison = results.law_comparison;
  in.fit_failure = results.fit_failure;
  in.provenance = results.provenance;
  in.options = results.options;
  in.command = results.command;
  const nlohmann::json data = ReportDataJson(in);
  std::vector<std::string> inputs;
  for (const ReportRecording& r : in.recordings) inputs.push_back(r.path);
  if (!paths.html.empty()) {
    if (progress != nullptr) progress->Stage("writing " + paths.html);
    WriteHtmlReport(paths.html, data, {.force = paths.force, .inputs = inputs});
  }
  if (!paths.plot.empty()) {
    if (progress != nullptr) progress->Stage("rendering " + paths.plot + " with gnuplot");
    WriteFigure(paths.plot, data, {.force = paths.force, .inputs = inputs});
  }
  if (progress != nullptr) progress->Done();
}

void WriteReports(const ReportPaths& paths, const std::vector<std::string>& files,
                  const DetectOptions& detect, const Scene& scene, const AnalysisOptions& analysis,
                  const ReportResults& results, Progress* progress) {
  if (!paths.any()) return;
  WriteReportOutputs(paths, LoadRecordings(files, detect, scene, analysis, progress), results,
                     progress);
}

}  // namespace bouncecal::cli
