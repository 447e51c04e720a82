#!/usr/bin/env bash
# Regenerates the bundled default recording data/default_steel_copper.flac and its ground truth
# data/default_steel_copper.truth.json from the scene data/default_steel_copper.toml with the
# renderer of `bouncecal synth` (deterministic: the same binary version gives the same bytes).
# Usage: tools/make_default_recording.sh [path/to/bouncecal]   (default: build/bouncecal)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${1:-$root/build/bouncecal}
cd "$root"
exec "$bin" synth --preset steel-copper --scene data/default_steel_copper.toml --seed 1 \
  --force -o data/default_steel_copper.flac
