"""A client of carvemap's job API (proto/carvemap/v1/jobs.proto; docs/RPC.md): submit a job,
watch it with its progress, get, list and cancel jobs, and fetch the outputs to a folder.

    from carvemap.client import JobClient
    with JobClient("127.0.0.1:7600", token_file="TOKEN") as c:
        job = c.submit("scan.h5", output_name="floor3")   # a path in your tenant's folder
        for event in c.watch(job.job_id):
            print(event)
        c.fetch(job.job_id, "floor3/")                     # job.json and every output
        up = c.upload("local/scan.h5")                     # or send the scan from here
        job = c.submit(upload_id=up.upload_id)

Every call carries `authorization: Bearer <token>`. Without arguments the client takes what
`carvemap submit` takes from the environment: CARVEMAP_SERVER, CARVEMAP_TOKEN or
CARVEMAP_TOKEN_FILE, CARVEMAP_TLS_CA, CARVEMAP_TLS_SERVER_NAME. Errors of the server are
JobError, with the gRPC status code's name (NOT_FOUND, UNAUTHENTICATED, ...) and its message.
"""
import atexit
import hashlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field
from typing import Optional

import grpc


def _load_stubs():
    """(jobs_pb2, jobs_pb2_grpc): generated from proto/ when the package was built (setup.py);
    in a source checkout that was not built, generated now from ../proto with grpc_tools."""
    try:
        from carvemap.v1 import jobs_pb2, jobs_pb2_grpc
        return jobs_pb2, jobs_pb2_grpc
    except ImportError:
        pass
    proto = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "proto")
    if not os.path.isfile(os.path.join(proto, "carvemap", "v1", "jobs.proto")):
        raise ImportError("carvemap.v1.jobs_pb2 is missing: install the package with pip, "
                          "which generates it from proto/carvemap/v1/jobs.proto")
    try:
        from grpc_tools import protoc
    except ImportError as e:
        raise ImportError(f"{e}: running carvemap from its source folder needs grpc_tools to "
                          "generate the stubs (Debian: python3-grpc-tools); or install it with "
                          "pip") from e
    out = tempfile.mkdtemp(prefix="carvemap-stubs-")
    atexit.register(shutil.rmtree, out, True)
    rc = protoc.main(["grpc_tools.protoc", f"-I{os.path.abspath(proto)}", f"--python_out={out}",
                      f"--grpc_python_out={out}",
                      os.path.join(os.path.abspath(proto), "carvemap", "v1", "jobs.proto")])
    if rc != 0:
        raise ImportError(f"grpc_tools.protoc failed ({rc}) on {proto}/carvemap/v1/jobs.proto")
    import carvemap.v1
    # The generated modules import each other as carvemap.v1.*: make them part of it.
    carvemap.v1.__path__.append(os.path.join(out, "carvemap", "v1"))
    from carvemap.v1 import jobs_pb2, jobs_pb2_grpc
    return jobs_pb2, jobs_pb2_grpc


pb, pb_grpc = _load_stubs()

STATES = ("UNSPECIFIED", "QUEUED", "INGESTING", "CARVING", "MERGING", "SUCCEEDED", "FAILED",
          "CANCELLED")
TERMINAL = frozenset({"SUCCEEDED", "FAILED", "CANCELLED"})
DEFAULT_SERVER = "127.0.0.1:7600"


class JobError(Exception):
    """A call the server refused or that failed: code is the gRPC status code's name."""

    def __init__(self, code, details):
        super().__init__(f"{code}: {details}")
        self.code = code
        self.details = details

    @classmethod
    def from_rpc(cls, error):
        code = error.code() if hasattr(error, "code") else None
        details = error.details() if hasattr(error, "details") else str(error)
        return cls(code.name if code is not None else "UNKNOWN", details or "")


def _state(value):
    return STATES[value] if 0 <= value < len(STATES) else str(value)


def _state_number(name):
    name = name.upper()
    if name.startswith("JOB_STATE_"):
        name = name[len("JOB_STATE_"):]
    if name not in STATES:
        raise ValueError(f"unknown job state {name!r}; one of {', '.join(STATES[1:])}")
    return STATES.index(name)


def _enum(enum, prefix, name, what):
    names = [n[len(prefix):].lower() for n in enum.keys() if not n.endswith("UNSPECIFIED")]
    if name.lower() not in names:
        raise ValueError(f"{what} {name!r}: one of {', '.join(names)}")
    return enum.Value(prefix + name.upper())


@dataclass
class Job:
    """A job as the server reports it (Job in jobs.proto); state is a name, e.g. "CARVING"."""
    job_id: str
    tenant: str
    state: str
    input_path: str
    output_name: str
    error: str
    params: dict
    created_unix_ms: int
    updated_unix_ms: int
    finished_unix_ms: int
    chunks_total: int
    chunks_done: int
    chunks_leased: int
    chunk_retries: int
    idempotency_key: str
    # SubmitJob only: the idempotency key matched an earlier job, none was created.
    deduplicated: bool = False

    @property
    def terminal(self):
        return self.state in TERMINAL

    @classmethod
    def from_proto(cls, job, deduplicated=False):
        p = job.params
        params = dict(resolution_m=p.resolution_m,
                      method=pb.CarveMethod.Name(p.method)[len("CARVE_METHOD_"):].lower(),
                      workers_hint=p.workers_hint, object_resolution_m=p.object_resolution_m,
                      floorplan_method=p.floorplan_method, trimmed_points=p.trimmed_points,
                      min_object_volume_m3=p.min_object_volume_m3,
                      evaluation=pb.CarveEvaluation.Name(p.evaluation)[
                          len("CARVE_EVALUATION_"):].lower(),
                      north=p.north, location=p.location, survey_date=p.survey_date)
        c = job.progress
        return cls(job.job_id, job.tenant, _state(job.state), job.input_path, job.output_name,
                   job.error, params, job.created_unix_ms, job.updated_unix_ms,
                   job.finished_unix_ms, c.chunks_total, c.chunks_done, c.chunks_leased,
                   c.chunk_retries, job.idempotency_key, deduplicated)


@dataclass
class Upload:
    """Where an upload stands (Upload in jobs.proto): input_path is "uploads/<name>" in your
    tenant's folder; complete once every byte arrived and the SHA-256 matched."""
    upload_id: str
    name: str
    input_path: str
    size_bytes: int
    received_bytes: int
    complete: bool

    @classmethod
    def from_proto(cls, u):
        return cls(u.upload_id, u.name, u.input_path, u.size_bytes, u.received_bytes,
                   u.complete)


def _sha256_of(path):
    """hashlib's SHA-256 object over the file at `path` (to be continued or read)."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest


# What a broken connection or a restarting server answers: worth resuming an upload after.
_RESUMABLE = ("UNAVAILABLE", "ABORTED", "DEADLINE_EXCEEDED", "INTERNAL", "UNKNOWN", "CANCELLED")


@dataclass
class Stage:
    name: str
    elapsed_s: float
    finished: bool


@dataclass
class Event:
    """One event of WatchJob: kind "snapshot" (the first, with `job`), "state" (from_state ➜
    to_state, with the reason in `error` for FAILED/CANCELLED) or "progress". `state` is the
    job's state once the event happened. Progress: chunks, rays (CARVING), rays per second,
    the running stage with its own counts (MERGING) and eta_s (None when not known yet)."""
    kind: str
    sequence: int
    time_unix_ms: int
    state: str
    job: Optional[Job] = None
    from_state: str = ""
    to_state: str = ""
    error: str = ""
    chunks_done: int = 0
    chunks_total: int = 0
    chunks_leased: int = 0
    chunk_retries: int = 0
    rays_done: int = 0
    rays_total: int = 0
    rays_per_s: float = 0.0
    active_workers: int = 0
    eta_s: Optional[float] = None
    stage: str = ""
    stage_done: int = 0
    stage_total: int = 0
    stages: list = field(default_factory=list)

    def __str__(self):
        if self.kind == "snapshot":
            return f"{self.job.job_id}: {self.state}"
        if self.kind == "state":
            return f"{self.from_state} -> {self.to_state}" + (f": {self.error}" if self.error
                                                              else "")
        parts = [self.state]
        if self.stage:
            parts.append(self.stage)
        if self.chunks_total:
            parts.append(f"chunks {self.chunks_done}/{self.chunks_total}")
        if self.rays_total:
            parts.append(f"rays {self.rays_done}/{self.rays_total} "
                         f"({self.rays_per_s / 1e6:.2f} M/s)")
        if self.stage_total:
            parts.append(f"{self.stage_done}/{self.stage_total}")
        if self.eta_s is not None:
            parts.append(f"eta {self.eta_s:.0f} s")
        return "  ".join(parts)


class JobClient:
    """JobService over one gRPC channel. server: "host:port"; token or token_file: the bearer
    token (none: an open server on loopback, tenant "default"); tls: TLS trusting the system's
    roots; tls_ca: TLS trusting this PEM file's CA certificate(s); tls_server_name: the name
    on the server's certificate when it is not the host of `server` (a port-forward);
    timeout_s: the deadline of each unary call and of each fetched file's stream."""

    def __init__(self, server=None, token=None, token_file=None, tls=False, tls_ca=None,
                 tls_server_name=None, timeout_s=60.0):
        self.server = server or os.environ.get("CARVEMAP_SERVER") or DEFAULT_SERVER
        if token is None:
            token_file = token_file or os.environ.get("CARVEMAP_TOKEN_FILE")
            if token_file:
                with open(token_file) as f:
                    token = f.read().strip()
            else:
                token = os.environ.get("CARVEMAP_TOKEN")
        self._metadata = [("authorization", f"Bearer {token}")] if token else []
        tls_ca = tls_ca or os.environ.get("CARVEMAP_TLS_CA")
        tls_server_name = tls_server_name or os.environ.get("CARVEMAP_TLS_SERVER_NAME")
        options = []
        if tls_server_name:
            options.append(("grpc.ssl_target_name_override", tls_server_name))
        if tls or tls_ca:
            roots = None
            if tls_ca:
                with open(tls_ca, "rb") as f:
                    roots = f.read()
            self._channel = grpc.secure_channel(
                self.server, grpc.ssl_channel_credentials(root_certificates=roots), options)
        else:
            self._channel = grpc.insecure_channel(self.server, options)
        self._stub = pb_grpc.JobServiceStub(self._channel)
        self.timeout_s = timeout_s

    def close(self):
        self._channel.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def _call(self, method, request, timeout=None):
        try:
            return method(request, metadata=self._metadata,
                          timeout=self.timeout_s if timeout is None else timeout)
        except grpc.RpcError as e:
            raise JobError.from_rpc(e) from None

    # -- jobs
    def submit(self, input_path=None, output_name="", idempotency_key="", resolution_m=0.0,
               object_resolution_m=0.0, floorplan_method="", trimmed_points=False,
               min_object_volume_m3=0.0, evaluation="", north="", location="",
               survey_date="", method="", workers_hint=0, upload_id=""):
        """Submits a job on `input_path`, a scan.h5 relative to your tenant's folder on the
        server, or on a finished upload (`upload_id`, from upload()); returns the Job (QUEUED).
        0 and "" mean the server's default; the resolved values come back in Job.params.
        evaluation "fast" | "exact"; method "probabilistic" | "voxel"; the rest as in
        jobs.proto JobParams and `carvemap submit --help`."""
        if (input_path is None) == (not upload_id):
            raise ValueError("submit: give input_path or upload_id, not both")
        req = pb.SubmitJobRequest(output_name=output_name, idempotency_key=idempotency_key)
        if upload_id:
            req.upload_id = upload_id
        else:
            req.input_path = os.fspath(input_path)
        p = req.params
        p.resolution_m = resolution_m
        p.object_resolution_m = object_resolution_m
        p.floorplan_method = floorplan_method
        p.trimmed_points = trimmed_points
        p.min_object_volume_m3 = min_object_volume_m3
        p.north = north
        p.location = location
        p.survey_date = survey_date
        p.workers_hint = workers_hint
        if evaluation:
            p.evaluation = _enum(pb.CarveEvaluation, "CARVE_EVALUATION_", evaluation,
                                 "evaluation")
        if method:
            p.method = _enum(pb.CarveMethod, "CARVE_METHOD_", method, "method")
        r = self._call(self._stub.SubmitJob, req)
        return Job.from_proto(r.job, r.deduplicated)

    def get(self, job_id):
        return Job.from_proto(self._call(self._stub.GetJob, pb.GetJobRequest(job_id=job_id)))

    def list(self, state=None, page_size=0, limit=None):
        """The tenant's jobs, newest first (every page, up to `limit`); state: only jobs in
        that state ("SUCCEEDED", ...)."""
        req = pb.ListJobsRequest(page_size=page_size,
                                 state_filter=_state_number(state) if state else 0)
        jobs = []
        while True:
            r = self._call(self._stub.ListJobs, req)
            jobs.extend(Job.from_proto(j) for j in r.jobs)
            if limit is not None and len(jobs) >= limit:
                return jobs[:limit]
            if not r.next_page_token:
                return jobs
            req.page_token = r.next_page_token

    def cancel(self, job_id, reason=""):
        """Cancels a job (idempotent on a cancelled one; a finished one is
        FAILED_PRECONDITION); returns it."""
        r = self._call(self._stub.CancelJob, pb.CancelJobRequest(job_id=job_id, reason=reason))
        return Job.from_proto(r.job)

    def watch(self, job_id, min_interval_s=1.0, timeout_s=None):
        """Yields the job's Events: a snapshot, then state changes and progress (at most every
        min_interval_s), until the job is SUCCEEDED, FAILED or CANCELLED. Leaving the loop
        early stops the stream, not the job."""
        try:
            stream = self._stub.WatchJob(
                pb.WatchJobRequest(job_id=job_id, min_interval_s=min_interval_s),
                metadata=self._metadata, timeout=timeout_s)
        except grpc.RpcError as e:
            raise JobError.from_rpc(e) from None
        state = "UNSPECIFIED"
        try:
            for e in stream:
                kind = e.WhichOneof("event")
                if kind == "snapshot":
                    job = Job.from_proto(e.snapshot)
                    state = job.state
                    c = e.snapshot.progress
                    yield Event("snapshot", e.sequence, e.time_unix_ms, state, job=job,
                                chunks_done=c.chunks_done, chunks_total=c.chunks_total,
                                chunks_leased=c.chunks_leased, chunk_retries=c.chunk_retries)
                elif kind == "state_change":
                    sc = e.state_change
                    state = _state(sc.to_state)
                    yield Event("state", e.sequence, e.time_unix_ms, state,
                                from_state=_state(sc.from_state), to_state=state,
                                error=sc.error)
                elif kind == "progress":
                    p = e.progress
                    stages = [Stage(s.stage, s.elapsed_s, s.finished) for s in p.stages]
                    running = [s.name for s in stages if not s.finished]
                    yield Event("progress", e.sequence, e.time_unix_ms, state,
                                chunks_done=p.chunks.chunks_done,
                                chunks_total=p.chunks.chunks_total,
                                chunks_leased=p.chunks.chunks_leased,
                                chunk_retries=p.chunks.chunk_retries, rays_done=p.rays_done,
                                rays_total=p.rays_total, rays_per_s=p.rays_per_s,
                                active_workers=p.active_workers,
                                eta_s=p.eta_s if p.eta_s >= 0 else None,
                                stage=running[-1] if running else "",
                                stage_done=p.stage_done, stage_total=p.stage_total,
                                stages=stages)
        except grpc.RpcError as e:
            raise JobError.from_rpc(e) from None
        finally:
            stream.cancel()

    def wait(self, job_id, on_event=None, min_interval_s=1.0, timeout_s=None):
        """Watches the job to its end, calling on_event(event) for each event; returns the
        finished Job."""
        for event in self.watch(job_id, min_interval_s, timeout_s):
            if on_event is not None:
                on_event(event)
        return self.get(job_id)

    # -- uploads
    def upload(self, path, name="", chunk_size_bytes=256 << 10, max_attempts=8,
               on_progress=None):
        """Uploads the local file `path` into your tenant's uploads/ folder on the server
        (as `name`, default its own name) and returns the finished Upload; submit it with
        submit(upload_id=...). Resumable: after a broken connection it goes on from the bytes
        the server holds, also when called again for the same file. on_progress(received,
        size) is called after every message. Gives up after `max_attempts` streams in a row
        that moved no byte. JobError: ALREADY_EXISTS (the name is taken by another file),
        RESOURCE_EXHAUSTED (quota, disk), DATA_LOSS (the file changed while it was sent)."""
        path = os.fspath(path)
        digest = _sha256_of(path)
        start = pb.StartUploadRequest(name=name or os.path.basename(path),
                                      size_bytes=os.path.getsize(path),
                                      sha256_hex=digest.hexdigest())
        # Until the server has answered once, an error is the answer (a wrong address, a
        # server that is down); after that, wait_for_ready rides out a reconnect.
        idle, wait_s, answered = 0, 0.5, False
        while True:
            begin, sent, short = None, [0], [False]
            try:
                try:
                    state = self._stub.StartUpload(start, metadata=self._metadata,
                                                   timeout=self.timeout_s,
                                                   wait_for_ready=answered)
                except grpc.RpcError as e:
                    if not answered:
                        raise JobError.from_rpc(e) from None
                    raise
                answered = True
                if on_progress:
                    on_progress(state.received_bytes, state.size_bytes)
                if state.complete:
                    return Upload.from_proto(state)
                begin = sent[0] = state.received_bytes

                def messages():
                    # At least one message, empty when the server holds every byte already
                    # (it stopped before it could check and place the file).
                    with open(path, "rb") as f:
                        f.seek(begin)
                        first = True
                        while sent[0] < state.size_bytes or first:
                            first = False
                            data = f.read(chunk_size_bytes) if sent[0] < state.size_bytes else b""
                            if not data and sent[0] < state.size_bytes:
                                short[0] = True
                                return
                            yield pb.UploadScanRequest(upload_id=state.upload_id,
                                                       offset=sent[0], data=data)
                            sent[0] += len(data)
                            if on_progress:
                                on_progress(sent[0], state.size_bytes)

                result = self._stub.UploadScan(messages(), metadata=self._metadata)
                if result.complete:
                    return Upload.from_proto(result)
                error = JobError("UNAVAILABLE", "the upload stream ended early")
            except grpc.RpcError as e:
                error = JobError.from_rpc(e)
                resumable = error.code in _RESUMABLE or (
                    error.code == "FAILED_PRECONDITION" and "resume from" in error.details)
                if not resumable:
                    raise error from None
            if short[0]:
                raise JobError("DATA_LOSS", f"{path}: the file got shorter while it was sent")
            if begin is not None and sent[0] > begin:
                idle, wait_s = 0, 0.5  # it moved: the next stream is a fresh try
            idle += 1
            if idle >= max_attempts:
                raise error
            time.sleep(wait_s)
            wait_s = min(wait_s * 2, 8.0)

    # -- outputs
    def fetch_file(self, job_id, name, dest, chunk_size_bytes=0):
        """Downloads output `name` (e.g. "levels.json", "mesh/objects/3.ply") of a job to the
        file `dest`, through "<dest>.partial": a download cut short resumes from that file's
        end on the next call. The SHA-256 the server sends is checked. Returns dest."""
        dest = os.fspath(dest)
        partial = dest + ".partial"
        os.makedirs(os.path.dirname(os.path.abspath(dest)), exist_ok=True)
        offset = os.path.getsize(partial) if os.path.exists(partial) else 0
        digest = _sha256_of(partial) if offset else hashlib.sha256()
        req = pb.FetchArtifactRequest(job_id=job_id, name=name, offset=offset,
                                      chunk_size_bytes=chunk_size_bytes)
        sha, total, done = "", None, False
        try:
            with open(partial, "ab") as out:
                for c in self._stub.FetchArtifact(req, metadata=self._metadata,
                                                  timeout=self.timeout_s):
                    if c.offset != offset:
                        raise JobError("DATA_LOSS", f"{name}: a chunk at byte {c.offset}, "
                                                    f"expected {offset}")
                    out.write(c.data)
                    digest.update(c.data)
                    offset += len(c.data)
                    total = c.total_size_bytes
                    if c.last:
                        sha, done = c.sha256_hex, True
                out.flush()
                os.fsync(out.fileno())
        except grpc.RpcError as e:
            if e.code() == grpc.StatusCode.OUT_OF_RANGE and offset:
                os.remove(partial)  # the file changed under a stale partial: start again
            raise JobError.from_rpc(e) from None
        if not done or offset != total:
            raise JobError("DATA_LOSS", f"{name}: the stream ended at byte {offset} of {total}")
        if digest.hexdigest() != sha:
            os.remove(partial)
            raise JobError("DATA_LOSS", f"{name}: SHA-256 {digest.hexdigest()} differs from "
                                        f"the server's {sha}")
        os.replace(partial, dest)
        return dest

    def fetch(self, job_id, folder, names=None, chunk_size_bytes=0):
        """Downloads a finished job's outputs into `folder` (made if missing) at their
        relative paths: `names`, or job.json and every file its "outputs" lists. Returns the
        local paths."""
        folder = os.fspath(folder)
        paths = []
        if names is None:
            paths.append(self.fetch_file(job_id, "job.json", os.path.join(folder, "job.json"),
                                         chunk_size_bytes))
            with open(paths[0]) as f:
                names = [n for n in json.load(f).get("outputs", []) if n != "job.json"]
        for name in names:
            parts = name.replace("\\", "/").split("/")
            if name.startswith("/") or any(p in ("", ".", "..") for p in parts):
                raise ValueError(f"{name!r}: not a relative path inside the output folder")
            paths.append(self.fetch_file(job_id, name, os.path.join(folder, *parts),
                                         chunk_size_bytes))
        return paths

