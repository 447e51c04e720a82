#!/usr/bin/env bash
# Installs the dependencies (Debian 12 packages) and builds bouncecal into build/ (Release).
# Usage: tools/build.sh [extra cmake -D options]
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/install-deps.sh"
jobs=$(nproc 2>/dev/null || echo 2)
cmake -S "$root" -B "$root/build" -DCMAKE_BUILD_TYPE=Release -DBOUNCECAL_WERROR=ON "$@" >/dev/null
cmake --build "$root/build" -j "$jobs"
