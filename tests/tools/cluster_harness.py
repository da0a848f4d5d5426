"""A local carvemap cluster for the fault, recovery, load and client tests:
a coordinator, workers and merge services as separate `carvemap` processes (docs/DESIGN.md §1, §9),
each with its own log, and a gRPC
client (Python stubs generated from proto/ at test time with grpc_tools.protoc) to submit and
watch jobs. Nothing here knows carvemap's C++ code: only the documented CLI flags (docs/RPC.md,
docs/CLUSTER.md), the wire API (proto/) and the job store's schema (docs/JOB_STORE.md).

Children die with the test (setpriv --pdeathsig, not a preexec_fn, which is unsafe with the
threads some tests run), so a test killed by ctest's timeout leaves no server behind. Every
wait polls with a deadline; nothing sleeps a fixed time to "let things settle".
"""
import atexit
import hashlib
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time

PROTO_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "proto")

JOB_STATES = ["UNSPECIFIED", "QUEUED", "INGESTING", "CARVING", "MERGING", "SUCCEEDED", "FAILED",
              "CANCELLED"]
TERMINAL = {"SUCCEEDED", "FAILED", "CANCELLED"}
SKIP = 77  # ctest SKIP_RETURN_CODE of the tests that need the kernel's permission


class TestFailure(Exception):
    pass


def log(msg):
    print(msg, flush=True)


# ---- stubs -----------------------------------------------------------------------------------

_stubs = None


def stubs():
    """(jobs_pb2, jobs_pb2_grpc, grpc), generated from proto/ into a temporary folder once."""
    global _stubs
    if _stubs is not None:
        return _stubs
    try:
        import grpc  # noqa: F401  (Debian: python3-grpcio)
        from grpc_tools import protoc  # Debian: python3-grpc-tools
    except ImportError as e:
        raise TestFailure(f"{e}: install python3-grpcio and python3-grpc-tools "
                          "(scripts/install-deps.sh)")
    out = tempfile.mkdtemp(prefix="carvemap-stubs-")
    atexit.register(shutil.rmtree, out, True)
    proto = os.path.abspath(PROTO_DIR)
    files = [os.path.join(proto, f"carvemap/v1/{name}.proto")
             for name in ("jobs", "carve", "merge")]
    rc = protoc.main(["protoc", f"-I{proto}", f"--python_out={out}", f"--grpc_python_out={out}"]
                     + files)
    if rc != 0:
        raise TestFailure(f"grpc_tools.protoc failed on {files} ({rc})")
    sys.path.insert(0, out)
    from carvemap.v1 import jobs_pb2, jobs_pb2_grpc  # noqa: E402
    _stubs = (jobs_pb2, jobs_pb2_grpc, grpc)
    return _stubs


def merge_stubs():
    """(merge_pb2, merge_pb2_grpc): the internal MergeService (proto/carvemap/v1/merge.proto)."""
    stubs()
    from carvemap.v1 import merge_pb2, merge_pb2_grpc  # noqa: E402
    return merge_pb2, merge_pb2_grpc


class JobApi:
    """JobService with a bearer token; reconnects with a fresh channel on demand."""

    def __init__(self, address, token):
        self.address, self.token = address, token
        self.channel = None
        self.reconnect()

    def reconnect(self):
        pb, pb_grpc, grpc = stubs()
        if self.channel is not None:
            self.channel.close()
        # Short reconnect backoff: the coordinator comes back within a second in the restart
        # tests, and gRPC's default would wait up to 2 minutes between attempts.
        self.channel = grpc.insecure_channel(self.address, options=[
            ("grpc.initial_reconnect_backoff_ms", 100), ("grpc.min_reconnect_backoff_ms", 100),
            ("grpc.max_reconnect_backoff_ms", 1000)])
        self.stub = pb_grpc.JobServiceStub(self.channel)

    def md(self):
        return [("authorization", f"Bearer {self.token}")]

    def submit(self, input_path, output_name="", key="", resolution=0.0, object_resolution=0.0):
        pb = stubs()[0]
        req = pb.SubmitJobRequest(input_path=input_path, output_name=output_name,
                                  idempotency_key=key)
        req.params.resolution_m = resolution
        req.params.object_resolution_m = object_resolution
        return self.stub.SubmitJob(req, metadata=self.md(), timeout=30).job

    def get(self, job_id, timeout=10):
        pb = stubs()[0]
        return self.stub.GetJob(pb.GetJobRequest(job_id=job_id), metadata=self.md(),
                                timeout=timeout)

    def try_get(self, job_id):
        """The job, or None while the coordinator cannot be reached."""
        grpc = stubs()[2]
        try:
            return self.get(job_id, timeout=5)
        except grpc.RpcError as e:
            if e.code() in (grpc.StatusCode.UNAVAILABLE, grpc.StatusCode.DEADLINE_EXCEEDED):
                return None
            raise

    def wait(self, job_id, until, timeout_s, what="", poll_s=0.02):
        """Polls GetJob until until(job) is true (or the job ends); returns the job."""
        deadline = time.monotonic() + timeout_s
        job = None
        while time.monotonic() < deadline:
            job = self.try_get(job_id)
            if job is not None and (until(job) or state(job) in TERMINAL):
                return job
            time.sleep(poll_s)
        raise TestFailure(f"job {job_id}: not {what or 'there'} within {timeout_s} s (last: "
                          f"{state(job) if job else 'unreachable'})")

    def wait_done(self, job_id, timeout_s=600):
        return self.wait(job_id, lambda j: False, timeout_s, "finished", poll_s=0.1)


def state(job):
    return JOB_STATES[job.state]


# ---- processes -------------------------------------------------------------------------------

def random_secret():
    return os.urandom(32).hex()


def write_private(path, text):
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)


class Cluster:
    """A coordinator, workers and merge services over one work dir (job store, partial sums, logs,
    secrets).

    tenants: {tenant: token}; with one tenant the folders are shared (--shared-dirs) unless
    shared_dirs=False. mergers: how many merge services (`carvemap merger`) start_coordinator
    starts first, if none runs yet; the coordinator gets all their addresses (--merge-server).
    """

    def __init__(self, carvemap, work, data_root, output_root, tenants=None, shared_dirs=None,
                 listen_host="127.0.0.1", heartbeat_s=0.5, worker_timeout_s=3.0,
                 max_attempts=5, log_format=None, extra_coordinator_args=(), mergers=1,
                 extra_merger_args=()):
        self.carvemap = carvemap
        self.work = os.path.abspath(work)
        self.data_root = os.path.abspath(data_root)
        self.output_root = os.path.abspath(output_root)
        os.makedirs(self.work, exist_ok=True)
        os.makedirs(self.output_root, exist_ok=True)
        self.tenants = tenants or {"local": random_secret()}
        self.shared_dirs = len(self.tenants) == 1 if shared_dirs is None else shared_dirs
        self.listen_host = listen_host
        self.heartbeat_s, self.worker_timeout_s = heartbeat_s, worker_timeout_s
        self.max_attempts = max_attempts
        self.log_format = log_format
        self.extra_coordinator_args = list(extra_coordinator_args)
        self.extra_merger_args = list(extra_merger_args)
        self.tokens_file = os.path.join(self.work, "tokens")
        self.secret_file = os.path.join(self.work, "cluster-secret")
        write_private(self.tokens_file,
                      "".join(f"{tok} {tenant}\n" for tenant, tok in self.tenants.items()))
        write_private(self.secret_file, random_secret() + "\n")
        self.coordinator = None
        self.coordinator_starts = 0
        self.port = 0
        self.workers = []  # Popen, in start order (worker-1 is workers[0])
        self.worker_logs = []
        self.initial_mergers = mergers
        self.mergers = []  # Popen of merge service k (merger-k is mergers[k - 1]), latest start
        self.merger_ports = []
        self.merger_logs = []  # every log, restarts included (merger-2.log, merger-2.2.log)

    # -- coordinator
    def start_coordinator(self, port=None):
        """Starts (or restarts, on the same port) the coordinator; returns host:port."""
        port_file = os.path.join(self.work, "port")
        if os.path.exists(port_file):
            os.remove(port_file)
        self.coordinator_starts += 1
        log_path = os.path.join(self.work, f"coordinator-{self.coordinator_starts}.log")
        while len(self.mergers) < self.initial_mergers:
            self.start_merger()
        merge = (["--merge-server", ",".join(self.merger_addresses())] if self.mergers
                 else ["--no-merge"])
        args = [self.carvemap, "coordinator", "--listen",
                f"{self.listen_host}:{port if port is not None else self.port}",
                "--port-file", port_file, "--tokens", self.tokens_file,
                "--cluster-secret-file", self.secret_file,
                "--data-root", self.data_root, "--output-root", self.output_root,
                "--work-dir", self.work,
                "--heartbeat-interval-s", str(self.heartbeat_s),
                "--worker-timeout-s", str(self.worker_timeout_s),
                "--max-attempts", str(self.max_attempts)] + merge + self.extra_coordinator_args
        if self.shared_dirs:
            args.append("--shared-dirs")
        if self.log_format:
            args += ["--log-format", self.log_format]
        self.coordinator = self._spawn(args, log_path)
        self.coordinator_log = log_path
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if os.path.exists(port_file):
                with open(port_file) as f:
                    address = f.read().strip()
                if address:
                    self.port = int(address.rsplit(":", 1)[1])
                    return self.address()
            if self.coordinator.poll() is not None:
                raise TestFailure(f"coordinator exited during start-up ({self.coordinator.returncode}):"
                                  f"\n{tail(log_path)}")
            time.sleep(0.02)
        raise TestFailure(f"coordinator did not start within 60 s:\n{tail(log_path)}")

    def address(self, host=None):
        host = host or ("127.0.0.1" if self.listen_host in ("0.0.0.0", "127.0.0.1")
                        else self.listen_host)
        return f"{host}:{self.port}"

    def kill_coordinator(self):
        """SIGKILL: no shutdown, no flush; what a crash or an OOM kill does."""
        self.coordinator.send_signal(signal.SIGKILL)
        self.coordinator.wait()

    def api(self, tenant=None):
        tenant = tenant or next(iter(self.tenants))
        return JobApi(self.address(), self.tenants[tenant])

    # -- merge services
    def start_merger(self, n=None):
        """Starts merge service n (1-based; default: a new one) and returns host:port; an
        existing n is started again on its old port, as a restarted pod behind its Service."""
        if n is None:
            self.mergers.append(None)
            self.merger_ports.append(0)
            n = len(self.mergers)
        starts = sum(1 for p in self.merger_logs if os.path.basename(p).startswith(f"merger-{n}."))
        name = f"merger-{n}.log" if starts == 0 else f"merger-{n}.{starts + 1}.log"
        log_path = os.path.join(self.work, name)
        port_file = os.path.join(self.work, f"merger-{n}.port")
        if os.path.exists(port_file):
            os.remove(port_file)
        args = [self.carvemap, "merger", "--listen", f"127.0.0.1:{self.merger_ports[n - 1]}",
                "--port-file", port_file, "--cluster-secret-file", self.secret_file]
        args += self.extra_merger_args
        if self.log_format:
            args += ["--log-format", self.log_format]
        proc = self._spawn(args, log_path)
        self.mergers[n - 1] = proc
        self.merger_logs.append(log_path)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if os.path.exists(port_file):
                with open(port_file) as f:
                    address = f.read().strip()
                if address:
                    self.merger_ports[n - 1] = int(address.rsplit(":", 1)[1])
                    return address
            if proc.poll() is not None:
                raise TestFailure(f"merge service {n} exited during start-up ({proc.returncode}):"
                                  f"\n{tail(log_path)}")
            time.sleep(0.02)
        raise TestFailure(f"merge service {n} did not start within 60 s:\n{tail(log_path)}")

    def merger_addresses(self):
        return [f"127.0.0.1:{port}" for port in self.merger_ports]

    def kill_merger(self, n):
        """SIGKILL merge service n (1-based), mid-merge or not."""
        p = self.mergers[n - 1]
        p.send_signal(signal.SIGKILL)
        p.wait()

    def merger_serving(self, job_id):
        """Numbers of the merge services whose latest log says they started job_id's merge."""
        serving = []
        for n in range(1, len(self.mergers) + 1):
            logs = [p for p in self.merger_logs if os.path.basename(p).startswith(f"merger-{n}.")]
            if logs and f"job {job_id}: merge started" in read_text(logs[-1]):
                serving.append(n)
        return serving

    # -- workers
    def start_worker(self, prefix=(), coordinator_host=None, extra=()):
        """A worker, optionally run through `prefix` (e.g. ip netns exec NS)."""
        n = len(self.workers) + 1
        log_path = os.path.join(self.work, f"worker-{n}.log")
        args = list(prefix) + [self.carvemap, "worker", "--coordinator",
                               self.address(coordinator_host), "--cluster-secret-file",
                               self.secret_file, "--listen", "127.0.0.1:0"] + list(extra)
        if self.log_format:
            args += ["--log-format", self.log_format]
        self.workers.append(self._spawn(args, log_path))
        self.worker_logs.append(log_path)
        return n

    def kill_worker(self, n):
        p = self.workers[n - 1]
        p.send_signal(signal.SIGKILL)
        p.wait()

    # -- all
    def _spawn(self, args, log_path):
        out = open(log_path, "ab")
        try:
            # util-linux's setpriv sets PR_SET_PDEATHSIG and execs: the pid is the server's.
            return subprocess.Popen(["setpriv", "--pdeathsig", "KILL", "--"] + args, stdout=out,
                                    stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                    start_new_session=True)
        finally:
            out.close()

    def stop(self):
        """Workers first (SIGTERM: each finishes and reports the chunk in hand), then the
        coordinator, then the merge services, as `carvemap run` does: a tile a worker finishes
        after its job failed is then still reported, and removed by the coordinator, instead
        of left behind."""
        for group in ([p for p in self.workers if p is not None], [self.coordinator],
                      [p for p in self.mergers if p is not None]):
            group = [p for p in group if p is not None]
            for p in group:
                if p.poll() is None:
                    p.send_signal(signal.SIGTERM)
            deadline = time.monotonic() + 15
            for p in group:
                try:
                    p.wait(timeout=max(0.1, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    p.send_signal(signal.SIGKILL)
                    p.wait()

    def logs(self):
        """Every log's text, coordinator(s) first, then workers, then merge services."""
        paths = [os.path.join(self.work, f"coordinator-{i}.log")
                 for i in range(1, self.coordinator_starts + 1)] + self.worker_logs + \
            self.merger_logs
        return {os.path.basename(p): read_text(p) for p in paths if os.path.exists(p)}

    def store_job_state(self, job_id):
        """The job's state number in the job store (docs/JOB_STORE.md), read-only."""
        db = sqlite3.connect(f"file:{os.path.join(self.work, 'jobs.db')}?mode=ro", uri=True,
                             timeout=10)
        try:
            row = db.execute("SELECT state FROM jobs WHERE id = ?", (job_id,)).fetchone()
        finally:
            db.close()
        return row[0] if row else None

    def store_chunks(self, job_id):
        """{(x, y, z): row} from the job store, read-only (docs/JOB_STORE.md); row is a dict of
        the chunks table's columns, state 1 QUEUED, 2 LEASED, 3 DONE."""
        db = sqlite3.connect(f"file:{os.path.join(self.work, 'jobs.db')}?mode=ro", uri=True,
                             timeout=10)
        db.row_factory = sqlite3.Row
        try:
            rows = db.execute("SELECT * FROM chunks WHERE job_id = ?", (job_id,)).fetchall()
        finally:
            db.close()
        return {(r["x"], r["y"], r["z"]): dict(r) for r in rows}


def read_text(path):
    with open(path, "rb") as f:
        return f.read().decode("utf-8", "replace")


def tail(path, n=30):
    try:
        return "\n".join(read_text(path).splitlines()[-n:])
    except OSError:
        return f"({path} missing)"


# ---- outputs ---------------------------------------------------------------------------------

# What a job writes that depends on the moment it ran (timings), not on the data: job.json,
# and the report's copy of it.
VOLATILE = {"job.json", "report/data.js"}


def output_files(out_dir):
    """{relative path: sha256} of every file under out_dir but VOLATILE's and hidden folders."""
    files = {}
    for root, dirs, names in os.walk(out_dir):
        dirs[:] = [d for d in dirs if not d.startswith(".")]
        for name in names:
            rel = os.path.relpath(os.path.join(root, name), out_dir)
            if rel in VOLATILE:
                continue
            files[rel] = sha256_file(os.path.join(root, name))
    return files


def sha256_file(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def compare_outputs(reference, got):
    """[] when `got` has exactly the reference's files with the same bytes, else the differences."""
    problems = []
    for rel in sorted(set(reference) | set(got)):
        if rel not in got:
            problems.append(f"missing {rel}")
        elif rel not in reference:
            problems.append(f"extra {rel}")
        elif reference[rel] != got[rel]:
            problems.append(f"differs {rel}")
    return problems


def summarize(files):
    tiles = sum(1 for f in files if f.startswith("tiles/"))
    objects = sum(1 for f in files if f.startswith("object_tiles/"))
    meshes = sum(1 for f in files if f.endswith(".ply"))
    return f"{tiles} tiles, {objects} object tiles, {meshes} meshes, {len(files)} files"


def proc_status(pid):
    """/proc/<pid>/status as {field: text}, e.g. {"VmRSS": "40724 kB", "Threads": "17"}."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, value = line.partition(":")
            out[key] = value.strip()
    return out


def fresh_dir(path):
    shutil.rmtree(path, ignore_errors=True)
    os.makedirs(path)
    return path
