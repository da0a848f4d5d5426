#!/usr/bin/env bash
# The image for real: builds deploy/Dockerfile, runs the coordinator, two
# workers and the merge service as containers on one network sharing a volume, as
# deploy/k8s/base says (their args, user and group, fsGroup, read-only root file system, no
# capabilities, no privilege escalation, the emptyDir /tmp, the Secrets mounted read-only with
# mode 0440, the memory and CPU limits, the coordinator's init container), and runs a job
# through them from the host with the host's carvemap client, over TLS with a tenant's token,
# as docs/CLUSTER.md steps 3, 5 and 6 do it on a cluster.
#
# Steps: check for a container engine (podman, or docker with a running daemon) and, when the
# base images are missing, debootstrap; make debian:12 and debian:12-slim with debootstrap
# (bookworm, minbase) and import them, so deploy/Dockerfile's FROM lines resolve without a
# registry (reused when they exist); build the image from the repository root (nice -n 19,
# BUILD_JOBS=2); make a network, the shared and the job-store volumes, the Secrets (tokens,
# cluster secret, a CA and a certificate for carvemap-coordinator, carvemap-merger and
# localhost); run the coordinator's init container, then the merge service, the coordinator
# and the workers; check each runs as 10001:10001 with a read-only root file system and no
# capabilities; simulate a small scan on the host (the office, 10 Hz, 1° beams, a 2-minute
# walk), copy it onto the volume through the coordinator container with tar (as `kubectl
# cp`), `carvemap submit --watch` through the coordinator's published port, then check the
# job SUCCEEDED and its outputs (job.json, mesh/*.ply, level_*/floorplan.*). Everything it
# started (containers, network, volumes) is removed on exit, also on failure; the images stay
# as a cache.
#
# Needs: root; podman (Debian: apt-get install podman; where crun cannot run containers,
# runc too) or docker with a daemon; debootstrap (only while the base images are missing);
# python3 with python3-yaml (reads the manifests); openssl; a built carvemap (build/carvemap,
# or CARVEMAP=PATH) as the client and the scan simulator; Debian's mirror reachable (the base
# images and the build stage's packages); ~10 GB of disk.
# Takes (2 cores, 24 GiB): ~1 min for the base images (once); 12 min for the image build on a
# quiet machine, 19 min with other builds running beside it (the build stage installs the
# packages and compiles carvemap; cached layers make an unchanged tree's rebuild instant, but
# any change in the tree compiles it all again); ~1-2 min for the containers and the job (the
# job 50-100 s). 14 min in all from nothing (no images) on a quiet machine.
# The build context is the work tree as it is, uncommitted edits included; to build a commit,
# export it and point CT_CONTEXT there (git archive HEAD | tar -x -C DIR).
#
# Exit status: 0 passed; 77 skipped (this machine cannot build or run containers: the reason
# is printed); anything else failed.
#
# Environment:
#   CARVEMAP        host client (default: build/carvemap)
#   CT_CONTEXT      build context (default: the repository root)
#   CT_SCRATCH      scratch folder (default: a new one under ${TMPDIR:-/tmp}; kept)
#   CT_IMAGE        image tag (default carvemap:0.1.0, the manifests' image)
#   CT_REUSE_IMAGE  1: do not build when CT_IMAGE exists already
#   CT_MIRROR       Debian mirror for debootstrap (default http://deb.debian.org/debian)
#   CT_SCAN_SECONDS the simulated walk's length (default 120)
#   CT_LIMITS       0: do not apply the manifests' memory/CPU limits
#   CT_KEEP         1: leave containers, network and volumes for a look (remove them with
#                   this script's printed commands)
#   BUILD_JOBS      parallel compiles in the build stage (default 2)
#   CT_OPT_IN       1 (ctest's deploy_container_job sets it): skip unless
#                   CARVEMAP_CONTAINER_TEST=1, so that the suite does not build the image
#                   unasked

# shellcheck disable=SC2154  # INIT_*, MAIN_*, REPLICAS_*: made from the manifests at run time
set -euo pipefail

ROOT=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
CONTEXT=${CT_CONTEXT:-$ROOT}
CARVEMAP=${CARVEMAP:-$ROOT/build/carvemap}
IMAGE=${CT_IMAGE:-carvemap:0.1.0}
MIRROR=${CT_MIRROR:-http://deb.debian.org/debian}
SCAN_SECONDS=${CT_SCAN_SECONDS:-120}
BUILD_JOBS=${BUILD_JOBS:-2}
PREFIX=carvemap-ct
NET=$PREFIX-net
TENANT=acme

say() { printf '[container_job %(%H:%M:%S)T] %s\n' -1 "$*"; }
skip() { printf 'SKIP (container_job): %s\n' "$*" >&2; exit 77; }
die() { printf 'FAIL (container_job): %s\n' "$*" >&2; exit 1; }

if [ "${CT_OPT_IN:-0}" = 1 ] && [ "${CARVEMAP_CONTAINER_TEST:-0}" != 1 ]; then
  skip "set CARVEMAP_CONTAINER_TEST=1 to build the image and run a job in containers (~14 min)"
fi

# ---- what this machine has -------------------------------------------------------------
reasons=()
ENGINE=""
if command -v podman >/dev/null; then
  if out=$(podman info 2>&1 >/dev/null); then ENGINE=podman
  else reasons+=("podman is installed but \`podman info\` fails: $out"); fi
fi
if [ -z "$ENGINE" ] && command -v docker >/dev/null; then
  if out=$(docker info 2>&1 >/dev/null); then ENGINE=docker
  else reasons+=("docker client without a daemon: \`docker info\`: $(echo "$out" | tail -1)"); fi
fi
if [ -z "$ENGINE" ]; then
  command -v podman >/dev/null || reasons+=("no podman (apt-get install podman)")
  command -v docker >/dev/null || reasons+=("no docker")
  skip "no container engine: $(printf '%s; ' "${reasons[@]}")"
fi
[ "$(id -u)" -eq 0 ] || skip "needs root (debootstrap, rootful $ENGINE, volume ownership)"
command -v openssl >/dev/null || skip "no openssl"
python3 -c 'import yaml' 2>/dev/null || skip "no python3 with yaml (apt-get install python3-yaml)"
[ -x "$CARVEMAP" ] || skip "no carvemap client at $CARVEMAP (./scripts/build.sh carvemap, or CARVEMAP=PATH)"
"$CARVEMAP" --version >/dev/null || die "$CARVEMAP does not run"

if [ "$ENGINE" = podman ]; then
  BASE_FULL=docker.io/library/debian:12
  BASE_SLIM=docker.io/library/debian:12-slim
else
  BASE_FULL=debian:12
  BASE_SLIM=debian:12-slim
fi
image_exists() { "$ENGINE" image inspect "$1" >/dev/null 2>&1; }
if ! image_exists "$BASE_FULL" || ! image_exists "$BASE_SLIM"; then
  command -v debootstrap >/dev/null ||
    skip "the base images $BASE_FULL/$BASE_SLIM are missing and there is no debootstrap to make them (apt-get install debootstrap)"
fi

SCRATCH=${CT_SCRATCH:-$(mktemp -d "${TMPDIR:-/tmp}/carvemap-ct.XXXXXX")}
mkdir -p "$SCRATCH"
SCRATCH=$(cd "$SCRATCH" && pwd)
say "engine: $ENGINE ($("$ENGINE" --version)); scratch $SCRATCH"

# ---- teardown: everything this script starts, also on failure ----------------------------
started_containers=()
made_network=""
made_volumes=()
cleanup() {
  local rc=$?
  set +e
  if [ "${CT_KEEP:-0}" = 1 ]; then
    say "CT_KEEP=1: left running; remove with:"
    echo "  $ENGINE rm -f ${started_containers[*]}; $ENGINE network rm $made_network; $ENGINE volume rm ${made_volumes[*]}"
    exit "$rc"
  fi
  if [ "$rc" -ne 0 ] && [ "$rc" -ne 77 ] && [ ${#started_containers[@]} -gt 0 ]; then
    for c in "${started_containers[@]}"; do
      "$ENGINE" logs "$c" > "$SCRATCH/$c.log" 2>&1 && {
        echo "---- last lines of $c (all in $SCRATCH/$c.log) ----"; tail -15 "$SCRATCH/$c.log"; }
    done
  fi
  # Workers first, the merge service last, as `carvemap run` stops them.
  for ((i = ${#started_containers[@]} - 1; i >= 0; i--)); do
    "$ENGINE" rm -f -t 10 "${started_containers[i]}" >/dev/null 2>&1
  done
  [ -n "$made_network" ] && "$ENGINE" network rm "$made_network" >/dev/null 2>&1
  for v in "${made_volumes[@]}"; do "$ENGINE" volume rm -f "$v" >/dev/null 2>&1; done
  [ -d "$SCRATCH/rootfs" ] && rm -rf "$SCRATCH/rootfs"
  exit "$rc"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Leftovers of an earlier run that was killed (SIGKILL skips the trap): same names.
for c in $("$ENGINE" ps -a --format '{{.Names}}' | grep "^$PREFIX-" || true); do
  say "removing leftover container $c"; "$ENGINE" rm -f -t 0 "$c" >/dev/null
done
"$ENGINE" network rm "$NET" >/dev/null 2>&1 || true
for v in $PREFIX-carvemap-shared $PREFIX-carvemap-coordinator-state; do
  "$ENGINE" volume rm -f "$v" >/dev/null 2>&1 || true
done

# ---- base images: Debian 12 made with debootstrap, tagged as the Dockerfile's FROM lines ----
make_base_images() {
  local rootfs=$SCRATCH/rootfs
  say "debootstrap bookworm (minbase) from $MIRROR"
  rm -rf "$rootfs"
  debootstrap --variant=minbase bookworm "$rootfs" "$MIRROR" > "$SCRATCH/debootstrap.log" 2>&1 ||
    { tail -20 "$SCRATCH/debootstrap.log"; die "debootstrap failed (log: $SCRATCH/debootstrap.log)"; }
  # Sources as Debian's own images have them (the release, its updates, security).
  rm -f "$rootfs/etc/apt/sources.list"
  cat > "$rootfs/etc/apt/sources.list.d/debian.sources" <<EOF
Types: deb
URIs: $MIRROR
Suites: bookworm bookworm-updates
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg

Types: deb
URIs: ${MIRROR%/debian}/debian-security
Suites: bookworm-security
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
EOF
  chroot "$rootfs" apt-get clean
  rm -rf "$rootfs"/var/lib/apt/lists/* "$rootfs"/var/cache/apt/*.bin "$rootfs"/var/log/*.log \
         "$rootfs"/var/cache/ldconfig/aux-cache "$rootfs"/debootstrap
  : > "$rootfs/etc/resolv.conf"
  echo localhost > "$rootfs/etc/hostname"
  local change=(--change 'CMD ["bash"]' --change 'ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin')
  tar --numeric-owner -C "$rootfs" -cf - . |
    "$ENGINE" import "${change[@]}" --message "debootstrap --variant=minbase bookworm" - "$BASE_FULL" \
      >> "$SCRATCH/import.log" 2>&1 || die "$ENGINE import failed: $(tail -3 "$SCRATCH/import.log")"
  # -slim as Debian's: no documentation, manuals or translations, and dpkg keeps them out.
  cat > "$rootfs/etc/dpkg/dpkg.cfg.d/docker" <<'EOF'
path-exclude /usr/share/doc/*
path-include /usr/share/doc/*/copyright
path-exclude /usr/share/man/*
path-exclude /usr/share/groff/*
path-exclude /usr/share/info/*
path-exclude /usr/share/lintian/*
path-exclude /usr/share/linda/*
path-exclude /usr/share/locale/*
path-include /usr/share/locale/locale.alias
EOF
  find "$rootfs/usr/share/doc" -mindepth 1 -not -name copyright -not -type d -delete
  find "$rootfs/usr/share/doc" -mindepth 1 -type d -empty -delete
  rm -rf "$rootfs"/usr/share/{man,groff,info,lintian,linda}/*
  find "$rootfs/usr/share/locale" -mindepth 1 -maxdepth 1 -not -name locale.alias -exec rm -rf {} +
  tar --numeric-owner -C "$rootfs" -cf - . |
    "$ENGINE" import "${change[@]}" --message "debootstrap --variant=minbase bookworm, slimmed" - "$BASE_SLIM" \
      >> "$SCRATCH/import.log" 2>&1 || die "$ENGINE import failed: $(tail -3 "$SCRATCH/import.log")"
  rm -rf "$rootfs"
}
if image_exists "$BASE_FULL" && image_exists "$BASE_SLIM"; then
  say "base images $BASE_FULL and $BASE_SLIM exist: reused"
else
  t0=$SECONDS
  make_base_images
  say "base images made in $((SECONDS - t0)) s: $BASE_FULL, $BASE_SLIM"
fi

# ---- can this machine run a container, and with which options? ---------------------------
# Rootful podman asks for RLIMIT_NOFILE and RLIMIT_NPROC of 1048576 in each container, which
# fails where root lacks CAP_SYS_RESOURCE (a sandboxed root); crun refuses cgroup v1 with a
# cgroup v2 hierarchy that still holds a controller ("hybrid mode"), runc does not. Try the
# engine as it is first, then those workarounds, and say which one was needed and why.
ENGINE_OPTS=()
if [ "$ENGINE" = podman ]; then
  hn=$(ulimit -Hn); hu=$(ulimit -Hu)
  [ "$hu" = unlimited ] && hu=1048576
  [ "$hn" = unlimited ] && hn=1048576
  candidates=("")
  command -v runc >/dev/null && candidates+=("--runtime runc")
  for np in "$hu" 32768; do
    lim="--ulimit nofile=$hn:$hn --ulimit nproc=$np:$np"
    candidates+=("$lim")
    command -v runc >/dev/null && candidates+=("--runtime runc $lim")
  done
  ok=""
  for cand in "${candidates[@]}"; do
    read -r -a opts <<< "$cand"
    if out=$(podman run --rm "${opts[@]}" "$BASE_SLIM" true 2>&1); then ok=1; ENGINE_OPTS=("${opts[@]}"); break; fi
    say "podman run ${cand:-(no extra options)}: $(echo "$out" | tail -1)"
  done
  [ -n "$ok" ] || {
    command -v runc >/dev/null || reasons+=("no runc to try (apt-get install runc)")
    skip "podman cannot start a container on this machine (errors above) ${reasons[*]:-}"; }
  [ ${#ENGINE_OPTS[@]} -gt 0 ] && say "containers need: ${ENGINE_OPTS[*]}"
else
  out=$(docker run --rm "$BASE_SLIM" true 2>&1) || skip "docker cannot start a container: $out"
fi

# ---- the image ----------------------------------------------------------------------------
if [ "${CT_REUSE_IMAGE:-0}" = 1 ] && image_exists "$IMAGE"; then
  say "CT_REUSE_IMAGE=1: using the existing $IMAGE"
else
  say "building $IMAGE from $CONTEXT (deploy/Dockerfile, BUILD_JOBS=$BUILD_JOBS, nice 19; log $SCRATCH/build.log)"
  t0=$SECONDS
  if [ "$ENGINE" = podman ]; then
    build=(podman build "${ENGINE_OPTS[@]}" --pull=never --layers
           --ignorefile "$CONTEXT/deploy/Dockerfile.dockerignore")
  else
    export DOCKER_BUILDKIT=1
    build=(docker build)
  fi
  build+=(-f "$CONTEXT/deploy/Dockerfile" --build-arg "BUILD_JOBS=$BUILD_JOBS" -t "$IMAGE" "$CONTEXT")
  echo "  ${build[*]}"
  # Steps and ninja's progress on the terminal, everything in the log.
  if ! nice -n 19 "${build[@]}" > >(tee "$SCRATCH/build.log" |
        grep --line-buffered -E '^(\[[0-9]+/[0-9]+\] )?(STEP|COMMIT)|^#[0-9]+ \[|^\[[0-9]+/[0-9]+\] (Building|Linking)|rror' |
        awk '/^\[[0-9]+\/[0-9]+\] (Building|Linking)/ { if (++n % 25 != 1) next } { print; fflush() }') 2>&1; then
    sleep 1; tail -30 "$SCRATCH/build.log"; die "image build failed (log: $SCRATCH/build.log)"
  fi
  sleep 1
  say "image built in $((SECONDS - t0)) s"
fi
size=$("$ENGINE" image inspect --format '{{.Size}}' "$IMAGE")
say "image $IMAGE: $((size / 1000000)) MB; $("$ENGINE" run --rm "${ENGINE_OPTS[@]}" "$IMAGE" --version)"

# ---- Secrets (docs/CLUSTER.md, step 3) ------------------------------------------------------
SECRETS=$SCRATCH/secrets
rm -rf "$SECRETS" "$SCRATCH/mounts"
mkdir -p "$SECRETS"/{carvemap-tokens,carvemap-cluster-secret,carvemap-tls}
(
  umask 077
  cd "$SECRETS"
  token=$(openssl rand -hex 32)
  echo "$token $TENANT" > carvemap-tokens/tokens
  echo "$token" > "$TENANT.token"
  openssl rand -hex 32 > carvemap-cluster-secret/secret
  openssl req -x509 -newkey rsa:3072 -nodes -days 2 -subj /CN=carvemap-ca \
      -keyout ca.key -out carvemap-tls/ca.crt 2>/dev/null
  openssl req -newkey rsa:3072 -nodes -subj /CN=carvemap-coordinator \
      -keyout carvemap-tls/tls.key -out tls.csr 2>/dev/null
  printf 'subjectAltName=DNS:carvemap-coordinator,DNS:carvemap-coordinator.carvemap,DNS:carvemap-coordinator.carvemap.svc,DNS:carvemap-coordinator.carvemap.svc.cluster.local,DNS:localhost,DNS:carvemap-merger,DNS:carvemap-merger.carvemap,DNS:carvemap-merger.carvemap.svc,DNS:carvemap-merger.carvemap.svc.cluster.local\nextendedKeyUsage=serverAuth\n' > san.ext
  openssl x509 -req -in tls.csr -CA carvemap-tls/ca.crt -CAkey ca.key -CAcreateserial -days 2 \
      -extfile san.ext -out carvemap-tls/tls.crt 2>/dev/null
  cp carvemap-tls/ca.crt ca.crt
)

# ---- the manifests, as container runs -------------------------------------------------------
# Reads deploy/k8s/base's Deployments and turns each container into the engine's flags: args
# (and an init container's command), runAsUser/runAsGroup (+ fsGroup as a supplementary group),
# readOnlyRootFilesystem, capabilities drop ALL, allowPrivilegeEscalation false
# (no-new-privileges), limits, volume mounts: a PersistentVolumeClaim is a named volume, an
# emptyDir a tmpfs of its sizeLimit, a Secret a read-only folder of its keys (or items) with
# its defaultMode, owned root:fsGroup as the kubelet makes it.
python3 - "$ROOT/deploy/k8s/base" "$ENGINE" "$IMAGE" "$PREFIX" "$SECRETS" "$SCRATCH/mounts" \
    "${CT_LIMITS:-1}" > "$SCRATCH/manifests.sh" <<'PY'
import glob, os, shlex, shutil, sys, yaml
base, engine, image, prefix, secrets, mounts, limits = sys.argv[1:]
docs = []
for f in sorted(glob.glob(os.path.join(base, "*.yaml"))):
    docs += [d for d in yaml.safe_load_all(open(f)) if d]
def size(q):  # Kubernetes quantity -> bytes
    units = {"Ki": 1 << 10, "Mi": 1 << 20, "Gi": 1 << 30, "Ti": 1 << 40, "k": 10**3, "M": 10**6, "G": 10**9}
    q = str(q)
    for u, m in units.items():
        if q.endswith(u):
            return int(float(q[: -len(u)]) * m)
    return int(q)
def cpus(q):
    q = str(q)
    return float(q[:-1]) / 1000 if q.endswith("m") else float(q)
out = []
names = []
for d in docs:
    if d.get("kind") != "Deployment":
        continue
    name = d["metadata"]["name"]
    var = name.replace("-", "_")
    names.append(name)
    pod = d["spec"]["template"]["spec"]
    psc = pod.get("securityContext", {})
    vols = {v["name"]: v for v in pod.get("volumes", [])}
    def flags(c, cname):
        sc = dict(psc); sc.update(c.get("securityContext", {}))
        f = []
        uid, gid = sc.get("runAsUser"), sc.get("runAsGroup", 0)
        if sc.get("runAsNonRoot") and not uid:
            sys.exit(f"{name}/{c['name']}: runAsNonRoot without a numeric runAsUser")
        if uid is not None:
            f += ["--user", f"{uid}:{gid}"]
        if psc.get("fsGroup") is not None:
            f += ["--group-add", str(psc["fsGroup"])]
        if sc.get("readOnlyRootFilesystem"):
            f += ["--read-only"] + (["--read-only-tmpfs=false"] if engine == "podman" else [])
        for cap in sc.get("capabilities", {}).get("drop", []):
            f += ["--cap-drop", cap]
        if sc.get("allowPrivilegeEscalation") is False:
            f += ["--security-opt", "no-new-privileges"]
        lim = c.get("resources", {}).get("limits", {})
        if limits == "1":
            if "memory" in lim:
                f += ["--memory", str(size(lim["memory"]))]
            if "cpu" in lim:
                f += ["--cpus", str(cpus(lim["cpu"]))]
        for m in c.get("volumeMounts", []):
            v = vols[m["name"]]
            ro = ",ro" if m.get("readOnly") else ""
            if "persistentVolumeClaim" in v:
                f += ["-v", f"{prefix}-{v['persistentVolumeClaim']['claimName']}:{m['mountPath']}{ro.replace(',', ':')}"]
            elif "emptyDir" in v:
                sl = v["emptyDir"].get("sizeLimit")
                f += ["--tmpfs", f"{m['mountPath']}:rw,mode=1777" + (f",size={size(sl)}" if sl else "")]
            elif "secret" in v:
                s = v["secret"]
                src = os.path.join(secrets, s["secretName"])
                dst = os.path.join(mounts, f"{cname}-{m['name']}")
                os.makedirs(dst)
                items = s.get("items") or [{"key": k, "path": k} for k in sorted(os.listdir(src))]
                for it in items:
                    p = os.path.join(dst, it["path"])
                    shutil.copyfile(os.path.join(src, it["key"]), p)
                    os.chown(p, 0, psc.get("fsGroup", 0))
                    os.chmod(p, s.get("defaultMode", 0o644))
                os.chmod(dst, 0o755)
                f += ["-v", f"{dst}:{m['mountPath']}:ro"]
            else:
                sys.exit(f"{name}: volume {m['name']}: kind not handled")
        return f
    for kind, cs in (("INIT", pod.get("initContainers", [])), ("MAIN", pod["containers"])):
        assert len(cs) <= 1, f"{name}: one {kind} container expected"
        for c in cs:
            f = flags(c, f"{name}-{c['name']}")
            cmd = c.get("command", [])
            if cmd:
                f += ["--entrypoint", cmd[0]]
            f += [image] + cmd[1:] + c.get("args", [])
            out.append(f"{kind}_{var}=({' '.join(shlex.quote(x) for x in f)})")
            if kind == "MAIN":
                ports = [f"{p['containerPort']}" for p in c.get("ports", [])]
                out.append(f"PORTS_{var}=({' '.join(ports)})")
    out.append(f"REPLICAS_{var}={d['spec'].get('replicas', 1)}")
print(f"DEPLOYMENTS=({' '.join(names)})")
print("\n".join(out))
PY
# shellcheck disable=SC1091
source "$SCRATCH/manifests.sh"
for d in carvemap-coordinator carvemap-merger carvemap-worker; do
  [[ " ${DEPLOYMENTS[*]} " == *" $d "* ]] || die "deploy/k8s/base has no Deployment $d"
done

# ---- network, volumes, fsGroup --------------------------------------------------------------
"$ENGINE" network create "$NET" >/dev/null
made_network=$NET
for v in carvemap-shared carvemap-coordinator-state; do
  "$ENGINE" volume create "$PREFIX-$v" >/dev/null
  made_volumes+=("$PREFIX-$v")
done
# What the kubelet does for fsGroup 10001 on a volume that supports it: group 10001, group
# writable, setgid folders.
# shellcheck disable=SC2016  # ($d is the container shell's)
"$ENGINE" run --rm "${ENGINE_OPTS[@]}" --user 0:0 --entrypoint /bin/sh \
    -v "$PREFIX-carvemap-shared:/data" -v "$PREFIX-carvemap-coordinator-state:/var/lib/carvemap/state" \
    "$IMAGE" -ec 'for d in /data /var/lib/carvemap/state; do chgrp -R 10001 $d; chmod -R g+rwX $d; chmod 2775 $d; done'

# ---- the pods ---------------------------------------------------------------------------------
run_container() {  # NAME ALIAS [PUBLISH] -- FLAGS...
  local name=$1 alias=$2 publish=$3; shift 4
  local args=(run -d --name "$name" --hostname "$name" --network "$NET" --network-alias "$alias")
  [ -n "$publish" ] && args+=(-p "$publish")
  # (podman's DNS server, aardvark-dns, says it has no syslog: noise)
  "$ENGINE" "${args[@]}" "${ENGINE_OPTS[@]}" "$@" > /dev/null 2> >(grep -v 'failed to connect to syslog' >&2)
  started_containers+=("$name")
}
wait_log() {  # NAME PATTERN SECONDS
  local i
  for ((i = 0; i < $3 * 2; i++)); do
    # (grep -c reads all: grep -q would end the pipe early, and pipefail fail it)
    [ "$("$ENGINE" logs "$1" 2>&1 | grep -c -- "$2")" -gt 0 ] && return 0
    [ "$("$ENGINE" inspect -f '{{.State.Running}}' "$1")" = true ] ||
      die "$1 exited: $("$ENGINE" logs "$1" 2>&1 | tail -5)"
    sleep 0.5
  done
  die "$1: no '$2' in its log after $3 s: $("$ENGINE" logs "$1" 2>&1 | tail -5)"
}
# Checks what the manifests ask of every running container: the user, no capabilities, a
# read-only root file system (and a writable /tmp and volume).
check_container() {  # NAME
  local c=$1 ids caps ro
  ids=$("$ENGINE" exec "$c" id)
  [[ "$ids" == "uid=10001"*"gid=10001"* ]] || die "$c runs as $ids, not 10001:10001"
  caps=$("$ENGINE" exec "$c" sh -c 'grep -E "^Cap(Eff|Prm|Bnd)" /proc/1/status | tr -s "\t" " " | tr "\n" " "')
  [[ "$caps" == *"CapEff: 0000000000000000"* ]] || die "$c has capabilities: $caps"
  ro=$("$ENGINE" inspect -f '{{.HostConfig.ReadonlyRootfs}}' "$c")
  [ "$ro" = true ] || die "$c: root file system not read-only"
  # /var/tmp is world-writable in the image: only a read-only root file system refuses.
  local err
  if err=$("$ENGINE" exec "$c" touch /var/tmp/x 2>&1); then die "$c could write its root file system"; fi
  [[ "$err" == *"Read-only file system"* ]] || die "$c: writing /var/tmp failed otherwise: $err"
  "$ENGINE" exec "$c" sh -c 'touch /tmp/x && rm /tmp/x && touch /data/.w && rm /data/.w' ||
    die "$c cannot write /tmp or /data"
  say "$c: $ids; $caps; root fs read-only (a write fails), /tmp and /data writable"
}

COORD=$PREFIX-coordinator
MERGER=$PREFIX-merger
# The coordinator's init container (prepare-dirs): the folders, and jobs.db linked to the
# state volume.
"$ENGINE" run --rm --name "$PREFIX-prepare-dirs" --network "$NET" "${ENGINE_OPTS[@]}" \
    "${INIT_carvemap_coordinator[@]}"
say "init container prepare-dirs done: $("$ENGINE" run --rm "${ENGINE_OPTS[@]}" --entrypoint ls \
    -v "$PREFIX-carvemap-shared:/data" "$IMAGE" -l /data/work/jobs.db | cut -d' ' -f9-)"

run_container "$MERGER" carvemap-merger "" -- "${MAIN_carvemap_merger[@]}"
wait_log "$MERGER" "listening on" 60
# The job API published on the host's loopback (kubectl port-forward's place).
run_container "$COORD" carvemap-coordinator "127.0.0.1::7600" -- "${MAIN_carvemap_coordinator[@]}"
wait_log "$COORD" "listening on" 300
for ((i = 1; i <= REPLICAS_carvemap_worker; i++)); do
  run_container "$PREFIX-worker-$i" carvemap-worker "" -- "${MAIN_carvemap_worker[@]}"
done
for ((i = 1; i <= REPLICAS_carvemap_worker; i++)); do
  wait_log "$PREFIX-worker-$i" "registered as" 60
done
for c in "${started_containers[@]}"; do check_container "$c"; done
"$ENGINE" ps --filter "name=^$PREFIX-" --format '  {{.Names}}  {{.Status}}  {{.Ports}}'

# The merger's memory budget comes from its cgroup's limit (--merge-memory-mb 0).
"$ENGINE" logs "$MERGER" 2>&1 | sed -n '1,5s/^/  merger: /p'

PORT=$("$ENGINE" port "$COORD" 7600/tcp | sed -n '1s/.*://p')
[ -n "$PORT" ] || die "no published port for the coordinator"
export CARVEMAP_SERVER=127.0.0.1:$PORT CARVEMAP_TLS_CA=$SECRETS/ca.crt \
       CARVEMAP_TLS_SERVER_NAME=carvemap-coordinator CARVEMAP_TOKEN_FILE=$SECRETS/$TENANT.token
say "job API at $CARVEMAP_SERVER (TLS, certificate name carvemap-coordinator)"
"$CARVEMAP" list >/dev/null || die "the host client cannot reach the coordinator through $CARVEMAP_SERVER"

# ---- a scan, onto the volume through the coordinator (docs/CLUSTER.md, step 5) ----------------
rm -rf "$SCRATCH/scan" "$SCRATCH/out"
"$CARVEMAP" simulate --preset office --rate-hz 10 --beam-step-deg 1 --max-duration "$SCAN_SECONDS" \
    --seed 1 -q -o "$SCRATCH/scan"
say "scan: $(du -h "$SCRATCH/scan/scan.h5" | cut -f1) ($SCAN_SECONDS s of the office walk, 10 Hz, 1° beams)"
"$ENGINE" exec "$COORD" mkdir -p "/data/in/$TENANT/office"
tar -C "$SCRATCH/scan" -cf - scan.h5 | "$ENGINE" exec -i "$COORD" tar -xf - -C "/data/in/$TENANT/office"

# ---- the job ------------------------------------------------------------------------------------
say "submit (host client $CARVEMAP)"
t0=$SECONDS
submit_rc=0
"$CARVEMAP" submit -o office office/scan.h5 --watch > "$SCRATCH/submit.log" 2>&1 || submit_rc=$?
tr '\r' '\n' < "$SCRATCH/submit.log" | grep -v '^ *$' | tail -n 4 | sed 's/^/  submit: /'
job=$(tr '\r' '\n' < "$SCRATCH/submit.log" | sed -n '1{/^j-[0-9A-Za-z-]*$/p}')  # its first line
[ -n "$job" ] || die "no job id from submit: $(tail -5 "$SCRATCH/submit.log")"
elapsed=$((SECONDS - t0))
[ "$submit_rc" -eq 0 ] || say "submit --watch exited $submit_rc"
"$CARVEMAP" status "$job" | tee "$SCRATCH/status.txt"
grep -q SUCCEEDED "$SCRATCH/status.txt" || die "job $job did not succeed"
say "job $job SUCCEEDED in ${elapsed} s (submit to end, as seen from the host)"

# The outputs, out of the volume through the coordinator (kubectl cp's way) and by `fetch`.
mkdir -p "$SCRATCH/out"
"$ENGINE" exec "$COORD" tar -C "/data/out/$TENANT" --exclude=tiles --exclude=object_tiles -cf - office |
  tar -xf - -C "$SCRATCH/out"
O=$SCRATCH/out/office
missing=()
for f in job.json octree.bt octree.ot levels.json mesh/dense.ply mesh/building.ply; do
  [ -s "$O/$f" ] || missing+=("$f")
done
compgen -G "$O/level_*/floorplan.geojson" >/dev/null || missing+=("level_*/floorplan.geojson")
compgen -G "$O/level_*/floorplan.svg" >/dev/null || missing+=("level_*/floorplan.svg")
compgen -G "$O/level_*/floorplan.dxf" >/dev/null || missing+=("level_*/floorplan.dxf")
[ ${#missing[@]} -eq 0 ] || die "job $job: outputs missing: ${missing[*]} (have: $(cd "$O" && find . -type f | head -30 | tr '\n' ' '))"
# job.json names the job and lists its outputs: each must be there, not empty.
python3 - "$O" "$job" <<'PY' || die "job.json does not match the job or its outputs"
import json, os, sys
out, job = sys.argv[1:]
j = json.load(open(os.path.join(out, "job.json")))
assert j["job_id"] == job, f"job.json is of {j['job_id']}, not {job}"
assert j["output_name"] == "office", j["output_name"]
outs = j["outputs"]
bad = [o for o in outs if not os.path.isfile(os.path.join(out, o)) or os.path.getsize(os.path.join(out, o)) == 0]
assert not bad, f"listed in job.json but missing or empty: {bad}"
c = j.get("counts", {})
print(f"  job.json: {len(outs)} outputs listed, all there; rooms {c.get('rooms')}, "
      f"building {c.get('building_triangles')} triangles (watertight {c.get('building_watertight')}), "
      f"dense {c.get('dense_triangles')} triangles, {c.get('objects')} objects")
PY
(cd "$SCRATCH/out" && "$CARVEMAP" fetch "$job" job.json >/dev/null 2>&1 && cmp -s job.json office/job.json) ||
  die "carvemap fetch $job job.json differs from the volume's"
say "outputs of $job (from the volume):"
(cd "$O" && find . -type f -printf '  %P %s\n' | sort)
say "PASS: image $IMAGE ($((size / 1000000)) MB), coordinator + ${REPLICAS_carvemap_worker} workers + merge service as $ENGINE containers, job $job SUCCEEDED in ${elapsed} s"
