#!/usr/bin/env bash
# README command 2: set up, build, and run the whole test suite (GoogleTest through ctest).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/build.sh"
# The integration suite (ctest label "integration") runs the real DEM simulators.
"$root/tools/install-integration-deps.sh"
cd "$root/build"
ctest --output-on-failure -j "$(nproc 2>/dev/null || echo 2)" "$@"
