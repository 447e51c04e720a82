#!/usr/bin/env bash
# Installs what the fuzz targets and the clang sanitizer build need (tools/run-fuzz.sh,
# tools/run-sanitizers.sh, the sanitizer stage of .ci/run): Debian 12's clang (14) and its
# compiler runtime (libclang-rt-dev: libFuzzer and the ASan/UBSan/TSan runtimes; clang only
# recommends it, and the project installs without recommends).
# Idempotent: skips apt entirely when every package is already installed.
set -euo pipefail
pkgs=(clang libclang-rt-dev)
"$(dirname "$0")/apt-install-missing.sh" install-sanitizer-deps "${pkgs[@]}"
