#!/usr/bin/env bash
# Writes what bouncecal prints and writes for a fixed set of inputs into a folder, so that two
# builds can be compared byte for byte (a change meant to keep every output is checked with
# `diff -r`):
#
#   tools/golden_outputs.sh build/bouncecal /tmp/golden-before
#   ... change, rebuild ...
#   tools/golden_outputs.sh build/bouncecal /tmp/golden-after
#   diff -r /tmp/golden-before /tmp/golden-after && echo identical
#
# Inputs: the bundled recording (data/default_steel_copper.flac), a recording of every synth
# preset (`bouncecal synth --list-presets`, seed 1), a stereo recording of 250 s (three detection
# blocks), and the real recordings in ../shared/recordings when that folder exists. Each goes
# through detect (text, --json, --csv), analyze (text, --json) and calibrate (--json and its
# parameter file) with --threads 1, 2 and 3; the bundled recording also through report (HTML),
# simulate, export and laws. Every command's exit code, stdout and stderr are kept; the date in
# provenance sections (the only value that changes from run to run) is replaced by DATE.
set -euo pipefail

if [[ $# -ne 2 ]]; then
  echo "usage: $0 BOUNCECAL OUTDIR" >&2
  exit 2
fi
bin=$(realpath "$1")
out=$2
root=$(cd "$(dirname "$0")/.." && pwd)
shared=$(realpath -m "$root/../shared/recordings")
[[ -d $shared ]] || shared=/work/shared/recordings
mkdir -p "$out"
out=$(realpath "$out")
work=$(mktemp -d "${TMPDIR:-/tmp}/golden_outputs.XXXXXX")
trap 'rm -rf "$work"' EXIT
cd "$work"

# run NAME ARGS...: bouncecal ARGS in $work; NAME.out, NAME.err and NAME.code in $out.
run() {
  local name=$1
  shift
  local code=0
  "$bin" "$@" >"$out/$name.out" 2>"$out/$name.err" || code=$?
  echo "$code" >"$out/$name.code"
  sed -i -E 's/[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}Z/DATE/g' \
    "$out/$name.out" "$out/$name.err"
}

# keep NAME FILE...: copies written files into $out (dates replaced), then removes them.
keep() {
  local name=$1
  shift
  for f in "$@"; do
    if [[ -d $f ]]; then
      (cd "$f" && find . -type f | sort | while read -r g; do
        echo "== $g"
        sed -E 's/[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}Z/DATE/g' "$g"
      done) >"$out/$name.$(basename "$f").tree"
    elif [[ -f $f ]]; then
      case $f in
        *.wav | *.flac) sha256sum <"$f" >"$out/$name.$(basename "$f").sha256" ;;
        *) sed -E 's/[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}Z/DATE/g' "$f" \
             >"$out/$name.$(basename "$f")" ;;
      esac
    fi
    rm -rf "$f"
  done
}

# recording NAME FILE [SCENE]: detect / analyze / calibrate at 1, 2 and 3 threads.
recording() {
  local name=$1 file=$2 scene=${3:-}
  local scene_args=()
  [[ -n $scene ]] && scene_args=(--scene "$scene")
  for t in 1 2 3; do
    run "$name.t$t.detect" detect "$file" --threads "$t"
    run "$name.t$t.detect_json" detect "$file" --json --threads "$t"
    run "$name.t$t.detect_csv" detect "$file" --csv --threads "$t"
    run "$name.t$t.analyze" analyze "$file" "${scene_args[@]}" --threads "$t"
    run "$name.t$t.analyze_json" analyze "$file" "${scene_args[@]}" --json --threads "$t"
    if [[ -n $scene ]]; then
      run "$name.t$t.calibrate" calibrate "$file" "${scene_args[@]}" --json --threads "$t" \
        -o params.json
      keep "$name.t$t.calibrate" params.json
    fi
  done
}

# The bundled recording, and the commands that need no recording.
bundled=$root/data/default_steel_copper.flac
bundled_scene=$root/data/default_steel_copper.toml
recording bundled "$bundled" "$bundled_scene"
for t in 1 2 3; do
  run "bundled.t$t.report" report "$bundled" --scene "$bundled_scene" --threads "$t" -o report.html
  keep "bundled.t$t.report" report.html
  run "bundled.t$t.compare" calibrate "$bundled" --scene "$bundled_scene" --law all --jobs "$t" \
    --threads "$t" --json
  run "bundled.t$t.sequence_all" analyze "$bundled" --scene "$bundled_scene" --sequence all \
    --channel auto --start 0.5 --threads "$t" --json
done
run bundled.calibrate_params calibrate "$bundled" --scene "$bundled_scene" -o params.json
run bundled.simulate_params simulate --params params.json --json
for to in lammps liggghts yade; do
  run "bundled.export_$to" export params.json --to "$to" -o "deck_$to" --json
  keep "bundled.export_$to" "deck_$to"
done
for to in lammps liggghts; do
  run "bundled.export_packing_$to" export params.json --to "$to" --scene packing \
    -o "packing_$to" --json
  keep "bundled.export_packing_$to" "packing_$to"
done
keep bundled.calibrate_params params.json
run simulate_scene simulate --scene "$bundled_scene" --json
run simulate_scene_text simulate --scene "$bundled_scene"
run simulate_integrate simulate --scene "$bundled_scene" --integrate --json
run laws laws
while read -r law; do
  run "laws.$law" laws "$law"
  run "simulate.$law" simulate --scene "$bundled_scene" --law "$law" --max-impacts 8 --json
  [[ $law == expression ]] && continue
  # Every law's fit exported to every simulator (the mapping each registry row names).
  run "export.$law.calibrate" calibrate "$bundled" --scene "$bundled_scene" --law "$law" \
    -o "p_$law.json"
  for to in lammps liggghts yade; do
    run "export.$law.$to" export "p_$law.json" --to "$to" -o "x_${law}_$to" --force \
      --allow-approximation --json
    keep "export.$law.$to" "x_${law}_$to"
  done
  keep "export.$law.calibrate" "p_$law.json"
done < <("$bin" laws --json | python3 -c 'import json,sys; [print(l["name"]) for l in json.load(sys.stdin)["laws"]]')

# Every synth preset (its file and truth are outputs too), with the preset's scene.
run synth_presets synth --list-presets
for preset in $("$bin" synth --list-presets | awk 'NR > 0 && $1 ~ /^[a-z0-9-]+$/ {print $1}'); do
  run "synth.$preset" synth --preset "$preset" --seed 1 -o "$preset.wav"
  keep "synth.$preset" "$preset.truth.json"
  sha256sum <"$preset.wav" >"$out/synth.$preset.wav.sha256"
  scene=$root/data/scenes/$preset.toml
  [[ -f $scene ]] || scene=
  recording "preset.$preset" "$preset.wav" "$scene"
  rm -f "$preset.wav"
done

# A stereo recording in three detection blocks (DetectOptions::max_block_s = 120 s).
run synth_long synth --preset steel-copper --seed 2 --drops 24 --drop-gap 2 --duration 250 \
  --channels 2 -o long.wav
sha256sum <long.wav >"$out/synth_long.wav.sha256"
recording long long.wav
rm -f long.wav long.truth.json

# The shared real recordings.
if [[ -d $shared ]]; then
  for wav in "$shared"/*.wav; do
    name=$(basename "$wav" .wav)
    scene=${wav%.wav}.toml
    [[ -f $scene ]] || scene=
    recording "shared.$name" "$wav" "$scene"
  done
fi
echo "$(find "$out" -type f | wc -l) files in $out"
