#!/usr/bin/env bash
# Regenerates the bundled default recording data/default_steel_copper.flac and its ground truth
# data/default_steel_copper.truth.json: the scene data/default_steel_copper.toml names the
# contact law (hertz-viscoelastic, A = 5.16e-7 s), so `bouncecal synth` simulates the impacts
# with that law (--truth-from law: the simulator of `bouncecal simulate`/`calibrate`) and renders
# them with the steel-copper preset's sound (copper-dish modes, click, noise, hum). Deterministic:
# the same binary version gives the same bytes. See data/README.md.
# Usage: tools/make_default_recording.sh [path/to/bouncecal]   (default: build/bouncecal)
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
bin=${1:-$root/build/bouncecal}
cd "$root"
exec "$bin" synth --preset steel-copper --scene data/default_steel_copper.toml --truth-from law \
  --seed 1 --force -o data/default_steel_copper.flac
