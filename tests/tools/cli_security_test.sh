#!/usr/bin/env bash
# The security flags of the `carvemap` binary end to end (docs/RPC.md, "Authentication"):
# a coordinator (and a merge service) off loopback refuses to start open, a coordinator
# without a merge service too; with tokens, the job commands need a
# token (flag, file or variable) and see only their tenant's jobs; a worker without the
# cluster secret exits with the reason; bad token files are named at start. Last, the
# refusals as `carvemap watch --metrics` shows them from the coordinator's /metrics.
# Usage: cli_security_test.sh CARVEMAP WORKDIR
set -u
CARVEMAP=$1
WORK=$2
rm -rf "$WORK"
mkdir -p "$WORK/data/acme" "$WORK/data/beta" "$WORK/out"
failures=0
fail() { echo "FAIL: $*" >&2; failures=$((failures + 1)); }
pass() { echo "ok: $*"; }
expect() {  # expect NAME WANT_EXIT REGEX -- command...
  local name=$1 want=$2 regex=$3; shift 4
  local out rc
  out=$("$@" 2>&1); rc=$?
  if [ "$rc" != "$want" ]; then echo "$out"; fail "$name: exit $rc, want $want"; return; fi
  if ! grep -Eq -- "$regex" <<< "$out"; then echo "$out"; fail "$name: output does not match /$regex/"; return; fi
  pass "$name"
}

pids=()
cleanup() { for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null; done; wait 2>/dev/null; }
trap cleanup EXIT

# ---- start-up rules
expect "help says when --insecure is needed" 0 "--insecure" -- "$CARVEMAP" coordinator --help
expect "open on 0.0.0.0 refused" 2 "without bearer tokens.*--insecure" -- \
    timeout 20 "$CARVEMAP" coordinator --listen 0.0.0.0:0 --data-root "$WORK/data" \
    --output-root "$WORK/out" --work-dir "$WORK/w0"
printf 'short acme\n' > "$WORK/bad_tokens"
expect "short token named by file and line" 2 "bad_tokens: entry 1: token: 5 characters" -- \
    timeout 20 "$CARVEMAP" coordinator --tokens "$WORK/bad_tokens" --work-dir "$WORK/w1"
expect "no merge service refused" 2 "no merge service: give --merge-server" -- \
    timeout 20 "$CARVEMAP" coordinator --data-root "$WORK/data" --output-root "$WORK/out" \
    --work-dir "$WORK/w3"
expect "merger open on 0.0.0.0 refused" 2 "open merge API.*--insecure" -- \
    timeout 20 "$CARVEMAP" merger --listen 0.0.0.0:0

# ---- a coordinator with two tenants, a cluster secret, per-tenant folders
(umask 077
 echo "acme-token-0123456789abcdef acme" > "$WORK/tokens"
 echo "beta-token-0123456789abcdef beta" >> "$WORK/tokens"
 echo "acme-token-0123456789abcdef" > "$WORK/acme.token"
 echo "cluster-secret-0123456789abcdef" > "$WORK/secret")
echo junk > "$WORK/data/acme/junk.h5"
"$CARVEMAP" merger --listen 127.0.0.1:0 --port-file "$WORK/merger-port" \
    --cluster-secret-file "$WORK/secret" > "$WORK/merger.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 300); do [ -s "$WORK/merger-port" ] && break; sleep 0.1; done
MERGER=$(cat "$WORK/merger-port" 2>/dev/null)
[ -n "$MERGER" ] || { cat "$WORK/merger.log"; fail "merger did not start"; exit 1; }
"$CARVEMAP" coordinator --listen 127.0.0.1:0 --port-file "$WORK/port" --tokens "$WORK/tokens" \
    --cluster-secret-file "$WORK/secret" --data-root "$WORK/data" --output-root "$WORK/out" \
    --work-dir "$WORK/w2" --metrics-listen 127.0.0.1:0 --merge-server "$MERGER" \
    > "$WORK/coordinator.log" 2>&1 &
pids+=($!)
for _ in $(seq 1 300); do [ -s "$WORK/port" ] && break; sleep 0.1; done
ADDR=$(cat "$WORK/port" 2>/dev/null)
[ -n "$ADDR" ] || { cat "$WORK/coordinator.log"; fail "coordinator did not start"; exit 1; }

expect "no token: UNAUTHENTICATED" 1 "missing bearer token" -- "$CARVEMAP" list --server "$ADDR"
expect "wrong token" 1 "invalid bearer token" -- \
    "$CARVEMAP" list --server "$ADDR" --token wrong-token-0123456789abcdef
JOB=$("$CARVEMAP" submit --server "$ADDR" --token-file "$WORK/acme.token" -o first junk.h5 2>&1)
if [[ "$JOB" =~ ^j- ]]; then pass "submit with --token-file: $JOB"; else fail "submit: $JOB"; fi
[ -d "$WORK/out/acme/first" ] && pass "outputs in the tenant's folder" || fail "no out/acme/first"
expect "token from CARVEMAP_TOKEN, server from CARVEMAP_SERVER" 0 "$JOB" -- \
    env CARVEMAP_SERVER="$ADDR" CARVEMAP_TOKEN=acme-token-0123456789abcdef "$CARVEMAP" list
expect "another tenant sees no such job" 2 "job $JOB not found" -- \
    env CARVEMAP_TOKEN=beta-token-0123456789abcdef "$CARVEMAP" status --server "$ADDR" "$JOB"
expect "escaping path refused" 2 "must not contain '..'" -- \
    "$CARVEMAP" submit --server "$ADDR" --token-file "$WORK/acme.token" ../beta/x.h5
expect "worker without the secret exits" 1 "cluster secret" -- \
    timeout 30 "$CARVEMAP" worker --coordinator "$ADDR" --listen ""
expect "worker with a short secret variable" 2 "CARVEMAP_CLUSTER_SECRET: 3 characters" -- \
    env CARVEMAP_CLUSTER_SECRET=abc timeout 30 "$CARVEMAP" worker --coordinator "$ADDR" --listen ""
if grep -q "acme-token-0123456789abcdef\|wrong-token" "$WORK/coordinator.log"; then
  fail "a token appears in the coordinator's log"
else
  pass "no token in the coordinator's log"
fi

# Three calls were refused above: two on the job API (no token, wrong token), one on the
# carve-task API (the worker without the secret).
METRICS=$(grep -o "metrics on http://[0-9.:]*/metrics" "$WORK/coordinator.log" | sed 's|metrics on ||')
expect "watch --metrics shows the refusals" 0 "workers 0 .*refused calls 3" -- \
    "$CARVEMAP" watch --metrics "$METRICS" --count 2 --interval 0.2

if [ $failures != 0 ]; then echo "$failures failure(s)"; exit 1; fi
echo "all CLI security tests passed"
