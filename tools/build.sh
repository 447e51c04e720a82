#!/usr/bin/env bash
# Installs the dependencies (Debian 12 packages) and builds bouncecal into build/ (Release).
# Usage: tools/build.sh [--program] [extra cmake -D options]
#   --program   only the program (bouncecal and its library), not the tests, the benchmark
#               programs and the Python module (README: a fraction of the whole build's time)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
targets=()
if [[ ${1:-} == --program ]]; then
  targets=(--target bouncecal)
  shift
fi
"$root/tools/install-deps.sh"
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE=Release -DBOUNCECAL_WERROR=ON "$@" >/dev/null
cmake --build "$root/build" -j "$jobs" "${targets[@]}"
