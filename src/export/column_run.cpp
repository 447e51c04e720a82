// run.sh and column.awk of the column scene (column.hpp): run the simulator, then turn its dumps
// (LAMMPS' custom dump format, which the Yade script also writes) into profile.csv, front.csv
// and summary.json.
#include <sstream>

#include "bouncecal/core/user_text.hpp"
#include "bouncecal/export/export.hpp"
#include "export/column_deck.hpp"
#include "export/deck.hpp"

namespace bouncecal::exporter {

std::string ColumnAwk() {
  return R"AWK(# column.awk (bouncecal export): the collapse of seed 003's column from the simulator's output.
# Inputs, in this order: the simulator's log (its "Loop time of W on P procs for N steps with A
# atoms" lines and the deck's "column: ..." lines), column.dump (a snapshot every ~10 ms from the
# gate's removal, LAMMPS custom format: id x y z radius) and rest.dump (the last state).
# The deposit of a snapshot: x is cut into bins of width w (the mean bead diameter) across the
# box's width; from the left wall the bins are followed while the beads centred in them cover at
# least half the floor (sum of pi r^2 >= 0.45 w width: half a hexagonal monolayer, 0.907): beyond,
# beads lie scattered rather than as a layer (the paper's front is 2-3 beads thick). Its front is
# the largest x + r of those beads and its height in a bin the largest z + r there.
# The failure at the first frame (the paper: along the diagonal (0, H)-(L, 0) by 0.04 s): of the
# beads above and below that diagonal at t = 0, the fractions that have moved by more than a tenth
# of w at the snapshot nearest `frame` (what the paper's video could not resolve).
# Writes profile.csv (label,time_s,x_m,height_m: the deposit at t = 0, at multiples of the
# paper's frame interval `frame` up to `frames` of them, and at rest), front.csv
# (time_s,front_m,height_m every snapshot) and prints the measured part of summary.json.
# Usage: awk -v dt=S -v every=S -v w=M -v width=0.2 -v h_col=0.18 -v frame=0.04 -v frames=13 -v li=0.1 -v ranks=N -v wall=S
#            -f column.awk LOG column.dump rest.dump
BEGIN {
  nloop = 0; beads = -1; atrest = -1; h0 = -1
  print "label,time_s,x_m,height_m" > "profile.csv.tmp"
  print "time_s,front_m,height_m" > "front.csv.tmp"
}
FNR == 1 { if (natoms_seen) finish(); file++; section = "" }
file == 1 && /Loop time of/ {
  for (i = 1; i <= NF; i++) {
    if ($i == "of") loop_wall[nloop] = $(i + 1)
    if ($i == "for") loop_steps[nloop] = $(i + 1)
  }
  nloop++; next
}
file == 1 && /^column: beads/ { beads = $3; floor_n = $5; box = $7 "," $8 "," $9 "," $10 "," $11 "," $12; next }
file == 1 && /^column: collapse ended/ { atrest = $NF + 0; next }
file == 1 { next }
/^ITEM: TIMESTEP/ { section = "step"; next }
/^ITEM: NUMBER OF ATOMS/ { section = "n"; next }
/^ITEM: BOX/ { section = "box"; next }
/^ITEM: ATOMS/ { section = "atoms"; next }
section == "step" { if (natoms_seen) finish(); step = $1 + 0; snapfile = file; natoms_seen = 1; section = ""; next }
section == "atoms" {
  if (snapfile == 2 && step == 0) { x0[$1] = $2; z0[$1] = $4 }
  cx[$1] = $2; cz[$1] = $4
  b = int($2 / w); occ[b] += 3.14159265358979 * $5 * $5 / (w * width)
  if (!(b in top) || $4 + $5 > top[b]) top[b] = $4 + $5
  if (!(b in right) || $2 + $5 > right[b]) right[b] = $2 + $5
  next
}
function finish(   t, k, b, front, height, label) {
  t = step * dt
  front = 0; height = 0
  for (b = 0; (b in occ) && occ[b] >= 0.45; b++) { if (right[b] > front) front = right[b]; if (top[b] > height) height = top[b] }
  label = ""
  if (snapfile == 3) label = "rest"
  else if (step == 0) label = "0"
  else { k = int(t / frame + 0.5); if (k >= 1 && k <= frames && (t - k * frame) ^ 2 < (0.5 * every) ^ 2) label = sprintf("%.2f", k * frame) }
  if (label == sprintf("%.2f", frame) && !done_failure) failure()
  if (label != "") for (b = 0; (b in occ) && occ[b] >= 0.45; b++) printf "%s,%.6g,%.6g,%.6g\n", label, t, (b + 0.5) * w, top[b] > "profile.csv.tmp"
  if (snapfile == 2) printf "%.6g,%.6g,%.6g\n", t, front, height > "front.csv.tmp"
  if (snapfile == 2 && h0 < 0) h0 = height
  last_front = front; last_height = height; last_t = t
  natoms_seen = 0
  for (b in occ) { delete occ[b]; delete top[b]; delete right[b] }
  for (id in cx) { delete cx[id]; delete cz[id] }
}
function failure(   id, above, moved) {
  done_failure = 1
  for (id in cx) {
    if (!(id in x0)) continue
    above = z0[id] > h_col * (1 - x0[id] / li)
    moved = (cx[id] - x0[id]) ^ 2 + (cz[id] - z0[id]) ^ 2 > (0.1 * w) ^ 2
    n_side[above]++; n_moved[above] += moved
  }
}
END {
  if (natoms_seen) finish()
  close("profile.csv.tmp"); close("front.csv.tmp")
  settle_steps = loop_steps[0] + 0; collapse_steps = loop_steps[1] + 0
  settle_wall = loop_wall[0] + 0; collapse_wall = loop_wall[1] + 0
  pps = (collapse_wall > 0 && beads > 0) ? beads * collapse_steps / collapse_wall / ranks : 0
  printf "  \"beads\": %d,\n  \"floor_spheres\": %d,\n  \"box_m\": [%s],\n", beads, floor_n, box
  printf "  \"initial_height_m\": %.6g,\n  \"column_length_m\": %g,\n  \"aspect_ratio\": %.4g,\n", h0, li, h0 / li
  printf "  \"run_out_m\": %.6g,\n  \"run_out_normalized\": %.4g,\n", last_front, (last_front - li) / li
  printf "  \"final_height_m\": %.6g,\n  \"final_height_normalized\": %.4g,\n", last_height, last_height / li
  printf "  \"at_rest\": %s,\n  \"time_to_rest_s\": %s,\n", atrest == 1 ? "true" : "false", atrest == 1 ? sprintf("%.4g", last_t) : "null"
  printf "  \"settle_steps\": %d,\n  \"collapse_steps\": %d,\n  \"steps\": %d,\n", settle_steps, collapse_steps, settle_steps + collapse_steps
  printf "  \"ranks\": %d,\n  \"wall_time_s\": %.4g,\n  \"settle_wall_s\": %.4g,\n  \"collapse_wall_s\": %.4g,\n", ranks, wall, settle_wall, collapse_wall
  printf "  \"particle_steps_per_s_per_rank\": %.4g,\n", pps
  printf "  \"moved_by_first_frame\": {\"above_diagonal\": %s, \"below_diagonal\": %s},\n", \
    n_side[1] ? sprintf("%.3f", n_moved[1] / n_side[1]) : "null", n_side[0] ? sprintf("%.3f", n_moved[0] / n_side[0]) : "null"
}
)AWK";
}

namespace {

// Text inside a shell single-quoted printf format: ' closes and reopens the quote, % doubles.
std::string ShellPrintfText(const std::string& text) {
  std::string out;
  for (char c : text) {
    if (c == '\'') {
      out += "'\\''";
    } else if (c == '%') {
      out += "%%";
    } else if (c == '"' || c == '\\') {
      out += ' ';
    } else {
      out += c;
    }
  }
  return out;
}

}  // namespace

std::string ColumnRunScript(const ColumnPlan& p) {
  const ExportTarget t = p.target;
  const std::string prog = SimulatorProgram(t), pkg = SimulatorPackage(t);
  const bool yade = t == ExportTarget::kYade;
  std::ostringstream os;
  os << "#!/bin/sh\n"
     << "# bouncecal export (column): runs " << prog
     << " on this directory's deck, then column.awk\n"
     << "# turns its dumps into profile.csv, front.csv and summary.json.\n"
     << (yade ? "# NP=N ./run.sh runs Yade with N threads (-j N); BOUNCECAL_SETTLE_STEPS and\n"
                "# BOUNCECAL_COLLAPSE_STEPS shorten the phases.\n"
              : "# NP=N ./run.sh runs N MPI ranks; extra arguments go to lmp (-var settle_steps N\n"
                "# -var collapse_steps N shorten the phases).\n")
     << "# BOUNCECAL_POSTPROCESS=1 ./run.sh only remakes the outputs from a finished run's log "
        "and\n"
     << "# dumps (its wall time kept from summary.json).\n"
     << "# Fails loudly (message on stderr, non-zero exit) when " << prog
     << " is missing or fails.\n"
     << "set -eu\n"
     << "cd \"$(dirname \"$0\")\"\n"
     << "NP=${NP:-1}\n"
     << "if [ \"${BOUNCECAL_POSTPROCESS:-0}\" = 1 ]; then\n"
     << "  [ -s rest.dump ] || { echo \"run.sh: no finished run to post-process\" >&2; exit 1; }\n"
     << "  wall=$(grep -o '\"wall_time_s\": [0-9.e+-]*' summary.json 2>/dev/null | awk '{print "
        "$2}')\n"
     << "  wall=${wall:-0}\n"
     << "else\n"
     << "if ! command -v " << prog << " >/dev/null 2>&1; then\n"
     << "  echo \"run.sh: " << prog << " not found on PATH (Debian 12: apt-get install -y " << pkg
     << ")\" >&2\n"
     << "  exit 127\n"
     << "fi\n"
     << "rm -f column.dump rest.dump profile.csv front.csv summary.json\n"
     << "start=$(date +%s.%N)\n";
  std::string log;
  if (yade) {
    log = "yade.log";
    os << "if ! yade -j \"$NP\" -n -x column.py \"$@\" >yade.log 2>&1 </dev/null; then\n"
       << "  echo \"run.sh: yade failed, see yade.log:\" >&2; tail -5 yade.log >&2\n";
  } else {
    log = "log.column";
    os << "command -v mpirun >/dev/null 2>&1 || { echo \"run.sh: mpirun not found on PATH "
          "(Debian 12: apt-get install -y openmpi-bin)\" >&2; exit 127; }\n"
       << "MPIFLAGS=\"--oversubscribe\"\n"
       << "if [ \"$(id -u)\" = 0 ]; then MPIFLAGS=\"$MPIFLAGS --allow-run-as-root\"; fi\n"
       << "if ! mpirun $MPIFLAGS -np \"$NP\" lmp -in in.column -log log.column -screen none \"$@\" "
          "</dev/null; then\n"
       << "  echo \"run.sh: lmp failed, see log.column:\" >&2; tail -5 log.column >&2\n";
  }
  os << "  exit 1\n"
     << "fi\n"
     << "end=$(date +%s.%N)\n"
     << "[ -s rest.dump ] || { echo \"run.sh: " << prog << " wrote no rest.dump\" >&2; exit 1; }\n"
     << "wall=$(echo \"$end $start\" | awk '{printf \"%.3f\", $1 - $2}')\n"
     << "fi\n"
     << "{\n"
     << "  printf '{\\n  \"schema\": \"bouncecal.column/1\",\\n  \"simulator\": \"" << prog
     << "\",\\n'\n"
     << "  awk -v dt=" << FormatShortest(p.time_step_s)
     << " -v every=" << FormatShortest(p.dump_interval_s) << " -v w=" << FormatShortest(p.d_mean_m)
     << " -v width=" << FormatShortest(ColumnPaper::kBoxWidth_m)
     << " -v h_col=" << FormatShortest(ColumnPaper::kColumnHeight_m)
     << " -v frame=" << FormatShortest(ColumnPaper::kFrameInterval_s)
     << " -v frames=13 -v li=" << FormatShortest(ColumnPaper::kColumnLength_m)
     << " -v ranks=\"$NP\" -v wall=\"$wall\" -f column.awk " << log << " column.dump rest.dump\n"
     << "  printf '  \"time_step_s\": " << FormatShortest(p.time_step_s)
     << ",\\n  \"time_step_choice\": \"" << ShellPrintfText(p.time_step_choice)
     << "\",\\n  \"plan\": '\n"
     << "  cat column.json\n"
     << "  printf '}\\n'\n"
     << "} > summary.json.tmp\n"
     << "mv profile.csv.tmp profile.csv\n"
     << "mv front.csv.tmp front.csv\n"
     << "mv summary.json.tmp summary.json\n"
     << "echo \"run.sh: " << prog << " done in ${wall} s: profile.csv, front.csv, summary.json\"\n";
  return os.str();
}

}  // namespace bouncecal::exporter
