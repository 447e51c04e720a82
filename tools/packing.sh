#!/usr/bin/env bash
# The seed paper's packing validation (seed 002, docs/physics.md §1; issue 12) run through
# `bouncecal export --scene packing`: 2000 spheres (d = 1 cm, 7800 kg/m^3) poured from a 20 cm
# hopper into a cylinder of radius 10 cm, k_n = k_s = 1e7 N/m, mu = 0.3, the fitted damping.
# Prints a Markdown table: packing density between z = 0.005 and 0.045 m (paper: 0.625; classic
# experiments 0.63-0.64), wall time with N and 1 MPI ranks (speed-up), and the density for other
# pairwise restitutions on 1 rank (the paper: damping barely changes the density).
#
# Usage: tools/packing.sh [--params FILE] [--target lammps|liggghts] [--time S] [--np N]
#                         [--restitutions "0.3 0.6"]
#   --params: a parameter file (default: calibrate the bundled recording with the seed law)
#   --time:   simulated seconds (default 3, the paper's); --np: ranks of the main run (default 2)
# Needs build/bouncecal, the simulator and mpirun (tools/install-integration-deps.sh).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin="$root/build/bouncecal"
params="" target=lammps time_s=3 np=2 restitutions="0.3 0.6"
while [ $# -gt 0 ]; do
  case "$1" in
    --params) params=$2; shift 2 ;;
    --target) target=$2; shift 2 ;;
    --time) time_s=$2; shift 2 ;;
    --np) np=$2; shift 2 ;;
    --restitutions) restitutions=$2; shift 2 ;;
    *) echo "packing.sh: unknown argument $1" >&2; exit 2 ;;
  esac
done
[ -x "$bin" ] || { echo "packing.sh: $bin missing: run tools/build.sh" >&2; exit 1; }
work=$(mktemp -d "${TMPDIR:-/tmp}/bouncecal_packing.XXXXXX")
trap 'rm -rf "$work"' EXIT
if [ -z "$params" ]; then
  params="$work/params.json"
  "$bin" calibrate "$root/data/default_steel_copper.flac" --scene "$root/data/default_steel_copper.toml" \
    --law walton-braun -o "$params" >/dev/null
fi

# run DIR NP -> "density,in_slab,spheres,wall_s,ranks"
run() { NP=$2 "$1/run.sh" | tail -1; }

echo "packing: $target, $time_s s simulated, params $params" >&2
"$bin" export "$params" --to "$target" --scene packing --packing-time "$time_s" -o "$work/fit" \
  --json >"$work/fit.json"
field() { grep -o "\"$1\": [0-9.e+-]*" "$work/fit.json" | head -1 | awk '{print $2}'; }
e_fit=$(field packing_restitution)
e_fit=$(awk -v e="$e_fit" 'BEGIN{printf "%.4f", e}')
dt=$(field time_step_s)
steps=$(field steps)
echo "load average before the runs: $(cut -d' ' -f1-3 /proc/loadavg)"
echo
echo "| ranks | pairwise e | density 0.005-0.045 m | spheres in slab / poured | wall time (s) |"
echo "|---|---|---|---|---|"
main=$(run "$work/fit" "$np")
IFS=, read -r d_main n_main total_main t_main _ <<<"$main"
echo "| $np | $e_fit (fit) | $d_main | $n_main / $total_main | $t_main |"
if [ "$np" != 1 ]; then
  one=$(run "$work/fit" 1)
  IFS=, read -r d_one n_one total_one t_one _ <<<"$one"
  echo "| 1 | $e_fit (fit) | $d_one | $n_one / $total_one | $t_one |"
fi
for e in $restitutions; do
  "$bin" export "$params" --to "$target" --scene packing --packing-time "$time_s" \
    --packing-restitution "$e" -o "$work/e_$e" >/dev/null
  row=$(run "$work/e_$e" 1)
  IFS=, read -r d n total t _ <<<"$row"
  echo "| 1 | $e | $d | $n / $total | $t |"
done
if [ "$np" != 1 ]; then
  echo
  echo "time step $dt s, $steps steps; speed-up 1 -> $np ranks: $(awk -v a="$t_one" -v b="$t_main" 'BEGIN{printf "%.2f", a/b}')x"
fi
