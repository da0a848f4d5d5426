#!/usr/bin/env python3
"""Load, bounded and on loopback only: 4 tenants submit 8 jobs at once (2 each, from
8 threads released together) to one coordinator with 2 workers, while 50 watchers stream
WatchJob (each with its own tenant's token, spread over the jobs). Then:

  - none lost: every job SUCCEEDED, with its outputs in <output-root>/<tenant>/<name>/ and
    nothing of another tenant's there; every watcher's stream is the whole story of its job
    (snapshot of that job first, sequence 1, 2, 3, ..., state changes strictly forward, the
    terminal SUCCEEDED last) and ended without an error;
  - isolation: each tenant lists exactly its own 2 jobs; GetJob, WatchJob and FetchArtifact of
    another tenant's job are NOT_FOUND with the very message of a job id that does not exist.

Small jobs (the `room` preset, 5 Hz, 2° beams, 4 s of walk, no second carving pass).
Usage: load_test.py --carvemap BIN --work DIR [--jobs-per-tenant 2 --watchers 50]
"""
import argparse
import os
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster_harness import (Cluster, TestFailure, fresh_dir, log, random_secret,  # noqa: E402
                             stubs)

TENANTS = ["acme", "beta", "gamma", "delta"]
ORDER = {"QUEUED": 1, "INGESTING": 2, "CARVING": 3, "MERGING": 4, "SUCCEEDED": 5, "FAILED": 5,
         "CANCELLED": 5}


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--jobs-per-tenant", type=int, default=2)
    p.add_argument("--watchers", type=int, default=50)
    args = p.parse_args()
    start = time.monotonic()
    work = fresh_dir(os.path.abspath(args.work))
    data = os.path.join(work, "data")
    sim = subprocess.run([args.carvemap, "simulate", "--preset", "room", "--seed", "2",
                          "--rate-hz", "5", "--beam-step-deg", "2", "--max-duration", "4", "-q",
                          "-o", os.path.join(data, "sim")], capture_output=True, text=True)
    if sim.returncode != 0:
        print(f"FAIL: simulate: {sim.stdout}{sim.stderr}")
        return 1
    for t in TENANTS:  # each tenant's folder holds its own copy (a hard link) of the scan
        os.makedirs(os.path.join(data, t))
        os.link(os.path.join(data, "sim", "scan.h5"), os.path.join(data, t, "scan.h5"))
    tokens = {t: random_secret() for t in TENANTS}
    outputs = os.path.join(work, "outputs")
    cluster = Cluster(args.carvemap, os.path.join(work, "servers"), data, outputs,
                      tenants=tokens, shared_dirs=False)
    try:
        address = cluster.start_coordinator(port=0)
        cluster.start_worker()
        cluster.start_worker()
        run_load(args, address, tokens, outputs)
    except TestFailure as e:
        print(f"FAIL: {e}")
        for name, text in cluster.logs().items():
            print(f"--- {name}\n" + "\n".join(text.splitlines()[-20:]))
        return 1
    finally:
        cluster.stop()
    log(f"load: passed in {time.monotonic() - start:.1f} s")
    return 0


def run_load(args, address, tokens, outputs):
    pb, pb_grpc, grpc = stubs()
    channel = grpc.insecure_channel(address)
    grpc.channel_ready_future(channel).result(timeout=30)
    api = pb_grpc.JobServiceStub(channel)

    def md(tenant):
        return [("authorization", f"Bearer {tokens[tenant]}")]

    # ---- 8 submits at once
    submits = [(t, k) for t in TENANTS for k in range(args.jobs_per_tenant)]
    barrier = threading.Barrier(len(submits))
    jobs, errors = {}, []
    lock = threading.Lock()

    def submit(tenant, k):
        req = pb.SubmitJobRequest(input_path="scan.h5", output_name=f"job{k}")
        req.params.object_resolution_m = 0.0625  # = the resolution: no second pass
        barrier.wait()
        try:
            job = api.SubmitJob(req, metadata=md(tenant), timeout=60).job
            with lock:
                jobs[job.job_id] = (tenant, f"job{k}")
        except grpc.RpcError as e:
            with lock:
                errors.append(f"submit {tenant}/job{k}: {e.code()} {e.details()}")

    threads = [threading.Thread(target=submit, args=s) for s in submits]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if errors or len(jobs) != len(submits):
        raise TestFailure(f"{len(jobs)} of {len(submits)} submits went through: {errors}")
    log(f"{len(jobs)} jobs submitted at once by {len(TENANTS)} tenants")

    # ---- 50 watchers, each on a job of its own tenant
    ids = sorted(jobs)
    results = {}

    def watch(n, job_id):
        tenant = jobs[job_id][0]
        events = []
        try:
            for e in api.WatchJob(pb.WatchJobRequest(job_id=job_id, min_interval_s=0.2),
                                  metadata=md(tenant), timeout=900):
                events.append(e)
            results[n] = (job_id, events, None)
        except grpc.RpcError as e:
            results[n] = (job_id, events, f"{e.code()}: {e.details()}")

    watchers = [threading.Thread(target=watch, args=(n, ids[n % len(ids)]))
                for n in range(args.watchers)]
    for t in watchers:
        t.start()

    # ---- isolation, checked while the jobs run
    missing = "j-0000000000000000"  # the shape of a job id, but no job's
    for job_id, (owner, _) in jobs.items():
        for tenant in TENANTS:
            if tenant == owner:
                continue
            for name, call in (
                    ("GetJob", lambda i: api.GetJob(pb.GetJobRequest(job_id=i),
                                                    metadata=md(tenant), timeout=10)),
                    ("WatchJob", lambda i: list(api.WatchJob(pb.WatchJobRequest(job_id=i),
                                                             metadata=md(tenant), timeout=10))),
                    ("FetchArtifact", lambda i: list(api.FetchArtifact(
                        pb.FetchArtifactRequest(job_id=i, name="job.json"),
                        metadata=md(tenant), timeout=10)))):
                theirs, nobodys = answer(grpc, call, job_id), answer(grpc, call, missing)
                want = (grpc.StatusCode.NOT_FOUND, nobodys[1].replace(missing, job_id))
                if theirs != want or nobodys[0] != grpc.StatusCode.NOT_FOUND:
                    raise TestFailure(f"{tenant} {name} of {owner}'s {job_id}: {theirs}; a "
                                      f"missing id: {nobodys}")
    for tenant in TENANTS:
        listed = api.ListJobs(pb.ListJobsRequest(), metadata=md(tenant), timeout=10)
        mine = {j for j, (t, _) in jobs.items() if t == tenant}
        got = {j.job_id for j in listed.jobs}
        if got != mine or any(j.tenant != tenant for j in listed.jobs):
            raise TestFailure(f"{tenant} lists {sorted(got)}, owns {sorted(mine)}")
    log(f"isolation: {len(jobs) * (len(TENANTS) - 1) * 3} cross-tenant GetJob/WatchJob/"
        "FetchArtifact calls NOT_FOUND exactly as for a missing id; each tenant lists its own")

    for t in watchers:
        t.join(timeout=900)
    # ---- every watcher saw its job through
    ended = {}
    for n in range(args.watchers):
        if n not in results:
            raise TestFailure(f"watcher {n} never ended")
        job_id, events, error = results[n]
        if error:
            raise TestFailure(f"watcher {n} of {job_id} ended with {error} after "
                              f"{len(events)} events")
        check_story(pb, n, job_id, jobs[job_id][0], events)
        ended[job_id] = pb.JobState.Name(events[-1].state_change.to_state)[len("JOB_STATE_"):]
    for job_id, (tenant, name) in jobs.items():
        job = api.GetJob(pb.GetJobRequest(job_id=job_id), metadata=md(tenant), timeout=10)
        if pb.JobState.Name(job.state) != "JOB_STATE_SUCCEEDED":
            raise TestFailure(f"job {job_id} of {tenant}: {pb.JobState.Name(job.state)} "
                              f"{job.error}")
        folder = os.path.join(outputs, tenant, name)
        if not os.path.exists(os.path.join(folder, "job.json")):
            raise TestFailure(f"job {job_id}: no {folder}/job.json")
    for tenant in TENANTS:
        names = sorted(os.listdir(os.path.join(outputs, tenant)))
        want = sorted(n for t, n in jobs.values() if t == tenant)
        if names != want:
            raise TestFailure(f"{outputs}/{tenant} holds {names}, its jobs are {want}")
    if set(os.listdir(outputs)) - set(TENANTS) - {".carvemap"}:
        raise TestFailure(f"{outputs} holds {os.listdir(outputs)}")
    log(f"{args.watchers} watchers each saw the whole story of its job; all {len(jobs)} jobs "
        f"SUCCEEDED, outputs in their tenant's folder ({sorted(set(ended.values()))})")
    channel.close()


def answer(grpc, call, job_id):
    try:
        call(job_id)
        return ("OK", "")
    except grpc.RpcError as e:
        return (e.code(), e.details())


def check_story(pb, n, job_id, tenant, events):
    name = lambda s: pb.JobState.Name(s)[len("JOB_STATE_"):]  # noqa: E731
    if not events or events[0].WhichOneof("event") != "snapshot":
        raise TestFailure(f"watcher {n}: no snapshot first")
    snap = events[0].snapshot
    if snap.job_id != job_id or snap.tenant != tenant:
        raise TestFailure(f"watcher {n} of {tenant}'s {job_id} got a snapshot of "
                          f"{snap.tenant}'s {snap.job_id}")
    if [e.sequence for e in events] != list(range(1, len(events) + 1)):
        raise TestFailure(f"watcher {n}: sequence {[e.sequence for e in events][:20]}")
    current = name(snap.state)
    for e in events[1:]:
        if e.WhichOneof("event") == "state_change":
            sc = e.state_change
            if name(sc.from_state) != current or ORDER[name(sc.to_state)] <= ORDER[current]:
                raise TestFailure(f"watcher {n}: {name(sc.from_state)} -> {name(sc.to_state)} "
                                  f"while {current}")
            current = name(sc.to_state)
    if current != "SUCCEEDED" or events[-1].WhichOneof("event") != "state_change":
        raise TestFailure(f"watcher {n} of {job_id}: the story ends in {current}")


if __name__ == "__main__":
    sys.exit(main())
