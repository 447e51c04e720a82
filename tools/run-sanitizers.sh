#!/usr/bin/env bash
# The test suite under AddressSanitizer + UndefinedBehaviorSanitizer, the threaded tests under
# ThreadSanitizer, and the fuzz targets' regression inputs. Any sanitizer report fails the run
# (-fno-sanitize-recover=all, halt_on_error=1).
#
#   tools/run-sanitizers.sh [asan|tsan|all|ci]        (default all)
#
# asan  clang build in build-asan/ with -DBOUNCECAL_FUZZ=ON: the library, the CLI and every test
#       built with ASan + UBSan and libFuzzer's coverage instrumentation, so the same build also
#       gives the fuzz targets (tests/fuzz/). Runs every test except the labels `integration`
#       (the DEM simulators are not ours) and `bench` (timings), including `fuzz_replay_*`
#       (every input under tests/fuzz/regressions/).
# tsan  GCC build in build-tsan/ with ThreadSanitizer of the CLI and the five test programs
#       that run threads (batch --jobs, law comparison, detection threads, the parallel-for
#       helper); runs those tests.
# all   asan, then tsan.
# ci    what .ci/run runs: asan restricted to the test programs in CI_ASAN_TESTS below, the
#       fuzz targets for FUZZ_SECONDS each (default 30) from their seeds and regressions, with
#       libFuzzer's seed fixed (FUZZ_SEED, default 1: a CI run does not fail by luck), then
#       tsan. See .ci/run for the measured times.
#
# Build directories are reused when they exist (incremental); .ci/run removes them first.
# BOUNCECAL_ASAN_BUILD / BOUNCECAL_TSAN_BUILD name other directories.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
asan_dir=${BOUNCECAL_ASAN_BUILD:-$root/build-asan}
tsan_dir=${BOUNCECAL_TSAN_BUILD:-$root/build-tsan}
what=${1:-all}
jobs=$(nproc 2>/dev/null || echo 2)
"$root/tools/install-deps.sh"
"$root/tools/install-sanitizer-deps.sh"
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1:abort_on_error=0
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1

# The test programs of the CI subset: parsing (scene, parameter, impacts files), audio decoding,
# detection (onsets, sequences, the whole detector), calibration and the batch/threads, the
# hardening cases and the CLI's bad-input exit codes. Left out in CI (run by `asan`): the
# exporters, the report, synth, the law catalogue's sweeps, the README's examples.
CI_ASAN_TESTS=(
  scene_test param_file_test impacts_file_test given_scene_test
  audio_test blocks_test onsets_test sequence_test detect_test
  kinematics_test calibrate_test calibrate_cli_test hardening_test cli_test contact_map_test
)
TSAN_TESTS=(calibrate_cli_test calibrate_test hardening_test blocks_test parallel_test)
TSAN_REGEX='Batch|Jobs|LawComparison|CalibrateCompare|Parallel|Async|Thread'

timed() {  # name command...: runs it, prints its wall time like .ci/run's stages
  local name=$1 start=$SECONDS
  shift
  "$@"
  echo "sanitizers: $name took $((SECONDS - start)) s"
}

asan_configure() {
  CXX=clang++ CC=clang cmake -S "$root" -B "$asan_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBOUNCECAL_FUZZ=ON -DBOUNCECAL_BUILD_TESTS=ON -DBOUNCECAL_BUILD_TOOLS=OFF \
    -DBOUNCECAL_PYTHON=OFF >/dev/null
}

run_asan() {  # [test programs...]: none = all
  local targets=("$@") exclude='integration|bench'
  asan_configure
  if [ ${#targets[@]} -eq 0 ]; then
    timed asan-build cmake --build "$asan_dir" -j "$jobs"
    timed asan-tests ctest --test-dir "$asan_dir" --output-on-failure -j "$jobs" \
      -LE "$exclude"
  else
    local fuzz=(fuzz_scene fuzz_impacts fuzz_params fuzz_expression fuzz_audio fuzz_serve)
    timed asan-build cmake --build "$asan_dir" -j "$jobs" \
      --target bouncecal "${targets[@]}" "${fuzz[@]}"
    # gtest_discover_tests lists a program that was not built as one failing test
    # "<program>_NOT_BUILT": those are the programs left out on purpose.
    timed asan-tests ctest --test-dir "$asan_dir" --output-on-failure -j "$jobs" \
      -LE "$exclude" -E '_NOT_BUILT$'
  fi
}

run_tsan() {
  cmake -S "$root" -B "$tsan_dir" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBOUNCECAL_SANITIZE=thread -DBOUNCECAL_BUILD_TOOLS=OFF -DBOUNCECAL_PYTHON=OFF >/dev/null
  timed tsan-build cmake --build "$tsan_dir" -j "$jobs" --target bouncecal "${TSAN_TESTS[@]}"
  timed tsan-tests ctest --test-dir "$tsan_dir" --output-on-failure -j "$jobs" \
    -R "$TSAN_REGEX"
}

case $what in
  asan) run_asan ;;
  tsan) run_tsan ;;
  all) run_asan && run_tsan ;;
  ci)
    run_asan "${CI_ASAN_TESTS[@]}"
    timed fuzz env BOUNCECAL_FUZZ_BUILD="$asan_dir" FUZZ_SEED="${FUZZ_SEED:-1}" \
      "$root/tools/run-fuzz.sh" "${FUZZ_SECONDS:-30}"
    run_tsan ;;
  *) echo "usage: $0 [asan|tsan|all|ci]" >&2; exit 2 ;;
esac
