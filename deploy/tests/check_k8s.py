#!/usr/bin/python3
"""Renders deploy/k8s/base and every overlay with `kubectl kustomize` and checks the objects.

Usage: check_k8s.py [--carvemap BUILD/carvemap]

With --carvemap, container args are also checked against the binary's own `--help` (no flag
the binary does not have). Uses Debian's kubectl (kubernetes-client, /usr/bin/kubectl first,
else the first on PATH; CARVEMAP_KUBECTL overrides) and python3-yaml (a dependency of
yamllint). Fails, never skips, when they are missing.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
K8S = os.path.join(ROOT, "deploy", "k8s")
INSTALL = "run scripts/install-deps.sh (Debian packages kubernetes-client, yamllint)"

COORDINATOR = "carvemap-coordinator"
WORKER = "carvemap-worker"
MERGER = "carvemap-merger"
SHARED_PVC = "carvemap-shared"
STATE_PVC = "carvemap-coordinator-state"
# Secrets the base references but does not contain: created by hand on a real cluster
# (docs/CLUSTER.md), shipped with development values by overlays/local.
TOKENS_SECRET = "carvemap-tokens"
CLUSTER_SECRET = "carvemap-cluster-secret"
TLS_SECRET = "carvemap-tls"
EXTERNAL_SECRETS = {TOKENS_SECRET, CLUSTER_SECRET, TLS_SECRET}
# Which Secret each file flag must read from (docs/RPC.md, "Authentication").
SECRET_OF_FLAG = {
    "coordinator": {"--tokens": TOKENS_SECRET, "--cluster-secret-file": CLUSTER_SECRET,
                    "--tls-cert": TLS_SECRET, "--tls-key": TLS_SECRET,
                    "--tls-client-ca": TLS_SECRET},
    "worker": {"--cluster-secret-file": CLUSTER_SECRET, "--tls-ca": TLS_SECRET,
               "--tls-cert": TLS_SECRET, "--tls-key": TLS_SECRET},
    "merger": {"--cluster-secret-file": CLUSTER_SECRET, "--tls-cert": TLS_SECRET,
               "--tls-key": TLS_SECRET, "--tls-client-ca": TLS_SECRET},
}
# The coordinator's flags for reaching the merge service (it is their client).
SECRET_OF_FLAG["coordinator"].update({"--merge-tls-ca": TLS_SECRET,
                                      "--merge-tls-cert": TLS_SECRET,
                                      "--merge-tls-key": TLS_SECRET})

errors = []


def fail(msg):
    errors.append(msg)


def die(msg):
    print(f"FAIL: {msg}", file=sys.stderr)
    sys.exit(1)


try:
    import yaml  # python3-yaml, installed with yamllint
except ImportError:
    die(f"python3 cannot import yaml: {INSTALL}")


def find_kubectl():
    override = os.environ.get("CARVEMAP_KUBECTL")
    if override:
        return override
    if os.access("/usr/bin/kubectl", os.X_OK):
        return "/usr/bin/kubectl"
    found = shutil.which("kubectl")
    if not found:
        die(f"kubectl not found: {INSTALL}")
    return found


def render(kubectl, path):
    proc = subprocess.run([kubectl, "kustomize", path], capture_output=True, text=True)
    if proc.returncode != 0:
        die(f"`{kubectl} kustomize {path}` failed:\n{proc.stderr}")
    return [d for d in yaml.safe_load_all(proc.stdout) if d]


# ---- helpers

def quantity(q):
    """A Kubernetes quantity as a float (cpu in cores, memory in bytes)."""
    q = str(q)
    m = re.fullmatch(r"([0-9.]+)(m|k|M|G|T|Ki|Mi|Gi|Ti)?", q)
    if not m:
        raise ValueError(f"bad quantity {q!r}")
    scale = {None: 1, "m": 1e-3, "k": 1e3, "M": 1e6, "G": 1e9, "T": 1e12,
             "Ki": 2**10, "Mi": 2**20, "Gi": 2**30, "Ti": 2**40}[m.group(2)]
    return float(m.group(1)) * scale


def flag(args, name):
    """Value of --name=V or --name V in a container's args, or None."""
    for i, a in enumerate(args):
        if a == name and i + 1 < len(args):
            return args[i + 1]
        if a.startswith(name + "="):
            return a.split("=", 1)[1]
    return None


def split_hostport(addr):
    host, _, port = addr.rpartition(":")
    return host, int(port) if port.isdigit() else None


def selects(selector, labels):
    return all(labels.get(k) == v for k, v in (selector or {}).items())


def pod_spec(dep):
    return dep["spec"]["template"]["spec"]


def volume_claims(spec):
    return {v["name"]: v["persistentVolumeClaim"]["claimName"]
            for v in spec.get("volumes", []) if "persistentVolumeClaim" in v}


def mount_path_of_claim(spec, container, claim):
    names = [n for n, c in volume_claims(spec).items() if c == claim]
    for m in container.get("volumeMounts", []):
        if m["name"] in names:
            return m["mountPath"]
    return None


def under(path, root):
    return path == root or path.startswith(root.rstrip("/") + "/")


def referenced_secrets(spec):
    refs = set()
    for v in spec.get("volumes", []):
        if "secret" in v:
            refs.add(v["secret"]["secretName"])
        for src in v.get("projected", {}).get("sources", []):
            if "secret" in src:
                refs.add(src["secret"]["name"])
    for s in spec.get("imagePullSecrets", []):
        refs.add(s["name"])
    for c in spec.get("containers", []) + spec.get("initContainers", []):
        for e in c.get("env", []):
            ref = e.get("valueFrom", {}).get("secretKeyRef")
            if ref:
                refs.add(ref["name"])
        for e in c.get("envFrom", []):
            if "secretRef" in e:
                refs.add(e["secretRef"]["name"])
    return refs


def secret_file_of(spec, container, path):
    """(secret name, key) that a file path inside `container` comes from, or None."""
    volumes = {v["name"]: v for v in spec.get("volumes", [])}
    for m in container.get("volumeMounts", []):
        v = volumes.get(m["name"])
        if v is None or "secret" not in v or not under(path, m["mountPath"]):
            continue
        rel = path[len(m["mountPath"].rstrip("/")) + 1:]
        items = v["secret"].get("items")
        if items is None:
            return v["secret"]["secretName"], rel
        for it in items:
            if it["path"] == rel:
                return v["secret"]["secretName"], it["key"]
        return v["secret"]["secretName"], None  # mounted, but that file is not projected
    return None


def help_flags(carvemap, sub):
    out = subprocess.run([carvemap, sub, "--help"], capture_output=True, text=True).stdout
    return set(re.findall(r"(--[a-z0-9][a-z0-9-]*)", out))


# ---- checks of one rendered kustomization

def check(label, objs, carvemap):
    def where(msg):
        fail(f"{label}: {msg}")

    by = {}
    for o in objs:
        by[(o["kind"], o["metadata"]["name"])] = o

    def get(kind, name):
        o = by.get((kind, name))
        if o is None:
            where(f"no {kind} {name}")
        return o

    coord = get("Deployment", COORDINATOR)
    worker = get("Deployment", WORKER)
    merger = get("Deployment", MERGER)
    svc = get("Service", COORDINATOR)
    msvc = get("Service", MERGER)
    shared = get("PersistentVolumeClaim", SHARED_PVC)
    state = get("PersistentVolumeClaim", STATE_PVC)
    hpa = get("HorizontalPodAutoscaler", WORKER)
    pdb = get("PodDisruptionBudget", WORKER)
    if None in (coord, worker, merger, svc, msvc, shared, state, hpa, pdb):
        return

    namespaces = {o["metadata"].get("namespace") for o in objs if o["kind"] != "Namespace"}
    if len(namespaces) != 1 or None in namespaces:
        where(f"objects should share one namespace, got {namespaces}")
    namespace = next(iter(namespaces))

    # The merge service is `carvemap merger`; `carvemap merge` is the offline batch command.
    for o in objs:
        if o["kind"] in ("Deployment", "StatefulSet", "DaemonSet", "Job"):
            for c in pod_spec(o)["containers"]:
                if (c.get("args") or [""])[0] == "merge":
                    where(f"{o['kind']} {o['metadata']['name']} runs `carvemap merge`, "
                          "which is a batch command, not a server")

    # Coordinator: one replica, never two during a rollout.
    if coord["spec"].get("replicas") != 1:
        where("coordinator replicas must be 1 (single writer of the job store)")
    if coord["spec"].get("strategy", {}).get("type") != "Recreate":
        where("coordinator strategy must be Recreate")

    # Volumes.
    if "ReadWriteMany" not in shared["spec"].get("accessModes", []):
        where(f"PVC {SHARED_PVC} must be ReadWriteMany")
    if state["spec"].get("accessModes") != ["ReadWriteOnce"]:
        where(f"PVC {STATE_PVC} must be ReadWriteOnce")
    pvcs = {n for (k, n) in by if k == "PersistentVolumeClaim"}

    cspec, wspec, mspec = pod_spec(coord), pod_spec(worker), pod_spec(merger)
    cc = next((c for c in cspec["containers"] if c["name"] == "coordinator"), None)
    wc = next((c for c in wspec["containers"] if c["name"] == "worker"), None)
    mc = next((c for c in mspec["containers"] if c["name"] == "merger"), None)
    if cc is None or wc is None or mc is None:
        where("containers named coordinator, worker and merger expected")
        return
    cargs, wargs, margs = cc.get("args", []), wc.get("args", []), mc.get("args", [])
    if cargs[:1] != ["coordinator"] or wargs[:1] != ["worker"] or margs[:1] != ["merger"]:
        where("the containers must run `carvemap coordinator`, `carvemap worker` and "
              "`carvemap merger`")

    for name, spec in ((COORDINATOR, cspec), (WORKER, wspec), (MERGER, mspec)):
        for claim in volume_claims(spec).values():
            if claim not in pvcs:
                where(f"{name} uses PVC {claim}, which is not rendered")

    c_shared = mount_path_of_claim(cspec, cc, SHARED_PVC)
    w_shared = mount_path_of_claim(wspec, wc, SHARED_PVC)
    m_shared = mount_path_of_claim(mspec, mc, SHARED_PVC)
    if c_shared is None or w_shared is None or m_shared is None:
        where(f"coordinator, worker and merger must all mount {SHARED_PVC}")
    elif len({c_shared, w_shared, m_shared}) != 1:
        where(f"{SHARED_PVC} mounted at {c_shared} (coordinator), {w_shared} (worker), "
              f"{m_shared} (merger): leases, tiles and merge requests carry absolute paths, "
              "the paths must match")
    else:
        for f in ("--data-root", "--output-root", "--work-dir"):
            v = flag(cargs, f)
            if v is None or not under(v, c_shared):
                where(f"coordinator {f}={v} is not on the shared volume ({c_shared})")
    c_state = mount_path_of_claim(cspec, cc, STATE_PVC)
    if c_state is None:
        where(f"coordinator must mount the job store PVC {STATE_PVC}")
    else:
        # jobs.db lives in --work-dir (on the shared volume, for the partial sums); an init
        # container must link it to the state volume.
        work = flag(cargs, "--work-dir") or ""
        link = f"{work.rstrip('/')}/jobs.db"
        linked = False
        for ic in cspec.get("initContainers", []):
            script = " ".join(ic.get("command", []) + ic.get("args", []))
            m = re.search(r"ln\s+-sfn\s+(\S+)\s+(\S+)", script)
            if m and m.group(2) == link and under(m.group(1), c_state) \
                    and mount_path_of_claim(cspec, ic, STATE_PVC) == c_state \
                    and mount_path_of_claim(cspec, ic, SHARED_PVC) == c_shared:
                linked = True
        if not linked:
            where(f"no init container links {link} to the job store volume ({c_state})")

    # Secrets: the coordinator reads all three; workers the cluster secret and the CA, never
    # the tenants' tokens.
    secrets = {n for (k, n) in by if k == "Secret"}
    for name, spec in ((COORDINATOR, cspec), (WORKER, wspec), (MERGER, mspec)):
        refs = referenced_secrets(spec)
        for s in refs - secrets:
            if label == "base" and s in EXTERNAL_SECRETS:
                continue
            where(f"{name} references Secret {s}, which does not exist")
    if not EXTERNAL_SECRETS <= referenced_secrets(cspec):
        where(f"coordinator should mount the Secrets {sorted(EXTERNAL_SECRETS)}")
    if not {CLUSTER_SECRET, TLS_SECRET} <= referenced_secrets(wspec):
        where(f"worker should mount the Secrets {CLUSTER_SECRET} and {TLS_SECRET}")
    if TOKENS_SECRET in referenced_secrets(wspec):
        where(f"worker mounts {TOKENS_SECRET}: workers have no business with tenants' tokens")
    if TOKENS_SECRET in referenced_secrets(mspec):
        where(f"merger mounts {TOKENS_SECRET}: the merge service has no business with tenants' "
              "tokens")
    if CLUSTER_SECRET not in referenced_secrets(mspec):
        where(f"merger should mount the Secret {CLUSTER_SECRET}")
    # Each security flag names a file of the right Secret, and that Secret has the key.
    for role, spec, c, args in (("coordinator", cspec, cc, cargs), ("worker", wspec, wc, wargs),
                                ("merger", mspec, mc, margs)):
        for f, secret in SECRET_OF_FLAG[role].items():
            path = flag(args, f)
            if path is None:
                continue
            found = secret_file_of(spec, c, path)
            if found is None or found[0] != secret:
                where(f"{role} {f}={path} is not a file of the mounted Secret {secret}")
                continue
            data = by.get(("Secret", secret))
            if found[1] is None:
                where(f"{role} {f}={path}: the {secret} volume does not project that file")
            elif data is not None and found[1] not in {**data.get("data", {}),
                                                       **data.get("stringData", {})}:
                where(f"{role} {f}={path}: Secret {secret} has no key {found[1]}")
    # Off loopback the binary refuses to start open; the manifests must not ask it to.
    if "--insecure" in cargs:
        where("coordinator runs with --insecure")
    if "--insecure" in margs:
        where("merger runs with --insecure")
    if flag(margs, "--cluster-secret-file") is None and flag(margs, "--tls-client-ca") is None:
        where("merger has neither --cluster-secret-file nor --tls-client-ca: its merge API "
              "would be open")
    if flag(margs, "--cluster-secret-file") is not None and \
            flag(cargs, "--cluster-secret-file") is None:
        where("the merger requires the cluster secret but the coordinator has none to present")
    if flag(margs, "--tls-client-ca") is not None and flag(margs, "--cluster-secret-file") is None \
            and flag(cargs, "--merge-tls-cert") is None:
        where("the merger requires a client certificate but the coordinator presents none")
    m_tls = flag(margs, "--tls-cert") is not None
    cm_tls = flag(cargs, "--merge-tls-ca") is not None
    if m_tls != cm_tls:
        where(f"merger TLS {m_tls} but the coordinator's merge client TLS {cm_tls}: they "
              "cannot talk")
    if label == "base" and not m_tls:
        where("the base must serve the merge service over TLS (--tls-cert/--tls-key)")
    if flag(cargs, "--tokens") is None:
        where("coordinator has no --tokens: the job API would be open")
    needs_secret = flag(cargs, "--cluster-secret-file") is not None
    if not needs_secret and flag(cargs, "--tls-client-ca") is None:
        where("coordinator has neither --cluster-secret-file nor --tls-client-ca")
    if needs_secret and flag(wargs, "--cluster-secret-file") is None and \
            flag(wargs, "--tls-cert") is None:
        where("the coordinator requires the cluster secret but workers do not present it")
    c_tls = flag(cargs, "--tls-cert") is not None
    w_tls = flag(wargs, "--tls-ca") is not None or "--tls" in wargs
    if c_tls != w_tls:
        where(f"coordinator TLS {c_tls} but worker TLS {w_tls}: they cannot talk")
    if label == "base" and not c_tls:
        where("the base must serve TLS (--tls-cert/--tls-key)")

    # Service ➜ coordinator.
    clabels = coord["spec"]["template"]["metadata"]["labels"]
    wlabels = worker["spec"]["template"]["metadata"]["labels"]
    if not selects(svc["spec"].get("selector"), clabels):
        where("the coordinator Service does not select the coordinator pods")
    if selects(svc["spec"].get("selector"), wlabels):
        where("the coordinator Service also selects worker pods")
    if not selects(coord["spec"]["selector"]["matchLabels"], clabels) or \
            not selects(worker["spec"]["selector"]["matchLabels"], wlabels):
        where("a Deployment's selector does not match its pod template")
    if selects(worker["spec"]["selector"]["matchLabels"], clabels):
        where("the worker Deployment's selector also matches coordinator pods")
    cports = {p["name"]: p["containerPort"] for p in cc.get("ports", [])}
    svc_ports = {}
    for p in svc["spec"]["ports"]:
        target = p.get("targetPort", p["port"])
        svc_ports[p["port"]] = cports.get(target) if isinstance(target, str) else target
    _, listen_port = split_hostport(flag(cargs, "--listen") or "")
    listen_host = (flag(cargs, "--listen") or "").rpartition(":")[0]
    if listen_host not in ("0.0.0.0", "[::]", ""):
        where(f"coordinator --listen host {listen_host!r}: other pods cannot reach it")
    if listen_port not in svc_ports.values():
        where(f"no Service port targets the coordinator's --listen port {listen_port}")

    # The coordinator finds the merge service through its Service.
    if not selects(msvc["spec"].get("selector"), merger["spec"]["template"]["metadata"]["labels"]):
        where("the merger Service does not select the merger pods")
    for other, olabels in ((COORDINATOR, clabels), (WORKER, wlabels)):
        if selects(msvc["spec"].get("selector"), olabels):
            where(f"the merger Service also selects {other} pods")
    if selects(svc["spec"].get("selector"), merger["spec"]["template"]["metadata"]["labels"]):
        where("the coordinator Service also selects merger pods")
    mports = {p["name"]: p["containerPort"] for p in mc.get("ports", [])}
    msvc_ports = {}
    for p in msvc["spec"]["ports"]:
        target = p.get("targetPort", p["port"])
        msvc_ports[p["port"]] = mports.get(target) if isinstance(target, str) else target
    m_listen_host, _, _ = (flag(margs, "--listen") or "").rpartition(":")
    _, m_listen_port = split_hostport(flag(margs, "--listen") or "")
    if m_listen_host not in ("0.0.0.0", "[::]", ""):
        where(f"merger --listen host {m_listen_host!r}: the coordinator's pod cannot reach it")
    merge_addr = flag(cargs, "--merge-server")
    if "--no-merge" in cargs:
        where("coordinator runs with --no-merge: jobs would end without outputs")
    elif not merge_addr:
        where("coordinator has no --merge-server")
    else:
        for addr in merge_addr.split(","):
            host, port = split_hostport(addr)
            names = {MERGER, f"{MERGER}.{namespace}", f"{MERGER}.{namespace}.svc",
                     f"{MERGER}.{namespace}.svc.cluster.local"}
            if host not in names:
                where(f"coordinator --merge-server host {host!r} is not the merger Service's "
                      f"DNS name ({sorted(names)})")
            if port not in msvc_ports or msvc_ports[port] != m_listen_port:
                where(f"coordinator --merge-server port {port} is not a merger Service port "
                      f"that reaches the merger's port {m_listen_port}")

    # Workers find the coordinator through the Service.
    coord_addr = flag(wargs, "--coordinator") or flag(wargs, "--server")
    if not coord_addr:
        where("worker has no --coordinator")
    else:
        host, port = split_hostport(coord_addr)
        names = {COORDINATOR, f"{COORDINATOR}.{namespace}", f"{COORDINATOR}.{namespace}.svc",
                 f"{COORDINATOR}.{namespace}.svc.cluster.local"}
        if host not in names:
            where(f"worker --coordinator host {host!r} is not the Service's DNS name "
                  f"({sorted(names)})")
        if port not in svc_ports or svc_ports[port] != listen_port:
            where(f"worker --coordinator port {port} is not a Service port that reaches the "
                  f"coordinator's port {listen_port}")

    # Autoscaler and disruption budget.
    ref = hpa["spec"].get("scaleTargetRef", {})
    if (ref.get("kind"), ref.get("name")) != ("Deployment", WORKER):
        where(f"HPA targets {ref}, not Deployment {WORKER}")
    if hpa["apiVersion"] != "autoscaling/v2":
        where("HPA should be autoscaling/v2")
    lo, hi = hpa["spec"].get("minReplicas", 1), hpa["spec"].get("maxReplicas", 0)
    if not 1 <= lo <= hi:
        where(f"HPA replicas {lo}..{hi}")
    if not any(m.get("type") == "Resource" and m["resource"]["name"] == "cpu"
               for m in hpa["spec"].get("metrics", [])):
        where("HPA does not scale on cpu")
    reps = worker["spec"].get("replicas")
    if reps is not None and not lo <= reps <= hi:
        where(f"worker replicas {reps} outside the HPA's {lo}..{hi}")
    psel = pdb["spec"].get("selector", {}).get("matchLabels")
    if not psel or not selects(psel, wlabels):
        where("the PodDisruptionBudget does not select the worker pods")
    if psel and selects(psel, clabels):
        where("the PodDisruptionBudget also selects the coordinator")

    # Every container: requests/limits, non-root; main containers: gRPC probes on the port
    # they listen on.
    for dep in (coord, worker, merger):
        spec = pod_spec(dep)
        psc = spec.get("securityContext", {})
        if psc.get("runAsNonRoot") is not True or not psc.get("runAsUser"):
            where(f"{dep['metadata']['name']}: pod securityContext needs runAsNonRoot "
                  "and a non-zero runAsUser")
        for c in spec["containers"] + spec.get("initContainers", []):
            cname = f"{dep['metadata']['name']}/{c['name']}"
            res = c.get("resources", {})
            for kind in ("cpu", "memory"):
                req = res.get("requests", {}).get(kind)
                lim = res.get("limits", {}).get(kind)
                if req is None or lim is None:
                    where(f"{cname}: needs requests and limits for {kind}")
                elif quantity(req) > quantity(lim):
                    where(f"{cname}: {kind} request {req} > limit {lim}")
            sc = c.get("securityContext", {})
            if sc.get("runAsNonRoot") is False or sc.get("runAsUser") == 0:
                where(f"{cname}: runs as root")
            if sc.get("allowPrivilegeEscalation") is not False:
                where(f"{cname}: allowPrivilegeEscalation must be false")
            if c.get("image", "").split(":")[0].split("/")[-1] != "carvemap":
                where(f"{cname}: image {c.get('image')} is not the carvemap image")
        for c in spec["containers"]:
            cname = f"{dep['metadata']['name']}/{c['name']}"
            args = c.get("args", [])
            _, port = split_hostport(flag(args, "--listen") or "")
            declared = {p["containerPort"] for p in c.get("ports", [])}
            if port is None or port not in declared:
                where(f"{cname}: --listen port {port} is not a declared containerPort")
            # Kubelet gRPC probes speak plaintext: with TLS they need the health-only port.
            probe_port = port
            if flag(args, "--health-listen") is not None:
                _, probe_port = split_hostport(flag(args, "--health-listen"))
                if probe_port not in declared:
                    where(f"{cname}: --health-listen port {probe_port} is not a declared "
                          "containerPort")
            elif flag(args, "--tls-cert") is not None:
                where(f"{cname}: serves TLS without a plaintext --health-listen port for the "
                      "probes")
            for probe in ("readinessProbe", "livenessProbe"):
                p = c.get(probe)
                if not p or "grpc" not in p:
                    where(f"{cname}: needs a native gRPC {probe}")
                elif p["grpc"].get("port") != probe_port:
                    where(f"{cname}: {probe} on port {p['grpc'].get('port')}, "
                          f"but health is served on {probe_port}")

    # Only flags the binary has.
    if carvemap:
        for dep in (coord, worker, merger):
            for c in pod_spec(dep)["containers"]:
                args = c.get("args", [])
                known = help_flags(carvemap, args[0])
                for a in args[1:]:
                    if a.startswith("--") and a.split("=", 1)[0] not in known:
                        where(f"{dep['metadata']['name']}: `carvemap {args[0]}` has no "
                              f"flag {a.split('=', 1)[0]}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--carvemap", help="the built binary, to check flags against its --help")
    opts = ap.parse_args()
    if opts.carvemap and not os.access(opts.carvemap, os.X_OK):
        die(f"{opts.carvemap} does not exist: build carvemap first (scripts/build.sh)")
    kubectl = find_kubectl()
    targets = [("base", os.path.join(K8S, "base"))]
    overlays = os.path.join(K8S, "overlays")
    for name in sorted(os.listdir(overlays)):
        targets.append((f"overlays/{name}", os.path.join(overlays, name)))
    if "overlays/local" not in [t[0] for t in targets]:
        fail("deploy/k8s/overlays/local is missing")
    for label, path in targets:
        objs = render(kubectl, path)
        check(label, objs, opts.carvemap)
        print(f"{label}: {len(objs)} objects rendered by {kubectl}")
    # The Secrets the base expects must be the ones the guide tells people to create.
    guide = open(os.path.join(ROOT, "docs", "CLUSTER.md"), encoding="utf-8").read()
    for s in sorted(EXTERNAL_SECRETS):
        if not re.search(r"kubectl[^\n]*create secret[^\n]*\b" + re.escape(s) + r"\b", guide):
            fail(f"docs/CLUSTER.md does not show how to create Secret {s}")
    if errors:
        for e in errors:
            print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)
    print("deploy/k8s: all checks passed")


if __name__ == "__main__":
    main()
