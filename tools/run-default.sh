#!/usr/bin/env bash
# README command 1: set up, build the program (not the tests), and analyze the bundled default
# recording.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
"$root/tools/build.sh" --program >&2
exec "$root/build/bouncecal" analyze "$root/data/default_steel_copper.flac" \
  --scene "$root/data/default_steel_copper.toml" "$@"
