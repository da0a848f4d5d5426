#!/usr/bin/env python3
"""Streamed uploads over a connection that breaks (docs/RPC.md "Uploads").

A coordinator with two tenants; `carvemap upload` of a large file (1 GiB by default) through a
TCP proxy that cuts the connection twice mid-way (after about a third of the file on each of
the first two connections). The CLI resumes from what the server holds each time; the file in
the tenant's uploads/ folder must be byte-identical to the local one, and nothing else but the
upload's record is left. Then, with the job API's stubs (generated from proto/ at test time):
the same file started again is complete at once; the name with other content is
ALREADY_EXISTS; an upload past the tenant's quota is RESOURCE_EXHAUSTED; the other tenant
cannot submit the upload (NOT_FOUND); a submit with the upload id names uploads/<name>; an
input path into .uploads/ is INVALID_ARGUMENT; a wrong offset says where to resume.

Usage: upload_test.py --carvemap BIN --work DIR [--size-mb 1024]
"""
import argparse
import hashlib
import json
import os
import shutil
import socket
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster_harness import (Cluster, TestFailure, fresh_dir, log, random_secret,  # noqa: E402
                             sha256_file, stubs)


class CuttingProxy:
    """Forwards 127.0.0.1:port to `target`; the k-th connection (k < len(cuts)) is closed once
    cuts[k] bytes went from the client to the server, as a network that breaks would."""

    def __init__(self, target, cuts):
        self.target = target
        self.cuts = list(cuts)
        self.connections = 0
        self.cut_count = 0
        self.server = socket.socket()
        self.server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        self.server.bind(("127.0.0.1", 0))
        self.server.listen(8)
        self.port = self.server.getsockname()[1]
        threading.Thread(target=self._accept, daemon=True).start()

    def _accept(self):
        while True:
            try:
                client, _ = self.server.accept()
            except OSError:
                return
            k = self.connections
            self.connections += 1
            limit = self.cuts[k] if k < len(self.cuts) else None
            host, port = self.target.rsplit(":", 1)
            upstream = socket.create_connection((host, int(port)))
            for s in (client, upstream):
                s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            threading.Thread(target=self._pump, args=(client, upstream, limit),
                             daemon=True).start()
            threading.Thread(target=self._pump, args=(upstream, client, None),
                             daemon=True).start()

    def _pump(self, src, dst, limit):
        sent = 0
        try:
            while True:
                data = src.recv(1 << 20)
                if not data:
                    break
                if limit is not None and sent + len(data) >= limit:
                    self.cut_count += 1
                    break
                dst.sendall(data)
                sent += len(data)
        except OSError:
            pass
        for s in (src, dst):
            try:
                s.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            s.close()


def write_big_file(path, size):
    """`size` bytes of a seeded pseudo-random stream (no two 1 MiB blocks alike)."""
    block = hashlib.sha256(b"carvemap upload test").digest() * (1 << 15)  # 1 MiB
    with open(path, "wb") as f:
        written = 0
        k = 0
        while written < size:
            head = hashlib.sha256(k.to_bytes(8, "little")).digest()
            chunk = (head + block[len(head):])[: size - written]
            f.write(chunk)
            written += len(chunk)
            k += 1


def expect_code(call, code, what):
    grpc = stubs()[2]
    try:
        call()
    except grpc.RpcError as e:
        if e.code().name != code:
            raise TestFailure(f"{what}: {e.code().name} ({e.details()}), expected {code}")
        log(f"  {what}: {code}: {e.details()}")
        return e.details()
    raise TestFailure(f"{what}: succeeded, expected {code}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--carvemap", required=True)
    ap.add_argument("--work", required=True)
    ap.add_argument("--size-mb", type=int, default=1024)
    args = ap.parse_args()
    work = fresh_dir(args.work)
    size = args.size_mb << 20
    tokens = {"alice": random_secret(), "bob": random_secret()}
    data_root = os.path.join(work, "data")
    for tenant in tokens:
        os.makedirs(os.path.join(data_root, tenant), exist_ok=True)
    quota_gb = 2 * size / (1 << 30)
    cluster = Cluster(args.carvemap, os.path.join(work, "cluster"), data_root,
                      os.path.join(work, "out"), tenants=tokens, mergers=0,
                      extra_coordinator_args=["--upload-quota-gb", f"{quota_gb:.6f}"])
    try:
        address = cluster.start_coordinator()
        local = os.path.join(work, "big.bin")
        t0 = time.monotonic()
        write_big_file(local, size)
        local_sha = sha256_file(local)
        log(f"{size / 1e6:.0f} MB file written and hashed in {time.monotonic() - t0:.1f} s")

        proxy = CuttingProxy(address, [size // 3, size // 3])
        token_file = os.path.join(work, "alice.token")
        with open(token_file, "w") as f:
            f.write(tokens["alice"] + "\n")
        t0 = time.monotonic()
        run = subprocess.run([args.carvemap, "upload", local, "--name", "big.h5", "--server",
                              f"127.0.0.1:{proxy.port}", "--token-file", token_file],
                             capture_output=True, text=True, timeout=900)
        took = time.monotonic() - t0
        log(run.stderr.strip())
        if run.returncode != 0:
            raise TestFailure(f"carvemap upload failed ({run.returncode}):\n{run.stderr}\n"
                              f"coordinator:\n{cluster.logs()}")
        if proxy.cut_count != 2:
            raise TestFailure(f"the proxy cut {proxy.cut_count} connection(s), expected 2")
        resumed = run.stderr.count("resuming in")
        if resumed < 2:
            raise TestFailure(f"the CLI reported {resumed} resume(s), expected at least 2")
        upload_id, input_path = run.stdout.split()
        if input_path != "uploads/big.h5" or not upload_id.startswith("u-"):
            raise TestFailure(f"carvemap upload printed {run.stdout!r}")
        placed = os.path.join(data_root, "alice", "uploads", "big.h5")
        if os.path.getsize(placed) != size or sha256_file(placed) != local_sha:
            raise TestFailure(f"{placed} differs from the uploaded file")
        log(f"upload through 2 cuts: {size / 1e6:.0f} MB in {took:.1f} s "
            f"({size / 1e6 / took:.0f} MB/s), {proxy.connections} connection(s); "
            "the server's file is byte-identical")
        left = sorted(os.path.relpath(os.path.join(d, f), os.path.join(data_root, "alice"))
                      for d, _, files in os.walk(os.path.join(data_root, "alice"))
                      for f in files)
        if left != [f".uploads/{upload_id}.json", "uploads/big.h5"]:
            raise TestFailure(f"the tenant's folder holds {left}")

        # A coordinator that stopped with every byte received but before it checked and placed
        # the file (made here on disk, as docs/RPC.md lays it out): the next upload of the same
        # file finishes it without sending the bytes again.
        held = os.path.join(work, "held.bin")
        with open(held, "wb") as f:
            f.write(os.urandom(100000))
        held_sha = sha256_file(held)
        held_id = "u-" + hashlib.sha256(f"held.h5\n100000\n{held_sha}".encode()).hexdigest()[:24]
        work_dir = os.path.join(data_root, "alice", ".uploads")
        shutil.copy(held, os.path.join(work_dir, held_id + ".partial"))
        with open(os.path.join(work_dir, held_id + ".json"), "w") as f:
            json.dump({"name": "held.h5", "size_bytes": 100000, "sha256_hex": held_sha,
                       "complete": False}, f)
        finish = subprocess.run([args.carvemap, "upload", held, "--name", "held.h5", "--server",
                                 address, "--token-file", token_file, "-q"],
                                capture_output=True, text=True, timeout=120)
        placed_held = os.path.join(data_root, "alice", "uploads", "held.h5")
        if finish.returncode != 0 or finish.stdout.split() != [held_id, "uploads/held.h5"] or \
                sha256_file(placed_held) != held_sha:
            raise TestFailure(f"an upload held whole but unfinished: {finish.returncode} "
                              f"{finish.stdout!r} {finish.stderr}")
        log("  every byte held but not placed: finished by the next upload, no byte sent")

        # No server at all: the CLI says so at once instead of resuming (nothing answered yet).
        closed = socket.socket()
        closed.bind(("127.0.0.1", 0))
        t0 = time.monotonic()
        nobody = subprocess.run([args.carvemap, "upload", local, "--server",
                                 f"127.0.0.1:{closed.getsockname()[1]}", "--token-file",
                                 token_file, "-q"], capture_output=True, text=True, timeout=120)
        closed.close()
        if nobody.returncode == 0 or time.monotonic() - t0 > 40 or "resuming" in nobody.stderr:
            raise TestFailure(f"an upload to no server: exit {nobody.returncode} after "
                              f"{time.monotonic() - t0:.1f} s: {nobody.stderr}")
        log(f"  no server: refused in {time.monotonic() - t0:.1f} s: {nobody.stderr.strip()}")

        pb, pb_grpc, grpc = stubs()
        channel = grpc.insecure_channel(address)
        api = pb_grpc.JobServiceStub(channel)
        alice = [("authorization", f"Bearer {tokens['alice']}")]
        bob = [("authorization", f"Bearer {tokens['bob']}")]
        again = api.StartUpload(pb.StartUploadRequest(name="big.h5", size_bytes=size,
                                                      sha256_hex=local_sha), metadata=alice)
        if not again.complete or again.upload_id != upload_id or again.received_bytes != size:
            raise TestFailure(f"the same upload started again: {again}")
        expect_code(lambda: api.StartUpload(pb.StartUploadRequest(
            name="big.h5", size_bytes=5, sha256_hex="0" * 64), metadata=alice),
            "ALREADY_EXISTS", "the name with other content")
        expect_code(lambda: api.StartUpload(pb.StartUploadRequest(
            name="more.h5", size_bytes=size + 1, sha256_hex="1" * 64), metadata=alice),
            "RESOURCE_EXHAUSTED", "past the quota")
        expect_code(lambda: api.StartUpload(pb.StartUploadRequest(
            name="../x", size_bytes=5, sha256_hex="1" * 64), metadata=alice),
            "INVALID_ARGUMENT", "a name with a path")
        small = api.StartUpload(pb.StartUploadRequest(name="small.h5", size_bytes=10,
                                                      sha256_hex="2" * 64), metadata=alice)
        details = expect_code(lambda: api.UploadScan(iter([pb.UploadScanRequest(
            upload_id=small.upload_id, offset=4, data=b"abc")]), metadata=alice),
            "FAILED_PRECONDITION", "data at the wrong offset")
        if "resume from 0" not in details:
            raise TestFailure(f"the wrong offset's error does not say where to resume: {details}")
        expect_code(lambda: api.SubmitJob(pb.SubmitJobRequest(upload_id=small.upload_id),
                                          metadata=alice),
                    "FAILED_PRECONDITION", "a submit of an unfinished upload")
        expect_code(lambda: api.SubmitJob(pb.SubmitJobRequest(upload_id=upload_id),
                                          metadata=bob),
                    "NOT_FOUND", "another tenant's upload")
        expect_code(lambda: api.SubmitJob(pb.SubmitJobRequest(
            input_path=f".uploads/{small.upload_id}.partial"), metadata=alice),
            "INVALID_ARGUMENT", "an input path into .uploads/")
        job = api.SubmitJob(pb.SubmitJobRequest(upload_id=upload_id, output_name="big"),
                            metadata=alice).job
        if job.input_path != "uploads/big.h5":
            raise TestFailure(f"the job of the upload reads {job.input_path!r}")
        # Random bytes are no scan: the job fails at ingest, naming the file.
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            job = api.GetJob(pb.GetJobRequest(job_id=job.job_id), metadata=alice)
            if job.state in (5, 6, 7):
                break
            time.sleep(0.1)
        if job.state != 6 or "big.h5" not in job.error:
            raise TestFailure(f"the job of random bytes ended {job.state}: {job.error!r}")
        log(f"  a job of the upload: input uploads/big.h5, FAILED: {job.error}")
        log("PASS")
    finally:
        cluster.stop()
    # The two copies of the file are 2 GiB of the build folder: gone once passed.
    shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except TestFailure as e:
        print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)
