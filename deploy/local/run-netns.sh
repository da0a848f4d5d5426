#!/usr/bin/env bash
# The multi-host harness: run-local.sh with each worker on a "host" of its own, a network
# namespace joined to this machine by a veth pair (deploy/local/netns.sh). The coordinator
# listens on every address of this machine, so off loopback it runs as on a cluster: bearer
# token for the job API, cluster secret for the workers (docs/RPC.md, "Authentication"). The
# merge service stays on this machine's loopback (the coordinator is its only caller), with
# the cluster secret too.
# Workers share this machine's filesystem (the scan, partial sums and tiles), as pods share a volume.
# Needs root (network namespaces) and iproute2.
# Usage: deploy/local/run-netns.sh SCAN.h5 OUT [CARVEMAP] [WORKERS (default 2)]
set -euo pipefail
SCAN=$(realpath "$1")
OUT=$(realpath -m "$2")
CARVEMAP=$(realpath "${3:-$(dirname "$0")/../../build/carvemap}")
WORKERS=${4:-2}
HERE=$(cd "$(dirname "$0")" && pwd)
NAME=cmr$$
NAME=${NAME:0:9}
WORK=$OUT/.carvemap
mkdir -p "$WORK"
rm -f "$WORK/port" "$WORK/merger-port" "$WORK/jobs.db"*

random_secret() { od -An -tx1 -N32 /dev/urandom | tr -d ' \n'; }
(
  umask 077
  TOKEN=$(random_secret)
  echo "$TOKEN local" > "$WORK/tokens"
  echo "$TOKEN" > "$WORK/token"
  random_secret > "$WORK/cluster-secret"
)

pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill -TERM "$pid" 2>/dev/null || true; done
  wait "${pids[@]}" 2>/dev/null || true
  "$HERE/netns.sh" down "$NAME" "$WORKERS"
}
trap cleanup EXIT
"$HERE/netns.sh" up "$NAME" "$WORKERS"

"$CARVEMAP" merger --listen 127.0.0.1:0 --port-file "$WORK/merger-port" \
    --cluster-secret-file "$WORK/cluster-secret" > "$WORK/merger.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 300); do [ -s "$WORK/merger-port" ] && break; sleep 0.1; done
[ -s "$WORK/merger-port" ] || { echo "the merge service did not start (see $WORK/merger.log)" >&2; exit 1; }

"$CARVEMAP" coordinator --listen 0.0.0.0:0 --port-file "$WORK/port" \
    --merge-server "$(cat "$WORK/merger-port")" \
    --tokens "$WORK/tokens" --cluster-secret-file "$WORK/cluster-secret" --shared-dirs \
    --data-root "$(dirname "$SCAN")" --output-root "$(dirname "$OUT")" --work-dir "$WORK" \
    --heartbeat-interval-s 1 --worker-timeout-s 5 > "$WORK/coordinator.log" 2>&1 &
COORDINATOR=$!
pids+=($COORDINATOR)
for _ in $(seq 1 300); do
  [ -s "$WORK/port" ] && break
  kill -0 $COORDINATOR 2>/dev/null || { echo "the coordinator did not start:" >&2; tail -5 "$WORK/coordinator.log" >&2; exit 1; }
  sleep 0.1
done
[ -s "$WORK/port" ] || { echo "the coordinator did not start within 30 s (see $WORK/coordinator.log)" >&2; exit 1; }
PORT=$(sed 's/.*://' "$WORK/port")
echo "coordinator on port $PORT of every address; workers in namespaces $NAME-1..$NAME-$WORKERS"

for k in $(seq 1 "$WORKERS"); do
  ip netns exec "$NAME-$k" "$CARVEMAP" worker \
      --coordinator "$("$HERE/netns.sh" host-ip "$k"):$PORT" \
      --cluster-secret-file "$WORK/cluster-secret" > "$WORK/worker-$k.log" 2>&1 &
  pids+=($!)
done

"$CARVEMAP" submit --server "127.0.0.1:$PORT" --token-file "$WORK/token" --watch \
    -o "$(basename "$OUT")" "$(basename "$SCAN")"
