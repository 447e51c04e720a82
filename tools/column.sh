#!/usr/bin/env bash
# Seed 003's granular column collapse (Fei et al. 2016; docs/column.md, issue 33) run through
# `bouncecal export --scene column`: the scaled column to rest in LAMMPS (1 and 2 MPI ranks) and
# in Yade, the damping study (the fitted e and --restitutions) in LAMMPS, and the full column
# (>= 25 000 beads) for a few thousand steps on 1 and 2 ranks to measure its cost.
# Prints Markdown tables: run-out and final height against the paper and published
# channel-collapse scaling at a = 1.8, the damping study, the measured strong scaling and the
# extrapolated cost of the full 0.6 s run on 1, 2, 16 and 64 ranks.
#
# Usage: tools/column.sh [--params FILE] [--wall-params FILE] [--scale S] [--full-steps N]
#                        [--restitutions "0.3 0.6 0.9"] [--skip-yade] [--skip-full] [--keep DIR]
#                        [--reuse]
#   --params: a parameter file (default: the bundled recording's fit, hertz-viscoelastic, e 0.920-0.956:
#             carried as its middle e, an approximation of 0.02 that --allow-approximation accepts)
#   --scale:  the scaled column's bead scale (default 0.333: ~930 beads of 16 mm)
#   --full-steps: steps of each phase of the full column's timing runs (default 1000)
#   --keep DIR: work in DIR and keep it; --reuse: with --keep, runs already finished there are
#             not rerun, only their outputs remade from their dumps (BOUNCECAL_POSTPROCESS=1)
# Needs build/bouncecal, lmp, yade and mpirun (tools/install-integration-deps.sh).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/build/bouncecal"
params="" wall_params="" scale=0.333 full_steps=1000 restitutions="0.3 0.6 0.9"
skip_yade=0 skip_full=0 keep="" reuse=0
while [ $# -gt 0 ]; do
  case "$1" in
    --params) params=$2; shift 2 ;;
    --wall-params) wall_params=$2; shift 2 ;;
    --scale) scale=$2; shift 2 ;;
    --full-steps) full_steps=$2; shift 2 ;;
    --restitutions) restitutions=$2; shift 2 ;;
    --skip-yade) skip_yade=1; shift ;;
    --skip-full) skip_full=1; shift ;;
    --keep) keep=$2; shift 2 ;;
    --reuse) reuse=1; shift ;;
    *) echo "column.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -x "$bin" ] || { echo "column.sh: $bin missing: run tools/build.sh" >&2; exit 1; }
if [ -n "$keep" ]; then
  mkdir -p "$keep"; work=$(cd "$keep" && pwd)
else
  work=$(mktemp -d "${TMPDIR:-/tmp}/bouncecal_column.XXXXXX")
  trap 'rm -rf "$work"' EXIT
fi
if [ -z "$params" ]; then
  params="$work/params.json"
  [ "$reuse" = 1 ] && [ -s "$params" ] || "$bin" calibrate "$root/data/default_steel_copper.flac" --scene "$root/data/default_steel_copper.toml" \
    -o "$params" >/dev/null
fi
wall_flag=()
[ -n "$wall_params" ] && wall_flag=(--wall-params "$wall_params")

# export NAME TARGET SCALE [extra flags...] -> $work/NAME
export_deck() {
  local name=$1 target=$2 s=$3; shift 3
  "$bin" export "$params" "${wall_flag[@]}" --to "$target" --scene column --scale "$s" \
    -o "$work/$name" --force --allow-approximation --json "$@" >"$work/$name.json"
}
# json FILE KEY -> the first number after "KEY":
json() { grep -o "\"$2\": [-0-9.e+]*" "$1" | head -1 | awk '{print $2}'; }
load() { cut -d' ' -f1-3 /proc/loadavg; }
# run NAME NP [args...]: runs the deck, returns nothing; summary in $work/NAME/summary.json
run() {
  local name=$1 np=$2 post=0; shift 2
  [ "$reuse" = 1 ] && [ -s "$work/$name/rest.dump" ] && [ -s "$work/$name/summary.json" ] && post=1
  BOUNCECAL_POSTPROCESS=$post NP=$np "$work/$name/run.sh" "$@" >"$work/$name.run.log" 2>&1 ||
    { echo "column.sh: $name failed:" >&2; tail -5 "$work/$name.run.log" >&2; exit 1; }
}
# copy FROM TO: a second run of the same deck (its dumps kept when reusing)
copy() {
  if [ "$reuse" = 1 ] && [ -s "$work/$2/rest.dump" ]; then  # keep the dumps, take the new deck's files
    for f in "$work/$1"/*; do case "$f" in *.dump|*.csv|*/summary.json|*/log.column|*/yade.log) ;; *) cp "$f" "$work/$2/" ;; esac; done
    return 0
  fi
  rm -rf "$work/$2"; cp -r "$work/$1" "$work/$2"
}
row() {  # row LABEL SIMULATOR DIR
  local s="$work/$3/summary.json"
  printf '| %s | %s | %s | %s | %.3f | %.2f | %.3f | %.2f | %s | %s | %.3g | %.0f | %.3g |\n' "$1" "$2" \
    "$(json "$s" ranks)" "$(json "$s" beads)" "$(json "$s" run_out_m)" "$(json "$s" run_out_normalized)" \
    "$(json "$s" final_height_m)" "$(json "$s" final_height_normalized)" "$(json "$s" time_to_rest_s || echo -)" \
    "$(json "$s" steps)" "$(json "$s" time_step_s)" "$(json "$s" wall_time_s)" \
    "$(json "$s" particle_steps_per_s_per_rank)"
}

echo "column: params $params, scale $scale, work $work" >&2
echo "load average before the runs: $(load) (2 cores)"
echo
echo "### Scaled column (scale $scale) to rest, against the paper and channel-collapse scaling (a = 1.8)"
echo
echo "| run | simulator | ranks | beads | L_f (m) | (L_f - L_i)/L_i | H_f (m) | H_f/L_i | time to rest (s) | steps | dt (s) | wall (s) | particle-steps/s/rank |"
echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|"
echo "| paper (Fei et al. 2016, fig. 7) | experiment, Yade DEM | | 25167 | not stated; front 2-3 beads thick | | not stated | | 0.40-0.52 | | | | |"
echo "| Lube et al. 2005 (2D channel): 1.2 a, a^0.4 | | | | 0.316 | 2.16 | 0.127 | 1.27 | | | | | |"
export_deck lammps lammps "$scale"
run lammps 1
row "fitted e" LAMMPS lammps
copy lammps lammps2
run lammps2 2
row "fitted e" LAMMPS lammps2
if [ "$skip_yade" = 0 ]; then
  export_deck yade yade "$scale"
  run yade 1
  row "fitted e" Yade yade
fi
echo
l=$(json "$work/lammps/summary.json" run_out_m) y=$(json "$work/yade/summary.json" run_out_m 2>/dev/null || true)
l2=$(json "$work/lammps2/summary.json" run_out_m) d=$(json "$work/lammps/column.json" mean)
echo "LAMMPS 1 vs 2 ranks (the same deck, only the order of floating-point sums differs): run-out $l vs $l2 m;"
[ -n "$y" ] && echo "LAMMPS vs Yade: $l vs $y m, $(awk -v a="$l" -v b="$y" -v d="$d" 'BEGIN{printf "%.1f", (a > b ? a - b : b - a) / d}') mean bead diameters ($d m)."
echo "Particle-steps: the beads after the trim times the collapse steps, per second of the collapse's wall time."
echo
echo "load average after: $(load)"
echo
echo "### Damping (LAMMPS, scale $scale, 1 rank)"
echo
echo "| pairwise e | L_f (m) | H_f (m) | time to rest (s) | wall (s) |"
echo "|---|---|---|---|---|"
s="$work/lammps/summary.json"
printf '| %s (fit) | %.4f | %.4f | %s | %.0f |\n' "$(json "$work/lammps/column.json" restitution)" \
  "$(json "$s" run_out_m)" "$(json "$s" final_height_m)" "$(json "$s" time_to_rest_s)" "$(json "$s" wall_time_s)"
for e in $restitutions; do
  export_deck "e_$e" lammps "$scale" --column-restitution "$e"
  run "e_$e" 1
  s="$work/e_$e/summary.json"
  printf '| %s | %.4f | %.4f | %s | %.0f |\n' "$e" "$(json "$s" run_out_m)" "$(json "$s" final_height_m)" \
    "$(json "$s" time_to_rest_s)" "$(json "$s" wall_time_s)"
done
echo
echo "### Rolling friction (LAMMPS, scale $scale, 1 rank, fitted e)"
echo
echo "| mu_r | L_f (m) | H_f (m) | time to rest (s) |"
echo "|---|---|---|---|"
for mr in 0 0.05 "$(json "$work/lammps/column.json" rolling_friction)"; do
  if [ "$mr" = "$(json "$work/lammps/column.json" rolling_friction)" ]; then s="$work/lammps/summary.json"; else
    export_deck "mr_$mr" lammps "$scale" --rolling-friction "$mr"; run "mr_$mr" 1; s="$work/mr_$mr/summary.json"; fi
  printf '| %s | %.4f | %.4f | %s |\n' "$mr" "$(json "$s" run_out_m)" "$(json "$s" final_height_m)" "$(json "$s" time_to_rest_s)"
done
[ "$skip_full" = 1 ] && exit 0

echo
echo "### Full column (scale 1), $full_steps settling + $full_steps collapse steps"
echo
echo "| simulator | ranks | spheres at start (beads + floor) | beads after trim | collapse steps | collapse wall (s) | particle-steps/s/rank |"
echo "|---|---|---|---|---|---|---|"
export_deck full lammps 1
full_row() {  # full_row SIMULATOR DIR
  local s="$work/$2/summary.json"
  printf '| %s | %s | %s | %s | %s | %.1f | %.3g |\n' "$1" "$(json "$s" ranks)" \
    "$(( $(json "$work/$2/column.json" poured_beads) + $(json "$work/$2/column.json" floor_spheres) ))" \
    "$(json "$s" beads)" "$(json "$s" collapse_steps)" "$(json "$s" collapse_wall_s)" \
    "$(json "$s" particle_steps_per_s_per_rank)"
}
run full 1 -var settle_steps "$full_steps" -var collapse_steps "$full_steps"
full_row LAMMPS full
copy full full2
run full2 2 -var settle_steps "$full_steps" -var collapse_steps "$full_steps"
full_row LAMMPS full2
if [ "$skip_yade" = 0 ]; then
  export_deck fully yade 1
  BOUNCECAL_SETTLE_STEPS=$((full_steps / 5)) BOUNCECAL_COLLAPSE_STEPS=$((full_steps / 5)) run fully 1
  full_row Yade fully
fi
echo
echo "load average after: $(load)"
echo
# Extrapolation: the full run settles the pour (its surplus included) for up to settle_max_s, then
# collapses 0.6 s, at the full column's dt; at the dense rate (the scaled column's collapse,
# 1 rank) and the sparse one (the full column's first steps, 1 rank), with ideal scaling.
dt=$(json "$work/full.json" time_step_s)
settle=$(json "$work/full/column.json" settle_max_s)
poured=$(json "$work/full/column.json" poured_beads)
beads=$(json "$work/full/column.json" expected_beads)
dense=$(json "$work/lammps/summary.json" particle_steps_per_s_per_rank)
sparse=$(json "$work/full/summary.json" particle_steps_per_s_per_rank)
echo "### Extrapolated cost of the full run (LAMMPS, $beads beads): settling (<= $settle s, $poured poured) + 0.6 s at dt = $dt s"
echo
echo "| ranks | beads per rank | wall time at the dense rate ($dense /s/rank) | at the sparse rate ($sparse /s/rank) |"
echo "|---|---|---|---|"
awk -v dt="$dt" -v settle="$settle" -v poured="$poured" -v n="$beads" -v dense="$dense" -v sparse="$sparse" 'BEGIN {
  work = poured * settle / dt + n * 0.6 / dt
  split("1 2 16 64", ranks, " ")
  for (i = 1; i <= 4; i++) {
    r = ranks[i]
    printf "| %d | %d | %.2g h | %.2g h |\n", r, n / r, work / (dense * r) / 3600, work / (sparse * r) / 3600
  }
  printf "\nwork: %.3g particle-steps (%.3g steps)\n", work, (settle + 0.6) / dt
}'
