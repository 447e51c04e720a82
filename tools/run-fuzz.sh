#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz/fuzz_*.cpp) with clang into build-fuzz/ and runs each
# for SECONDS (default 60), seeded from the project's own inputs (data/, example scenes, the
# bundled recording, parameter and impacts files made by the CLI). Findings (crash-*, leak-*,
# timeout-*) stay in build-fuzz/findings/<target>/: each becomes a regression input under
# tests/fuzz/regressions/<target>/ (replayed by `tools/run-fuzz.sh 0`, which runs every target
# once over its corpus and regressions without fuzzing).
# BOUNCECAL_FUZZ_BUILD names another build directory configured with -DBOUNCECAL_FUZZ=ON (the
# sanitizer stage of CI reuses build-asan/, tools/run-sanitizers.sh); its settings are kept.
#   tools/run-fuzz.sh [SECONDS] [TARGET...]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
seconds=${1:-60}
shift || true
build=${BOUNCECAL_FUZZ_BUILD:-$root/build-fuzz}
"$root/tools/install-sanitizer-deps.sh"
if [ ! -f "$build/CMakeCache.txt" ]; then
  CXX=clang++ CC=clang cmake -S "$root" -B "$build" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBOUNCECAL_FUZZ=ON -DBOUNCECAL_BUILD_TESTS=OFF -DBOUNCECAL_BUILD_TOOLS=OFF \
    -DBOUNCECAL_PYTHON=OFF >/dev/null
fi
targets=("$@")
[ ${#targets[@]} -gt 0 ] || targets=(fuzz_scene fuzz_impacts fuzz_params fuzz_expression fuzz_audio fuzz_serve)
cmake --build "$build" -j "$(nproc)" --target "${targets[@]}"

seed() {  # target corpus-dir: the project's own valid inputs
  local t=$1 dir=$2
  mkdir -p "$dir"
  case $t in
    fuzz_scene) cp "$root"/data/*.toml "$root"/data/scenes/*.toml "$dir"/ 2>/dev/null || true ;;
    fuzz_impacts)
      printf '1.5\n1.87\n2.21\n2.53\n' >"$dir/list.txt"
      printf 'time_s,sigma_s\n1.5,1e-5\n1.87,1e-5\n2.21,1e-5\n' >"$dir/times.csv"
      printf '1.5\t1.5\timpact\n1.87\t1.87\timpact\n2.21\t2.21\timpact\n' >"$dir/labels.txt" ;;
    fuzz_params)
      [ -x "$root/build/bouncecal" ] && "$root/build/bouncecal" calibrate \
        "$root/data/default_steel_copper.flac" --scene "$root/data/default_steel_copper.toml" \
        --json >"$dir/params.json" 2>/dev/null || true ;;
    fuzz_expression)
      printf 'k * d^1.5 * (1 + c * v)' >"$dir/hc"; printf 'k*d + c*v' >"$dir/kv" ;;
    fuzz_audio)
      # A short cut of the bundled recording as WAV (libsndfile's header and data paths).
      [ -x "$root/build/bouncecal" ] && "$root/build/bouncecal" synth --preset phone-16k \
        --duration 2 --seed 1 --force -o "$dir/short.wav" >/dev/null 2>&1 || true
      rm -f "$dir"/*.truth.json ;;
    fuzz_serve)
      # The selector byte (tests/fuzz/fuzz_serve.cpp), then a query, a multipart body, live
      # messages (0xFF 0xFE between them, 'b' for binary), a request through the router.
      printf '\000/api/analyze?height=0.2&diameter=0.01&material=steel&set=k%%3D1e9&law=walton-braun' >"$dir/query"
      printf '\001multipart/form-data; boundary=xyz\n--xyz\r\nContent-Disposition: form-data; name="f"; filename="a.wav"\r\n\r\nRIFF\r\n--xyz--\r\n' >"$dir/multipart"
      printf '\002{"rate": 48000}' >"$dir/start"
      printf '\003{"stop": true}' >"$dir/stop"
      printf '\005{"rate": 8000}\377\376b\000\000\200\077\000\000\200\277\377\376{"stop": true}' >"$dir/live"
      printf '\006GET /api/sessions\n\n' >"$dir/sessions"
      printf '\006POST /api/export?to=lammps\napplication/json\n{"schema": "bouncecal.params/2"}' >"$dir/export" ;;
  esac
}

for t in "${targets[@]}"; do
  corpus=$build/corpus/$t
  findings=$build/findings/$t
  regressions=$root/tests/fuzz/regressions/$t
  mkdir -p "$findings"
  seed "$t" "$corpus"
  inputs=("$corpus")
  [ -d "$regressions" ] && inputs+=("$regressions")
  start=$SECONDS
  if [ "$seconds" = 0 ]; then
    "$build/$t" -runs=0 "${inputs[@]}"
  else
    # FUZZ_SEED fixes libFuzzer's random seed (CI: the same tree explores the same inputs, so a
    # CI run does not fail by luck); unset, every run explores anew.
    seed_flag=()
    [ -n "${FUZZ_SEED:-}" ] && seed_flag=(-seed="$FUZZ_SEED")
    "$build/$t" -max_total_time="$seconds" -timeout=20 -rss_limit_mb=4096 "${seed_flag[@]}" \
      -artifact_prefix="$findings/" "${inputs[@]}" 2>"$build/$t.log" || {
      echo "$t: FINDING (see $build/$t.log and $findings/)"; tail -30 "$build/$t.log"; exit 1; }
    echo "$t: $((SECONDS - start)) s, $(grep -o 'cov: [0-9]*' "$build/$t.log" | tail -1), \
$(grep -o 'Done [0-9]* runs' "$build/$t.log" | tail -1), no finding"
  fi
done
