#!/usr/bin/env bash
# One command from a fresh Debian 12 machine: install what is missing, build, run every test.
# Prints ctest's summary and exits non-zero when any test fails.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
"$root/scripts/install-deps.sh"
"$root/scripts/build.sh"
cd "$root/build"
ctest --output-on-failure -j "${CARVEMAP_TEST_JOBS:-$(nproc)}" --timeout 900
