// The HTML report, the static figures and the progress line (issue 13 items 2, 3, 5):
// - the waveform decimation keeps every sample's extremes and full resolution near onsets;
// - the report object holds what the library computed (impacts, residuals, fit, energy);
// - the report of the bundled recording, rendered in headless Chromium with every network
//   request blocked, draws every chart (non-blank pixels in each chart's area of a screenshot)
//   with as many impact marks as `detect` finds, and holds no network URL;
// - a recording without impacts still gets its waveform and the reason;
// - bad output paths are refused (exit 11, message), figures have the impact marks;
// - progress appears on a terminal only, never with --quiet.
#include <png.h>
#include <sys/stat.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <map>
#include <numbers>
#include <random>
#include <regex>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "bouncecal/acoustic/audio.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/fit/calibrate.hpp"
#include "bouncecal/physics/scene.hpp"
#include "bouncecal/report/figures.hpp"
#include "bouncecal/report/html_report.hpp"
#include "bouncecal/report/report_data.hpp"
#include "test_util.hpp"

namespace bouncecal {
namespace {

using testing_util::RunCommand;
using testing_util::ScratchDir;
using testing_util::Slurp;

const std::string kSource = BOUNCECAL_SOURCE_DIR;
const std::string kFlac = kSource + "/data/default_steel_copper.flac";
const std::string kScene = kSource + "/data/default_steel_copper.toml";

// ---- waveform decimation ----

TEST(ReportWaveform, EnvelopeHoldsEachBinsExtremesAndWindowsAreExact) {
  // 10 s at 1 kHz of a ramp with one spike per second: bin extremes are known exactly.
  const double rate = 1000.0;
  std::vector<float> x(10000);
  for (size_t i = 0; i < x.size(); ++i) x[i] = static_cast<float>(i % 100) / 200.0f;
  for (int s = 0; s < 10; ++s) x[static_cast<size_t>(s * 1000 + 500)] = -0.75f;
  ReportDataOptions o;
  o.envelope_bins = 100;  // 100 samples per bin
  o.window_before_s = 0.002;
  o.window_after_s = 0.008;
  const nlohmann::json w = WaveformJson(x, rate, {0.5, 0.505, 3.5}, o);
  const double scale = w["scale"].get<double>();
  EXPECT_DOUBLE_EQ(w["peak"].get<double>(), 0.75);
  ASSERT_EQ(w["envelope"]["min"].size(), 100u);
  EXPECT_DOUBLE_EQ(w["envelope"]["bin_s"].get<double>(), 0.1);
  for (int b = 0; b < 100; ++b) {
    const double mn = w["envelope"]["min"][b].get<int>() * scale;
    const double mx = w["envelope"]["max"][b].get<int>() * scale;
    EXPECT_NEAR(mx, 99.0 / 200.0, scale / 2) << "bin " << b;
    EXPECT_NEAR(mn, b % 10 == 5 ? -0.75 : 0.0, scale / 2) << "bin " << b;
  }
  // 0.5 s and 0.505 s overlap: one window [0.498, 0.513), and one at [3.498, 3.508).
  ASSERT_EQ(w["windows"].size(), 2u);
  EXPECT_NEAR(w["windows"][0]["start_s"].get<double>(), 0.498, 1e-12);
  EXPECT_EQ(w["windows"][0]["samples"].size(), 15u);
  EXPECT_EQ(w["windows"][1]["samples"].size(), 10u);
  EXPECT_NEAR(w["windows"][0]["samples"][2].get<int>() * scale, -0.75, scale / 2);
  // The budget drops windows that do not fit.
  o.max_window_samples = 12;
  const nlohmann::json small = WaveformJson(x, rate, {0.5, 0.505, 3.5}, o);
  EXPECT_EQ(small["windows"].size(), 1u);
  EXPECT_EQ(small["windows_dropped"].get<int>(), 1);
}

TEST(ReportWaveform, InvalidOptionsNameTheField) {
  ReportDataOptions o;
  o.envelope_bins = 3;
  std::string why;
  EXPECT_FALSE(o.IsValid(&why));
  EXPECT_NE(why.find("envelope_bins = 3"), std::string::npos) << why;
  ReportInput in;
  try {
    ReportDataJson(in, o);
    FAIL() << "expected Error";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::kBadParameter);
  }
}

// ---- the report object of the bundled recording ----

struct BundledReport {
  nlohmann::json data;
  DetectionResult detection;
  Calibration fit;
};

const BundledReport& Bundled() {
  static const BundledReport r = [] {
    BundledReport b;
    const Scene scene = LoadSceneFile(kScene);
    ReportRecording rec = LoadReportRecording(kFlac, DetectOptions{}, scene, AnalysisOptions{});
    b.detection = *rec.detection;
    CalibrationOptions trajectory;  // impact-time residuals (the restitution fit's are e's)
    trajectory.strategy = FitStrategy::kTrajectory;
    b.fit = Calibrate({{kFlac, rec.detection->main()}}, scene, trajectory);
    ReportInput in;
    in.recordings.push_back(std::move(rec));
    in.calibration = &b.fit;
    in.provenance = MakeProvenance({kFlac});
    b.data = ReportDataJson(in);
    return b;
  }();
  return r;
}

TEST(ReportData, HoldsTheDetectionFitAndLedger) {
  const BundledReport& b = Bundled();
  const nlohmann::json& d = b.data;
  EXPECT_EQ(d["schema"], "bouncecal.report/2");
  ASSERT_EQ(d["recordings"].size(), 1u);
  const nlohmann::json& rec = d["recordings"][0];
  const auto& main = b.detection.main().impacts;
  ASSERT_EQ(rec["impacts"].size(), main.size());
  for (size_t k = 0; k < main.size(); ++k) {
    EXPECT_EQ(rec["impacts"][k]["time_s"].get<double>(), main[k].time_s);
    EXPECT_EQ(rec["impacts"][k]["time_sigma_s"].get<double>(), main[k].sigma_s);
  }
  // Rejected: candidates that no sequence kept (the guided search adds impacts that are not
  // candidates, so the two lists need not add up to the candidates).
  for (const auto& c : rec["rejected"]) {
    const double t = c["time_s"].get<double>();
    bool is_candidate = false;
    for (const Impact& i : b.detection.candidates) is_candidate = is_candidate || i.time_s == t;
    EXPECT_TRUE(is_candidate) << t;
    for (const Impact& i : main) EXPECT_GT(std::fabs(i.time_s - t), 0.0015) << t;
  }
  size_t kept = 0;
  for (const Impact& c : b.detection.candidates) {
    for (const Impact& i : main) {
      if (std::fabs(i.time_s - c.time_s) <= 0.0015) {
        ++kept;
        break;
      }
    }
  }
  EXPECT_EQ(kept + rec["rejected"].size(), b.detection.candidates.size());
  EXPECT_TRUE(rec["no_impacts_reason"].is_null());
  ASSERT_EQ(rec["intervals"].size(), main.size() - 1);
  EXPECT_DOUBLE_EQ(rec["intervals"][3]["interval_s"].get<double>(),
                   main[4].time_s - main[3].time_s);
  EXPECT_DOUBLE_EQ(rec["intervals"][3]["interval_sigma_s"].get<double>(),
                   std::hypot(main[3].sigma_s, main[4].sigma_s));
  // Residuals: one per impact, the fit's own numbers, weighted by the onset sigmas.
  ASSERT_EQ(rec["residuals"]["values"].size(), b.fit.recordings[0].residuals.size());
  EXPECT_EQ(rec["residuals"]["unit"], "s");
  EXPECT_EQ(rec["residuals"]["values"][7]["residual"].get<double>(),
            b.fit.recordings[0].residuals[7]);
  EXPECT_EQ(rec["residuals"]["values"][7]["sigma"].get<double>(), main[7].sigma_s);
  // The fit in the parameter file's schema.
  EXPECT_EQ(d["fit"]["schema"], "bouncecal.params/2");
  EXPECT_EQ(d["fit"]["law"]["parameters"]["A"]["value"].get<double>(), b.fit.parameters[1].value);
  // Energy ledger: started at the fitted first impact speed on the surface, so the initial
  // energy is 1/2 m v0^2 (m from the scene: 7800 kg/m^3, d = 1 cm), and it balances.
  const nlohmann::json& e = d["energy"];
  const double m = 7800.0 * std::numbers::pi / 6 * 1e-6;
  const double v0 = b.fit.recordings[0].impact_speed_m_s;
  EXPECT_NEAR(e["initial_j"].get<double>(), 0.5 * m * v0 * v0, 1e-12);
  EXPECT_NEAR(e["impacts"][0]["time_s"].get<double>(), b.fit.recordings[0].time_origin_s, 1e-12);
  const double sum = e["final_mechanical_j"].get<double>() +
                     e["dissipated_contact_j"].get<double>() +
                     e["dissipated_drag_j"].get<double>() + e["internal_j"].get<double>() +
                     e["balance_error_j"].get<double>();
  EXPECT_NEAR(sum, e["initial_j"].get<double>(), 1e-15);
  EXPECT_EQ(d["provenance"]["inputs"][0]["sha256"].get<std::string>().size(), 64u);
}

TEST(ReportHtml, EmbedsTheDataSafelyAndHoldsNoNetworkUrl) {
  nlohmann::json d = Bundled().data;
  d["recordings"][0]["file"] = "a</script><b>.wav";  // must not end the data element
  const std::string html = RenderHtmlReport(d);
  EXPECT_EQ(html.find("a</script>"), std::string::npos);
  EXPECT_NE(html.find("a\\u003c/script>"), std::string::npos);
  const std::regex url(R"((https?|ftp|wss?|file):|//cdn|(src|href)\s*=\s*["']?//)",
                       std::regex::icase);
  EXPECT_FALSE(std::regex_search(html, url));
  // The libraries are inlined, not referenced.
  EXPECT_EQ(html.find("<script src"), std::string::npos);
  EXPECT_NE(html.find("Chart.js v"), std::string::npos);
}

// ---- the page in a real browser ----

std::string Chromium() {
  for (const char* c : {"chromium", "chromium-browser", "google-chrome"}) {
    const std::string which = std::string("command -v ") + c + " >/dev/null 2>&1";
    if (std::system(which.c_str()) == 0) return c;
  }
  return "";
}

// Headless Chromium with a fresh profile; every host name resolves to nothing, so a page that
// tried to fetch anything would fail to draw.
testing_util::CommandResult RunChromium(const ScratchDir& dir, const std::string& page,
                                        const std::string& mode, int height) {
  static int profile = 0;
  const std::string args =
      "--headless --no-sandbox --disable-gpu --disable-quic --no-first-run "
      "--disable-background-networking --disable-component-update --disable-sync "
      "--hide-scrollbars --force-device-scale-factor=1 --host-resolver-rules='MAP * ~NOTFOUND' "
      "--user-data-dir=" +
      dir / ("profile" + std::to_string(profile++)) + " --window-size=1280," +
      std::to_string(height) + " --virtual-time-budget=10000 " + mode + " file://" + page;
  return RunCommand("timeout 120 " + Chromium(), args);
}

struct Canvas {
  std::map<std::string, std::string> attr;
  int x = 0, y = 0, w = 0, h = 0;
};

std::map<std::string, Canvas> Canvases(const std::string& dom) {
  std::map<std::string, Canvas> out;
  const std::regex tag(R"(<canvas [^>]*>)"), attr(R"(([a-z-]+)="([^"]*)\")");
  for (auto it = std::sregex_iterator(dom.begin(), dom.end(), tag); it != std::sregex_iterator();
       ++it) {
    Canvas c;
    const std::string t = it->str();
    for (auto a = std::sregex_iterator(t.begin(), t.end(), attr); a != std::sregex_iterator(); ++a)
      c.attr[(*a)[1]] = (*a)[2];
    std::sscanf(c.attr["data-rect"].c_str(), "%d,%d,%d,%d", &c.x, &c.y, &c.w, &c.h);
    out[c.attr["data-chart"]] = c;
  }
  return out;
}

std::string BodyAttr(const std::string& dom, const std::string& name) {
  std::smatch m;
  const std::regex re("<body[^>]* " + name + R"(="([^"]*)\")");
  return std::regex_search(dom, m, re) ? m[1].str() : "";
}

struct Image {
  int width = 0, height = 0;
  std::vector<unsigned char> rgb;
  const unsigned char* At(int x, int y) const {
    return &rgb[3 * (static_cast<size_t>(y) * static_cast<size_t>(width) + static_cast<size_t>(x))];
  }
};

Image ReadPng(const std::string& path) {
  png_image img{};
  img.version = PNG_IMAGE_VERSION;
  Image out;
  if (!png_image_begin_read_from_file(&img, path.c_str())) return out;
  img.format = PNG_FORMAT_RGB;
  out.rgb.resize(PNG_IMAGE_SIZE(img));
  if (!png_image_finish_read(&img, nullptr, out.rgb.data(), 0, nullptr)) return {};
  out.width = static_cast<int>(img.width);
  out.height = static_cast<int>(img.height);
  return out;
}

// Pixels in the rectangle that are not the white page, and those close to `rgb`.
struct PixelCount {
  long non_white = 0, near_color = 0, total = 0;
};
PixelCount CountPixels(const Image& img, const Canvas& c, int r, int g, int b) {
  PixelCount n;
  for (int y = c.y; y < std::min(c.y + c.h, img.height); ++y) {
    for (int x = c.x; x < std::min(c.x + c.w, img.width); ++x) {
      const unsigned char* p = img.At(x, y);
      ++n.total;
      if (p[0] < 245 || p[1] < 245 || p[2] < 245) ++n.non_white;
      if (std::abs(p[0] - r) < 24 && std::abs(p[1] - g) < 24 && std::abs(p[2] - b) < 24)
        ++n.near_color;
    }
  }
  return n;
}

// Renders `page` twice: the DOM after the scripts ran (what the page recorded about its charts)
// and a screenshot of the whole page.
struct Rendered {
  std::string dom;
  Image shot;
};
Rendered Render(const ScratchDir& dir, const std::string& page) {
  Rendered r;
  const auto dump = RunChromium(dir, page, "--dump-dom", 900);
  r.dom = dump.out;
  const int height = std::atoi(BodyAttr(r.dom, "data-page-height").c_str());
  if (height <= 0) return r;
  const std::string png = dir / "shot.png";
  RunChromium(dir, page, "--screenshot=" + png, height);
  r.shot = ReadPng(png);
  return r;
}

TEST(ReportBrowser, BundledRecordingDrawsEveryChartWithEveryImpact) {
  ASSERT_FALSE(Chromium().empty()) << "chromium is missing: run tools/install-deps.sh";
  ScratchDir dir("bc_report");
  const std::string html = dir / "report.html";
  const auto run =
      RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " --scene " + kScene + " -o " + html);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  // The expected number of marks comes from `detect`, a separate command.
  const auto det = RunCommand(BOUNCECAL_BINARY, "detect " + kFlac + " --json");
  ASSERT_EQ(det.exit_code, 0) << det.err;
  const nlohmann::json d = nlohmann::json::parse(det.out);
  const size_t expected_impacts =
      d["sequences"][d["chosen_sequences"][0].get<int>()]["impacts"].size();
  ASSERT_EQ(expected_impacts, 74u);  // README worked example

  const Rendered r = Render(dir, html);
  ASSERT_EQ(BodyAttr(r.dom, "data-report-state"), "drawn") << BodyAttr(r.dom, "data-report-error");
  const auto canvases = Canvases(r.dom);
  for (const char* chart : {"waveform-0", "intervals-0", "residuals-0", "restitution", "energy"}) {
    ASSERT_EQ(canvases.count(chart), 1u) << chart;
    EXPECT_EQ(canvases.at(chart).attr.at("data-drawn"), "1") << chart;
  }
  EXPECT_EQ(std::stoul(canvases.at("waveform-0").attr.at("data-impact-marks")), expected_impacts);
  EXPECT_EQ(std::stoul(canvases.at("intervals-0").attr.at("data-point-marks")),
            expected_impacts - 1);
  // The default (restitution) fit has one residual per bounce with an e: all but the last.
  EXPECT_EQ(std::stoul(canvases.at("residuals-0").attr.at("data-point-marks")),
            expected_impacts - 1);
  EXPECT_EQ(std::stoul(canvases.at("restitution").attr.at("data-point-marks")),
            expected_impacts - 1);  // the last impact has no e

  ASSERT_GT(r.shot.width, 0) << "no screenshot";
  for (const auto& [name, c] : canvases) {
    ASSERT_GT(c.w, 100) << name;
    const PixelCount n = CountPixels(r.shot, c, 0, 0, 0);
    // Axes, grid and data: measured 9-35 % of each chart's area; an empty canvas is 0 %.
    EXPECT_GT(n.non_white, n.total / 50) << name << ": " << n.non_white << " of " << n.total;
  }
  // The impact triangles' red (#d62728) is on the waveform: 74 triangles of radius 6 px.
  const PixelCount red = CountPixels(r.shot, canvases.at("waveform-0"), 0xd6, 0x27, 0x28);
  EXPECT_GT(red.near_color, 74 * 20) << red.near_color;
  // The fitted curve's green (#2ca02c) is on the restitution chart.
  // Measured 499 px on the bundled recording (66 impacts); 0 without the curve.
  EXPECT_GT(CountPixels(r.shot, canvases.at("restitution"), 0x2c, 0xa0, 0x2c).near_color, 250);
  // The fit's next step is on the page (a converged fit: its export).
  const std::size_t hint = r.dom.find("id=\"fit-hint\"");
  ASSERT_NE(hint, std::string::npos);
  EXPECT_NE(r.dom.find("bouncecal export", hint), std::string::npos);

  const std::string text = Slurp(html);
  const std::regex url(R"((https?|ftp|wss?):|//cdn|(src|href)\s*=\s*["']?//)", std::regex::icase);
  EXPECT_FALSE(std::regex_search(text, url));
  EXPECT_LT(text.size(), 5u * 1024 * 1024);
}

// A hand-made result (what the detector and the kinematics return) with two rejected candidates
// and two warnings, one of them at impact 2: the page marks each where it belongs.
TEST(ReportBrowser, RejectedCandidatesAndWarningsAreMarkedWhereTheyBelong) {
  ASSERT_FALSE(Chromium().empty()) << "chromium is missing: run tools/install-deps.sh";
  ScratchDir dir("bc_report");
  const double rate = 8000.0;
  ReportRecording rec;
  rec.path = "hand-made.wav";
  rec.audio.path = rec.path;
  rec.audio.sample_rate_hz = rate;
  rec.audio.channels = 1;
  rec.audio.frames = 16000;
  rec.channel = 0;
  rec.samples.assign(16000, 0.0f);
  DetectionResult d;
  d.audio = rec.audio;
  d.channel = 0;
  Sequence q;
  for (double t : {0.5, 0.9, 1.2, 1.42}) q.impacts.push_back({t, 5e-6, 0.5, 40.0, 0.9, false});
  d.sequences = {q};
  d.main_sequence = 0;
  d.candidates = q.impacts;
  for (double t : {0.7, 1.6}) d.candidates.push_back({t, 2e-5, 0.2, 12.0, 0.3, false});
  for (const Impact& i : d.candidates) {
    for (int k = 0; k < 40; ++k) {
      rec.samples[static_cast<size_t>(i.time_s * rate) + static_cast<size_t>(k)] =
          static_cast<float>(i.amplitude * std::exp(-k / 6.0) * (k % 2 ? -1 : 1));
    }
  }
  d.warnings = {
      {"missed_impact", "an impact seems missing after impact 2", 2, "listen to the impacts kept"},
      {"clipped", "channel 0 is clipped", -1, "record at a lower gain"}};
  rec.detection = d;
  rec.candidates = d.candidates;
  AnalysisOptions no_drop;
  no_drop.use_drop = false;
  rec.analysis = AnalyzeBounces(q, Scene{}, no_drop);
  ReportInput in;
  in.recordings.push_back(rec);
  const nlohmann::json data = ReportDataJson(in);
  ASSERT_EQ(data["recordings"][0]["rejected"].size(), 2u);
  EXPECT_EQ(data["recordings"][0]["warnings"][0]["time_s"].get<double>(), 1.2);
  EXPECT_TRUE(data["recordings"][0]["warnings"][1]["time_s"].is_null());
  EXPECT_EQ(data["recordings"][0]["warnings"][1]["hint"], "record at a lower gain");
  const std::string html = dir / "hand.html";
  WriteHtmlReport(html, data, {.force = false, .inputs = {}});

  const Rendered r = Render(dir, html);
  ASSERT_EQ(BodyAttr(r.dom, "data-report-state"), "drawn") << BodyAttr(r.dom, "data-report-error");
  const auto canvases = Canvases(r.dom);
  const Canvas& wave = canvases.at("waveform-0");
  EXPECT_EQ(wave.attr.at("data-impact-marks"), "4");
  EXPECT_EQ(wave.attr.at("data-rejected-marks"), "2");
  EXPECT_EQ(wave.attr.at("data-warning-lines"), "1");  // the clipped warning has no place
  EXPECT_NE(r.dom.find("<code>missed_impact</code>"), std::string::npos);
  EXPECT_NE(r.dom.find("<code>clipped</code>"), std::string::npos);
  EXPECT_NE(r.dom.find("Next: record at a lower gain"), std::string::npos);  // its next step
  ASSERT_GT(r.shot.width, 0);
  // Orange crosses (#ff7f0e) and the purple warning line (#9467bd) are on the screenshot.
  EXPECT_GT(CountPixels(r.shot, wave, 0xff, 0x7f, 0x0e).near_color, 2 * 10);
  EXPECT_GT(CountPixels(r.shot, wave, 0x94, 0x67, 0xbd).near_color, 100);
}

// 3 s of noise and one click: no bounce sequence.
std::string WriteNoImpactRecording(const ScratchDir& dir) {
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 0.01f);
  std::vector<float> x(3 * 48000);
  for (float& v : x) v = noise(rng);
  for (int i = 0; i < 40; ++i)
    x[60000 + static_cast<size_t>(i)] += 0.6f * std::exp(-static_cast<float>(i) / 8.0f);
  const std::string path = dir / "noise.wav";
  WriteAudio(path, {x}, 48000);
  return path;
}

TEST(ReportBrowser, RecordingWithoutImpactsShowsTheWaveformAndWhy) {
  ASSERT_FALSE(Chromium().empty()) << "chromium is missing: run tools/install-deps.sh";
  ScratchDir dir("bc_report");
  const std::string wav = WriteNoImpactRecording(dir);
  const std::string html = dir / "none.html";
  const auto run = RunCommand(BOUNCECAL_BINARY, "report " + wav + " -o " + html);
  // Documented: the report is written, the exit code says there is nothing to fit.
  EXPECT_EQ(run.exit_code, 7) << run.err;
  EXPECT_NE(run.err.find("no bounce sequence"), std::string::npos) << run.err;
  EXPECT_NE(run.err.find("the report was written"), std::string::npos) << run.err;
  const Rendered r = Render(dir, html);
  ASSERT_EQ(BodyAttr(r.dom, "data-report-state"), "drawn") << BodyAttr(r.dom, "data-report-error");
  EXPECT_NE(r.dom.find("id=\"no-impacts-0\""), std::string::npos);
  EXPECT_NE(r.dom.find("No impacts to analyse"), std::string::npos);
  const auto canvases = Canvases(r.dom);
  ASSERT_EQ(canvases.count("waveform-0"), 1u);
  EXPECT_EQ(canvases.at("waveform-0").attr.at("data-impact-marks"), "0");
  ASSERT_GT(r.shot.width, 0);
  const PixelCount n = CountPixels(r.shot, canvases.at("waveform-0"), 0, 0, 0);
  EXPECT_GT(n.non_white, n.total / 50);
  EXPECT_EQ(canvases.count("restitution"), 0u);  // nothing to show
}

// ---- bad output paths ----

TEST(ReportCli, RefusesAnExistingOutputWithoutForce) {
  ScratchDir dir("bc_report");
  const std::string html = dir / "r.html";
  { std::ofstream(html) << "keep me"; }
  const auto run = RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " -o " + html);
  EXPECT_EQ(run.exit_code, 11);
  EXPECT_NE(run.err.find("exists; use --force"), std::string::npos) << run.err;
  EXPECT_EQ(Slurp(html), "keep me");
  const auto forced = RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " --scene " + kScene +
                                                       " -o " + html + " --force --quiet");
  EXPECT_EQ(forced.exit_code, 0) << forced.err;
  EXPECT_NE(Slurp(html).find("bouncecal.report/2"), std::string::npos);
}

TEST(ReportCli, RefusesUnwritableDirectories) {
  ScratchDir dir("bc_report");
  const std::string file = dir / "plain";
  { std::ofstream(file) << "x"; }
  // A directory that does not exist, a "directory" that is a file, and /proc (not writable even
  // by root, so the test means the same for every user).
  for (const std::string& out :
       {dir / "missing/r.html", file + "/r.html", std::string("/proc/bouncecal_report.html")}) {
    const auto run = RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " -o " + out);
    EXPECT_EQ(run.exit_code, 11) << out;
    EXPECT_NE(run.err.find(out), std::string::npos) << run.err;
  }
  // The refusal comes before the work: an unwritable figure leaves no report behind either.
  const auto both = RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " -o " + dir / "ok.html" +
                                                     " --plot " + dir / "missing/f.svg");
  EXPECT_EQ(both.exit_code, 11);
  EXPECT_FALSE(std::filesystem::exists(dir / "ok.html"));
  const auto ext = RunCommand(BOUNCECAL_BINARY, "report " + kFlac + " --plot " + dir / "f.pdf");
  EXPECT_EQ(ext.exit_code, 2);
  EXPECT_NE(ext.err.find("expected .svg or .png"), std::string::npos) << ext.err;
  const auto nothing = RunCommand(BOUNCECAL_BINARY, "report " + kFlac);
  EXPECT_EQ(nothing.exit_code, 2);
  EXPECT_NE(nothing.err.find("nothing to write"), std::string::npos) << nothing.err;
}

// ---- figures ----

TEST(ReportFigures, SvgHasOneTrianglePerImpactAndPngIsAnImage) {
  ScratchDir dir("bc_report");
  const std::string svg = dir / "f.svg", png = dir / "f.png";
  const auto run = RunCommand(
      BOUNCECAL_BINARY, "report " + kFlac + " --scene " + kScene + " --plot " + svg + " --quiet");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::string text = Slurp(svg);
  ASSERT_NE(text.find("<svg"), std::string::npos);
  // gnuplot draws point type 9 (filled triangle) as <use xlink:href='#gpPt8' ... color=red>:
  // one per impact plus the key's sample.
  const std::regex tri(R"(<use xlink:href='#gpPt8'[^>]*color='rgb\(214,\s*39,\s*40\)')");
  const auto n =
      std::distance(std::sregex_iterator(text.begin(), text.end(), tri), std::sregex_iterator());
  EXPECT_EQ(n, 74 + 1);
  for (const char* title : {"intervals per bounce", "fit residuals",
                            "restitution against impact speed", "kinetic energy at impact"}) {
    EXPECT_NE(text.find(title), std::string::npos) << title;
  }
  const auto run_png = RunCommand(
      BOUNCECAL_BINARY, "report " + kFlac + " --scene " + kScene + " --plot " + png + " --quiet");
  ASSERT_EQ(run_png.exit_code, 0) << run_png.err;
  const Image img = ReadPng(png);
  EXPECT_EQ(img.width, 1400);   // 2 columns of 700 px
  EXPECT_EQ(img.height, 1260);  // 3 rows of 420 px (5 panels)
}

// ---- calibrate --report: the same fit as the parameter file ----

TEST(ReportCli, CalibrateReportCarriesTheFitOfTheParameterFile) {
  ScratchDir dir("bc_report");
  const std::string html = dir / "c.html", params = dir / "p.json";
  const auto run = RunCommand(BOUNCECAL_BINARY, "calibrate " + kFlac + " --scene " + kScene +
                                                    " -o " + params + " --report " + html);
  ASSERT_EQ(run.exit_code, 0) << run.err;
  const std::string page = Slurp(html);
  const std::string open = "<script type=\"application/json\" id=\"bouncecal-data\">";
  const size_t a = page.find(open) + open.size(), b = page.find("</script>", a);
  const nlohmann::json data = nlohmann::json::parse(page.substr(a, b - a));
  const nlohmann::json p = nlohmann::json::parse(Slurp(params));
  EXPECT_EQ(data["fit"]["law"]["parameters"]["A"]["value"], p["law"]["parameters"]["A"]["value"]);
  EXPECT_EQ(data["fit"]["law"]["parameters"]["A"]["sigma"], p["law"]["parameters"]["A"]["sigma"]);
  EXPECT_EQ(data["recordings"][0]["impacts"].size(), 74u);
  // An existing report is refused before the fit (and the parameter file is not written).
  const auto again =
      RunCommand(BOUNCECAL_BINARY, "calibrate " + kFlac + " --scene " + kScene + " -o " +
                                       dir / "p2.json" + " --report " + html);
  EXPECT_EQ(again.exit_code, 11);
  EXPECT_FALSE(std::filesystem::exists(dir / "p2.json"));
}

// ---- progress ----

TEST(ReportProgress, NothingOnStderrWhenItIsNotATerminal) {
  ScratchDir dir("bc_report");
  const auto run = RunCommand(BOUNCECAL_BINARY,
                              "report " + kFlac + " --scene " + kScene + " -o " + dir / "r.html");
  ASSERT_EQ(run.exit_code, 0) << run.err;
  // No progress line: what stderr holds is the coded warnings (the bundled recording has one,
  // a tail impact too uncertain to keep), one line each.
  std::istringstream lines(run.err);
  for (std::string line; std::getline(lines, line);)
    EXPECT_EQ(line.rfind("bouncecal: warning [", 0), 0u) << line;
}

TEST(ReportProgress, ALineOnATerminalAndNoneWithQuiet) {
  ASSERT_EQ(std::system("command -v script >/dev/null 2>&1"), 0)
      << "`script` (bsdutils) is missing: run tools/install-deps.sh";
  ScratchDir dir("bc_report");
  // `script` runs the command on a pseudo-terminal (stdin, stdout and stderr are all the pty)
  // and copies what it printed to its own stdout.
  auto on_tty = [&](const std::string& extra, const std::string& out) {
    const std::string cmd = std::string(BOUNCECAL_BINARY) + " report " + kFlac + " --scene " +
                            kScene + " -o " + out + extra;
    return RunCommand("script", "-qec '" + cmd + "' /dev/null </dev/null");
  };
  const auto shown = on_tty("", dir / "a.html");
  ASSERT_EQ(shown.exit_code, 0) << shown.out << shown.err;
  EXPECT_NE(shown.out.find("\r\033[Kbouncecal: [1/1] reading and detecting"), std::string::npos)
      << shown.out;
  EXPECT_NE(shown.out.find("bouncecal: fitting hertz-viscoelastic"), std::string::npos);
  EXPECT_NE(shown.out.find("wrote "), std::string::npos);
  const auto quiet = on_tty(" --quiet", dir / "b.html");
  ASSERT_EQ(quiet.exit_code, 0) << quiet.out << quiet.err;
  EXPECT_EQ(quiet.out.find("\033[K"), std::string::npos) << quiet.out;
  EXPECT_EQ(quiet.out.find("reading and detecting"), std::string::npos);
  EXPECT_NE(quiet.out.find("wrote "), std::string::npos);
}

}  // namespace
}  // namespace bouncecal
