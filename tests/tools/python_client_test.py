#!/usr/bin/env python3
"""An independent client of the job API: Python, Debian's python3-grpcio, stubs
generated from proto/ at test time with python3-grpc-tools; it knows only the .proto files and
docs/RPC.md, none of carvemap's C++.

Against a running coordinator (started here with two workers and a merge service, `carvemap
coordinator|worker|merger`, a bearer token for the tenant): no token and a wrong token are
UNAUTHENTICATED without the token in the answer; SubmitJob with the token; the same idempotency key again is deduplicated;
WatchJob streams a snapshot, state changes strictly forward, progress, and ends after the
terminal SUCCEEDED; FetchArtifact streams levels.json (in 4 KiB chunks) and mesh/dense.ply,
contiguous, with the SHA-256 of the whole in the last chunk, byte-identical to the files on
disk; a PLY's size agrees with its header; a fetch resumed at an offset gives the tail;
another tenant's token sees nothing of the job. The internal MergeService of the merge
service: no cluster secret, a wrong one or a tenant's token are UNAUTHENTICATED; with the
secret the call gets past authentication (a bad MergeJob is INVALID_ARGUMENT).

Usage: python_client_test.py --carvemap BIN --work DIR
"""
import argparse
import atexit
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster_harness import Cluster, TestFailure, fresh_dir, log, random_secret  # noqa: E402

PROTO = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..",
                                     "proto"))


def generate_stubs():
    """jobs_pb2, jobs_pb2_grpc from proto/carvemap/v1/*.proto, generated now (merge_pb2 and
    merge_pb2_grpc are importable afterwards)."""
    try:
        import grpc  # noqa: F401
        from grpc_tools import protoc
    except ImportError as e:
        raise TestFailure(f"{e}: install python3-grpcio and python3-grpc-tools "
                          "(scripts/install-deps.sh)")
    out = tempfile.mkdtemp(prefix="carvemap-pyclient-")
    atexit.register(shutil.rmtree, out, True)
    files = [os.path.join(PROTO, f"carvemap/v1/{name}.proto") for name in ("jobs", "carve",
                                                                          "merge")]
    rc = protoc.main(["protoc", f"-I{PROTO}", f"--python_out={out}", f"--grpc_python_out={out}"]
                     + files)
    if rc != 0:
        raise TestFailure(f"protoc failed on {files}")
    sys.path.insert(0, out)
    from carvemap.v1 import jobs_pb2, jobs_pb2_grpc
    return jobs_pb2, jobs_pb2_grpc


def expect(cond, what):
    if not cond:
        raise TestFailure(what)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True)
    args = p.parse_args()
    start = time.monotonic()
    work = fresh_dir(os.path.abspath(args.work))
    data = os.path.join(work, "data")
    sim = subprocess.run([args.carvemap, "simulate", "--preset", "room", "--seed", "5",
                          "--rate-hz", "5", "--beam-step-deg", "2", "--max-duration", "6", "-q",
                          "-o", data], capture_output=True, text=True)
    if sim.returncode != 0:
        print(f"FAIL: simulate: {sim.stdout}{sim.stderr}")
        return 1
    token, other = random_secret(), random_secret()
    cluster = Cluster(args.carvemap, os.path.join(work, "servers"), data,
                      os.path.join(work, "outputs"), tenants={"acme": token, "beta": other},
                      shared_dirs=False)
    # Tenant folders: the scan in acme's.
    os.makedirs(os.path.join(data, "acme"))
    os.link(os.path.join(data, "scan.h5"), os.path.join(data, "acme", "scan.h5"))
    try:
        address = cluster.start_coordinator(port=0)
        cluster.start_worker()
        cluster.start_worker()
        run_client(address, token, other, os.path.join(work, "outputs", "acme"))
        check_merge_service(cluster.merger_addresses()[0],
                            open(cluster.secret_file).read().strip(), token)
    except TestFailure as e:
        print(f"FAIL: {e}")
        for name, text in cluster.logs().items():
            print(f"--- {name}\n" + "\n".join(text.splitlines()[-20:]))
        return 1
    finally:
        cluster.stop()
    log(f"python client: passed in {time.monotonic() - start:.1f} s")
    return 0


def check_merge_service(address, secret, tenant_token):
    """The internal MergeService refuses callers without the cluster secret."""
    generate_stubs()
    import grpc
    from carvemap.v1 import merge_pb2, merge_pb2_grpc
    channel = grpc.insecure_channel(address)
    grpc.channel_ready_future(channel).result(timeout=30)
    merge = merge_pb2_grpc.MergeServiceStub(channel)

    def call(md, tiles_dir):
        start = merge_pb2.MergeClientMessage(start=merge_pb2.MergeJob(
            job_id="j-python", tiles_dir=tiles_dir, output_dir="/nonexistent/out"))
        try:
            list(merge.Merge(iter([start]), metadata=md, timeout=30))
            return grpc.StatusCode.OK, ""
        except grpc.RpcError as e:
            return e.code(), e.details()

    for md, what in (([], "no secret"),
                     ([("authorization", "Bearer " + "y" * 40)], "a wrong secret"),
                     ([("authorization", f"Bearer {tenant_token}")], "a tenant's token")):
        code, details = call(md, "/nonexistent/tiles")
        expect(code == grpc.StatusCode.UNAUTHENTICATED, f"MergeService with {what}: {code}")
        expect("cluster secret" in details and "y" * 20 not in details and
               tenant_token not in details, f"MergeService with {what}: {details!r}")
    code, details = call([("authorization", f"Bearer {secret}")], "relative/tiles")
    expect(code == grpc.StatusCode.INVALID_ARGUMENT and "absolute" in details,
           f"MergeService with the secret and a relative tiles_dir: {code} {details!r}")
    log("MergeService: no secret, a wrong one, a tenant's token: UNAUTHENTICATED; with the "
        "cluster secret a bad MergeJob is INVALID_ARGUMENT")


def run_client(address, token, other_token, output_root):
    pb, pb_grpc = generate_stubs()
    import grpc
    channel = grpc.insecure_channel(address)
    grpc.channel_ready_future(channel).result(timeout=30)
    jobs = pb_grpc.JobServiceStub(channel)
    auth = [("authorization", f"Bearer {token}")]
    other = [("authorization", f"Bearer {other_token}")]

    # ---- no token, wrong token
    for md, want in (([], "missing bearer token"), ([("authorization", "Bearer " + "x" * 40)],
                                                     "invalid bearer token")):
        try:
            jobs.ListJobs(pb.ListJobsRequest(), metadata=md, timeout=10)
            raise TestFailure("ListJobs without a valid token succeeded")
        except grpc.RpcError as e:
            expect(e.code() == grpc.StatusCode.UNAUTHENTICATED, f"{e.code()}: {e.details()}")
            expect(want in e.details(), f"'{e.details()}' does not say '{want}'")
            expect("x" * 20 not in e.details(), "the token is echoed")
    log("no token / wrong token: UNAUTHENTICATED, token not echoed")

    # ---- submit (twice with one key)
    req = pb.SubmitJobRequest(input_path="scan.h5", output_name="pyclient",
                              idempotency_key="python client test")
    req.params.resolution_m = 0.0625
    req.params.object_resolution_m = 0.0625  # no second pass: the job stays short
    first = jobs.SubmitJob(req, metadata=auth, timeout=30)
    job_id = first.job.job_id
    expect(job_id and first.job.tenant == "acme", f"submitted: {first}")
    expect(not first.deduplicated, "first submit deduplicated")
    again = jobs.SubmitJob(req, metadata=auth, timeout=30)
    expect(again.deduplicated and again.job.job_id == job_id, f"second submit: {again}")
    log(f"submitted {job_id} (tenant acme); the same key again: deduplicated")

    # ---- watch to the end
    order = {pb.JOB_STATE_QUEUED: 1, pb.JOB_STATE_INGESTING: 2, pb.JOB_STATE_CARVING: 3,
             pb.JOB_STATE_MERGING: 4, pb.JOB_STATE_SUCCEEDED: 5, pb.JOB_STATE_FAILED: 5,
             pb.JOB_STATE_CANCELLED: 5}
    events = list(jobs.WatchJob(pb.WatchJobRequest(job_id=job_id, min_interval_s=0.2),
                                metadata=auth, timeout=600))
    expect(events and events[0].WhichOneof("event") == "snapshot", "no snapshot first")
    expect(events[0].snapshot.job_id == job_id, "snapshot of another job")
    expect([e.sequence for e in events] == list(range(1, len(events) + 1)),
           "sequence numbers are not 1, 2, 3, ...")
    current = events[0].snapshot.state
    states = [pb.JobState.Name(current)]
    progress = 0
    for e in events[1:]:
        kind = e.WhichOneof("event")
        if kind == "state_change":
            sc = e.state_change
            expect(sc.from_state == current, f"state change from {sc.from_state}, was {current}")
            expect(order[sc.to_state] > order[current], f"state went back: {sc}")
            current = sc.to_state
            states.append(pb.JobState.Name(current))
        elif kind == "progress":
            c = e.progress.chunks
            expect(0 <= c.chunks_done <= c.chunks_total, f"progress {c}")
            progress += 1
        else:
            raise TestFailure(f"unexpected event {kind}")
    expect(current == pb.JOB_STATE_SUCCEEDED, f"ended in {pb.JobState.Name(current)}")
    expect(events[-1].WhichOneof("event") == "state_change", "the terminal change is not last")
    got = jobs.GetJob(pb.GetJobRequest(job_id=job_id), metadata=auth, timeout=10)
    expect(got.state == pb.JOB_STATE_SUCCEEDED and got.progress.chunks_done ==
           got.progress.chunks_total > 0, f"GetJob after the end: {got}")
    log(f"watched: {len(events)} events, states {' -> '.join(s[10:] for s in states)}, "
        f"{progress} progress events, {got.progress.chunks_total} chunks")

    # ---- fetch outputs, check their bytes
    out_dir = os.path.join(output_root, "pyclient")
    levels, _, _ = fetch(jobs, pb, auth, job_id, "levels.json")
    with open(os.path.join(out_dir, "levels.json"), "rb") as f:
        expect(f.read() == levels, "levels.json differs from the file on disk")
    parsed = json.loads(levels)
    expect(isinstance(parsed, list) and parsed and all(
        {"index", "floor_z", "ceiling_z"} <= set(level) for level in parsed),
        f"levels.json: {parsed}")
    octree, _, pieces = fetch(jobs, pb, auth, job_id, "octree.bt", chunk=4096)
    with open(os.path.join(out_dir, "octree.bt"), "rb") as f:
        expect(f.read() == octree, "octree.bt differs from the file on disk")
    expect(octree.startswith(b"# Octomap OcTree binary file"), "octree.bt: not OctoMap's format")
    expect(pieces == (len(octree) + 4095) // 4096, f"octree.bt came in {pieces} chunks")
    dense, dense_sha, _ = fetch(jobs, pb, auth, job_id, "mesh/dense.ply")
    with open(os.path.join(out_dir, "mesh", "dense.ply"), "rb") as f:
        expect(f.read() == dense, "dense.ply differs from the file on disk")
    check_ply_size(dense)
    half = len(dense) // 2
    tail, tail_sha, _ = fetch(jobs, pb, auth, job_id, "mesh/dense.ply", offset=half)
    expect(tail == dense[half:], "a fetch resumed at an offset is not the tail")
    expect(tail_sha == dense_sha, "the resumed fetch's SHA-256 is not the whole file's")
    log(f"fetched levels.json ({len(levels)} B, {len(parsed)} level(s)), octree.bt ({len(octree)} "
        f"B in {pieces} chunks of 4 KiB) and mesh/dense.ply ({len(dense)} B), SHA-256 checked, "
        f"identical to the files on disk; resumed at {half}")

    # ---- another tenant sees nothing
    for call in (lambda: jobs.GetJob(pb.GetJobRequest(job_id=job_id), metadata=other, timeout=10),
                 lambda: list(jobs.FetchArtifact(pb.FetchArtifactRequest(
                     job_id=job_id, name="levels.json"), metadata=other, timeout=10))):
        try:
            call()
            raise TestFailure("another tenant reached the job")
        except grpc.RpcError as e:
            expect(e.code() == grpc.StatusCode.NOT_FOUND, f"{e.code()}: {e.details()}")
    listed = jobs.ListJobs(pb.ListJobsRequest(), metadata=other, timeout=10)
    expect(len(listed.jobs) == 0, f"tenant beta lists {len(listed.jobs)} job(s)")
    log("tenant beta: NOT_FOUND for the job and its artifact, lists no job")
    channel.close()


def fetch(jobs, pb, auth, job_id, name, chunk=0, offset=0):
    """(the artifact's bytes from `offset`, the SHA-256 the server sent, chunks); checks the
    chunks are contiguous and the hash matches when the whole file was fetched."""
    data, sha, total, last, pieces = bytearray(), "", None, False, 0
    for c in jobs.FetchArtifact(pb.FetchArtifactRequest(job_id=job_id, name=name, offset=offset,
                                                        chunk_size_bytes=chunk),
                                metadata=auth, timeout=120):
        expect(not last, f"{name}: a chunk after the last one")
        expect(c.offset == offset + len(data), f"{name}: chunk at {c.offset}, expected "
               f"{offset + len(data)}")
        data += c.data
        pieces += 1
        total = c.total_size_bytes
        if c.last:
            last, sha = True, c.sha256_hex
    expect(last, f"{name}: no last chunk")
    expect(total == offset + len(data), f"{name}: {offset + len(data)} bytes of {total}")
    if offset == 0:
        expect(hashlib.sha256(data).hexdigest() == sha, f"{name}: SHA-256 mismatch")
    return bytes(data), sha, pieces


def check_ply_size(ply):
    """Binary little-endian PLY with float x y z vertices and uchar-int triangle lists
    (docs/DESIGN.md §7): the header's counts must account for every byte."""
    end = ply.index(b"end_header\n") + len(b"end_header\n")
    header = ply[:end].decode("ascii").splitlines()
    expect(header[0] == "ply" and header[1] == "format binary_little_endian 1.0",
           f"PLY header: {header[:2]}")
    counts = {w[1]: int(w[2]) for w in (line.split() for line in header)
              if w[0] == "element"}
    vertex_props = sum(1 for line in header if line.startswith("property float"))
    expect(vertex_props >= 3, "PLY without float x y z")
    body = len(ply) - end
    # Faces: 1 count byte + 3 int32; any extra face property would show as a size mismatch.
    face_bytes = body - counts["vertex"] * 4 * vertex_props
    expect(face_bytes == counts["face"] * 13,
           f"PLY body {body} B does not match {counts['vertex']} vertices and "
           f"{counts['face']} triangles")


if __name__ == "__main__":
    sys.exit(main())
