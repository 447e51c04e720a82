#!/usr/bin/env bash
# The law x simulator table of docs/export.md, from the rows the integration suite wrote (one per case,
# build/integration/LAW_TARGET.md). Run the suite first: (cd build && ctest -L integration).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir="$root/build/integration"
ls "$dir"/*.md >/dev/null 2>&1 || { echo "integration_table.sh: no rows in $dir: run ctest -L integration" >&2; exit 1; }
echo "| law | simulator | native law | mapping | stated e error | e fit (impact 0) | e simulator (impact 0) | max \|Δe\| (3 impacts) | time-step e error | max interval error | case time (s) |"
echo "|---|---|---|---|---|---|---|---|---|---|---|"
sort "$dir"/*.md
