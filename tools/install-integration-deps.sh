#!/usr/bin/env bash
# Installs the DEM simulators the integration suite runs (ctest label "integration", issue 12):
# Debian 12's LAMMPS ("29 Sep 2021 - Update 2"), LIGGGHTS 3.8.0, Yade 2023.02a and the MPI
# runner (Open MPI) that `bouncecal export --scene packing` decks use.
# Idempotent: skips apt entirely when every package is already installed.
set -euo pipefail
pkgs=(lammps liggghts yade openmpi-bin)
"$(dirname "$0")/apt-install-missing.sh" install-integration-deps "${pkgs[@]}"
