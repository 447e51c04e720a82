// The HTML report page (see html_report.hpp).
#include "bouncecal/report/html_report.hpp"

#include <string_view>

#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/provenance.hpp"
#include "report/report_assets.hpp"

namespace bouncecal {
namespace {

std::string HtmlEscape(const std::string& s) {
  std::string out;
  out.reserve(s.size());
  for (char c : s) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

// JSON text safe inside <script>: '<' only occurs inside JSON strings, where \u003c means the
// same character, so "</script>" in a value cannot close the element.
std::string ScriptSafeJson(const nlohmann::json& j) {
  const std::string text = DumpJson(j);
  std::string out;
  out.reserve(text.size() + 64);
  for (char c : text) {
    if (c == '<')
      out += "\\u003c";
    else
      out += c;
  }
  return out;
}

std::string Title(const nlohmann::json& data) {
  std::string files;
  if (data.contains("recordings")) {
    for (const auto& r : data["recordings"]) {
      if (!files.empty()) files += ", ";
      files += r.value("path", "");
    }
  }
  return "bouncecal report: " + files;
}

// Replaces the one occurrence of `key` in *page by `value` (the template has each once).
void Fill(std::string* page, std::string_view key, std::string_view value) {
  const size_t at = page->find(key);
  if (at != std::string::npos) page->replace(at, key.size(), value);
}

}  // namespace

std::string ReportLibraryVersions() { return std::string(report_assets::ChartLibraryVersions()); }

std::string RenderHtmlReport(const nlohmann::json& report_data) {
  std::string page(report_assets::PageTemplate());
  // Small values first: the large ones (data, code) are inserted last so that no later search
  // runs through them and no placeholder text inside them is ever replaced.
  Fill(&page, "@BOUNCECAL_VERSION@", BouncecalVersion());
  Fill(&page, "@BOUNCECAL_TITLE@", HtmlEscape(Title(report_data)));
  Fill(&page, "@BOUNCECAL_LIBRARIES@", HtmlEscape(ReportLibraryVersions()));
  Fill(&page, "@BOUNCECAL_CSS@", report_assets::PageCss());
  // The template holds these three in this order.
  constexpr std::string_view kData = "@BOUNCECAL_DATA@", kCode = "@BOUNCECAL_LIBRARY_CODE@",
                             kScript = "@BOUNCECAL_PAGE_SCRIPT@";
  const size_t data_at = page.find(kData), code_at = page.find(kCode),
               script_at = page.find(kScript);
  const std::string data = ScriptSafeJson(report_data);
  std::string out;
  out.reserve(page.size() + data.size() + report_assets::ChartLibraries().size() +
              report_assets::PageScript().size());
  out.append(page, 0, data_at);
  out += data;
  out.append(page, data_at + kData.size(), code_at - data_at - kData.size());
  out += report_assets::ChartLibraries();
  out.append(page, code_at + kCode.size(), script_at - code_at - kCode.size());
  out += report_assets::PageScript();
  out.append(page, script_at + kScript.size(), std::string::npos);
  return out;
}

void WriteHtmlReport(const std::string& path, const nlohmann::json& report_data,
                     const WriteOptions& options) {
  WriteFileAtomically(path, RenderHtmlReport(report_data), options);
}

}  // namespace bouncecal
