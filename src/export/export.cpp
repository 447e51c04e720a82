// Parameter file -> simulator directory (export.hpp): the stages, run.sh and the JSON result.
#include "bouncecal/export/export.hpp"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <sstream>

#include "bouncecal/core/atomic_file.hpp"
#include "bouncecal/core/error.hpp"
#include "bouncecal/core/user_text.hpp"
#include "bouncecal/io/param_file.hpp"
#include "bouncecal/io/param_resolved.hpp"
#include "bouncecal/io/schema.hpp"
#include "bouncecal/physics/law_registry.hpp"
#include "bouncecal/physics/simulator.hpp"
#include "export/deck.hpp"

namespace bouncecal {

namespace exporter {

PackingScene::PackingScene(double restitution) {
  const double le = std::log(restitution);
  const double zeta = -le / std::sqrt(le * le + M_PI * M_PI);
  const double m = rho * M_PI * d * d * d / 6.0;
  gn_pp = 2.0 * zeta * std::sqrt(kn / (0.5 * m));
  gn_pw = 2.0 * zeta * std::sqrt(kn / m);
}

std::string CommentBlock(const std::vector<std::string>& lines, const std::string& prefix) {
  std::string out;
  for (const std::string& line : lines) out += prefix + line + "\n";
  return out;
}

}  // namespace exporter

namespace {

using exporter::DeckInput;
namespace fs = std::filesystem;

// Trace samples at most every 0.2 ms of simulated time (issue 12).
constexpr double kTraceInterval_s = 2e-4;
// The time step starts at the shortest contact time / 50 and is halved (at most 12 times)
// until its e error is below the budget, or until a halving reduces it by less than 1.5x.
constexpr double kStepsPerContactStart = 50.0;
constexpr int kMaxHalvings = 12;
constexpr double kMinHalvingGain = 1.5;
// Packing: the seed paper's dt = 10 us is t_c / 4.5 for its spheres; we take t_c / 10.
constexpr double kPackingStepsPerContact = 10.0;
// The density slab of the seed paper's packing validation (docs/physics.md §1).
constexpr double kSlabLow_m = 0.005, kSlabHigh_m = 0.045;

std::string Capture(const std::string& command) {
  std::string out;
  FILE* p = popen(command.c_str(), "r");
  if (p == nullptr) return out;
  char buf[512];
  while (std::fgets(buf, sizeof buf, p) != nullptr) out += buf;
  pclose(p);
  return out;
}

std::string Trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == '\r' || s.back() == ' ')) s.pop_back();
  while (!s.empty() && s.front() == ' ') s.erase(s.begin());
  return s;
}

// ---- stage 1: the input ------------------------------------------------------------------

void CheckOutcome(const ParamFile& pf, const std::string& path, bool force) {
  if (pf.outcome == "converged" || force) return;
  auto text = [&](const char* key) {
    return pf.doc.contains("fit") && pf.doc["fit"].contains(key) && pf.doc["fit"][key].is_string()
               ? pf.doc["fit"][key].get<std::string>()
               : std::string();
  };
  const std::string message = text("message"), hint = text("hint");
  throw Error(ErrorCode::kFitFailed,
              path + ": fit.outcome is '" + (pf.outcome.empty() ? "missing" : pf.outcome) +
                  "', not 'converged'" + (message.empty() ? "" : " (" + message + ")") +
                  ": its parameters may not describe the recording; not exported "
                  "(ExportOptions::force overrides)" +
                  (hint.empty() ? "" : "; next, for the fit: " + hint));
}

// Checks the output directory (run it before any work); true when it already exists.
bool CheckDirectory(const std::string& dir, bool force) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) {
      throw Error(ErrorCode::kOutput, dir + ": exists and is not a directory");
    }
    if (!force) {
      throw Error(
          ErrorCode::kOutput,
          dir +
              ": output directory exists; not replaced (ExportOptions::force replaces its files)");
    }
    return true;
  }
  const fs::path parent = fs::absolute(fs::path(dir)).parent_path();
  if (!fs::is_directory(parent, ec)) {
    throw Error(ErrorCode::kOutput,
                dir + ": parent directory " + parent.string() + " does not exist");
  }
  return false;
}

void PrepareDirectory(const std::string& dir, bool force) {
  if (CheckDirectory(dir, force)) return;
  std::error_code ec;
  if (!fs::create_directory(dir, ec) || ec) {
    throw Error(ErrorCode::kOutput, dir + ": cannot create directory (" + ec.message() + ")");
  }
}

// Speeds the mapping is judged over: the fit's e_of_v speeds, else the replay's impacts.
std::vector<double> MappingSpeeds(const Replay& r, const ContactLaw& law) {
  if (!r.speeds_m_s.empty()) return r.speeds_m_s;
  Scene s = r.scene;
  s.limits.max_impacts = 10;
  std::vector<double> v;
  for (const SimImpact& i : Simulate(s, law, law.ParameterValues()).impacts) {
    if (i.v_in_m_s > 0.0) v.push_back(i.v_in_m_s);
  }
  return v;
}

// ---- stage 2: the time step ----------------------------------------------------------------

struct TimeStep {
  double dt_s = 0.0;
  double e_error = 0.0;
  double steps_per_contact = 0.0;
  double contact_time_s = 0.0;  // shortest, at the fastest speed
  bool floor = false;           // halving stopped: the error no longer falls with the step
};

TimeStep ChooseTimeStep(const Mapping& m, const ContactBody& body, double g, double budget) {
  const NativeModel model = m.Model();
  const double v_lo = *std::min_element(m.speeds_m_s.begin(), m.speeds_m_s.end());
  const double v_hi = *std::max_element(m.speeds_m_s.begin(), m.speeds_m_s.end());
  TimeStep ts;
  ts.contact_time_s = std::min(model.ContactTimeAt(body, v_hi), model.ContactTimeAt(body, v_lo));
  ts.dt_s = ts.contact_time_s / kStepsPerContactStart;
  // The error at the slowest and at the fastest speed, each on its own: one of them can sit on
  // its floor while the step still limits the other (a fit down to 0.016 m/s: the slow impact's
  // error stuck at 1.7e-3 from t_c/50 on, while the fast impact's, which sets the first flights,
  // still halved; judged on their maximum, the step stayed at t_c/50 and Yade's first interval
  // was 1.1e-3 off).
  const double speeds[2] = {v_lo, v_hi};
  double last[2] = {0.0, 0.0};
  bool floored[2] = {false, false};
  for (int i = 0; i <= kMaxHalvings; ++i) {
    // A second-order step's error falls ~4x per halving; when it falls by less than
    // kMinHalvingGain the rest is not the step's (at slow impacts with gravity: how the leapfrog
    // and the located contact read the rebound), and smaller steps only cost time (a fit down
    // to 0.03 m/s asked for 2.8e9 steps, hours of Yade, for an error stuck at 1.0e-3).
    double err[2];
    bool gained = false;
    for (int j = 0; j < 2; ++j) {
      err[j] = MaxTimeStepError(model, body, {speeds[j]}, ts.dt_s, g);
      if (i > 0 && err[j] > last[j] / kMinHalvingGain)
        floored[j] = true;
      else
        gained = true;
    }
    if (!gained) {  // this halving helped no speed: the step before it
      ts.dt_s *= 2.0;
      ts.floor = true;
      break;
    }
    last[0] = err[0], last[1] = err[1];
    ts.e_error = std::max(err[0], err[1]);
    // Halve again while a speed whose error still falls with the step is over the budget.
    const bool step_limited = (!floored[0] && err[0] > budget) || (!floored[1] && err[1] > budget);
    if (!step_limited || i == kMaxHalvings) {
      ts.floor =
          !step_limited && ts.e_error > budget;  // over it only where the step no longer helps
      break;
    }
    ts.dt_s *= 0.5;
  }
  ts.steps_per_contact = ts.contact_time_s / ts.dt_s;
  return ts;
}

// ---- stage 3: the run length -------------------------------------------------------------

struct RunPlan {
  double release_height_m = 0.0;
  double run_time_s = 0.0;
  int impacts = 0;
};

RunPlan PlanBounce(const Scene& scene, const ContactLaw& law, int impacts, double g) {
  const double v0 = scene.drop.impact_speed_m_s
                        ? *scene.drop.impact_speed_m_s
                        : std::sqrt(2.0 * g * scene.drop.height_m.value_or(0.0));
  RunPlan plan;
  plan.release_height_m = v0 * v0 / (2.0 * g);
  Scene s = scene;
  s.effects.drag = DragModel::kNone;  // as the simulators fly
  s.limits.max_impacts = impacts + 1;
  const std::vector<SimImpact> imp = Simulate(s, law, law.ParameterValues()).impacts;
  const double fall_s = v0 / g;
  const size_t n = std::min<size_t>(imp.size(), static_cast<size_t>(impacts));
  plan.impacts = static_cast<int>(n);
  if (n == 0) {
    plan.run_time_s = 2.0 * fall_s;
  } else if (imp.size() > n) {
    plan.run_time_s = fall_s + 0.5 * (imp[n - 1].time_s + imp[n].time_s);
  } else {
    plan.run_time_s = fall_s + imp[n - 1].time_s + std::max(0.01, 2.0 * imp[n - 1].v_out_m_s / g);
  }
  return plan;
}

// ---- stage 4: the files ---------------------------------------------------------------------

std::string LawSummary(const Scene& s) {
  std::string out = s.law.name + ":";
  for (const auto& [k, v] : s.law.parameters) out += " " + k + " = " + FormatShortest(v);
  return out;
}

// The fitted law's misfit to the measured bounces, beside the mapping's error in the header.
std::string LawMisfitComment(const ExportResult& r) {
  if (!std::isfinite(r.law_misfit_e))
    return "fit: the law's misfit to the measured bounces was not tested (too few bounces, the "
           "trajectory strategy, or an older parameter file)";
  const bool small = std::any_of(r.warnings.begin(), r.warnings.end(),
                                 [](const Warning& w) { return w.code == "law_misfit_small"; });
  return "fit: the law's e(v) differs from a smoother e(v) through the measured bounces by " +
         FormatShortest(r.law_misfit_e) + " rms (tolerance " +
         FormatShortest(r.law_misfit_tolerance_e) + "; " +
         (small ? "significant but below it: law_misfit_small" : "not significant") +
         "): the simulator reproduces the law, to the mapping error above, not that difference";
}

// The fit's law misfit and its warning from the parameter file (absent in older files).
void ReadLawMisfit(const ParamFile& pf, ExportResult* r) {
  const nlohmann::json& fit = pf.doc.contains("fit") ? pf.doc["fit"] : nlohmann::json();
  auto number = [&](const char* key) {
    return fit.is_object() && fit.contains(key) && fit[key].is_number()
               ? fit[key].get<double>()
               : std::numeric_limits<double>::quiet_NaN();
  };
  r->law_misfit_e = number("misfit_e");
  r->law_misfit_tolerance_e = number("misfit_tolerance_e");
  if (!pf.doc.contains("warnings") || !pf.doc["warnings"].is_array()) return;
  for (const auto& w : pf.doc["warnings"]) {
    if (!w.is_object() || w.value("code", "") != "law_misfit_small") continue;
    r->warnings.push_back({"law_misfit_small", w.value("message", ""), -1, w.value("hint", "")});
  }
}

std::vector<std::string> HeaderComments(const DeckInput& in, const ExportResult& r,
                                        const TimeStep& ts) {
  const Mapping& m = in.mapping;
  std::vector<std::string> c;
  c.push_back("bouncecal export (" + r.target + ", " + r.scene + ") of " + in.params_path);
  c.push_back("written for " + r.simulator_version);
  c.push_back("fitted law  " + in.law_summary);
  c.push_back("native law  " + m.native_law + "  [" + m.kind + "]");
  std::string coeffs = "coefficients";
  for (const auto& [k, v] : m.coefficients) coeffs += " " + k + " = " + FormatShortest(v);
  c.push_back(coeffs);
  c.push_back("mapping: max |e_native - e_fit| = " + FormatShortest(m.max_e_error) +
              ", max contact-time error " + FormatShortest(m.max_contact_time_error) +
              " (relative), over " + FormatShortest(m.speeds_m_s.front()) + " .. " +
              FormatShortest(m.speeds_m_s.back()) + " m/s");
  c.push_back(LawMisfitComment(r));
  c.push_back("ball: R = " + FormatShortest(in.radius_m) + " m, m = " + FormatShortest(in.mass_kg) +
              " kg (density " + FormatShortest(in.density_kg_m3) +
              " kg/m^3), rigid plane z = 0, g = " + FormatShortest(in.g_m_s2) + " m/s^2");
  c.push_back("time step " + FormatShortest(ts.dt_s) + " s = shortest contact time " +
              FormatShortest(ts.contact_time_s) + " s / " + FormatShortest(ts.steps_per_contact) +
              " (halved from t_c/50 until the e error of the simulators' leapfrog, measured on "
              "16 contact phases at the slowest and fastest speed, is <= " +
              FormatShortest(in.options.time_step_e_error) + "): e error " +
              FormatShortest(ts.e_error) +
              (ts.floor ? " (halving stopped: a smaller step no longer reduced it)" : ""));
  for (const std::string& n : m.notes) c.push_back("note: " + n);
  for (const std::string& n : r.notes) {
    if (std::find(m.notes.begin(), m.notes.end(), n) == m.notes.end()) c.push_back("note: " + n);
  }
  return c;
}

}  // namespace

namespace exporter {

std::string ImpactsAwk() {
  return R"AWK(# impacts.awk (bouncecal export): impacts of a bouncing ball from trace.csv (t_s,z_m,vz_m_s).
# Between contacts the ball flies under gravity alone, which the simulators' leapfrog follows
# exactly, so each impact is located from the flight samples next to it:
#   arrival: last flight sample (t1, z1, v1) before the bounce; z1 + v1 s - g s^2/2 = R gives
#            time_s = t1 + s, v_in = sqrt(v1^2 + 2 g (z1 - R));
#   rebound: first flight sample (t2, z2, v2) after it: v_out = sqrt(v2^2 + 2 g (z2 - R)).
# A bounce is a rise of vz between two samples; samples with z < R (in contact) are skipped.
# Stops when no flight sample precedes a bounce (the flights became shorter than a sample).
# Usage: awk -F, -v R=radius_m -v g=g_m_s2 -f impacts.awk trace.csv > impacts.csv
BEGIN { n = 0; have = 0; pending = 0; print "index,time_s,v_in_m_s,v_out_m_s" }
NR == 1 { next }
{
  t = $1 + 0; z = $2 + 0; v = $3 + 0
  if (have && !pending && v > pv + 1e-12 + 1e-9 * (pv < 0 ? -pv : pv)) {
    if (!(lz >= R)) exit
    w = sqrt(lv * lv + 2 * g * (lz - R))
    it = lt + (lv + w) / g; vin = w; pending = 1
  }
  have = 1; pv = v
  if (z >= R) {
    if (pending) {
      printf "%d,%.17g,%.17g,%.17g\n", n, it, vin, sqrt(v * v + 2 * g * (z - R))
      n++; pending = 0
    }
    lt = t; lz = z; lv = v
  }
}
)AWK";
}

std::string PackingAwk() {
  return R"AWK(# packing.awk (bouncecal export): solid fraction of the spheres in a slab lo < z < hi of the
# cylinder of radius Rc, from a LAMMPS/LIGGGHTS dump (ITEM: ATOMS id x y z radius).
# Each sphere contributes its part inside the slab: pi (r^2 u - u^3/3) between the cut heights
# u1, u2 relative to its centre. Prints: density,spheres_in_slab,spheres
# Usage: awk -v lo=0.005 -v hi=0.045 -v Rc=0.1 -f packing.awk packing.dump
BEGIN { pi = atan2(0, -1); vol = 0; n = 0; total = 0; atoms = 0 }
/^ITEM: ATOMS/ { atoms = 1; next }
/^ITEM:/ { atoms = 0; next }
atoms {
  z = $4 + 0; r = $5 + 0; total++
  a = (lo > z - r ? lo : z - r) - z; b = (hi < z + r ? hi : z + r) - z
  if (b > a) { vol += pi * (r * r * (b - a) - (b * b * b - a * a * a) / 3); n++ }
}
END { printf "%.6f,%d,%d\n", vol / (pi * Rc * Rc * (hi - lo)), n, total }
)AWK";
}

std::string RunScript(const DeckInput& in) {
  const ExportTarget t = in.mapping.target;
  const bool packing = in.options.scene == ExportScene::kPacking;
  const std::string prog = SimulatorProgram(t), pkg = SimulatorPackage(t);
  std::ostringstream os;
  os << "#!/bin/sh\n"
     << "# bouncecal export: runs " << prog << " on this directory's deck"
     << (packing ? " and prints the packing density.\n" : " and writes impacts.csv.\n")
     << "# Fails loudly (message on stderr, non-zero exit) when " << prog
     << " is missing or fails.\n"
     << (packing ? "# NP=2 ./run.sh runs 2 MPI ranks; extra arguments go to " + prog + ".\n"
                 : "# Extra arguments go to " + prog + ".\n")
     << "set -eu\n"
     << "cd \"$(dirname \"$0\")\"\n"
     << "if ! command -v " << prog << " >/dev/null 2>&1; then\n"
     << "  echo \"run.sh: " << prog << " not found on PATH (Debian 12: apt-get install -y " << pkg
     << ")\" >&2\n"
     << "  exit 127\n"
     << "fi\n";
  // LIGGGHTS 3.8.0 crashes with `-screen none` (insert/pack prints to the missing screen):
  // its screen output goes to a file instead.
  const std::string screen =
      t == ExportTarget::kLiggghts ? std::string("screen.") + prog : std::string("none");
  if (packing) {
    os << "command -v mpirun >/dev/null 2>&1 || { echo \"run.sh: mpirun not found on PATH "
          "(Debian 12: apt-get install -y openmpi-bin)\" >&2; exit 127; }\n"
       << "rm -f packing.dump\n"
       << "MPIFLAGS=\"--oversubscribe\"\n"
       << "if [ \"$(id -u)\" = 0 ]; then MPIFLAGS=\"$MPIFLAGS --allow-run-as-root\"; fi\n"
       << "start=$(date +%s.%N)\n"
       << "if ! mpirun $MPIFLAGS -np \"${NP:-1}\" " << prog
       << " -in in.packing -log log.packing -screen " << screen << " \"$@\" </dev/null; then\n"
       << "  echo \"run.sh: " << prog << " failed, see log.packing\" >&2\n"
       << "  exit 1\n"
       << "fi\n"
       << "end=$(date +%s.%N)\n"
       << "[ -s packing.dump ] || { echo \"run.sh: " << prog
       << " wrote no packing.dump\" >&2; exit 1; }\n"
       << "echo \"density,spheres_in_slab,spheres,wall_time_s,ranks\"\n"
       << "printf '%s,%s,%s\\n' \"$(awk -v lo=" << FormatShortest(kSlabLow_m)
       << " -v hi=" << FormatShortest(kSlabHigh_m)
       << " -v Rc=0.1 -f packing.awk packing.dump)\" \"$(echo \"$end - $start\" | "
          "awk '{printf \"%.2f\", $1 - $3}')\" \"${NP:-1}\"\n";
    return os.str();
  }
  os << "rm -f trace.csv impacts.csv\n";
  if (t == ExportTarget::kYade) {
    os << "if ! " << prog << " -n -x bounce.py \"$@\" >yade.log 2>&1 </dev/null; then\n"
       << "  echo \"run.sh: yade failed, see yade.log:\" >&2; tail -5 yade.log >&2\n";
  } else {
    os << "if ! " << prog << " -in in.bounce -log log." << prog << " -screen " << screen
       << " \"$@\""
       << " </dev/null; then\n"
       << "  echo \"run.sh: " << prog << " failed, see log." << prog << ":\" >&2; tail -5 log."
       << prog << " >&2\n";
  }
  os << "  exit 1\n"
     << "fi\n"
     << "[ -s trace.csv ] || { echo \"run.sh: " << prog << " wrote no trace.csv\" >&2; exit 1; }\n"
     << "awk -F, -v R=" << FormatShortest(in.radius_m) << " -v g=" << FormatShortest(in.g_m_s2)
     << " -f impacts.awk trace.csv > impacts.csv.tmp\n"
     << "mv impacts.csv.tmp impacts.csv\n"
     << "n=$(($(wc -l < impacts.csv) - 1))\n"
     << "[ \"$n\" -ge 1 ] || { echo \"run.sh: no impact found in trace.csv\" >&2; exit 1; }\n"
     << "echo \"run.sh: " << prog << " done, $n impacts in impacts.csv\"\n";
  return os.str();
}

}  // namespace exporter

const char* ExportSceneName(ExportScene scene) {
  switch (scene) {
    case ExportScene::kBounce:
      return "bounce";
    case ExportScene::kPacking:
      return "packing";
    case ExportScene::kColumn:
      return "column";
  }
  return "?";
}

bool ParseExportScene(const std::string& text, ExportScene* scene) {
  if (text == "bounce") {
    *scene = ExportScene::kBounce;
  } else if (text == "packing") {
    *scene = ExportScene::kPacking;
  } else if (text == "column") {
    *scene = ExportScene::kColumn;
  } else {
    return false;
  }
  return true;
}

const char* SimulatorProgram(ExportTarget target) {
  switch (target) {
    case ExportTarget::kLammps:
      return "lmp";
    case ExportTarget::kLiggghts:
      return "liggghts";
    case ExportTarget::kYade:
      return "yade";
  }
  return "?";
}

const char* SimulatorPackage(ExportTarget target) {
  switch (target) {
    case ExportTarget::kLammps:
      return "lammps";
    case ExportTarget::kLiggghts:
      return "liggghts";
    case ExportTarget::kYade:
      return "yade";
  }
  return "?";
}

std::string DetectSimulatorVersion(ExportTarget target) {
  const std::string prog = SimulatorProgram(target);
  if (Trim(Capture("command -v " + prog + " 2>/dev/null")).empty()) return "";
  if (target == ExportTarget::kLammps) {
    // -log none: the simulators open a log file in the working directory before they read -h;
    // exporting must not leave files outside its output directory.
    const std::string out = Capture("lmp -log none -h </dev/null 2>&1");
    const std::string key = "Parallel Simulator - ";
    const size_t at = out.find(key);
    if (at == std::string::npos) return "LAMMPS (unknown version)";
    return "LAMMPS " + Trim(out.substr(at + key.size(), out.find('\n', at) - at - key.size()));
  }
  if (target == ExportTarget::kLiggghts) {
    const std::string out = Capture("liggghts -log none -h </dev/null 2>&1");
    const std::string key = "(Version ";
    const size_t at = out.find(key);
    if (at == std::string::npos) return "LIGGGHTS (unknown version)";
    const size_t end = out.find(',', at);
    return Trim(out.substr(at + key.size(), end - at - key.size()));
  }
  const std::string out = Capture("yade --version </dev/null 2>&1");
  const std::string key = "Yade version:";
  const size_t at = out.find(key);
  if (at == std::string::npos) return "Yade (unknown version)";
  return "Yade " + Trim(out.substr(at + key.size(), out.find('\n', at) - at - key.size()));
}

bool ExportOptions::IsValid(std::string* error) const {
  auto fail = [error](const std::string& m) {
    if (error) *error = m;
    return false;
  };
  if (impacts < 1 || impacts > 10000) {
    return fail("impacts = " + std::to_string(impacts) + " must be in [1, 10000]");
  }
  if (!(time_step_e_error > 0.0 && time_step_e_error < 0.1)) {
    return fail("time_step_e_error = " + FormatShortest(time_step_e_error) +
                " must be in (0, 0.1)");
  }
  if (!(max_e_error > 0.0 && max_e_error <= 0.01)) {
    return fail("max_e_error = " + FormatShortest(max_e_error) + " must be in (0, 0.01]");
  }
  if (packing_particles < 1 || packing_particles > 1000000) {
    return fail("packing_particles = " + std::to_string(packing_particles) +
                " must be in [1, 1e6]");
  }
  if (!(packing_time_s > 0.0 && packing_time_s <= 100.0)) {
    return fail("packing_time_s = " + FormatShortest(packing_time_s) + " must be in (0, 100]");
  }
  if (!(packing_restitution == 0.0 || (packing_restitution > 0.0 && packing_restitution < 1.0))) {
    return fail("packing_restitution = " + FormatShortest(packing_restitution) +
                " must be in (0, 1), or 0 for the fit's");
  }
  if (scene == ExportScene::kPacking && target == ExportTarget::kYade) {
    return fail("scene packing: written for lammps and liggghts only (target yade)");
  }
  if (scene == ExportScene::kColumn && target == ExportTarget::kLiggghts) {
    return fail("scene column: written for lammps and yade only (target liggghts)");
  }
  if (scene == ExportScene::kColumn) return column.IsValid(error);
  return true;
}

namespace exporter {

nlohmann::json ExportedLawJson(const ParamFile& pf, const ContactLaw& law, const Scene& scene) {
  if (pf.schema == kParamFileSchema && pf.doc.contains("law")) return pf.doc["law"];
  return LawJson(law, law.ParameterValues(), scene.law.expression);
}

MappedFile MapParamFile(const std::string& path, ExportTarget target, bool force) {
  MappedFile f{ReadParamFile(path), {}, nullptr, {}, {}, {}, {}};
  CheckOutcome(f.pf, path, force);
  f.replay = ReplayFromParamFile(f.pf, path);
  const Scene& scene = f.replay.scene;
  f.law = CreateLaw(scene.law, scene);
  f.body = BodyFromScene(scene);
  f.speeds = MappingSpeeds(f.replay, *f.law);
  std::sort(f.speeds.begin(), f.speeds.end());
  f.mapping = MapLaw(scene, f.speeds, target);
  for (double v : f.speeds) {
    f.e_fit.push_back(
        SimulateContact(*f.law, f.law->ParameterValues(), f.body, v, 0.0).restitution);
  }
  return f;
}

void CheckOutputDirectory(const std::string& dir, bool force) { CheckDirectory(dir, force); }
void PrepareOutputDirectory(const std::string& dir, bool force) { PrepareDirectory(dir, force); }

void AddVersionNotes(ExportResult* r, ExportTarget target, const std::string& requested) {
  r->simulator_version = requested;
  if (r->simulator_version.empty()) r->simulator_version = DetectSimulatorVersion(target);
  const std::string verified = VerifiedSimulatorVersion(target);
  if (r->simulator_version.empty()) {
    r->simulator_version = verified;
    r->notes.push_back(std::string(SimulatorProgram(target)) +
                       " is not on PATH: written for the verified " + verified);
  } else if (r->simulator_version != verified) {
    r->notes.push_back(r->simulator_version + " is not the verified " + verified +
                       ": its mappings and slip compensations are assumed; check with the "
                       "integration suite");
  }
}

}  // namespace exporter

ExportResult ExportDeck(const std::string& params_path, const std::string& out_dir,
                        const ExportOptions& options) {
  std::string why;
  if (!options.IsValid(&why)) throw Error(ErrorCode::kUsage, "export: " + why);
  if (options.scene == ExportScene::kColumn) {
    return exporter::ExportColumn(params_path, out_dir, options);
  }
  // Stage 1: the parameter file, its fit outcome, the replay scene, the output directory.
  const ParamFile pf = ReadParamFile(params_path);
  CheckOutcome(pf, params_path, options.force);
  CheckDirectory(out_dir, options.force);
  const Replay replay = ReplayFromParamFile(pf, params_path);
  const Scene& scene = replay.scene;
  const std::unique_ptr<ContactLaw> law = CreateLaw(scene.law, scene);
  const ContactBody body = BodyFromScene(scene);
  const double g = scene.EffectiveGravity();

  ExportResult r;
  r.target = ExportTargetName(options.target);
  r.scene = ExportSceneName(options.scene);
  r.law = scene.law.name;
  r.law_json = exporter::ExportedLawJson(pf, *law, scene);
  ReadLawMisfit(pf, &r);
  exporter::AddVersionNotes(&r, options.target, options.simulator_version);
  if (scene.effects.drag != DragModel::kNone) {
    r.notes.push_back("air drag (" + std::string(DragModelName(scene.effects.drag)) +
                      ") is not exported: the simulator flies the ball in vacuum");
  }
  if (scene.effects.surface_compliance) {
    r.notes.push_back("surface compliance is not exported: the wall is rigid");
  }
  if (scene.effects.buoyancy)
    r.notes.push_back("buoyancy: gravity set to g_eff = " + FormatShortest(g));

  // Stage 2: the mapping over the measured speeds; refuse an approximation unless allowed.
  std::vector<double> speeds = MappingSpeeds(replay, *law);
  std::sort(speeds.begin(), speeds.end());
  const Mapping m = MapLaw(scene, speeds, options.target);
  if (m.max_e_error > options.max_e_error && !options.allow_approximation) {
    throw Error(ErrorCode::kBadParameter,
                params_path + ": law " + m.law + " cannot be expressed in " + r.target +
                    " within e error " + FormatShortest(options.max_e_error) +
                    ": the closest native law (" + m.native_law + ") is off by " +
                    FormatShortest(m.max_e_error) + " over " + FormatShortest(speeds.front()) +
                    " .. " + FormatShortest(speeds.back()) +
                    " m/s; not exported (ExportOptions::allow_approximation accepts it)");
  }
  r.native_law = m.native_law;
  r.kind = m.kind;
  r.exact = m.exact;
  r.max_e_error = m.max_e_error;
  r.max_contact_time_error = m.max_contact_time_error;
  r.coefficients = m.coefficients;
  r.speeds_m_s = speeds;

  // Stage 3: time step and run length.
  DeckInput in;
  in.mapping = m;
  in.options = options;
  in.params_path = params_path;
  in.law_summary = LawSummary(scene);
  in.radius_m = scene.ball.Radius();
  in.mass_kg = scene.ball.Mass();
  in.density_kg_m3 = in.mass_kg / scene.ball.Volume();
  const double nu = scene.ball.ResolvedPoissonRatio();
  in.poisson_ratio = std::isfinite(nu) ? nu : 0.3;
  in.g_m_s2 = g;
  TimeStep ts;
  if (options.scene == ExportScene::kBounce) {
    ts = ChooseTimeStep(m, body, g, options.time_step_e_error);
    const RunPlan plan = PlanBounce(scene, *law, options.impacts, g);
    in.release_height_m = plan.release_height_m;
    r.run_time_s = plan.run_time_s;
  } else {
    // Packing: linear springs k_n = 1e7 N/m between 1 cm steel spheres (m* = m/2) with the fit's
    // e at the middle measured speed.
    const size_t mid = speeds.size() / 2;
    in.packing_restitution =
        options.packing_restitution > 0.0
            ? options.packing_restitution
            : SimulateContact(*law, law->ParameterValues(), body, speeds[mid], 0.0).restitution;
    const double m_sphere = 7800.0 * M_PI * 1e-6 / 6.0;
    const double le = std::log(in.packing_restitution);
    const double zeta = -le / std::sqrt(le * le + M_PI * M_PI);
    const NativeModel pp(NativeForm::kLinear, false, 1e7,
                         2.0 * zeta * std::sqrt(0.5 * m_sphere * 1e7));
    const ContactBody pair = ContactBody::BallOnRigidWall(0.5 * m_sphere, 0.005);
    ts.contact_time_s = pp.ContactTimeAt(pair, 1.0);
    ts.dt_s = ts.contact_time_s / kPackingStepsPerContact;
    ts.steps_per_contact = kPackingStepsPerContact;
    ts.e_error = MaxTimeStepError(pp, pair, {0.1, 2.0}, ts.dt_s, 0.0);
    r.run_time_s = options.packing_time_s;
    r.packing_restitution = in.packing_restitution;
    r.notes.push_back("packing: linear springs k_n = k_s = 1e7 N/m, mu = 0.3, pairwise e = " +
                      FormatShortest(in.packing_restitution) +
                      (options.packing_restitution > 0.0
                           ? std::string(" (given, not the fit's)")
                           : " (the fit's e at " + FormatShortest(speeds[mid]) + " m/s)"));
  }
  r.time_step_s = ts.dt_s;
  r.time_step_e_error = ts.e_error;
  r.steps_per_contact = ts.steps_per_contact;
  r.steps = static_cast<long>(std::ceil(r.run_time_s / ts.dt_s));
  r.trace_every = std::max(1, static_cast<int>(std::floor(kTraceInterval_s / ts.dt_s * 1.000001)));
  in.time_step_s = ts.dt_s;
  in.steps = r.steps;
  in.trace_every = r.trace_every;
  in.comments = HeaderComments(in, r, ts);

  // Stage 4: the files, each written atomically.
  std::vector<std::pair<std::string, std::string>> files;
  const bool bounce = options.scene == ExportScene::kBounce;
  switch (options.target) {
    case ExportTarget::kLammps:
      files.push_back(bounce
                          ? std::pair{std::string("in.bounce"), exporter::LammpsBounceDeck(in)}
                          : std::pair{std::string("in.packing"), exporter::LammpsPackingDeck(in)});
      break;
    case ExportTarget::kLiggghts:
      files.push_back(
          bounce ? std::pair{std::string("in.bounce"), exporter::LiggghtsBounceDeck(in)}
                 : std::pair{std::string("in.packing"), exporter::LiggghtsPackingDeck(in)});
      break;
    case ExportTarget::kYade:
      files.push_back({"bounce.py", exporter::YadeBounceScript(in)});
      break;
  }
  files.push_back({"run.sh", exporter::RunScript(in)});
  files.push_back(bounce ? std::pair{std::string("impacts.awk"), exporter::ImpactsAwk()}
                         : std::pair{std::string("packing.awk"), exporter::PackingAwk()});
  PrepareDirectory(out_dir, options.force);  // only now: a refusal leaves nothing behind
  for (const auto& f : files) r.files.push_back(f.first);
  r.files.push_back("mapping.json");
  const WriteOptions wo{.force = true, .inputs = {params_path}};
  for (const auto& [name, text] : files) {
    WriteFileAtomically((fs::path(out_dir) / name).string(), text, wo);
  }
  fs::permissions(fs::path(out_dir) / "run.sh",
                  fs::perms::owner_exec | fs::perms::group_exec | fs::perms::others_exec,
                  fs::perm_options::add);
  WriteFileAtomically((fs::path(out_dir) / "mapping.json").string(),
                      DumpJson(ExportResultJson(r), 2) + "\n", wo);
  return r;
}

nlohmann::json ExportResultJson(const ExportResult& r) {
  nlohmann::json coeffs = nlohmann::json::object();
  for (const auto& [k, v] : r.coefficients) coeffs[k] = v;
  return {{"schema", kExportSchema},
          {"target", r.target},
          {"scene", r.scene},
          {"simulator_version", r.simulator_version},
          {"law", r.law_json.is_object() ? r.law_json : nlohmann::json(nullptr)},
          {"native_law", r.native_law},
          {"mapping", r.kind},
          {"exact", r.exact},
          {"max_e_error", r.max_e_error},
          {"max_contact_time_rel_error", r.max_contact_time_error},
          {"law_misfit_e", std::isfinite(r.law_misfit_e) ? nlohmann::json(r.law_misfit_e)
                                                         : nlohmann::json(nullptr)},
          {"law_misfit_tolerance_e", std::isfinite(r.law_misfit_tolerance_e)
                                         ? nlohmann::json(r.law_misfit_tolerance_e)
                                         : nlohmann::json(nullptr)},
          {"coefficients", coeffs},
          {"speeds_m_s", r.speeds_m_s},
          {"time_step_s", r.time_step_s},
          {"steps_per_contact", r.steps_per_contact},
          {"time_step_e_error", r.time_step_e_error},
          {"steps", r.steps},
          {"run_time_s", r.run_time_s},
          {"trace_every_steps", r.trace_every},
          {"packing_restitution",
           r.packing_restitution > 0.0 ? nlohmann::json(r.packing_restitution) : nullptr},
          {"files", r.files},
          {"column", r.column},
          {"notes", r.notes},
          {"warnings", WarningsJson(r.warnings)}};
}

}  // namespace bouncecal
