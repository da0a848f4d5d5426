#!/usr/bin/env python3
"""A real Prometheus (Debian's `prometheus` package) scrapes a carvemap cluster during a job,
and every query of the Grafana dashboard (deploy/grafana/carvemap-dashboard.json) returns data.

A coordinator, two workers and a merge service run as separate processes, each with
--metrics-listen on a free loopback port; Prometheus scrapes the four every second from its
own scratch folder. After a job on a small simulated scan has SUCCEEDED:
- every target is up;
- each query of the dashboard, over the job's time span, gives at least one series with a
  finite value (a renamed metric or a broken query fails here, not on a user's screen);
- the workers' rays (counted as they carve) add up to the coordinator's (counted from
  completed tasks), and the merge's seconds per stage add up to no more than its merges'
  seconds.

Usage: prometheus_test.py --carvemap BIN --work DIR [--prometheus BIN] [--dashboard FILE]
"""
import argparse
import json
import math
import os
import re
import shutil
import socket
import subprocess
import sys
import time
import urllib.parse
import urllib.request

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from cluster_harness import Cluster, TestFailure, fresh_dir, log, read_text, state  # noqa: E402

ROOT = os.path.abspath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
DASHBOARD = os.path.join(ROOT, "deploy", "grafana", "carvemap-dashboard.json")
METRICS_LINE = re.compile(r"metrics on http://[^/\s]+:(\d+)/metrics")


def expect(cond, what):
    if not cond:
        raise TestFailure(what)


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def metrics_port(log_path, deadline):
    """The port a server's log says it serves /metrics on."""
    while time.monotonic() < deadline:
        m = METRICS_LINE.search(read_text(log_path)) if os.path.exists(log_path) else None
        if m:
            return int(m.group(1))
        time.sleep(0.05)
    raise TestFailure(f"{os.path.basename(log_path)}: no 'metrics on' line within the deadline")


class Prometheus:
    def __init__(self, url):
        self.url = url

    def get(self, path, **params):
        q = urllib.parse.urlencode(params)
        with urllib.request.urlopen(f"{self.url}{path}?{q}", timeout=30) as r:
            body = json.loads(r.read())
        if body.get("status") != "success":
            raise TestFailure(f"Prometheus {path} {params}: {body}")
        return body["data"]

    def query(self, expr):
        return self.get("/api/v1/query", query=expr)["result"]

    def query_range(self, expr, start, end):
        return self.get("/api/v1/query_range", query=expr, start=f"{start:.3f}",
                        end=f"{end:.3f}", step="1")["result"]

    def scalar(self, expr):
        """The one value of an instant query (NaN when it returns nothing)."""
        r = self.query(expr)
        return float(r[0]["value"][1]) if r else math.nan


def dashboard_queries(path):
    with open(path) as f:
        dash = json.load(f)
    out = []
    for panel in dash["panels"]:
        for t in panel.get("targets", []):
            out.append((panel["title"], t["expr"]))
    expect(out, f"{path}: no queries")
    return out


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True)
    p.add_argument("--prometheus", default=shutil.which("prometheus") or "prometheus")
    p.add_argument("--dashboard", default=DASHBOARD)
    args = p.parse_args()
    if not os.path.exists(args.prometheus):
        print("FAIL: no prometheus binary: install Debian's prometheus "
              "(scripts/install-deps.sh)")
        return 1
    start = time.monotonic()
    work = fresh_dir(os.path.abspath(args.work))
    data = os.path.join(work, "data")
    sim = subprocess.run([args.carvemap, "simulate", "--preset", "room", "--seed", "7",
                          "--rate-hz", "5", "--beam-step-deg", "2", "--max-duration", "20", "-q",
                          "-o", data], capture_output=True, text=True)
    if sim.returncode != 0:
        print(f"FAIL: simulate: {sim.stdout}{sim.stderr}")
        return 1
    metrics = ["--metrics-listen", "127.0.0.1:0"]
    cluster = Cluster(args.carvemap, os.path.join(work, "servers"), data,
                      os.path.join(work, "outputs"), extra_coordinator_args=metrics,
                      extra_merger_args=metrics)
    prometheus = None
    try:
        cluster.start_coordinator(port=0)
        cluster.start_worker(extra=metrics)
        cluster.start_worker(extra=metrics)
        deadline = time.monotonic() + 60
        targets = {
            "carvemap-coordinator": [metrics_port(cluster.coordinator_log, deadline)],
            "carvemap-worker": [metrics_port(p, deadline) for p in cluster.worker_logs],
            "carvemap-merger": [metrics_port(p, deadline) for p in cluster.merger_logs],
        }
        prometheus, prom = start_prometheus(args.prometheus, cluster, work, targets)
        wait_up(prom, sum(len(v) for v in targets.values()))
        t_submit = time.time()
        api = cluster.api()
        job = api.submit("scan.h5", "out")
        job = api.wait_done(job.job_id, timeout_s=240)
        expect(state(job) == "SUCCEEDED", f"job {job.job_id}: {state(job)} {job.error}")
        log(f"job {job.job_id} SUCCEEDED in {time.time() - t_submit:.1f} s")
        # A scrape of every target after the end: the job's and the merge's results are
        # counted there.
        t_done = time.time()
        wait_for(lambda: prom.scalar("min(timestamp(up))") > t_done, "a scrape after the job")
        check_dashboard(prom, args.dashboard, t_submit - 2, time.time())
        check_consistency(prom)
    except TestFailure as e:
        print(f"FAIL: {e}")
        for name, text in cluster.logs().items():
            print(f"--- {name}\n" + "\n".join(text.splitlines()[-15:]))
        plog = os.path.join(work, "prometheus.log")
        if os.path.exists(plog):
            print("--- prometheus.log\n" + "\n".join(read_text(plog).splitlines()[-15:]))
        return 1
    finally:
        cluster.stop()
        if prometheus is not None and prometheus.poll() is None:
            prometheus.terminate()
            prometheus.wait()
    log(f"prometheus: passed in {time.monotonic() - start:.1f} s")
    return 0


def start_prometheus(binary, cluster, work, targets):
    port = free_port()
    config = os.path.join(work, "prometheus.yml")
    with open(config, "w") as f:
        f.write("global:\n  scrape_interval: 1s\n  evaluation_interval: 1s\n"
                "scrape_configs:\n")
        for job, ports in targets.items():
            f.write(f"  - job_name: {job}\n    static_configs:\n      - targets: [" +
                    ", ".join(f"'127.0.0.1:{p}'" for p in ports) + "]\n")
    proc = cluster._spawn([binary, f"--config.file={config}",
                           f"--storage.tsdb.path={os.path.join(work, 'tsdb')}",
                           f"--web.listen-address=127.0.0.1:{port}"],
                          os.path.join(work, "prometheus.log"))
    prom = Prometheus(f"http://127.0.0.1:{port}")
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise TestFailure(f"prometheus exited ({proc.returncode})")
        try:
            with urllib.request.urlopen(f"{prom.url}/-/ready", timeout=2) as r:
                if r.status == 200:
                    return proc, prom
        except OSError:
            pass
        time.sleep(0.1)
    raise TestFailure("prometheus not ready within 60 s")


def wait_for(cond, what, timeout_s=30):
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if cond():
            return
        time.sleep(0.2)
    raise TestFailure(f"not seen within {timeout_s} s: {what}")


def wait_up(prom, n):
    wait_for(lambda: len([r for r in prom.query("up") if r["value"][1] == "1"]) == n,
             f"all {n} targets up")
    log(f"Prometheus scrapes {n} targets, all up")


def check_dashboard(prom, path, t0, t1):
    empty = []
    for title, expr in dashboard_queries(path):
        series = prom.query_range(expr, t0, t1)
        values = [float(v) for s in series for _, v in s["values"]]
        finite = [v for v in values if math.isfinite(v)]
        log(f"  {title}: {expr}: {len(series)} series, {len(finite)} values")
        if not finite:
            empty.append(f"{title}: {expr}")
    expect(not empty, "dashboard queries with no data:\n  " + "\n  ".join(empty))
    log(f"every query of {os.path.basename(path)} returns data")


def check_consistency(prom):
    worker_rays = prom.scalar("sum(carvemap_worker_rays_carved_total)")
    coordinator_rays = prom.scalar("sum(carvemap_rays_carved_total)")
    expect(worker_rays > 0 and worker_rays == coordinator_rays,
           f"rays: workers {worker_rays}, coordinator {coordinator_rays}")
    stages = prom.scalar("sum(carvemap_merge_stage_seconds_total)")
    merges = prom.scalar("sum(carvemap_merge_seconds_sum)")
    expect(0 < stages <= merges + 1e-6, f"merge stage seconds {stages}, merges' {merges}")
    peak = prom.scalar('max(carvemap_process_peak_resident_memory_bytes{service="merger"})')
    expect(peak > 10e6, f"merge service peak memory {peak}")
    log(f"rays: workers {worker_rays:.0f} = coordinator {coordinator_rays:.0f}; merge stages "
        f"{stages:.2f} s of {merges:.2f} s; merge service peak {peak / 2**20:.0f} MiB")


if __name__ == "__main__":
    sys.exit(main())
