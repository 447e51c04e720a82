// bouncecal/report/figures.hpp — static figures of the report's charts, for papers and lab
// reports: SVG or PNG, rendered by gnuplot (Debian's gnuplot-nox: a long-maintained renderer
// with vector SVG and cairo PNG output, no display needed).
//
//   WriteFigure("fit.svg", ReportDataJson(input), {.force = false, .inputs = paths});
//
// One figure with one panel per chart the report has data for: the waveform envelope with the
// detected impacts (triangles) and rejected candidates (crosses) of the first recording, the
// intervals per bounce, e against impact speed with error bars and the fitted e(v) with its
// sigma band (other laws dashed), the fit residuals per impact, and the simulated kinetic energy
// at each impact with the measured one. The format comes from the extension (.svg or .png).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/atomic_file.hpp"

namespace bouncecal {

// The gnuplot program for a report object, writing to `output_path` in `format` ("svg" or
// "png"); its data blocks are inline. Exposed for tests.
std::string FigureScript(const nlohmann::json& report_data, const std::string& format,
                         const std::string& output_path);

// Renders the figure atomically (atomic_file.hpp rules). Throws Error(kUsage) for an extension
// other than .svg/.png, Error(kOutput) for an unusable path, and Error(kInternal) when gnuplot
// is missing (naming the Debian package) or fails (with its message).
void WriteFigure(const std::string& path, const nlohmann::json& report_data,
                 const WriteOptions& options);

}  // namespace bouncecal
