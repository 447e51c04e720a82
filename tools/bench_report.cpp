// Benchmark: HTML report generation for a 60 s recording (issue 13: <= 1 s and <= 5 MB).
//
// Renders 60 s recordings with `synth` (48 kHz, steel on copper: one drop followed by 54 s of
// noise, and six drops 10 s apart), then times each stage of `bouncecal report` in this
// process: reading + detection (LoadReportRecording), the fit (Calibrate), and the report itself
// (ReportDataJson: waveform decimation, energy-ledger simulation; RenderHtmlReport; the atomic
// write). Prints Markdown tables; times are wall-clock medians of 3 runs on this machine.
//
//   build/bench_report
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/io/provenance.hpp"
#include "bouncecal/report/html_report.hpp"
#include "bouncecal/report/report_data.hpp"
#include "bouncecal/synth/synth.hpp"

namespace {

using namespace bouncecal;

double MedianSeconds(const std::function<void()>& f, int runs = 3) {
  std::vector<double> t;
  for (int i = 0; i < runs; ++i) {
    const auto a = std::chrono::steady_clock::now();
    f();
    t.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - a).count());
  }
  std::sort(t.begin(), t.end());
  return t[t.size() / 2];
}

struct Case {
  std::string name;
  int drops = 1;
};

void Run(const Case& c, const std::filesystem::path& dir) {
  SynthSpec spec = SynthPreset("steel-copper");
  spec.drops.clear();
  for (int d = 0; d < c.drops; ++d) spec.drops.push_back({1.0 + 10.0 * d, std::nullopt});
  spec.render.duration_s = 60.0;
  const SynthResult synth = Synthesize(spec);
  const std::string wav = (dir / ("bench_" + std::to_string(c.drops) + ".wav")).string();
  WriteAudio(wav, synth.recording.channels, synth.recording.sample_rate_hz);

  AnalysisOptions analysis;
  ReportRecording rec;
  const double t_detect =
      MedianSeconds([&] { rec = LoadReportRecording(wav, DetectOptions{}, spec.scene, analysis); });
  Calibration fit;
  const double t_fit = MedianSeconds(
      [&] {
        fit = Calibrate({{wav, rec.detection->main()}}, spec.scene, CalibrationOptions{});
      },
      1);
  const Provenance prov = MakeProvenance({wav});
  const std::string html = (dir / ("bench_" + std::to_string(c.drops) + ".html")).string();
  nlohmann::json data;
  std::string page;
  ReportInput in;
  in.recordings.push_back(rec);
  in.calibration = &fit;
  in.provenance = prov;
  const double t_data = MedianSeconds([&] { data = ReportDataJson(in); });
  const double t_html = MedianSeconds([&] { page = RenderHtmlReport(data); });
  const double t_write =
      MedianSeconds([&] { WriteHtmlReport(html, data, {.force = true, .inputs = {}}); });
  const double report_s = t_data + t_write;  // the write renders the page again
  size_t impacts = 0;
  for (const Sequence& q : rec.detection->sequences) impacts += q.impacts.size();
  std::printf("| %s | %.1f | %zu | %.3f | %.3f | %.3f | %.3f | %.3f | **%.3f** | **%.2f** | %s |\n",
              c.name.c_str(), rec.audio.duration_s(), impacts, t_detect, t_fit, t_data, t_html,
              t_write, report_s, static_cast<double>(page.size()) / (1024.0 * 1024.0),
              report_s <= 1.0 && page.size() <= 5u * 1024 * 1024 ? "yes" : "NO");
}

}  // namespace

int main() {
  const std::filesystem::path dir =
      std::filesystem::temp_directory_path() / ("bc_bench_report_" + std::to_string(::getpid()));
  std::filesystem::create_directories(dir);
  std::printf(
      "Report generation for 60 s recordings (48 kHz; wall-clock medians of 3 runs, "
      "the fit timed once)\n\n");
  std::printf(
      "| recording | duration (s) | impacts | read + detect (s) | fit (s) | report data "
      "(s) | HTML page (s) | page + atomic write (s) | report total (s) | size (MB) | "
      "<= 1 s and <= 5 MB |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (const Case& c : {Case{"1 drop + 54 s of noise", 1}, Case{"6 drops, 10 s apart", 6}})
    Run(c, dir);
  std::printf(
      "\nreport total = report data (waveform decimation, energy-ledger simulation, the "
      "fit in the parameter file's schema) + page rendering and atomic write; the whole "
      "`bouncecal report` adds read + detect and the fit.\n");
  std::filesystem::remove_all(dir);
  return 0;
}
