#!/usr/bin/env bash
# Installs what the fuzz targets and the clang sanitizer build need (tools/run-fuzz.sh,
# tools/run-sanitizers.sh, the sanitizer stage of .ci/run): Debian 12's clang (14) and its
# compiler runtime (libclang-rt-dev: libFuzzer and the ASan/UBSan/TSan runtimes; clang only
# recommends it, and the project installs without recommends).
# Idempotent: skips apt entirely when every package is already installed.
set -euo pipefail
pkgs=(clang libclang-rt-dev)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "install-sanitizer-deps: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 \
  "${missing[@]}" >/dev/null
