// Static figures through gnuplot (see figures.hpp).
#include "bouncecal/report/figures.hpp"

#include <fcntl.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <vector>

#include "bouncecal/core/error.hpp"

extern char** environ;

namespace bouncecal {
namespace {

using nlohmann::json;

bool Finite(const json& v) { return v.is_number() && std::isfinite(v.get<double>()); }
double D(const json& v) { return v.get<double>(); }
double SigmaOr0(const json& v) { return Finite(v) ? D(v) : 0.0; }

// A gnuplot string literal (double quotes; the terminal is noenhanced, so no markup).
std::string Quote(const std::string& s) {
  std::string out = "\"";
  for (char c : s) {
    if (c == '"' || c == '\\') out += '\\';
    out += c;
  }
  return out + "\"";
}

// Inline data block `$name << EOD ... EOD` (rows of numbers, full precision).
class Block {
 public:
  explicit Block(std::string name) : name_(std::move(name)) { os_.precision(10); }
  void Row(std::initializer_list<double> values) {
    bool first = true;
    for (double v : values) {
      os_ << (first ? "" : " ") << v;
      first = false;
    }
    os_ << "\n";
    ++rows_;
  }
  void Gap() { os_ << "\n"; }  // a blank line breaks a line plot
  int rows() const { return rows_; }
  const std::string& name() const { return name_; }
  std::string Text() const { return name_ + " << EOD\n" + os_.str() + "EOD\n"; }

 private:
  std::string name_;
  std::ostringstream os_;
  int rows_ = 0;
};

struct Panel {
  std::string blocks;  // data blocks
  std::string plot;    // settings + plot command
};

Panel WaveformPanel(const json& rec) {
  const json& w = rec["waveform"];
  const double scale = D(w["scale"]), bin = D(w["envelope"]["bin_s"]);
  Block env("$envelope"), imp("$impacts"), rej("$rejected");
  const json& mins = w["envelope"]["min"];
  const json& maxs = w["envelope"]["max"];
  for (size_t i = 0; i < mins.size(); ++i) {
    env.Row({(static_cast<double>(i) + 0.5) * bin, mins[i].get<double>() * scale,
             maxs[i].get<double>() * scale});
  }
  const double floor = 0.02 * SigmaOr0(w["peak"]);
  for (const json& i : rec["impacts"])
    imp.Row({D(i["time_s"]), std::max(SigmaOr0(i["amplitude"]), floor)});
  for (const json& c : rec["rejected"])
    rej.Row({D(c["time_s"]), -std::max(SigmaOr0(c["amplitude"]), floor)});
  Panel p;
  p.blocks = env.Text() + imp.Text() + rej.Text();
  std::string title = "waveform: " + rec["file"].get<std::string>();
  if (!rec["no_impacts_reason"].is_null()) title += " (no impacts)";
  p.plot = "set title " + Quote(title) +
           "\nset xlabel 'time (s)'\nset ylabel 'amplitude (full scale)'\n"
           "plot $envelope using 1:2:3 with filledcurves lc rgb '#9ecae1' title 'min/max envelope'";
  if (imp.rows() > 0)
    p.plot += ", $impacts using 1:2 with points pt 9 ps 1.2 lc rgb '#d62728' title 'impacts'";
  if (rej.rows() > 0)
    p.plot +=
        ", $rejected using 1:2 with points pt 2 ps 1.2 lc rgb '#ff7f0e' title 'rejected "
        "candidates'";
  p.plot += "\n";
  return p;
}

Panel IntervalsPanel(const json& rec) {
  Block b("$intervals");
  for (const json& iv : rec["intervals"])
    b.Row({D(iv["index"]), D(iv["interval_s"]), SigmaOr0(iv["interval_sigma_s"])});
  return {b.Text(),
          "set title 'intervals per bounce'\nset xlabel 'bounce k'\nset ylabel 'interval (s)'\n"
          "plot $intervals using 1:2:3 with yerrorbars pt 7 ps 0.6 lc rgb '#1f77b4' title "
          "'t(k+1) - t(k) ± σ'\n"};
}

Panel RestitutionPanel(const json& data) {
  Panel p;
  std::string plots;
  Block pts("$e_points");
  for (const json& rec : data["recordings"]) {
    for (const json& b : rec["bounces"]) {
      if (!Finite(b["e"]) || !Finite(b["v_in_m_s"])) continue;
      pts.Row({D(b["v_in_m_s"]), D(b["e"]), SigmaOr0(b["v_in_sigma_m_s"]), SigmaOr0(b["e_sigma"])});
    }
  }
  p.blocks += pts.Text();
  const json& fit = data["fit"];
  if (fit.is_object() && fit.contains("e_of_v") && !fit["e_of_v"].empty()) {
    Block ev("$e_of_v");
    for (const json& q : fit["e_of_v"]) {
      if (!Finite(q["e"])) continue;
      const double s = SigmaOr0(q["e_sigma"]);
      ev.Row({D(q["v_m_s"]), D(q["e"]), D(q["e"]) - s, D(q["e"]) + s});
    }
    p.blocks += ev.Text();
    const std::string law = fit["law"]["name"].get<std::string>();
    plots +=
        "$e_of_v using 1:3:4 with filledcurves lc rgb '#2ca02c' fs transparent solid 0.25 "
        "title " +
        Quote(law + " e(v) ± σ") + ", $e_of_v using 1:2 with lines lw 2 lc rgb '#2ca02c' title " +
        Quote(law + " e(v)") + ", ";
  }
  const json& rows = data["law_comparison"];
  for (size_t r = 1; r < rows.size(); ++r) {
    if (rows[r]["e_of_v"].empty()) continue;
    Block other("$law" + std::to_string(r));
    for (const json& q : rows[r]["e_of_v"])
      if (Finite(q["e"])) other.Row({D(q["v_m_s"]), D(q["e"])});
    p.blocks += other.Text();
    plots += other.name() + " using 1:2 with lines dt 2 lw 1 title " +
             Quote(rows[r]["law"]["name"].get<std::string>()) + ", ";
  }
  p.plot =
      "set title 'restitution against impact speed'\nset logscale x\n"
      "set xlabel 'impact speed v_in (m/s)'\nset ylabel 'e'\nplot " +
      plots +
      "$e_points using 1:2:3:4 with xyerrorbars pt 7 ps 0.6 lc rgb '#1f77b4' title "
      "'measured e ± σ'\nunset logscale x\n";
  return p;
}

Panel ResidualsPanel(const json& rec) {
  const json& r = rec["residuals"];
  const bool seconds = r["unit"] == "s";
  const double k = seconds ? 1e6 : 1.0;
  Block b("$residuals");
  for (const json& v : r["values"])
    if (Finite(v["residual"]))
      b.Row({D(v["index"]), D(v["residual"]) * k, SigmaOr0(v["sigma"]) * k});
  return {b.Text(), std::string("set title 'fit residuals (model - measured)'\nset xlabel ") +
                        (seconds ? "'impact k'\nset ylabel 'residual (µs)'\n"
                                 : "'e point'\nset ylabel 'residual in e'\n") +
                        "plot $residuals using 1:2:3 with yerrorbars pt 7 ps 0.6 lc rgb '#2ca02c' "
                        "title 'residual ± onset σ', 0 with lines lc rgb '#999999' notitle\n"};
}

Panel EnergyPanel(const json& data) {
  const json& e = data["energy"];
  Block sim("$energy_sim"), meas("$energy_measured");
  for (const json& i : e["impacts"])
    if (D(i["kinetic_in_j"]) > 0) sim.Row({D(i["time_s"]), D(i["kinetic_in_j"])});
  const double m = D(e["mass_kg"]);
  for (const json& b : data["recordings"][0]["bounces"]) {
    if (!Finite(b["v_in_m_s"])) continue;
    const double v = D(b["v_in_m_s"]);
    meas.Row({D(b["time_s"]), 0.5 * m * v * v, m * v * SigmaOr0(b["v_in_sigma_m_s"])});
  }
  return {sim.Text() + meas.Text(),
          "set title 'kinetic energy at impact'\nset logscale y\nset xlabel 'time (s)'\n"
          "set ylabel 'energy (J)'\nplot $energy_sim using 1:2 with linespoints pt 7 ps 0.3 "
          "lc rgb '#2ca02c' title 'simulated (fitted law)', $energy_measured using 1:2:3 with "
          "yerrorbars pt 7 ps 0.6 lc rgb '#1f77b4' title 'measured ½ m v_in²'\nunset logscale y\n"};
}

// Runs `gnuplot script` and waits; its messages go to `log`. Throws Error(kOutput).
void RunGnuplot(const std::string& script, const std::string& log, const std::string& target) {
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, log.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0600);
  posix_spawn_file_actions_adddup2(&actions, STDOUT_FILENO, STDERR_FILENO);
  std::string prog = "gnuplot";
  std::vector<char*> argv = {prog.data(), const_cast<char*>(script.c_str()), nullptr};
  pid_t pid = 0;
  const int rc = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc != 0) {
    throw Error(ErrorCode::kOutput, target + ": cannot run gnuplot (" + std::strerror(rc) +
                                        "); the figures need it: apt-get install gnuplot-nox");
  }
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0) {
    std::ifstream in(log);
    std::stringstream ss;
    ss << in.rdbuf();
    std::string msg = ss.str();
    if (msg.size() > 400) msg = "..." + msg.substr(msg.size() - 400);
    throw Error(ErrorCode::kOutput, target + ": gnuplot failed: " + msg);
  }
}

}  // namespace

std::string FigureScript(const nlohmann::json& data, const std::string& format,
                         const std::string& output_path) {
  std::vector<Panel> panels;
  const json& recs = data["recordings"];
  bool any_bounces = false;
  for (const json& rec : recs) {
    panels.push_back(WaveformPanel(rec));
    if (!rec["intervals"].empty()) panels.push_back(IntervalsPanel(rec));
    if (rec["residuals"].is_object() && !rec["residuals"]["values"].empty())
      panels.push_back(ResidualsPanel(rec));
    any_bounces = any_bounces || !rec["bounces"].empty();
  }
  if (any_bounces) panels.push_back(RestitutionPanel(data));
  if (data["energy"].is_object() && !recs.empty()) panels.push_back(EnergyPanel(data));
  const int cols = panels.size() > 1 ? 2 : 1;
  const int rows = static_cast<int>((panels.size() + 1) / static_cast<size_t>(cols));
  // Pixels per panel: 700 x 420 reads well on a page at 2 columns.
  const int width = 700 * cols, height = 420 * rows;
  std::ostringstream s;
  s << "# bouncecal figure (report schema " << data.value("schema", "") << ")\n";
  if (format == "svg") {
    s << "set terminal svg size " << width << "," << height
      << " dynamic noenhanced font 'DejaVu Sans,12' background rgb 'white'\n";
  } else {
    s << "set terminal pngcairo size " << width << "," << height
      << " noenhanced font 'DejaVu Sans,10' background rgb 'white'\n";
  }
  s << "set output " << Quote(output_path) << "\nset encoding utf8\nset grid\nset key top right\n";
  for (const Panel& p : panels) s << p.blocks;
  s << "set multiplot layout " << rows << "," << cols << "\n";
  for (const Panel& p : panels) s << p.plot;
  s << "unset multiplot\nset output\n";
  return s.str();
}

void WriteFigure(const std::string& path, const nlohmann::json& report_data,
                 const WriteOptions& options) {
  const std::string ext = std::filesystem::path(path).extension().string();
  if (ext != ".svg" && ext != ".png") {
    throw Error(ErrorCode::kUsage, path +
                                       ": a figure's format comes from its extension, "
                                       "expected .svg or .png");
  }
  AtomicFile out(path, options);
  std::string dir_template =
      (std::filesystem::temp_directory_path() / "bouncecal-fig-XXXXXX").string();
  if (::mkdtemp(dir_template.data()) == nullptr) {
    throw Error(ErrorCode::kOutput, path + ": cannot create a temporary directory for gnuplot");
  }
  const std::filesystem::path dir(dir_template);
  struct Cleanup {
    std::filesystem::path dir;
    ~Cleanup() {
      std::error_code ec;
      std::filesystem::remove_all(dir, ec);
    }
  } cleanup{dir};
  const std::string script = (dir / "figure.gp").string();
  {
    std::ofstream f(script);
    f << FigureScript(report_data, ext.substr(1), out.temp_path());
    if (!f) throw Error(ErrorCode::kOutput, path + ": cannot write the gnuplot script");
  }
  RunGnuplot(script, (dir / "gnuplot.log").string(), path);
  out.Commit();
}

}  // namespace bouncecal
