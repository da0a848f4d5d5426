#!/usr/bin/env bash
# The two-worker harness (docs/DESIGN.md §9) by hand: a merge service, a coordinator and two workers
# on loopback, the job submitted with `carvemap submit --watch`, everything stopped at the
# end. What `carvemap run` does in one command, spelled out as separate servers (as in a
# cluster), including their secrets: a fresh bearer token for the job API and a cluster secret
# for the workers and the merge service, in files only this user can read (docs/RPC.md,
# "Authentication").
# Usage: deploy/local/run-local.sh SCAN.h5 OUT [CARVEMAP]
set -euo pipefail
SCAN=$(realpath "$1")
OUT=$(realpath -m "$2")
CARVEMAP=${3:-$(dirname "$0")/../../build/carvemap}
WORK=$OUT/.carvemap
mkdir -p "$WORK"
rm -f "$WORK/port" "$WORK/merger-port" "$WORK/jobs.db"*

# 32 random bytes as hex, from the kernel's CSPRNG.
random_secret() { od -An -tx1 -N32 /dev/urandom | tr -d ' \n'; }
(
  umask 077
  TOKEN=$(random_secret)
  echo "$TOKEN local" > "$WORK/tokens"
  echo "$TOKEN" > "$WORK/token"
  random_secret > "$WORK/cluster-secret"
)

pids=()
cleanup() {  # workers first, the merge service last (started first), as `carvemap run`
  for ((i = ${#pids[@]} - 1; i >= 0; i--)); do
    kill -TERM "${pids[i]}" 2>/dev/null || true
    wait "${pids[i]}" 2>/dev/null || true
  done
}
trap cleanup EXIT

# The merge service: the coordinator hands it the job's merge (tiles and outputs by path).
"$CARVEMAP" merger --listen 127.0.0.1:0 --port-file "$WORK/merger-port" \
    --cluster-secret-file "$WORK/cluster-secret" > "$WORK/merger.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 300); do [ -s "$WORK/merger-port" ] && break; sleep 0.1; done
[ -s "$WORK/merger-port" ] || { echo "the merge service did not start (see $WORK/merger.log)" >&2; exit 1; }
MERGER=$(cat "$WORK/merger-port")

"$CARVEMAP" coordinator --listen 127.0.0.1:0 --port-file "$WORK/port" --merge-server "$MERGER" \
    --tokens "$WORK/tokens" --cluster-secret-file "$WORK/cluster-secret" --shared-dirs \
    --data-root "$(dirname "$SCAN")" --output-root "$(dirname "$OUT")" --work-dir "$WORK" \
    --heartbeat-interval-s 1 --worker-timeout-s 5 > "$WORK/coordinator.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 300); do [ -s "$WORK/port" ] && break; sleep 0.1; done
ADDR=$(cat "$WORK/port")
echo "coordinator on $ADDR, merge service on $MERGER (logs in $WORK)"

for i in 1 2; do
  "$CARVEMAP" worker --coordinator "$ADDR" --cluster-secret-file "$WORK/cluster-secret" \
      > "$WORK/worker-$i.log" 2>&1 &
  pids+=($!)
done

"$CARVEMAP" submit --server "$ADDR" --token-file "$WORK/token" --watch \
    -o "$(basename "$OUT")" "$(basename "$SCAN")"
