#!/usr/bin/env bash
# The floor plan's 3D route on the real floor maps : for each map of
# tests/data/floormaps, `carvemap simulate --floormap … [--furniture …] --rooms …`, then
# `carvemap run SCAN -o OUT`, then OUT/level_0/floorplan.geojson scored against the map's
# *_gt_segmentation.png by build/tests/bench/floorplan_score (services/floorplan/eval/room_scoring.h:
# room F1 at IoU > 0.5 one-to-one, Bormann et al. recall / precision, room counts). Prints one
# Markdown table with a row per map and variant and the means per variant.
#
# Usage: tests/bench/floorplan_3d_eval.sh [options] [MAP...]
#   MAP            map name (office_d, lab_c_scan, …); default: all nine, smallest first
#   --variants V   furnished | plain | both (default furnished; "both" runs every furnished map
#                  first, then the plain ones)
#   --rate-hz R    simulated scanner rate (default 4; simulate's own default is 40)
#   --beam-deg B   angle between beams (default 2; simulate's own default is 0.25)
#   --resolution L carve leaf size (default 0.0625); objects are not re-carved
#                  (--object-resolution = L: §5.6.1's second pass does not change the floor plan)
#   --workers N    carvemap run workers (default 2)
#   --stop-at HH:MM  UTC time after which no new map is started (default: none)
#   --work DIR     scratch directory (default /tmp/carvemap-floorplan-3d); a map whose result
#                  line is already in DIR/results.txt is not run again (delete it to redo)
#   --keep         keep scans and run outputs (default: only job.json, level_*/floorplan.* and
#                  logs are kept)
#   --fresh        forget DIR/results.txt first (run every map again)
#   --min-f1 F     as a test: exit 1 unless every map run has room F1 >= F
#   --levels N     as a test: exit 1 unless every map run has N levels in levels.json
# Environment: CARVEMAP, FLOORPLAN_SCORE (binaries), MAPS (floor map folder), NICE (default 15).
# Build first: scripts/build.sh carvemap floorplan_score.
set -euo pipefail

here=$(cd "$(dirname "$0")/../.." && pwd)
carvemap=${CARVEMAP:-$here/build/carvemap}
score=${FLOORPLAN_SCORE:-$here/build/tests/bench/floorplan_score}
maps_dir=${MAPS:-$here/tests/data/floormaps}
nice_level=${NICE:-15}
variants=furnished rate=4 beam=2 res=0.0625 workers=2 stop_at="" work=/tmp/carvemap-floorplan-3d
keep=0 fresh=0 min_f1="" want_levels=""
names=()
while (($#)); do
  case $1 in
    --variants) variants=$2; shift 2 ;;
    --rate-hz) rate=$2; shift 2 ;;
    --beam-deg) beam=$2; shift 2 ;;
    --resolution) res=$2; shift 2 ;;
    --workers) workers=$2; shift 2 ;;
    --stop-at) stop_at=$2; shift 2 ;;
    --work) work=$2; shift 2 ;;
    --keep) keep=1; shift ;;
    --fresh) fresh=1; shift ;;
    --min-f1) min_f1=$2; shift 2 ;;
    --levels) want_levels=$2; shift 2 ;;
    -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    -*) echo "floorplan_3d_eval: unknown option $1" >&2; exit 2 ;;
    *) names+=("$1"); shift ;;
  esac
done
case $variants in
  furnished) variant_list=(furnished) ;;
  plain) variant_list=(plain) ;;
  both) variant_list=(furnished plain) ;;
  *) echo "floorplan_3d_eval: --variants must be furnished, plain or both, not '$variants'" >&2
     exit 2 ;;
esac
for bin in "$carvemap" "$score"; do
  [[ -x $bin ]] || { echo "floorplan_3d_eval: $bin not found; build carvemap and floorplan_score" >&2; exit 1; }
done
[[ -x /usr/bin/time ]] || { echo "floorplan_3d_eval: /usr/bin/time (Debian package time) needed for CPU seconds" >&2; exit 1; }
[[ -d $maps_dir ]] || { echo "floorplan_3d_eval: no floor map folder $maps_dir" >&2; exit 1; }
# Smallest map first (pixels), so a deadline cuts the largest ones.
((${#names[@]})) || names=(Freiburg52_scan lab_c_scan lab_d_scan lab_intel office_d office_a
                          office_b Freiburg101_scan office_c)
stop_epoch=""
[[ -n $stop_at ]] && stop_epoch=$(date -u -d "$stop_at" +%s)

mkdir -p "$work"
results=$work/results.txt  # one line per map and variant: name variant key=value…
((fresh)) && rm -f "$results"
touch "$results"

run_one() {  # name variant
  local name=$1 variant=$2 tag=$1-$2
  local plain=$maps_dir/$name.png furn=$maps_dir/${name}_furnitures.png gt=$maps_dir/${name}_gt_segmentation.png
  for f in "$plain" "$gt"; do [[ -f $f ]] || { echo "floorplan_3d_eval: missing $f" >&2; return 1; }; done
  local sim=$work/sim-$tag out=$work/out-$tag
  local furniture_args=()
  [[ $variant == furnished ]] && furniture_args=(--furniture "$furn")
  rm -rf "$sim" "$out"
  echo "floorplan_3d_eval: $tag: simulate" >&2
  /usr/bin/time -f "%U %S %e" -o "$work/$tag.sim.time" nice -n "$nice_level" "$carvemap" simulate \
    --floormap "$plain" "${furniture_args[@]}" --rooms "$gt" --resolution 0.05 --seed 1 \
    --rate-hz "$rate" --beam-step-deg "$beam" --quiet -o "$sim" > "$work/$tag.sim.log" 2>&1 ||
    { cat "$work/$tag.sim.log" >&2; return 1; }
  echo "floorplan_3d_eval: $tag: run" >&2
  /usr/bin/time -f "%U %S %e" -o "$work/$tag.run.time" nice -n "$nice_level" "$carvemap" run \
    "$sim/scan.h5" -o "$out" --resolution "$res" --object-resolution "$res" --workers "$workers" \
    --quiet > "$work/$tag.run.log" 2>&1 || { cat "$work/$tag.run.log" >&2; return 1; }
  local scores levels rays
  if [[ -f $out/level_0/floorplan.geojson ]]; then
    scores=$("$score" --geojson "$out/level_0/floorplan.geojson" --gt "$gt" --resolution 0.05)
  else
    scores="truth_rooms=? predicted_rooms=0 matched=0 precision=0 recall=0 f1=0 bormann_recall=0 bormann_precision=0 plan_rooms=0"
  fi
  # levels.json's entries (the building has one level: more is a levels-stage error), and
  # the rays the workers carved.
  levels=$(python3 -c "import json,sys; print(len(json.load(open(sys.argv[1]))))" "$out/levels.json")
  rays=$(python3 -c "import json,sys; print(json.load(open(sys.argv[1])).get('carve', {}).get('rays', 0))" "$out/job.json")
  read -r u s e < "$work/$tag.run.time"
  read -r su ss se < "$work/$tag.sim.time"
  echo "$name $variant $scores levels=$levels rays=$rays run_cpu_s=$(python3 -c "print(round($u+$s,1))") run_wall_s=$e sim_cpu_s=$(python3 -c "print(round($su+$ss,1))")" >> "$results"
  if ((!keep)); then  # the scores need only these; tiles and meshes are tens of MB per map
    rm -rf "$sim/scan.h5" "$out/tiles" "$out/mesh" "$out/octree.bt"
  fi
}

for variant in "${variant_list[@]}"; do
  for name in "${names[@]}"; do
    grep -q "^$name $variant " "$results" && continue
    if [[ -n $stop_epoch ]] && (($(date -u +%s) >= stop_epoch)); then
      echo "floorplan_3d_eval: past $stop_at UTC, not starting $name ($variant)" >&2
      continue
    fi
    run_one "$name" "$variant" || echo "floorplan_3d_eval: $name ($variant) FAILED" >&2
  done
done

echo "floorplan_3d_eval: $(date -u +%F), ${rate} Hz, ${beam}° beams, leaves ${res} m, objects not re-carved, $workers workers, nice $nice_level"
python3 - "$results" "${variant_list[@]}" -- "${names[@]}" <<'PY'
import sys
sep = sys.argv.index("--")
variants, names = sys.argv[2:sep], sys.argv[sep + 1:]
rows = []
for line in open(sys.argv[1]):
    f = line.split()
    if len(f) < 3: continue
    d = dict(kv.split("=", 1) for kv in f[2:])
    rows.append((f[0], f[1], d))
# Variant by variant, maps in the order they were asked for (others after, by name).
order = lambda r: (variants.index(r[1]) if r[1] in variants else len(variants),
                   names.index(r[0]) if r[0] in names else len(names), r[0])
rows.sort(key=order)
print()
print("| map | variant | room F1 | precision / recall | Bormann recall / precision | rooms pred / gt (plan) | levels | rays | run CPU s / wall s |")
print("|---|---|---|---|---|---|---|---|---|")
for name, variant, d in rows:
    if variant not in variants: continue
    print(f"| {name} | {variant} | {float(d['f1']):.3f} | {float(d['precision']):.3f} / {float(d['recall']):.3f} | "
          f"{float(d['bormann_recall']):.3f} / {float(d['bormann_precision']):.3f} | "
          f"{d['predicted_rooms']} / {d['truth_rooms']} ({d['plan_rooms']}) | {d['levels']} | "
          f"{int(d['rays']) / 1e6:.2f} M | {d['run_cpu_s']} / {d['run_wall_s']} |")
for variant in variants:
    sel = [d for _, v, d in rows if v == variant]
    if not sel: continue
    m = lambda k: sum(float(d[k]) for d in sel) / len(sel)
    print(f"| **mean, {variant} ({len(sel)} maps)** | | **{m('f1'):.3f}** | {m('precision'):.3f} / {m('recall'):.3f} | "
          f"{m('bormann_recall'):.3f} / {m('bormann_precision'):.3f} | | | | "
          f"{sum(float(d['run_cpu_s']) for d in sel):.0f} / {sum(float(d['run_wall_s']) for d in sel):.0f} (sum) |")
PY

# As a test (ctest e2e_floorplan_3d_*): every requested map and variant has a result line and
# meets the floors.
if [[ -n $min_f1 || -n $want_levels ]]; then
  python3 - "$results" "${min_f1:-0}" "${want_levels:-any}" "${variant_list[@]}" -- "${names[@]}" <<'PY'
import sys
results, min_f1, want_levels = sys.argv[1], float(sys.argv[2]), sys.argv[3]
sep = sys.argv.index("--")
variants, names = sys.argv[4:sep], sys.argv[sep + 1:]
got = {}
for line in open(results):
    f = line.split()
    if len(f) >= 3:
        got[(f[0], f[1])] = dict(kv.split("=", 1) for kv in f[2:])
bad = []
for v in variants:
    for n in names:
        d = got.get((n, v))
        if d is None:
            bad.append(f"{n} ({v}): no result (the run failed; see its .run.log)")
            continue
        if float(d["f1"]) < min_f1:
            bad.append(f"{n} ({v}): room F1 {float(d['f1']):.3f} < {min_f1}")
        if want_levels != "any" and d["levels"] != want_levels:
            bad.append(f"{n} ({v}): {d['levels']} levels in levels.json, expected {want_levels}")
for b in bad:
    print("floorplan_3d_eval: FAIL " + b, file=sys.stderr)
sys.exit(1 if bad else 0)
PY
fi
