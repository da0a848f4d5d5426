#!/usr/bin/python3
"""Soak benchmark: many jobs of mixed sizes from four tenants over several
minutes on one cluster (a coordinator, 2 workers, 2 merge services as separate `carvemap`
processes, tests/tools/cluster_harness.py), while a chaos thread SIGKILLs a worker or a merge
service at random moments and starts it again. Then:

  outcome   every job ends SUCCEEDED with outputs identical to the undisturbed reference run of
            its scan, or FAILED with a non-empty reason (counted, each reason printed); a job
            still running at the end, CANCELLED, or FAILED without a reason is a failure.
            "Identical": every file but job.json (timings), byte for byte, after the job id is
            masked: tiles record their job id (docs/RPC.md, SubmitJob) and the soak's jobs
            cannot share the reference's id, so the 18 bytes `j-<16 hex>` are replaced by a
            fixed string of the same length in both before hashing; nothing else is masked.
  growth    open fds, threads, resident and peak memory of every server, scraped from its
            /metrics (--metrics-listen; /proc/<pid> when a scrape fails) every --sample-s;
            and from /proc/<pid>/maps, what the metrics cannot show: VmSize and the thread
            stacks still mapped (anonymous mappings of RLIMIT_STACK's size: a thread that
            ended but was never joined keeps its stack, and process_threads does not count it).
            Start = after the reference runs (warm) and --settle-s of idle; end = after every
            job ended and --settle-s of idle; max = over the soak. The coordinator is never
            killed, so its growth is the main measure; the servers in --protect (default
            worker 2 and merge service 2) are never killed either and are measured the same
            way. fd or thread growth above --max-growth in any of these fails the run (exit 1),
            and so does a growth of the thread stacks above --max-growth plus the stacks that
            glibc may keep cached for reuse (40 MiB of them);
            memory growth is reported, not judged (a noisy, shared machine).

The scans: `carvemap simulate --rate-hz 5 --beam-step-deg 2` of three sizes (small: room
4 s, medium: office 8 s, large: office 16 s), in every tenant's folder as hard links; jobs at
6.25 cm with objects carved again at 3.125 cm (the merge's second pass runs, as in
fault_test.py). Submissions at a steady pace over --minutes (jittered, sometimes two at
once); kills every --kill-every seconds (uniform in the range; then up to --prefer-busy-s
for the victim to be carving or merging, so most kills hit work), down 0.5-5 s, then started
again (a worker as a new process, a merge service on its old port).

Usage: soak.py --carvemap BIN --work DIR [--jobs 50 --minutes 10 --seed 29]
  a short run: soak.py --carvemap BIN --work DIR --jobs 8 --minutes 2
Exit 0 when every check holds, 1 otherwise. Not run by ctest (see docs/BENCHMARKS.md).
"""
import argparse
import json
import os
import random
import re
import subprocess
import sys
import threading
import time
import urllib.request

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from cluster_harness import (TERMINAL, VOLATILE, Cluster, TestFailure, fresh_dir,  # noqa: E402
                             log, proc_status, random_secret, read_text, state, stubs)

TENANTS = ["acme", "beta", "gamma", "delta"]
RESOLUTION = 0.0625
OBJECT_RESOLUTION = 0.03125
# name: (preset, seconds of walk, weight in the mix)
SIZES = {"small": ("room", 4, 0.4), "medium": ("office", 8, 0.35), "large": ("office", 16, 0.25)}
METRICS_LINE = re.compile(r"metrics on http://([0-9.]+:[0-9]+)/metrics")
MASK = b"j-????????????????"
try:
    import resource
    STACK_BYTES = resource.getrlimit(resource.RLIMIT_STACK)[0]  # the servers inherit it
except (ImportError, ValueError):
    STACK_BYTES = 8 << 20
if STACK_BYTES <= 0:
    STACK_BYTES = 8 << 20
# glibc keeps up to 40 MiB of the stacks of joined threads mapped, for reuse: that many more
# stacks are allowed before their growth counts.
STACK_CACHE = (40 << 20) // STACK_BYTES


# ---- servers: who runs, where their metrics are ------------------------------------------------

class Server:
    """One incarnation of a server process: kind, slot name (worker-1, merger-2, coordinator),
    Popen, log, metrics address (from its log)."""

    def __init__(self, kind, slot, proc, log_path):
        self.kind, self.slot, self.proc, self.log_path = kind, slot, proc, log_path
        self.started = time.monotonic()
        self.metrics = None
        self.killed = False
        self.samples = []  # (t, dict)

    def name(self):
        return f"{self.slot} (pid {self.proc.pid})"

    def metrics_address(self):
        if self.metrics is None:
            try:
                m = METRICS_LINE.search(read_text(self.log_path))
            except OSError:
                m = None
            if m:
                self.metrics = m.group(1)
        return self.metrics


def parse_metrics(text):
    """{name: value} of the unlabelled and the service-labelled samples (Prometheus text)."""
    out = {}
    for line in text.splitlines():
        if not line or line.startswith("#"):
            continue
        try:
            key, value = line.rsplit(" ", 1)
            value = float(value)
        except ValueError:
            continue
        name = key.split("{", 1)[0]
        if "{" in key and not key.startswith(("process_", "carvemap_process_")):
            continue
        out[name] = value
    return out


def proc_sample(pid):
    """The same numbers from /proc/<pid>, when a scrape fails."""
    status = proc_status(pid)
    return {"fds": len(os.listdir(f"/proc/{pid}/fd")), "threads": int(status["Threads"]),
            "rss": int(status["VmRSS"].split()[0]) * 1024,
            "peak": int(status["VmHWM"].split()[0]) * 1024, "cpu": None, "src": "proc"}


def proc_extra(pid):
    """What /metrics does not say: VmSize, and the anonymous mappings of exactly a default
    thread stack's size (RLIMIT_STACK, 8 MiB here): one per thread whose stack is still
    mapped, running or finished but never joined (process_threads counts running ones only)."""
    vmsize = int(proc_status(pid)["VmSize"].split()[0]) * 1024
    stacks = maps = 0
    with open(f"/proc/{pid}/maps") as f:
        for line in f:
            maps += 1
            fields = line.split()
            lo, hi = (int(x, 16) for x in fields[0].split("-"))
            if len(fields) == 5 and hi - lo == STACK_BYTES:
                stacks += 1
    return {"vmsize": vmsize, "stacks": stacks, "maps": maps}


def sample(server):
    """{fds, threads, rss, peak, cpu, src, vmsize, stacks, maps} of a live server, or None once
    it has exited."""
    if server.proc.poll() is not None:
        return None
    try:
        extra = proc_extra(server.proc.pid)
    except (OSError, StopIteration, ValueError):
        return None
    v = sample_metrics(server)
    return None if v is None else v | extra


def sample_metrics(server):
    address = server.metrics_address()
    if address:
        try:
            with urllib.request.urlopen(f"http://{address}/metrics", timeout=5) as r:
                m = parse_metrics(r.read().decode())
            return {"fds": int(m["process_open_fds"]), "threads": int(m["process_threads"]),
                    "rss": int(m["process_resident_memory_bytes"]),
                    "peak": int(m["carvemap_process_peak_resident_memory_bytes"]),
                    "cpu": m["process_cpu_seconds_total"], "src": "metrics",
                    "merge_running": m.get("carvemap_merge_running"),
                    "tasks_running": m.get("carvemap_worker_tasks_running")}
        except (OSError, KeyError, ValueError):
            pass
    try:
        return proc_sample(server.proc.pid)
    except (OSError, KeyError, ValueError):
        return None


class Soak:
    def __init__(self, args):
        self.args = args
        self.rng = random.Random(args.seed)
        self.lock = threading.Lock()
        self.servers = []  # every incarnation, in start order
        self.slots = {}  # slot -> current Server
        self.kills = []  # dicts
        self.jobs = {}  # index -> dict
        self.stop_chaos = threading.Event()
        self.stop_sampler = threading.Event()
        self.problems = []

    # -- cluster
    def start(self):
        a = self.args
        work = a.work
        self.data = os.path.join(work, "data")
        self.outputs = os.path.join(work, "outputs")
        self.tokens = {t: random_secret() for t in TENANTS}
        metrics = ["--metrics-listen", "127.0.0.1:0"]
        self.cluster = Cluster(a.carvemap, os.path.join(work, "servers"), self.data, self.outputs,
                               tenants=self.tokens, shared_dirs=False, mergers=0,
                               extra_coordinator_args=metrics, extra_merger_args=metrics)
        c = self.cluster
        for n in range(1, a.mergers + 1):
            c.start_merger()
            self._track("merger", f"merger-{n}", c.mergers[n - 1], c.merger_logs[-1])
        c.start_coordinator(port=0)
        self._track("coordinator", "coordinator", c.coordinator, c.coordinator_log)
        for n in range(1, a.workers + 1):
            self._start_worker(f"worker-{n}")
        self.apis = {t: c.api(t) for t in TENANTS}

    def _track(self, kind, slot, proc, log_path):
        s = Server(kind, slot, proc, log_path)
        with self.lock:
            self.servers.append(s)
            self.slots[slot] = s
        deadline = time.monotonic() + 20
        while s.metrics_address() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        if s.metrics_address() is None:
            log(f"warning: {slot} logged no metrics address; sampling /proc/{proc.pid}")
        return s

    def _start_worker(self, slot):
        c = self.cluster
        n = c.start_worker(extra=["--metrics-listen", "127.0.0.1:0"])
        s = self._track("worker", slot, c.workers[n - 1], c.worker_logs[n - 1])
        s.index = n
        return s

    # -- sampling
    def sampler(self):
        while not self.stop_sampler.is_set():
            self.sample_all()
            self.stop_sampler.wait(self.args.sample_s)

    def sample_all(self):
        with self.lock:
            live = [s for s in self.servers if not s.killed]
        t = time.monotonic()
        for s in live:
            v = sample(s)
            if v is not None:
                s.samples.append((t, v))

    # -- chaos
    def chaos(self):
        a = self.args
        lo, hi = a.kill_every
        targets = [s for s in sorted(self.slots) if s != "coordinator" and s not in a.protect]
        if not targets:
            log("chaos: nothing to kill (every server protected)")
            return
        while not self.stop_chaos.wait(self.rng.uniform(lo, hi)):
            slot = self.rng.choice(targets)
            downtime = self.rng.uniform(0.5, 5.0)
            if a.prefer_busy_s > 0:  # wait a little for the victim to hold work, if it will
                deadline = time.monotonic() + a.prefer_busy_s
                while time.monotonic() < deadline and not self.stop_chaos.is_set():
                    v = sample(self.slots[slot]) or {}
                    if v.get("merge_running") or v.get("tasks_running"):
                        break
                    time.sleep(0.2)
            if self.stop_chaos.is_set():
                break
            self.kill_and_restart(slot, downtime)

    def kill_and_restart(self, slot, downtime):
        c = self.cluster
        victim = self.slots[slot]
        before = sample(victim) or {}
        busy = (before.get("merge_running") if victim.kind == "merger"
                else before.get("tasks_running"))
        t = time.monotonic() - self.t0
        active = sum(1 for j in self.jobs.values() if j.get("state") not in TERMINAL)
        with self.lock:
            victim.killed = True
        if victim.kind == "worker":
            c.kill_worker(victim.index)
        else:
            c.kill_merger(int(slot.split("-")[1]))
        what = ("idle" if not busy else
                ("merging" if victim.kind == "merger" else f"{int(busy)} task(s) running"))
        log(f"[{t:6.1f} s] chaos: SIGKILL {victim.name()} ({what}; {active} job(s) unfinished); "
            f"restart in {downtime:.1f} s")
        time.sleep(downtime)
        if victim.kind == "worker":
            new = self._start_worker(slot)
        else:
            n = int(slot.split("-")[1])
            c.start_merger(n)
            new = self._track("merger", slot, c.mergers[n - 1], c.merger_logs[-1])
        self.kills.append({"t": round(t, 1), "slot": slot, "pid": victim.proc.pid, "busy": bool(busy),
                           "what": what, "downtime": round(downtime, 1),
                           "new_pid": new.proc.pid})

    # -- jobs
    def submit(self, i, tenant, size, output_name, key):
        pb, _, grpc = stubs()
        api = self.apis[tenant]
        for attempt in range(10):
            try:
                return api.submit(f"{size}.h5", output_name, key, RESOLUTION, OBJECT_RESOLUTION)
            except grpc.RpcError as e:
                if e.code() not in (grpc.StatusCode.UNAVAILABLE,
                                    grpc.StatusCode.DEADLINE_EXCEEDED):
                    raise TestFailure(f"submit {tenant}/{output_name}: {e.code()} {e.details()}")
                time.sleep(1)
                api.reconnect()
        raise TestFailure(f"submit {tenant}/{output_name}: coordinator unreachable")

    def poll_jobs(self, jobs):
        for j in jobs:
            if j.get("state") in TERMINAL or "job_id" not in j:
                continue
            got = self.apis[j["tenant"]].try_get(j["job_id"])
            if got is None:
                continue
            st = state(got)
            if st != j.get("state"):
                j["state"] = st
                if st in TERMINAL:
                    j["ended"] = time.monotonic() - self.t0
                    j["error"] = got.error
                    j["retries"] = got.progress.chunk_retries
                    log(f"[{j['ended']:6.1f} s] job {j['i']:2d} {j['tenant']}/{j['output']} "
                        f"({j['size']}) {st} after {j['ended'] - j['submitted']:.1f} s"
                        + (f": {got.error}" if st != "SUCCEEDED" else "")
                        + (f" ({got.progress.chunk_retries} chunk retries)"
                           if got.progress.chunk_retries else ""))


# ---- outputs -----------------------------------------------------------------------------------

def masked_files(out_dir, job_id):
    """{relative path: (sha256 of the bytes, sha256 with the job id masked, id occurrences)} of
    every file under out_dir but job.json and hidden folders."""
    import hashlib
    files = {}
    ident = job_id.encode()
    assert len(ident) == len(MASK), job_id
    for root, dirs, names in os.walk(out_dir):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        for name in names:
            rel = os.path.relpath(os.path.join(root, name), out_dir)
            if rel in VOLATILE:
                continue
            with open(os.path.join(root, name), "rb") as f:
                data = f.read()
            n = data.count(ident)
            files[rel] = (hashlib.sha256(data).hexdigest(),
                          hashlib.sha256(data.replace(ident, MASK)).hexdigest(), n)
    return files


def compare_masked(ref, got):
    """(problems, files identical as they are, files identical once the id is masked)."""
    problems, same, masked = [], 0, 0
    for rel in sorted(set(ref) | set(got)):
        if rel not in got:
            problems.append(f"missing {rel}")
        elif rel not in ref:
            problems.append(f"extra {rel}")
        elif ref[rel][1] != got[rel][1]:
            problems.append(f"differs {rel}")
        elif ref[rel][2] != got[rel][2]:
            problems.append(f"{rel}: the job id {got[rel][2]} time(s), the reference's "
                            f"{ref[rel][2]}")
        elif ref[rel][0] == got[rel][0] or got[rel][2] == 0:
            same += 1
        else:
            masked += 1
    return problems, same, masked


# ---- report ------------------------------------------------------------------------------------

def mib(b):
    return b / (1 << 20)


def window(samples, t_from, t_to):
    return [v for t, v in samples if t_from <= t <= t_to]


def summarize_server(s, t_start, t_end):
    """start/end/max of fds, threads, rss, peak for one incarnation, between t_start and t_end
    (the start sample: the first at or after t_start; the end: the last at or before t_end)."""
    inside = window(s.samples, t_start, t_end)
    if not inside:
        return None
    first, last = inside[0], inside[-1]
    return {k: (first[k], last[k], max(v[k] for v in inside))
            for k in ("fds", "threads", "rss", "peak", "vmsize", "stacks", "maps")} | {
        "cpu": (first.get("cpu"), last.get("cpu")), "n": len(inside),
        "src": sorted({v["src"] for v in inside})}


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True, help="emptied first")
    p.add_argument("--jobs", type=int, default=50)
    p.add_argument("--minutes", type=float, default=10.0,
                   help="submissions spread over this long (the run ends once all jobs end)")
    p.add_argument("--seed", type=int, default=29)
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--mergers", type=int, default=2)
    p.add_argument("--kill-every", default="20,40", help="seconds between kills: LO,HI")
    p.add_argument("--protect", default="worker-2,merger-2",
                   help="servers never killed (measured over the whole run); '' for none")
    p.add_argument("--prefer-busy-s", type=float, default=10.0,
                   help="after the random moment, wait up to this long for the victim to be "
                        "carving or merging before the kill (0: kill at once)")
    p.add_argument("--sample-s", type=float, default=2.0)
    p.add_argument("--settle-s", type=float, default=20.0)
    p.add_argument("--max-growth", type=int, default=3,
                   help="fds or threads more than this above start at the end: failure")
    p.add_argument("--job-timeout-s", type=float, default=900)
    p.add_argument("--json", help="write the samples, kills and jobs here")
    args = p.parse_args()
    args.carvemap = os.path.abspath(args.carvemap)
    args.work = os.path.abspath(args.work)
    args.kill_every = tuple(float(x) for x in args.kill_every.split(","))
    args.protect = {x for x in args.protect.split(",") if x}
    log(f"soak: {args.jobs} jobs over {args.minutes} min from {len(TENANTS)} tenants, "
        f"{args.workers} workers, {args.mergers} merge services, kills every "
        f"{args.kill_every[0]:g}-{args.kill_every[1]:g} s (never {sorted(args.protect)}), "
        f"seed {args.seed}")
    soak = Soak(args)
    try:
        rc = run(soak)
    except TestFailure as e:
        print(f"FAIL: {e}", flush=True)
        rc = 1
    finally:
        soak.stop_chaos.set()
        soak.stop_sampler.set()
        if hasattr(soak, "cluster"):
            soak.cluster.stop()
    return rc


def run(soak):
    a = soak.args
    rng = soak.rng
    wall0 = time.monotonic()
    fresh_dir(a.work)
    # ---- scans, one per size, hard-linked into every tenant's folder
    sims = os.path.join(a.work, "sims")
    for size, (preset, seconds, _) in SIZES.items():
        sim = subprocess.run([a.carvemap, "simulate", "--preset", preset, "--seed", "1",
                              "--rate-hz", "5", "--beam-step-deg", "2", "--max-duration",
                              str(seconds), "-q", "-o", os.path.join(sims, size)],
                             capture_output=True, text=True)
        if sim.returncode != 0:
            raise TestFailure(f"simulate {size}: {sim.stdout}{sim.stderr}")
    for t in TENANTS:
        os.makedirs(os.path.join(a.work, "data", t))
        for size in SIZES:
            os.link(os.path.join(sims, size, "scan.h5"), os.path.join(a.work, "data", t,
                                                                     f"{size}.h5"))
    soak.start()
    sampler = threading.Thread(target=soak.sampler, daemon=True)
    sampler.start()
    soak.t0 = time.monotonic()

    # ---- 1. references: each scan once, undisturbed, on this cluster (which also warms it)
    refs = {}
    for size in SIZES:
        t = time.monotonic()
        job = soak.submit(-1, TENANTS[0], size, f"ref-{size}", f"soak reference {size}")
        done = soak.apis[TENANTS[0]].wait_done(job.job_id, a.job_timeout_s)
        if state(done) != "SUCCEEDED":
            raise TestFailure(f"reference {size}: {state(done)} {done.error}")
        files = masked_files(os.path.join(soak.outputs, TENANTS[0], f"ref-{size}"), job.job_id)
        with_id = sum(1 for v in files.values() if v[2])
        refs[size] = {"job_id": job.job_id, "files": files, "seconds": time.monotonic() - t,
                      "chunks": done.progress.chunks_total}
        log(f"reference {size}: {job.job_id} SUCCEEDED in {refs[size]['seconds']:.1f} s, "
            f"{done.progress.chunks_total} chunks, {len(files)} files ({with_id} record the job "
            "id)")
    time.sleep(a.settle_s)
    t_start = time.monotonic()
    soak.sample_all()
    log(f"warm and idle after {t_start - wall0:.0f} s: the start sample")

    # ---- 2. the soak: submissions at a steady pace, chaos meanwhile
    span = a.minutes * 60.0
    interval = span / max(1, a.jobs)
    offsets = []
    for i in range(a.jobs):
        if i > 0 and rng.random() < 0.12:
            offsets.append(offsets[-1])  # two at once
        else:
            offsets.append(max(0.0, (i + rng.uniform(-0.4, 0.4)) * interval))
    offsets.sort()
    names, weights = list(SIZES), [SIZES[s][2] for s in SIZES]
    plan = [(i, rng.choice(TENANTS), rng.choices(names, weights)[0], offsets[i])
            for i in range(a.jobs)]
    mix = {s: sum(1 for x in plan if x[2] == s) for s in SIZES}
    log(f"plan: {mix}; a submission every {interval:.1f} s on average")
    soak.t0 = time.monotonic()
    chaos = threading.Thread(target=soak.chaos, daemon=True)
    chaos.start()
    for i, tenant, size, offset in plan:
        soak.jobs[i] = {"i": i, "tenant": tenant, "size": size, "output": f"soak-{i:03d}-{size}"}
    pending = list(plan)
    deadline = None
    while True:
        now = time.monotonic() - soak.t0
        while pending and pending[0][3] <= now:
            i, tenant, size, _ = pending.pop(0)
            j = soak.jobs[i]
            job = soak.submit(i, tenant, size, j["output"], f"soak {a.seed} job {i}")
            j.update(job_id=job.job_id, submitted=time.monotonic() - soak.t0, state="QUEUED")
            log(f"[{j['submitted']:6.1f} s] submit job {i:2d} {tenant}/{j['output']} "
                f"({job.job_id})")
        soak.poll_jobs(soak.jobs.values())
        if not pending:
            if deadline is None:
                deadline = time.monotonic() + a.job_timeout_s
            if all(j.get("state") in TERMINAL for j in soak.jobs.values()):
                break
            if time.monotonic() > deadline:
                break
        time.sleep(0.5)
    soak.stop_chaos.set()
    chaos.join(timeout=60)  # a restart in progress finishes
    t_soak_end = time.monotonic()
    log(f"[{t_soak_end - soak.t0:6.1f} s] every job ended or timed out; {len(soak.kills)} "
        f"kills; idle {a.settle_s:.0f} s before the end sample")
    time.sleep(a.settle_s)
    soak.sample_all()
    t_end = time.monotonic()
    soak.stop_sampler.set()
    sampler.join(timeout=30)

    # ---- 3. outcomes
    ok = True
    succeeded, failed, bad = [], [], []
    same_files = masked_files_n = 0
    for i in sorted(soak.jobs):
        j = soak.jobs[i]
        st = j.get("state")
        folder = os.path.join(soak.outputs, j["tenant"], j["output"])
        if st == "SUCCEEDED":
            ref = refs[j["size"]]
            got = masked_files(folder, j["job_id"])
            problems, same, masked = compare_masked(ref["files"], got)
            if not os.path.exists(os.path.join(folder, "job.json")):
                problems.append("no job.json")
            if problems:
                bad.append(f"job {i} {j['tenant']}/{j['output']} ({j['job_id']}) SUCCEEDED but "
                           f"differs from reference {ref['job_id']}: {problems[:8]}"
                           + (f" (+{len(problems) - 8})" if len(problems) > 8 else ""))
            else:
                succeeded.append(i)
                same_files += same
                masked_files_n += masked
        elif st == "FAILED" and j.get("error", "").strip():
            failed.append(i)
            if os.path.exists(os.path.join(folder, "job.json")):
                bad.append(f"job {i} FAILED ({j['error']}) but wrote job.json")
        else:
            bad.append(f"job {i} {j['tenant']}/{j['output']} ({j.get('job_id')}) ended "
                       f"{st or 'never submitted'}"
                       + (" without a reason" if st == "FAILED" else "")
                       + (f": {j.get('error')}" if j.get("error") else ""))
    log("")
    log(f"jobs: {len(succeeded)} SUCCEEDED with outputs identical to their reference "
        f"({same_files} files byte for byte, {masked_files_n} identical once the job id is "
        f"masked), {len(failed)} FAILED with a reason, {len(bad)} not acceptable")
    by_size = {s: (sum(1 for i in succeeded if soak.jobs[i]["size"] == s),
                   sum(1 for i in failed if soak.jobs[i]["size"] == s)) for s in SIZES}
    log("  by size (succeeded/failed): " + ", ".join(f"{s} {a_}/{b_}"
                                                     for s, (a_, b_) in by_size.items()))
    reasons = {}
    for i in failed:
        reasons.setdefault(soak.jobs[i]["error"], []).append(i)
    for reason, ids in reasons.items():
        log(f"  FAILED x{len(ids)} (jobs {ids}): {reason}")
    for b in bad:
        log(f"  NOT OK: {b}")
    if bad:
        ok = False
    durations = sorted(j["ended"] - j["submitted"] for j in soak.jobs.values() if "ended" in j)
    if durations:
        log(f"  job time submit-to-end: median {durations[len(durations) // 2]:.1f} s, max "
            f"{durations[-1]:.1f} s; chunk retries in all {sum(j.get('retries', 0) for j in soak.jobs.values())}")
    busy = sum(1 for k in soak.kills if k["busy"])
    log(f"kills: {len(soak.kills)} ({sum(1 for k in soak.kills if k['slot'].startswith('worker'))} "
        f"worker, {sum(1 for k in soak.kills if k['slot'].startswith('merger'))} merge service; "
        f"{busy} while it was carving or merging)")

    # ---- 4. growth
    log("")
    log(f"growth, start (warm, idle) -> end (idle {a.settle_s:.0f} s after the last job), max "
        "over the soak:")
    header = (f"{'server':<24} {'fds start/end/max':>18} {'threads s/e/max':>16} "
              f"{'RSS MiB start/end/max':>22} {'RSS %':>6} {'peak MiB s/e':>13} {'CPU s':>6} "
              f"{'stacks s/e':>10} {'VmSize MiB s/e':>15}")
    log(header)
    measured = [s for s in soak.servers if not s.killed]
    rows = {}
    for s in measured:
        r = summarize_server(s, t_start, t_end)
        if r is None:
            log(f"{s.name():<24} no samples")
            continue
        rows[s.slot] = r
        whole = s.started <= t_start
        label = s.name() + ("" if whole else " *")
        f, th, rs, pk = r["fds"], r["threads"], r["rss"], r["peak"]
        st, vm = r["stacks"], r["vmsize"]
        cpu = (r["cpu"][1] - r["cpu"][0]) if None not in r["cpu"] else float("nan")
        log(f"{label:<24} {f'{f[0]}/{f[1]}/{f[2]}':>18} {f'{th[0]}/{th[1]}/{th[2]}':>16} "
            f"{f'{mib(rs[0]):.1f}/{mib(rs[1]):.1f}/{mib(rs[2]):.1f}':>22} "
            f"{100.0 * (rs[1] - rs[0]) / rs[0]:>+6.1f} "
            f"{f'{mib(pk[0]):.0f}/{mib(pk[1]):.0f}':>13} {cpu:>6.1f} "
            f"{f'{st[0]}/{st[1]}':>10} {f'{mib(vm[0]):.0f}/{mib(vm[1]):.0f}':>15}")
        if whole and (f[1] - f[0] > a.max_growth or th[1] - th[0] > a.max_growth
                      or st[1] - st[0] > a.max_growth + STACK_CACHE):
            soak.problems.append(f"{s.name()}: fds {f[0]} -> {f[1]}, threads {th[0]} -> {th[1]}, "
                                 f"thread stacks mapped {st[0]} -> {st[1]} (VmSize "
                                 f"{mib(vm[0]):.0f} -> {mib(vm[1]):.0f} MiB)")
    log("  (* started during the soak, after a kill: its start is its first sample, not "
        "comparable)")
    # RSS, fds and threads through the soak of the servers that ran all of it
    for s in measured:
        if s.started > t_start:
            continue
        inside = [(t, v) for t, v in s.samples if t_start <= t <= t_end]
        marks = []
        for q in (0.0, 0.25, 0.5, 0.75, 1.0):
            t_q = t_start + q * (t_soak_end - t_start)
            t, v = min(inside, key=lambda tv: abs(tv[0] - t_q))
            marks.append(f"{mib(v['rss']):.0f}/{v['fds']}/{v['threads']}/{v['stacks']}")
        log(f"  {s.slot:<12} RSS MiB/fds/threads/stacks at 0, 25, 50, 75, 100 % of the soak: "
            + ", ".join(marks))
    killed = [s for s in soak.servers if s.killed and s.samples]
    for kind in ("worker", "merger"):
        ks = [s for s in killed if s.kind == kind]
        if ks:
            vals = [v for s in ks for _, v in s.samples]
            log(f"  {len(ks)} killed {kind} incarnation(s): max fds {max(v['fds'] for v in vals)}, "
                f"threads {max(v['threads'] for v in vals)}, RSS "
                f"{mib(max(v['rss'] for v in vals)):.0f} MiB over their lives")
    coord = rows.get("coordinator")
    verdict = []
    if coord:
        f, th, rs = coord["fds"], coord["threads"], coord["rss"]
        verdict.append(f"coordinator fds {f[1] - f[0]:+d}, threads {th[1] - th[0]:+d}, "
                       f"thread stacks {coord['stacks'][1] - coord['stacks'][0]:+d}, RSS "
                       f"{100.0 * (rs[1] - rs[0]) / rs[0]:+.1f} %")
    for slot in sorted(a.protect):
        r = rows.get(slot)
        if r and soak.slots[slot].started <= t_start:
            verdict.append(f"{slot} fds {r['fds'][1] - r['fds'][0]:+d}, threads "
                           f"{r['threads'][1] - r['threads'][0]:+d}, thread stacks "
                           f"{r['stacks'][1] - r['stacks'][0]:+d}, RSS "
                           f"{100.0 * (r['rss'][1] - r['rss'][0]) / r['rss'][0]:+.1f} %")
    for prob in soak.problems:
        log(f"  NOT OK (growth above {a.max_growth}): {prob}")
        ok = False
    # errors in the logs, for the record
    errors = {}
    for name, text in soak.cluster.logs().items():
        n = sum(1 for line in text.splitlines() if "[error]" in line or "[critical]" in line)
        if n:
            errors[name] = n
    if errors:
        log(f"error lines in the logs: {errors}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump({"args": {k: (sorted(v) if isinstance(v, set) else v)
                                for k, v in vars(a).items()},
                       "kills": soak.kills, "jobs": soak.jobs,
                       "refs": {s: {k: v for k, v in r.items() if k != "files"}
                                for s, r in refs.items()},
                       "servers": [{"slot": s.slot, "pid": s.proc.pid, "killed": s.killed,
                                    "samples": [(round(t - wall0, 1), v) for t, v in s.samples]}
                                   for s in soak.servers]}, f, indent=1, default=str)
    log("")
    log(f"verdict: {'PASS' if ok else 'FAIL'}: {len(succeeded)}/{a.jobs} identical, "
        f"{len(failed)} failed with a reason, {len(bad)} not ok; {len(soak.kills)} kills; "
        + "; ".join(verdict) + f" (seed {a.seed}, {time.monotonic() - wall0:.0f} s)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
