#!/usr/bin/env bash
# E57 at a terrestrial scanner's density: the fixtures' room (tests/tools/e57/) as three
# structured scans of ROWS × COLS pixels, imported, then carved on one thread; prints the
# import's and the carve's wall time and peak memory, and the carve's own summary.
#
#   tests/bench/e57_bench.sh [CARVEMAP] [ROWS] [COLS] [WORK]
# defaults: build/carvemap, 1000 × 2000 (2 M pixels a scan, 6 M rays), /tmp/e57_bench; $PYTHON
# (default /usr/bin/python3) needs numpy.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
carvemap=${1:-build/carvemap}
rows=${2:-1000}
cols=${3:-2000}
work=${4:-/tmp/e57_bench}
mkdir -p "$work"
"${PYTHON:-/usr/bin/python3}" "$here/../tools/e57/make_large.py" "$work/large.e57" "$rows" "$cols"
echo "e57: $(stat -c %s "$work/large.e57") bytes, 3 scans of $rows × $cols"
/usr/bin/time -f "import: %e s wall, %M KB peak" "$carvemap" import e57 "$work/large.e57" \
  -o "$work/scan.h5" | tail -1
rm -rf "$work/carve"
/usr/bin/time -f "carve: %e s wall, %M KB peak" "$carvemap" carve "$work/scan.h5" \
  -o "$work/carve" --threads 1 -q
