#!/usr/bin/env bash
# apt-install-missing.sh LABEL PACKAGE...: installs those of Debian's packages that are not
# installed yet (without recommends; sudo when not root; waits up to 10 min for the dpkg lock),
# and skips apt entirely when every one is already there. Shared by tools/install-deps.sh,
# tools/install-integration-deps.sh and tools/install-sanitizer-deps.sh.
set -euo pipefail
label=$1
shift
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi
echo "$label: installing ${missing[*]}" >&2
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends -o DPkg::Lock::Timeout=600 \
  "${missing[@]}" >/dev/null
