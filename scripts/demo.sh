#!/usr/bin/env bash
# One command from a fresh Debian 12 machine: install what is missing, build, and run the demo
# (a simulated building end to end). Outputs go to ${1:-out/demo}.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
"$root/scripts/build.sh"
cd "$root"
out="${1:-out/demo}"
build/carvemap demo -o "$out"
