#!/usr/bin/env bash
# The test suite under AddressSanitizer + UndefinedBehaviorSanitizer (build-asan/), and the
# threaded batch and law-comparison tests under ThreadSanitizer (build-tsan/). Any sanitizer
# report fails the run (-fno-sanitize-recover, halt_on_error).
# Usage: tools/run-sanitizers.sh [asan|tsan|all]   (default all; .ci/run calls it)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
what=${1:-all}
jobs=$(nproc 2>/dev/null || echo 2)
"$root/tools/install-deps.sh"
export ASAN_OPTIONS=detect_leaks=1:halt_on_error=1:abort_on_error=0
export UBSAN_OPTIONS=print_stacktrace=1:halt_on_error=1
export TSAN_OPTIONS=halt_on_error=1:second_deadlock_stack=1

if [ "$what" = asan ] || [ "$what" = all ]; then
  cmake -S "$root" -B "$root/build-asan" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBOUNCECAL_SANITIZE=address,undefined -DBOUNCECAL_BUILD_TOOLS=OFF >/dev/null
  cmake --build "$root/build-asan" -j "$jobs"
  (cd "$root/build-asan" && ctest --output-on-failure -j "$jobs" -LE integration)
fi
if [ "$what" = tsan ] || [ "$what" = all ]; then
  cmake -S "$root" -B "$root/build-tsan" -DCMAKE_BUILD_TYPE=RelWithDebInfo \
    -DBOUNCECAL_SANITIZE=thread -DBOUNCECAL_BUILD_TOOLS=OFF >/dev/null
  cmake --build "$root/build-tsan" -j "$jobs" --target bouncecal calibrate_cli_test calibrate_test
  (cd "$root/build-tsan" && ctest --output-on-failure -j "$jobs" -R 'Batch|Jobs|LawComparison|Parallel|Thread')
fi
