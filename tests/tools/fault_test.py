#!/usr/bin/env python3
"""Fault injection and recovery through real processes (docs/DESIGN.md §5, §8).

Every job here is the same small job (the `room` preset, 5 Hz, 2° beams, 8 s of walk, objects
carved again at 3.125 cm), submitted by the same tenant with the same idempotency key, so it
gets the same job id and therefore (tiles record their job id) byte-identical outputs however
it ran. The undisturbed run is the reference; every disturbed run must reproduce all of its
files (tiles/, object_tiles/, meshes, plans, octree.bt: everything but job.json and the
report's copy of it, report/data.js, which hold timings) byte for byte.

  reference            simulate the scan and run the job undisturbed (the fixture of the rest)
  coordinator-restart  the coordinator SIGKILLed during ingest, during carving, and during the
                       merge's second carving pass (§5.6.1), then started again on the same
                       job store and port: the job resumes and completes; chunks DONE at the kill
                       are not carved again (their tiles keep their inode), LEASED ones are
                       carved (again or by their old lease); and once more during the combines
                       with a DONE chunk's tile cut to half its size, as a power loss can
                       leave it: that tile is combined again, not served
  worker-kill          N trials (seeded): at a random point of the job's carving work (a
                       fraction of the chunk commits of both passes, so load does not move it)
                       a worker holding a lease is SIGKILLed and a replacement started; every
                       job completes
  failures             the input deleted mid-job: FAILED with a reason naming the input, no
                       job.json, no tiles, no file that differs from the reference's
  storage-full         the output folder on a small tmpfs (a private mount namespace; skipped,
                       exit 77, only when the kernel refuses one): tiles that do not fit, and
                       meshes that do not fit: FAILED naming ENOSPC, nothing that looks complete
  merge-kill           the merge service SIGKILLed mid-merge (docs/DESIGN.md §8: the merge is
                       its own service): with a second service running, the coordinator
                       merges again
                       there; during the merge's second carving pass (§5.6.1) with the service
                       restarted on its port, it merges again there without carving the object
                       chunks a second time; with no service left, the job FAILS with the
                       reason and nothing that looks complete
  netns-link-cut       each worker in a network namespace of its own (deploy/local/netns.sh);
                       worker 1's link set down while it carves a chunk: the coordinator
                       declares it lost, the chunk is carved by the other, the job completes
                       identical (skipped, exit 77, only when the kernel refuses namespaces)
  run-netns            deploy/local/run-netns.sh end to end (the same skip)

Usage: fault_test.py COMMAND --carvemap BIN --work DIR [--trials N --seed S --parallel P]
Prints the time each part took.
"""
import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster_harness import (SKIP, Cluster, TestFailure, compare_outputs, fresh_dir, log,  # noqa
                             output_files, state, summarize, tail)

KEY = "fault-test room 8 s"
RESOLUTION = 0.0625
OBJECT_RESOLUTION = 0.03125
OUTPUT_NAME = "out"
SCAN_NAME = "scan.h5"


class Trial:
    """One job on its own cluster (work dir, job store, output root)."""

    def __init__(self, args, name, data_root=None, workers=2, **cluster_kw):
        self.args = args
        self.name = name
        self.dir = fresh_dir(os.path.join(args.work, name))
        self.out_root = os.path.join(self.dir, "outputs")
        self.out = os.path.join(self.out_root, OUTPUT_NAME)
        self.cluster = Cluster(args.carvemap, os.path.join(self.dir, "work"),
                               data_root or sim_dir(args), self.out_root, **cluster_kw)
        self.workers = workers
        self.notes = []

    def run(self, inject=None, timeout_s=600):
        """Runs the job, calling inject(trial, api, job_id, t0) once it is submitted; returns
        the finished job."""
        c = self.cluster
        try:
            c.start_coordinator(port=0)
            for _ in range(self.workers):
                c.start_worker()
            self.api = c.api()
            job = self.api.submit(SCAN_NAME, OUTPUT_NAME, KEY, RESOLUTION, OBJECT_RESOLUTION)
            self.job_id = job.job_id
            self.t0 = time.monotonic()
            if inject:
                inject(self, self.api, job.job_id, self.t0)
            done = self.api.wait_done(job.job_id, timeout_s)
            self.seconds = time.monotonic() - self.t0
            return done
        finally:
            c.stop()

    def fail(self, why):
        logs = self.cluster.logs()
        text = "\n".join(f"--- {name} (last lines)\n" + "\n".join(t.splitlines()[-25:])
                         for name, t in logs.items())
        raise TestFailure(f"{self.name}: {why}\n{text}")

    def coordinator_log(self):
        return "\n".join(t for n, t in self.cluster.logs().items() if n.startswith("coordinator"))


def sim_dir(args):
    return os.path.join(args.work, "sim")


def reference(args):
    return json.load(open(os.path.join(args.work, "reference.json")))


def check_same_as_reference(trial, ref):
    problems = compare_outputs(ref["files"], output_files(trial.out))
    if problems:
        trial.fail(f"outputs differ from the undisturbed run: {problems[:10]}")


def expect_succeeded(trial, job):
    if state(job) != "SUCCEEDED":
        trial.fail(f"job {job.job_id} {state(job)}: {job.error}")


# ---- reference -------------------------------------------------------------------------------

def cmd_reference(args):
    fresh_dir(args.work)
    sim = subprocess.run([args.carvemap, "simulate", "--preset", "room", "--seed", "1",
                          "--rate-hz", "5", "--beam-step-deg", "2", "--max-duration", "8", "-q",
                          "-o", sim_dir(args)], capture_output=True, text=True)
    if sim.returncode != 0:
        raise TestFailure(f"simulate failed:\n{sim.stdout}{sim.stderr}")
    trial = Trial(args, "reference", log_format=args.log_format)
    job = trial.run()
    expect_succeeded(trial, job)
    files = output_files(trial.out)
    if not any(f.startswith("object_tiles/") for f in files):
        trial.fail("the reference has no object_tiles/: the merge's second pass did not run, "
                   "so the restart-during-re-carving trial would test nothing")
    if not os.path.exists(os.path.join(trial.out, "job.json")):
        trial.fail("no job.json")
    sizes = {}
    for rel in files:
        top = rel.split("/")[0] if "/" in rel else "."
        sizes[top] = sizes.get(top, 0) + os.path.getsize(os.path.join(trial.out, rel))
    with open(os.path.join(args.work, "reference.json"), "w") as f:
        json.dump({"job_id": job.job_id, "files": files, "seconds": trial.seconds,
                   "chunks_total": job.progress.chunks_total, "bytes_by_folder": sizes}, f,
                  indent=1)
    log(f"reference: job {job.job_id} in {trial.seconds:.1f} s, {job.progress.chunks_total} "
        f"chunks; {summarize(files)}; bytes by folder {sizes}")
    if args.log_format == "json":
        check_json_logs(trial)


def check_json_logs(trial):
    """--log-format json: every line of every server's log is one JSON object with time, level,
    component and message; the job's lines carry its id, the workers' chunk lines the chunk."""
    with_job = with_chunk = 0
    c = trial.cluster
    secrets = list(c.tenants.values()) + [open(c.secret_file).read().strip()]
    for name, text in c.logs().items():
        if any(secret in text for secret in secrets):
            trial.fail(f"{name} contains a bearer token or the cluster secret")
        component = next(c for c in ("coordinator", "merger", "worker") if name.startswith(c))
        for n, line in enumerate(text.splitlines(), 1):
            try:
                rec = json.loads(line)
            except ValueError:
                trial.fail(f"{name}:{n} is not JSON: {line[:200]!r}")
            if not isinstance(rec, dict):
                trial.fail(f"{name}:{n} is not a JSON object")
            for key in ("time", "level", "component", "message"):
                if key not in rec:
                    trial.fail(f"{name}:{n} has no '{key}': {line[:200]}")
            if rec["component"] != component:
                trial.fail(f"{name}:{n}: component {rec['component']!r}, want {component!r}")
            if rec.get("job") == trial.job_id:
                with_job += 1
            if "chunk" in rec:
                with_chunk += 1
    if with_job == 0 or with_chunk == 0:
        trial.fail(f"JSON logs: {with_job} lines with the job id, {with_chunk} with a chunk")
    merger = "\n".join(t for n, t in c.logs().items() if n.startswith("merger"))
    if f'"job":"{trial.job_id}"' not in merger.replace(" ", ""):
        trial.fail("the merge service's JSON log has no line naming the job")
    log(f"reference: JSON logs ok ({with_job} lines name the job, {with_chunk} a chunk; no "
        "token or secret in them)")


# ---- coordinator restart ---------------------------------------------------------------------

def cmd_coordinator_restart(args):
    ref = reference(args)
    moments = [
        # The ingest is the slices' binning: INGESTING itself only plans the slices (a few
        # milliseconds), so the moment also covers CARVING before any slice is committed.
        ("ingest", lambda j: state(j) == "INGESTING"
         or (state(j) == "CARVING" and j.progress.chunks_done == 0)),
        ("carving", lambda j: state(j) == "CARVING"
         and j.progress.chunks_done >= j.progress.chunks_total // 3),
        # The merge's second pass: chunks queued or leased again during MERGING (docs/RPC.md).
        ("re-carving", lambda j: state(j) == "MERGING" and j.progress.chunks_total > 0 and (
            j.progress.chunks_leased > 0 or j.progress.chunks_done < j.progress.chunks_total)),
    ]
    for name, when in moments:
        start = time.monotonic()
        trial = Trial(args, f"coordinator_restart_{name}")
        seen = {}

        def inject(trial, api, job_id, t0, when=when, name=name):
            job = api.wait(job_id, when, 300, f"at the {name} moment", poll_s=0.01)
            if state(job) in ("SUCCEEDED", "FAILED", "CANCELLED"):
                trial.fail(f"the job ended ({state(job)}) before the {name} moment came")
            c = trial.cluster
            c.kill_coordinator()
            seen["state"] = state(job)
            seen["done"] = job.progress.chunks_done
            chunks = c.store_chunks(job_id)
            seen["chunks"] = chunks
            tiles_dir = os.path.join(trial.out, "tiles")
            # Chunks the store says DONE: their tiles must survive the restart untouched. In the
            # re-carving pass the first-pass tiles all count (the pass writes object_tiles/).
            keep = {}
            for key, row in chunks.items():
                path = os.path.join(tiles_dir, f"c_{key[0]}_{key[1]}_{key[2]}.h5")
                if (row["state"] == 3 or name == "re-carving") and os.path.exists(path):
                    s = os.stat(path)
                    keep[path] = (s.st_ino, s.st_mtime_ns)
            seen["keep"] = keep
            c.start_coordinator(port=c.port)  # same store, same port: the workers come back
            api.reconnect()

        job = trial.run(inject)
        expect_succeeded(trial, job)
        check_same_as_reference(trial, ref)
        if "resuming job" not in trial.coordinator_log():
            trial.fail("the restarted coordinator did not log that it resumed the job")
        rewritten = [p for p, st in seen["keep"].items()
                     if not os.path.exists(p) or (os.stat(p).st_ino, os.stat(p).st_mtime_ns) != st]
        if rewritten:
            trial.fail(f"{len(rewritten)} tile(s) committed before the kill were written again: "
                       f"{rewritten[:3]}")
        chunks = seen["chunks"]
        leased = sum(1 for v in chunks.values() if v["state"] == 2)
        done = sum(1 for v in chunks.values() if v["state"] == 3)
        log(f"coordinator killed during {name} ({seen['state']}; store: {done} done, {leased} "
            f"leased, {len(chunks) - done - leased} queued of {len(chunks)}), restarted: "
            f"SUCCEEDED, {summarize(ref['files'])} identical, {len(seen['keep'])} committed "
            f"tiles kept ({time.monotonic() - start:.1f} s)")


    coordinator_restart_truncated_tile(args, ref)


SLICE_X = -2147483648  # a slice task's key: (SLICE_X, slice, pass) (docs/JOB_STORE.md)


def coordinator_restart_truncated_tile(args, ref):
    """The coordinator killed while chunks are combined, and one DONE chunk's tile cut short
    before it starts again: the restart must combine that chunk again (docs/JOB_STORE.md,
    "Durability"), not hand the short tile to the merge."""
    start = time.monotonic()
    trial = Trial(args, "coordinator_restart_truncated_tile")
    seen = {}

    def inject(trial, api, job_id, t0):
        c = trial.cluster
        deadline = time.monotonic() + 300
        while True:
            if time.monotonic() > deadline:
                trial.fail("no chunk was combined within 300 s")
            chunks = c.store_chunks(job_id)
            done = [k for k, r in chunks.items() if k[0] != SLICE_X and r["state"] == 3]
            if done:
                break
            time.sleep(0.005)
        # Frozen first, so the job cannot move on while the store is read; then the crash.
        c.coordinator.send_signal(signal.SIGSTOP)
        job_state = c.store_job_state(job_id)
        c.kill_coordinator()
        if job_state != 3:  # CARVING
            trial.fail(f"the combines ended before the kill (job state {job_state}): the "
                       "trial needs a job still carving; make the scan longer")
        chunks = c.store_chunks(job_id)
        key = sorted(k for k, r in chunks.items() if k[0] != SLICE_X and r["state"] == 3)[0]
        path = os.path.join(trial.out, "tiles", chunks[key]["tile_path"])
        size = os.path.getsize(path)
        with open(path, "r+b") as f:
            f.truncate(size // 2)
        seen.update(path=path, size=size, key=key)
        c.start_coordinator(port=c.port)
        api.reconnect()

    job = trial.run(inject)
    expect_succeeded(trial, job)
    check_same_as_reference(trial, ref)
    if os.path.getsize(seen["path"]) != seen["size"]:
        trial.fail(f"{seen['path']} is {os.path.getsize(seen['path'])} bytes after the job, "
                   f"{seen['size']} before it was cut")
    if "is carved again" not in trial.coordinator_log():
        trial.fail("the restarted coordinator did not say it combines the cut tile again")
    log(f"coordinator killed while combining, tile of chunk {seen['key']} cut to "
        f"{seen['size'] // 2} of {seen['size']} bytes, restarted: combined again, SUCCEEDED, "
        f"{summarize(ref['files'])} identical ({time.monotonic() - start:.1f} s)")


# ---- worker kills ----------------------------------------------------------------------------

def cmd_worker_kill(args):
    ref = reference(args)
    rng = random.Random(args.seed)
    # The moments, drawn up front so the trials are the same whatever runs in parallel, as a
    # point in the job's carving work rather than in seconds (so a loaded machine moves them
    # nowhere): u of the chunk commits of the first pass and the merge's second pass together.
    first = ref["chunks_total"]
    second = sum(1 for f in ref["files"] if f.startswith("object_tiles/"))
    plan = [(i + 1, rng.random() * (first + second), rng.randint(1, 2))
            for i in range(args.trials)]
    results, errors = {}, []
    lock = threading.Lock()

    def one(i, target, preferred):
        trial = Trial(args, f"worker_kill_{i}")
        info = {}

        def reached(job, pass_seen):
            done, total = job.progress.chunks_done, job.progress.chunks_total
            if target < first:  # in the first pass (or past it, if the poll missed the moment)
                return state(job) not in ("QUEUED", "INGESTING") and done >= target
            # The second pass: the object chunks go back to the queue during MERGING, so done
            # drops by `second` and climbs back (docs/RPC.md, "Second pass").
            return pass_seen and done - (total - second) >= target - first

        def inject(trial, api, job_id, t0):
            pass_seen = False
            deadline = time.monotonic() + 300
            while time.monotonic() < deadline:
                job = api.try_get(job_id)
                if job is not None:
                    if state(job) == "MERGING" and (job.progress.chunks_done <
                                                    job.progress.chunks_total):
                        pass_seen = True
                    if reached(job, pass_seen) or state(job) in ("SUCCEEDED", "FAILED"):
                        break
                time.sleep(0.01)
            # The victim: a worker that holds a lease now (the job store says who), if any.
            holders = sorted({n for n, wid in worker_ids(trial).items()
                              for r in trial.cluster.store_chunks(job_id).values()
                              if r["state"] == 2 and r["worker_id"] == wid})
            victim = holders[(preferred - 1) % len(holders)] if holders else preferred
            info["victim"] = victim
            info["at"] = (f"{target:.1f} of {first}+{second} chunk commits ("
                          f"{'first' if target < first else 'second'} pass): {state(job)} "
                          f"{job.progress.chunks_done}/{job.progress.chunks_total} done, "
                          f"worker(s) {holders or 'none'} holding a lease")
            trial.cluster.kill_worker(victim)
            trial.cluster.start_worker()  # a replacement, as a Deployment would start

        start = time.monotonic()
        job = trial.run(inject)
        expect_succeeded(trial, job)
        check_same_as_reference(trial, ref)
        text = trial.coordinator_log()
        lost = [l for l in text.splitlines() if " lost (no heartbeat" in l]
        requeued = sum(int(l.split("; ")[1].split(" ")[0]) for l in lost if "; " in l)
        info["lost"] = f"{len(lost)} worker(s) declared lost, {requeued} lease(s) requeued"
        info["retries"] = job.progress.chunk_retries
        info["seconds"] = time.monotonic() - start
        with lock:
            results[i] = info

    def runner(items):
        for item in items:
            try:
                one(*item)
            except Exception as e:  # reported after all trials
                with lock:
                    errors.append(f"trial {item[0]}: {e}")

    groups = [plan[k::args.parallel] for k in range(args.parallel)]
    threads = [threading.Thread(target=runner, args=(g,)) for g in groups]
    start = time.monotonic()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i, _, _ in plan:
        if i in results:
            r = results[i]
            log(f"trial {i}: worker-{r['victim']} SIGKILLed at {r['at']}; {r['lost']}; "
                f"{r['retries']} chunk retries; SUCCEEDED, identical ({r['seconds']:.1f} s)")
    if errors:
        raise TestFailure("\n".join(errors))
    log(f"{args.trials} worker-kill trials (seed {args.seed}, {args.parallel} at a time): all "
        f"completed with outputs identical to the undisturbed run ({summarize(ref['files'])}) "
        f"in {time.monotonic() - start:.1f} s")


# ---- merge service kills ----------------------------------------------------------------------

def merge_started(trial, job_id):
    """Waits until a merge service runs job_id's merge past its levels (levels.json written,
    job.json not yet); returns the services serving it."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        serving = trial.cluster.merger_serving(job_id)
        if serving and os.path.exists(os.path.join(trial.out, "levels.json")):
            if os.path.exists(os.path.join(trial.out, "job.json")):
                trial.fail("the merge finished before the merge service could be killed")
            return serving
        job = trial.api.try_get(job_id)
        if job is not None and state(job) in ("SUCCEEDED", "FAILED", "CANCELLED"):
            trial.fail(f"the job ended ({state(job)}) before its merge was under way")
        time.sleep(0.01)
    trial.fail("no merge service started the merge within 300 s")


def cmd_merge_kill(args):
    ref = reference(args)

    # 1. Two merge services; the one merging is SIGKILLed after the levels: the coordinator
    #    merges again on the other.
    start = time.monotonic()
    trial = Trial(args, "merge_kill_other_service", mergers=2)
    seen = {}

    def inject(trial, api, job_id, t0):
        serving = merge_started(trial, job_id)
        seen["victim"] = serving[0]
        trial.cluster.kill_merger(serving[0])

    job = trial.run(inject)
    expect_succeeded(trial, job)
    check_same_as_reference(trial, ref)
    text = trial.coordinator_log()
    if "lost (attempt 1 of 3)" not in text:
        trial.fail("the coordinator did not log the lost merge service")
    other = 3 - seen["victim"]
    if "merge started (attempt 2)" not in trial.cluster.logs()[f"merger-{other}.log"]:
        trial.fail(f"merger-{other} did not run the second attempt")
    log(f"merge service {seen['victim']} of 2 SIGKILLed mid-merge (after levels.json): merged "
        f"again on service {other}, SUCCEEDED, {summarize(ref['files'])} identical "
        f"({time.monotonic() - start:.1f} s)")

    # 2. One merge service, SIGKILLed while the workers carve the object chunks again for it
    #    (§5.6.1), and started again on its port: the coordinator merges again there, and the
    #    object chunks are not carved a second time (their tiles keep their inode).
    start = time.monotonic()
    trial = Trial(args, "merge_kill_during_recarve")

    def inject(trial, api, job_id, t0):
        api.wait(job_id, lambda j: state(j) == "MERGING" and j.progress.chunks_total > 0 and (
            j.progress.chunks_leased > 0 or j.progress.chunks_done < j.progress.chunks_total),
            300, "re-carving", poll_s=0.01)
        c = trial.cluster
        c.kill_merger(1)
        seen["recarve_chunks"] = sum(1 for r in c.store_chunks(job_id).values()
                                     if r["state"] != 3)
        # Once the pass is done its tiles must stay untouched: the retry reuses them.
        api.wait(job_id, lambda j: j.progress.chunks_done == j.progress.chunks_total, 300,
                 "done re-carving", poll_s=0.01)
        tiles = os.path.join(trial.out, "object_tiles")
        seen["keep"] = {f: os.stat(os.path.join(tiles, f)).st_ino for f in os.listdir(tiles)
                        if f.endswith(".h5")}
        c.start_merger(1)  # the same port, as a pod restarted behind its Service

    job = trial.run(inject)
    expect_succeeded(trial, job)
    check_same_as_reference(trial, ref)
    text = trial.coordinator_log()
    if "lost (attempt 1 of 3)" not in text or "reusing them" not in text:
        trial.fail("the coordinator did not log the lost merge service and the reused re-carve")
    tiles = os.path.join(trial.out, "object_tiles")
    rewritten = [f for f, ino in seen["keep"].items()
                 if not os.path.exists(os.path.join(tiles, f)) or
                 os.stat(os.path.join(tiles, f)).st_ino != ino]
    if rewritten or not seen["keep"]:
        trial.fail(f"object tiles carved again after the retry: {rewritten[:3]} "
                   f"(of {len(seen['keep'])})")
    log(f"merge service SIGKILLed while {seen['recarve_chunks']} object chunks were carved "
        f"again, restarted on its port: merged again without carving them twice "
        f"({len(seen['keep'])} object tiles kept), SUCCEEDED, identical "
        f"({time.monotonic() - start:.1f} s)")

    # 3. One merge service, SIGKILLed and not restarted: after --merge-attempts the job FAILS
    #    with the reason, and nothing it left looks complete.
    start = time.monotonic()
    trial = Trial(args, "merge_kill_no_service_left", extra_coordinator_args=[
        "--merge-attempts", "2", "--merge-connect-timeout-s", "2"])

    def inject(trial, api, job_id, t0):
        merge_started(trial, job_id)
        trial.cluster.kill_merger(1)

    job = trial.run(inject)
    if state(job) != "FAILED":
        trial.fail(f"job {state(job)} with its only merge service killed")
    if "merge service was lost 2 time(s)" not in job.error or "no job.json" not in job.error:
        trial.fail(f"the reason does not say the merge service was lost: {job.error!r}")
    left = check_nothing_looks_complete(trial, ref, job)
    partial = [os.path.join(root, n) for root, _, names in os.walk(trial.out) for n in names
               if n.endswith(".partial")]
    if partial or os.path.exists(os.path.join(trial.out, ".segment")):
        trial.fail(f"the lost merge's temporary files stayed: {partial[:5]}")
    log(f"the only merge service SIGKILLed mid-merge, not restarted: FAILED: {job.error!r}; left "
        f"{len(left)} complete file(s), no job.json, no tiles ({time.monotonic() - start:.1f} s)")


# ---- failures --------------------------------------------------------------------------------

def check_nothing_looks_complete(trial, ref, job):
    """After a failed job: no job.json, no tiles, and every file left under a final name is
    byte-identical to the reference's (so complete), and no temporary files. And the reason,
    which the tenant reads, names no server folder."""
    if trial.dir in job.error or trial.cluster.work in job.error:
        trial.fail(f"the job's error shows the server's folders: {job.error!r}")
    left = output_files(trial.out) if os.path.isdir(trial.out) else {}
    if os.path.exists(os.path.join(trial.out, "job.json")):
        trial.fail("job.json written by a failed job")
    for rel, sha in left.items():
        if rel.startswith(("tiles/", "object_tiles/")):
            trial.fail(f"a failed job left {rel}")
        if rel not in ref["files"]:
            trial.fail(f"a failed job left {rel}, which no complete run writes")
        if ref["files"][rel] != sha:
            trial.fail(f"a failed job left {rel} half-written (differs from the complete one)")
    return left


def cmd_failures(args):
    ref = reference(args)
    start = time.monotonic()
    data = fresh_dir(os.path.join(args.work, "failures_data"))
    shutil.copy(os.path.join(sim_dir(args), SCAN_NAME), os.path.join(data, SCAN_NAME))
    trial = Trial(args, "input_disappears", data_root=data)

    def inject(trial, api, job_id, t0):
        api.wait(job_id, lambda j: state(j) == "CARVING", 300, "carving")
        os.remove(os.path.join(data, SCAN_NAME))

    job = trial.run(inject)
    if state(job) != "FAILED":
        trial.fail(f"job {state(job)} after its input was deleted")
    if SCAN_NAME not in job.error or "no such file" not in job.error:
        trial.fail(f"the reason does not name the missing input: {job.error!r}")
    left = check_nothing_looks_complete(trial, ref, job)
    log(f"input deleted while carving: FAILED: {job.error!r}; left {len(left)} complete "
        f"file(s), no tiles, no job.json ({time.monotonic() - start:.1f} s)")


# ---- storage full ----------------------------------------------------------------------------

def in_private_mount_namespace(args):
    """Re-runs this command in a private mount namespace (as root; else in a user namespace
    mapped to root). Returns None when already inside, else the exit code to return."""
    if os.environ.get("CARVEMAP_FAULT_MOUNT_NS") == "1":
        return None
    base = ["unshare", "--mount", "--propagation", "private"]
    if os.geteuid() != 0:
        base = ["unshare", "--user", "--map-root-user", "--mount"]
    probe_dir = fresh_dir(os.path.join(args.work, "tmpfs_probe"))
    probe = subprocess.run(base + ["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", probe_dir],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        log(f"SKIPPED: the kernel refuses a private mount namespace with a tmpfs ({' '.join(base)} "
            f"mount -t tmpfs): {probe.stderr.strip() or probe.returncode}; the storage-full test "
            "needs one (root, or unprivileged user namespaces)")
        return SKIP
    env = dict(os.environ, CARVEMAP_FAULT_MOUNT_NS="1")
    return subprocess.call(base + [sys.executable] + sys.argv, env=env)


def cmd_storage_full(args):
    rc = in_private_mount_namespace(args)
    if rc is not None:
        return rc
    ref = reference(args)
    sizes = ref["bytes_by_folder"]
    tiles = sizes.get("tiles", 0) + sizes.get("object_tiles", 0)
    cases = [
        # Room for a third of the tiles: the workers cannot write the rest.
        ("tiles", max(64 << 10, sizes["tiles"] // 3), "carv|chunk"),
        # Every tile fits (with a margin for HDF5's temporary files), the meshes do not.
        ("meshes", tiles + (1 << 20), "merge"),
    ]
    for name, size, stage in cases:
        start = time.monotonic()
        trial = Trial(args, f"storage_full_{name}")
        os.makedirs(trial.out_root, exist_ok=True)
        subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", trial.out_root],
                       check=True)
        try:
            job = trial.run()
            if state(job) != "FAILED":
                trial.fail(f"job {state(job)} with {size} bytes for outputs")
            if "No space left on device" not in job.error:
                trial.fail(f"the reason does not say the storage is full: {job.error!r}")
            left = check_nothing_looks_complete(trial, ref, job)
            partial = [f for f in os.listdir(trial.out_root) if f != OUTPUT_NAME]
            for root, _, names in os.walk(trial.out):
                partial += [os.path.join(root, n) for n in names if ".partial" in n
                            or n.endswith(".tmp")]
            if partial:
                trial.fail(f"temporary files left behind: {partial[:5]}")
            log(f"storage full ({name}: {size} bytes for outputs): FAILED: {job.error!r}; left "
                f"{len(left)} complete file(s), no tiles, no job.json "
                f"({time.monotonic() - start:.1f} s)")
        finally:
            subprocess.run(["umount", trial.out_root])


# ---- a worker's network cut -------------------------------------------------------------------

NETNS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "deploy", "local",
                     "netns.sh")
# Each test its own addresses (CTest may run the two at once; netns.sh refuses a subnet in use).
SUBNET = {"netns-link-cut": "10.231", "run-netns": "10.232"}


def worker_ids(trial):
    """{worker number: id the coordinator gave it} from the workers' logs."""
    ids = {}
    for n, path in enumerate(trial.cluster.worker_logs, 1):
        with open(path, errors="replace") as f:
            for line in f:
                if "registered as " in line:
                    ids[n] = line.split("registered as ")[1].split()[0].rstrip('",')
    return ids


def wait_for_lease(trial, api, job_id, worker):
    """Polls until worker `worker` (its latest id) holds a lease; prefers a chunk with many
    wedges (it carves longest), taking any once none of those is left."""
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline:
        job = api.try_get(job_id)
        if job is not None and state(job) not in ("QUEUED", "INGESTING", "CARVING"):
            trial.fail(f"the job is {state(job)}: it left carving before worker {worker} was cut")
        wid = worker_ids(trial).get(worker)
        if wid and job is not None:
            chunks = trial.cluster.store_chunks(job_id)
            queued_big = any(r["state"] == 1 and r["wedge_count"] >= 500 for r in chunks.values())
            for key, r in chunks.items():
                if r["state"] == 2 and r["worker_id"] == wid and (
                        r["wedge_count"] >= 500 or not queued_big):
                    return {"worker": wid, "chunk": key, "generation": r["generation"],
                            "done": job.progress.chunks_done, "total": job.progress.chunks_total}
        time.sleep(0.01)
    trial.fail(f"worker {worker} never held a lease")


def wait_lease_outcome(trial, api, job_id, lease):
    """After a cut: "requeued" once the coordinator has taken the chunk from the cut worker
    (leased again, or back in the queue, with the lost-worker reason), "completed" if the
    worker's report got through first."""
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline:
        r = trial.cluster.store_chunks(job_id)[lease["chunk"]]
        if r["generation"] == lease["generation"] and r["state"] == 3:
            return "completed"
        if r["generation"] > lease["generation"] or (
                r["state"] == 1 and "lost" in r["last_error"]):
            lease["how"] = (f"was leased again (generation {r['generation']}, worker "
                            f"{r['worker_id']})" if r["generation"] > lease["generation"]
                            else f"went back to the queue ({r['last_error']})")
            return "requeued"
        time.sleep(0.05)
    trial.fail(f"chunk {lease['chunk']} stayed with the cut worker for 120 s")


def cmd_netns_link_cut(args):
    os.environ["CARVEMAP_NETNS_SUBNET"] = SUBNET["netns-link-cut"]
    ref = reference(args)
    name = f"cmf{os.getpid() % 1000000}"
    up = subprocess.run([NETNS, "up", name, "2"], capture_output=True, text=True)
    if up.returncode != 0:
        log(f"SKIPPED: the kernel refused to create network namespaces with veth links "
            f"({NETNS} up: {up.stderr.strip() or up.returncode}); this test needs root "
            "(CAP_NET_ADMIN) and iproute2")
        return SKIP
    start = time.monotonic()
    try:
        host_ip = {k: subprocess.check_output([NETNS, "host-ip", str(k)], text=True).strip()
                   for k in (1, 2)}
        trial = Trial(args, "netns_link_cut", workers=0, listen_host="0.0.0.0")
        seen = {}

        def inject(trial, api, job_id, t0):
            c = trial.cluster
            for k in (1, 2):  # one worker per namespace, reaching the coordinator over its link
                c.start_worker(prefix=["ip", "netns", "exec", f"{name}-{k}"],
                               coordinator_host=host_ip[k])
            # Cut worker 1's link while it carves a chunk (the job store says which). If the
            # worker got its tile reported just before the cut, heal the link, let it come back
            # (the coordinator has declared it lost: it registers again) and try once more.
            for attempt in range(1, 6):
                lease = wait_for_lease(trial, api, job_id, worker=1)
                subprocess.run([NETNS, "cut", name, "1"], check=True)
                outcome = wait_lease_outcome(trial, api, job_id, lease)
                if outcome == "requeued":
                    seen.update(lease, attempt=attempt)
                    return
                subprocess.run([NETNS, "heal", name, "1"], check=True)
            trial.fail("five cuts in a row came after worker 1 had reported its chunk")

        job = trial.run(inject)
        expect_succeeded(trial, job)
        check_same_as_reference(trial, ref)
        text = trial.coordinator_log()
        lost = [l for l in text.splitlines() if f"worker {seen['worker']} lost" in l]
        log(f"link of worker 1 ({seen['worker']}, namespace {name}-1) cut while it carved chunk "
            f"{seen['chunk']} (cut {seen['attempt']}; {seen['done']}/{seen['total']} done): "
            f"{lost[0].split('coordinator: ')[-1][:100] if lost else ''}; the chunk "
            f"{seen['how']}; job SUCCEEDED, {summarize(ref['files'])} identical "
            f"({time.monotonic() - start:.1f} s)")
    finally:
        subprocess.run([NETNS, "down", name, "2"])


def cmd_run_netns(args):
    """deploy/local/run-netns.sh end to end: a job through workers in namespaces of their own."""
    os.environ["CARVEMAP_NETNS_SUBNET"] = SUBNET["run-netns"]
    probe = f"cmp{os.getpid() % 1000000}"
    up = subprocess.run([NETNS, "up", probe, "1"], capture_output=True, text=True)
    subprocess.run([NETNS, "down", probe, "1"])
    if up.returncode != 0:
        log(f"SKIPPED: the kernel refused to create a network namespace with a veth link "
            f"({NETNS} up: {up.stderr.strip() or up.returncode}); run-netns.sh needs root "
            "(CAP_NET_ADMIN) and iproute2")
        return SKIP
    out = os.path.join(fresh_dir(os.path.join(args.work, "run_netns")), "out")
    script = os.path.join(os.path.dirname(NETNS), "run-netns.sh")
    run = subprocess.run([script, os.path.join(sim_dir(args), SCAN_NAME), out, args.carvemap],
                         capture_output=True, text=True, timeout=500)
    if run.returncode != 0:
        raise TestFailure(f"run-netns.sh exited {run.returncode}:\n{run.stdout}{run.stderr}\n"
                          + tail(os.path.join(out, ".carvemap", "coordinator.log")))
    tiles = [f for f in os.listdir(os.path.join(out, "tiles")) if f.endswith(".h5")]
    if not os.path.exists(os.path.join(out, "job.json")) or not tiles:
        raise TestFailure(f"run-netns.sh: no job.json or no tiles in {out}")
    for k in (1, 2):
        text = open(os.path.join(out, ".carvemap", f"worker-{k}.log"), errors="replace").read()
        if "registered as" not in text:
            raise TestFailure(f"worker {k} (in its namespace) never registered:\n{text[-2000:]}")
    left = [line for line in subprocess.run(["ip", "netns", "list"], capture_output=True,
                                             text=True).stdout.splitlines()
            if line.startswith("cmr")]
    if left:
        raise TestFailure(f"run-netns.sh left its namespaces behind: {left}")
    log(f"run-netns.sh: job.json and {len(tiles)} tiles, both workers registered over their "
        "links, namespaces removed")


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("command", choices=["reference", "coordinator-restart", "worker-kill",
                                       "merge-kill", "failures", "storage-full",
                                       "netns-link-cut", "run-netns"])
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--trials", type=int, default=10)
    p.add_argument("--seed", type=int, default=7)
    p.add_argument("--parallel", type=int, default=2)
    p.add_argument("--log-format", default=None)
    args = p.parse_args()
    args.carvemap = os.path.abspath(args.carvemap)
    args.work = os.path.abspath(args.work)
    start = time.monotonic()
    try:
        rc = {"reference": cmd_reference, "coordinator-restart": cmd_coordinator_restart,
              "worker-kill": cmd_worker_kill, "merge-kill": cmd_merge_kill,
              "failures": cmd_failures,
              "storage-full": cmd_storage_full,
              "netns-link-cut": cmd_netns_link_cut,
              "run-netns": cmd_run_netns}[args.command](args)
    except TestFailure as e:
        print(f"FAIL: {e}", flush=True)
        return 1
    if rc is not None:  # the outcome of a re-run in a namespace, which said it already
        return rc
    log(f"{args.command}: passed in {time.monotonic() - start:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
