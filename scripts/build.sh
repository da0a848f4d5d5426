#!/usr/bin/env bash
# Configures (once) and builds carvemap into build/ with Ninja. Extra args go to ninja
# (e.g. a target name).
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
cd "$root"
if [ ! -f build/build.ninja ]; then
  cmake -S . -B build -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo
fi
# 2 cores and heavy headers: more parallel jobs than cores only thrash memory.
jobs="${CARVEMAP_BUILD_JOBS:-$(nproc)}"
cmake --build build -j "$jobs" -- "$@"
