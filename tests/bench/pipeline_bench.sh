#!/usr/bin/env bash
# The local pipeline's scaling benchmarks, through `carvemap run` as a user runs it:
#   1. wall time with 1 worker vs 2 workers on the same scan (and the carve stage alone);
#   2. peak RSS of the coordinator, of each worker and of the merge service for the same
#      building and walk scanned at 1×, 2× and 4× the data (scanner rate 10, 20, 40 Hz: the same
#      volume, more rays);
#   3. bytes per ray of the partial sums the slices write and of the tiles.
# Prints Markdown tables for docs/BENCHMARKS.md.
#
# Usage: tests/bench/pipeline_bench.sh [PRESET] [WALK_S] [BEAM_DEG] [WORK_DIR]
#   defaults: office2 120 1 /tmp/carvemap-pipeline-bench   (build first: scripts/build.sh)
set -euo pipefail

preset=${1:-office2}
walk_s=${2:-120}
beam_deg=${3:-1}
work=${4:-/tmp/carvemap-pipeline-bench}
here=$(cd "$(dirname "$0")/../.." && pwd)
carvemap=${CARVEMAP:-$here/build/carvemap}
py=/usr/bin/python3
[[ -x $carvemap ]] || { echo "pipeline_bench: $carvemap not found; run scripts/build.sh" >&2; exit 1; }

rm -rf "$work"
mkdir -p "$work"

simulate() {  # rate → scan path
  local rate=$1 dir=$work/sim-$1hz
  "$carvemap" simulate --preset "$preset" --seed 1 --rate-hz "$rate" --beam-step-deg "$beam_deg" \
    --max-duration "$walk_s" -o "$dir" > "$dir.log" 2>&1 || { cat "$dir.log" >&2; exit 1; }
  echo "$dir/scan.h5"
}

# run SCAN WORKERS NAME → prints: wall_s carve_s rays partial_B/ray tile_B/ray coord_rss
#   max_worker_rss merger_rss
run() {
  local scan=$1 workers=$2 out=$work/$3
  local t0 t1
  t0=$(date +%s.%N)
  "$carvemap" run "$scan" -o "$out" --workers "$workers" --quiet > "$out.log" 2>&1 ||
    { cat "$out.log" >&2; exit 1; }
  t1=$(date +%s.%N)
  "$py" - "$out" "$t0" "$t1" <<'PY'
import json, os, re, sys
out, t0, t1 = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
job = json.load(open(os.path.join(out, "job.json")))
carve = job.get("carve", {})
rays = carve.get("rays", 0)
tiles = os.path.join(out, "tiles")
tile_bytes = sum(os.path.getsize(os.path.join(tiles, f)) for f in os.listdir(tiles))
def rss(log):
    m = re.findall(r"peak_rss_mib=([0-9.]+)", open(log).read())
    return float(m[-1]) if m else float("nan")
logs = os.path.join(out, ".carvemap")
workers = [rss(os.path.join(logs, f)) for f in sorted(os.listdir(logs)) if f.startswith("worker-") and f.endswith(".log")]
print(f"{t1 - t0:.1f} {job['stage_seconds'].get('carve', 0):.1f} {rays} "
      f"{carve.get('partial_bytes_per_ray', 0):.1f} {tile_bytes / max(rays, 1):.1f} "
      f"{rss(os.path.join(logs, 'coordinator.log')):.0f} {max(workers) if workers else float('nan'):.0f} "
      f"{rss(os.path.join(logs, 'merger.log')):.0f}")
PY
}

echo "pipeline_bench: $preset, ${walk_s} s walk, ${beam_deg} deg beams, $(nproc) cores, $(date -u +%F)"
scan10=$(simulate 10)
read -r w1 c1 rays sp1 tb1 cr1 wr1 mr1 < <(run "$scan10" 1 w1-10hz)
read -r w2 c2 _ _ _ cr2 wr2 mr2 < <(run "$scan10" 2 w2-10hz)
echo
echo "| workers | rays | wall s | carve stage s | speed-up (wall / carve) |"
echo "|---|---|---|---|---|"
echo "| 1 | $rays | $w1 | $c1 | 1 |"
"$py" -c "print(f'| 2 | $rays | $w2 | $c2 | {$w1/$w2:.2f} / {$c1/max($c2,1e-9):.2f} |')"

echo
echo "| scanner rate | rays | coordinator peak RSS MiB | largest worker peak RSS MiB | merge service peak RSS MiB | partial sums B/ray | tile B/ray |"
echo "|---|---|---|---|---|---|---|"
echo "| 10 Hz (1×) | $rays | $cr2 | $wr2 | $mr2 | $sp1 | $tb1 |"
for rate in 20 40; do
  scan=$(simulate $rate)
  read -r _ _ r sp tb cr wr mr < <(run "$scan" 2 w2-${rate}hz)
  echo "| $rate Hz ($((rate / 10))×) | $r | $cr | $wr | $mr | $sp | $tb |"
done
