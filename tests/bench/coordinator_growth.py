#!/usr/bin/env python3
"""What a long-running coordinator keeps per job: N small jobs one after another on a local
cluster (one coordinator, one worker, one merge service; tests/tools/cluster_harness.py), the
coordinator's VmRSS and VmSize (/proc/<pid>/status) after every `--every` jobs. For
docs/BENCHMARKS.md; not run by ctest (a few minutes).

    /usr/bin/python3 tests/bench/coordinator_growth.py --carvemap build/carvemap --work /tmp/cg --jobs 60
"""
import argparse
import os
import subprocess
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "tools"))
from cluster_harness import (Cluster, TestFailure, fresh_dir, log, proc_status,  # noqa: E402
                             state)


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--carvemap", required=True)
    p.add_argument("--work", required=True, help="emptied first")
    p.add_argument("--jobs", type=int, default=60)
    p.add_argument("--every", type=int, default=10)
    a = p.parse_args()
    carvemap = os.path.abspath(a.carvemap)
    fresh_dir(a.work)
    data = os.path.join(a.work, "data")
    sim = subprocess.run([carvemap, "simulate", "--preset", "room", "--seed", "1", "--rate-hz",
                          "5", "--beam-step-deg", "2", "--max-duration", "4", "-q", "-o",
                          os.path.join(data, "room")], capture_output=True, text=True)
    if sim.returncode != 0:
        raise TestFailure(f"simulate: {sim.stdout}{sim.stderr}")
    cluster = Cluster(carvemap, os.path.join(a.work, "servers"), data,
                      os.path.join(a.work, "outputs"))
    try:
        cluster.start_coordinator()
        cluster.start_worker()
        api = cluster.api()
        pid = cluster.coordinator.pid
        log(f"jobs  VmRSS_KiB  VmSize_KiB")
        for n in range(1, a.jobs + 1):
            job = api.wait_done(api.submit("room/scan.h5", output_name=f"j{n}").job_id)
            if state(job) != "SUCCEEDED":
                raise TestFailure(f"job {n}: {state(job)} {job.error}")
            if n == 1 or n % a.every == 0:
                s = {k: int(v.split()[0]) for k, v in proc_status(pid).items()
                     if k in ("VmRSS", "VmSize")}
                log(f"{n:4d}  {s['VmRSS']:9d}  {s['VmSize']:10d}")
    finally:
        cluster.stop()


if __name__ == "__main__":
    try:
        main()
    except TestFailure as e:
        print(f"FAILED: {e}", file=sys.stderr)
        sys.exit(1)
