#!/usr/bin/env bash
# Installs every build, test and benchmark dependency of bouncecal from Debian 12's packages,
# then the report's charting libraries from the npm registry (package-lock.json: `npm ci`).
# Idempotent: skips apt entirely when every package is already installed, and npm when
# node_modules matches package-lock.json.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
pkgs=(
  build-essential cmake pkg-config
  libfftw3-dev libsndfile1-dev libavformat-dev libavcodec-dev libavutil-dev libswresample-dev
  libceres-dev libeigen3-dev libcli11-dev
  libboost-dev nlohmann-json3-dev libtomlplusplus-dev libmuparser-dev libssl-dev
  libgtest-dev libgmock-dev
  aubio-tools
  ffmpeg
  gnuplot-nox        # report figures (--plot FILE.svg|png)
  chromium           # the report's browser test (headless)
  libpng-dev         # the browser test reads its screenshot
  bsdutils           # `script`: the progress test runs the CLI on a pseudo-terminal
  # Python bindings (python/): pybind11 against Debian's python3; NumPy arrays; pytest runs
  # python/tests through ctest (python_test). No pip: every Python package is Debian's.
  pybind11-dev python3-dev python3-numpy python3-pytest
)
# Node.js and npm install the report's charting libraries at build time. A machine that already
# has them (Debian's packages or another node build that ships npm) keeps its own.
if ! command -v npm >/dev/null 2>&1; then pkgs+=(nodejs npm); fi
# A gnuplot with cairo terminals (gnuplot-qt, gnuplot-x11) serves as well as gnuplot-nox.
wanted=()
for p in "${pkgs[@]}"; do
  if [ "$p" = gnuplot-nox ] && command -v gnuplot >/dev/null 2>&1; then continue; fi
  wanted+=("$p")
done
"$root/tools/apt-install-missing.sh" install-deps "${wanted[@]}"
# The charting libraries inlined into the HTML report (versions pinned in package-lock.json).
if [ ! -f "$root/node_modules/.package-lock.json" ] ||
   [ "$root/package-lock.json" -nt "$root/node_modules/.package-lock.json" ]; then
  echo "install-deps: npm ci (charting libraries for the HTML report)" >&2
  (cd "$root" && npm ci --no-audit --no-fund --loglevel=error)
fi
