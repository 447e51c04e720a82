// bouncecal/report/html_report.hpp — the self-contained HTML report.
//
// One HTML file that opens offline in any browser: the report object (report_data.hpp) is
// embedded as JSON, the page script and the charting libraries (Chart.js with its error-bar,
// zoom and annotation plugins, from npm, pinned in package-lock.json) are inlined at build time.
// Nothing is fetched when the page is opened; the page holds no network URL.
//
//   nlohmann::json data = ReportDataJson(input);
//   WriteHtmlReport("report.html", data, {.force = false, .inputs = paths});
//
// The page marks what it drew, for tests and scripts: <body data-report-state="drawn"
// data-charts="N">, and every chart canvas data-drawn="1", data-impact-marks, data-rejected-marks
// and data-rect (its position in the page, CSS pixels).
#pragma once

#include <string>

#include <nlohmann/json.hpp>

#include "bouncecal/core/atomic_file.hpp"

namespace bouncecal {

// The page for a report object. The JSON is embedded inside a <script> element with every '<'
// escaped, so no value (a file name, a message) can end the element.
std::string RenderHtmlReport(const nlohmann::json& report_data);

// RenderHtmlReport written atomically (atomic_file.hpp): refuses an existing file without
// options.force, an input, a missing directory. Throws Error(kOutput) naming the path.
void WriteHtmlReport(const std::string& path, const nlohmann::json& report_data,
                     const WriteOptions& options);

// The charting libraries inlined in every report, with versions ("chart.js 4.5.1, ...").
std::string ReportLibraryVersions();

}  // namespace bouncecal
