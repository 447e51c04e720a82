#!/usr/bin/env bash
# Installs every build, test and benchmark dependency of bouncecal from Debian 12's packages.
# Idempotent: skips apt entirely when every package is already installed.
set -euo pipefail
pkgs=(
  build-essential cmake pkg-config
  libfftw3-dev libsndfile1-dev libavformat-dev libavcodec-dev libavutil-dev libswresample-dev
  libceres-dev libeigen3-dev libcli11-dev
  libboost-dev nlohmann-json3-dev libtomlplusplus-dev libmuparser-dev libssl-dev
  libgtest-dev libgmock-dev
  aubio-tools
  ffmpeg
)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "install-deps: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
