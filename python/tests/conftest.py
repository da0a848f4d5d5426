"""Set-up shared by the carvemap package's tests.

The package under test is the one pip installs: python/ and proto/carvemap/v1/jobs.proto are
copied to a scratch folder (so the build leaves nothing in the source tree) and installed with
`pip install --no-build-isolation --no-index --no-deps --target`, offline, which also runs the
build step that generates the gRPC stubs; that folder then comes first on sys.path.

CARVEMAP_BIN names the carvemap binary (CTest passes $<TARGET_FILE:carvemap>; default
build/carvemap). Servers are started as `carvemap coordinator|worker|merger` processes that die
with the test (setpriv --pdeathsig), each logging to a file under the test's folder.
"""
import atexit
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time

import pytest

REPO = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".."))
CARVEMAP = os.path.abspath(os.environ.get("CARVEMAP_BIN") or
                           os.path.join(REPO, "build", "carvemap"))


def _install_package():
    scratch = tempfile.mkdtemp(prefix="carvemap-pytest-")
    atexit.register(shutil.rmtree, scratch, True)
    src = os.path.join(scratch, "src")
    shutil.copytree(os.path.join(REPO, "python"), os.path.join(src, "python"),
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__",
                                                  "tests", ".pytest_cache"))
    os.makedirs(os.path.join(src, "proto", "carvemap", "v1"))
    shutil.copy(os.path.join(REPO, "proto", "carvemap", "v1", "jobs.proto"),
                os.path.join(src, "proto", "carvemap", "v1"))
    site = os.path.join(scratch, "site")
    r = subprocess.run([sys.executable, "-m", "pip", "install", "--no-build-isolation",
                        "--no-index", "--no-deps", "--no-cache-dir", "--quiet", "--target", site,
                        os.path.join(src, "python")], capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"pip install of python/ failed:\n{r.stdout}{r.stderr}")
    sys.path.insert(0, site)
    return site


SITE = _install_package()
# The client takes these from the environment when not given: the tests give everything.
for name in ("CARVEMAP_SERVER", "CARVEMAP_TOKEN", "CARVEMAP_TOKEN_FILE", "CARVEMAP_TLS_CA",
             "CARVEMAP_TLS_SERVER_NAME"):
    os.environ.pop(name, None)


@pytest.fixture(scope="session")
def carvemap_bin():
    assert os.access(CARVEMAP, os.X_OK), f"{CARVEMAP}: no carvemap binary (set CARVEMAP_BIN)"
    return CARVEMAP


def run_carvemap(*args, check=True, timeout=120, cwd=None):
    """Runs the carvemap binary; returns the CompletedProcess (text)."""
    r = subprocess.run([CARVEMAP, *map(str, args)], capture_output=True, text=True,
                       timeout=timeout, cwd=cwd)
    if check and r.returncode != 0:
        raise AssertionError(f"carvemap {' '.join(map(str, args))} exited {r.returncode}:\n"
                             f"{r.stdout}{r.stderr}")
    return r


@pytest.fixture(scope="session")
def simulated_room(tmp_path_factory, carvemap_bin):
    """A short noisy walk through the simulator's `room` (furniture included): its folder."""
    out = tmp_path_factory.mktemp("sim")
    run_carvemap("simulate", "--preset", "room", "--seed", "5", "--rate-hz", "5",
                 "--beam-step-deg", "2", "--max-duration", "6", "-q", "-o", out)
    return out


@pytest.fixture(scope="session")
def room_outputs(tmp_path_factory, simulated_room):
    """The outputs of `carvemap run` on simulated_room: its output folder."""
    out = tmp_path_factory.mktemp("run") / "out"
    run_carvemap("run", simulated_room / "scan.h5", "-o", out, "--object-resolution",
                 "0.0625", "-q", timeout=300)
    return out


# ---- a local cluster -------------------------------------------------------------------------

def _spawn(args, log_path):
    with open(log_path, "ab") as log:
        # setpriv sets PR_SET_PDEATHSIG and execs: a test killed by its timeout leaves no server.
        return subprocess.Popen(["setpriv", "--pdeathsig", "KILL", "--"] + [str(a) for a in args],
                                stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL,
                                start_new_session=True)


def _write_private(path, text):
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(text)


def tail(path, n=25):
    try:
        with open(path, "rb") as f:
            return "\n".join(f.read().decode("utf-8", "replace").splitlines()[-n:])
    except OSError:
        return f"({path} missing)"


class LocalCluster:
    """A merge service, a coordinator (bearer tokens, one folder per tenant) and workers on
    loopback, as docs/RPC.md describes them: data/<tenant>/ holds the inputs, out/<tenant>/
    the outputs."""

    def __init__(self, work, tenants, workers=2, coordinator_args=(), merge=True):
        self.work = str(work)
        self.data_root = os.path.join(self.work, "data")
        self.output_root = os.path.join(self.work, "out")
        self.tenants = tenants
        self.procs = []
        self.logs = []
        for tenant in tenants:
            os.makedirs(os.path.join(self.data_root, tenant), exist_ok=True)
        os.makedirs(self.output_root, exist_ok=True)
        self.tokens_file = os.path.join(self.work, "tokens")
        _write_private(self.tokens_file, "".join(f"{tok} {tenant}\n"
                                                 for tenant, tok in tenants.items()))
        self.secret_file = os.path.join(self.work, "cluster-secret")
        _write_private(self.secret_file, os.urandom(32).hex() + "\n")
        try:
            merge_args = ["--no-merge"]
            if merge:
                merger = self._start("merger", ["merger", "--listen", "127.0.0.1:0",
                                                "--cluster-secret-file", self.secret_file])
                merge_args = ["--merge-server", merger]
            self.address = self._start("coordinator", [
                "coordinator", "--listen", "127.0.0.1:0", "--tokens", self.tokens_file,
                "--cluster-secret-file", self.secret_file, "--data-root", self.data_root,
                "--output-root", self.output_root, "--work-dir", os.path.join(self.work, "store"),
                "--heartbeat-interval-s", "0.5", "--worker-timeout-s", "3"] + merge_args +
                list(coordinator_args))
            for k in range(workers):
                log = os.path.join(self.work, f"worker-{k + 1}.log")
                self.procs.append(_spawn([CARVEMAP, "worker", "--coordinator", self.address,
                                          "--cluster-secret-file", self.secret_file,
                                          "--listen", "127.0.0.1:0"], log))
                self.logs.append(log)
        except BaseException:
            self.stop()
            raise

    def _start(self, name, args):
        """Starts a server that writes its host:port to --port-file; returns it."""
        port_file = os.path.join(self.work, f"{name}.port")
        log = os.path.join(self.work, f"{name}.log")
        proc = _spawn([CARVEMAP] + args + ["--port-file", port_file], log)
        self.procs.append(proc)
        self.logs.append(log)
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline:
            if os.path.exists(port_file):
                with open(port_file) as f:
                    address = f.read().strip()
                if address:
                    return address
            if proc.poll() is not None:
                raise RuntimeError(f"{name} exited at start ({proc.returncode}):\n{tail(log)}")
            time.sleep(0.02)
        raise RuntimeError(f"{name} did not start within 60 s:\n{tail(log)}")

    def output_dir(self, tenant, output_name):
        return os.path.join(self.output_root, tenant, output_name)

    def stop(self):
        """Workers first, then the coordinator, then the merge service (as `carvemap run`)."""
        for p in reversed(self.procs):
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout=15)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def log_tails(self):
        return "\n".join(f"--- {os.path.basename(p)}\n{tail(p)}" for p in self.logs)
