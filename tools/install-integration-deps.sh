#!/usr/bin/env bash
# Installs the DEM simulators the integration suite runs (ctest label "integration", issue 12):
# Debian 12's LAMMPS ("29 Sep 2021 - Update 2"), LIGGGHTS 3.8.0, Yade 2023.02a and the MPI
# runner (Open MPI) that `bouncecal export --scene packing` decks use.
# Idempotent: skips apt entirely when every package is already installed.
set -euo pipefail
pkgs=(lammps liggghts yade openmpi-bin)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "install-integration-deps: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 \
  "${missing[@]}" >/dev/null
