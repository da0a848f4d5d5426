#!/usr/bin/env python3
"""The order "data durable -> name in place -> job marked done", checked on a real job's system
calls (docs/JOB_STORE.md, "Durability").

Runs `carvemap run` on a small scan under `strace -f` (every process: coordinator, workers,
merge service) and checks, in each process's own order of calls:
  - every rename onto a job file (tiles, partial sums, outputs, job.json) is preceded by an
    fsync of the file under its temporary name, and followed by an fsync of the folder it went
    into, before that process renames anything else;
  - job.json, the file that says a job is complete, is the merge's last rename into OUT, and
    is durable before the job store's last commit (the job marked SUCCEEDED);
  - the run wrote tiles, partial sums and outputs (so the checks above had something to check).
Fails on the first violation, printing the calls around it.

Usage: durability_trace.py CARVEMAP WORKDIR [--selftest]
--selftest first checks that the checker rejects traces with each rule broken.
"""
import os
import re
import shutil
import subprocess
import sys

CALL = re.compile(r'^(\d+)\s+(fsync|fdatasync|rename|renameat|renameat2)\((.*)\)\s+=\s+(-?\d+)')
FD = re.compile(r'^\d+<(.*)>$')
STR = re.compile(r'"((?:[^"\\]|\\.)*)"')


# What a process writes at each start for the others to find (the port it listens on): no one
# trusts it after a crash, the next start rewrites it.
RUNTIME_FILES = {'port', 'merger-port'}


UNFINISHED = re.compile(r'^(\d+)\s+(.*) <unfinished \.\.\.>$')
RESUMED = re.compile(r'^(\d+)\s+<\.\.\. \w+ resumed>(.*)$')


def joined(lines):
    """The trace's lines with each call that strace split in two (another thread's call came
    between its start and its end: `<unfinished ...>`, then `<... NAME resumed>`) put back
    together as one line."""
    started = {}
    for line in lines:
        line = line.strip()
        m = UNFINISHED.match(line)
        if m:
            started[m.group(1)] = m.group(2)
            continue
        m = RESUMED.match(line)
        if m:
            head = started.pop(m.group(1), None)
            if head is not None:
                yield f'{m.group(1)} {head}{m.group(2)}'
            continue
        yield line


def parse(lines):
    """Yields (pid, kind, args) for each completed, successful call: kind 'sync' with the synced
    path, or 'rename' with (source, destination)."""
    for line in joined(lines):
        m = CALL.match(line)
        if not m or int(m.group(4)) != 0:
            continue
        pid, name, args = int(m.group(1)), m.group(2), m.group(3)
        if name in ('fsync', 'fdatasync'):
            fd = FD.match(args.strip())
            if fd:
                yield pid, 'sync', os.path.normpath(fd.group(1))
        else:
            paths = STR.findall(args)
            if len(paths) >= 2:
                yield pid, 'rename', (paths[0], paths[1])


def absolute(path, cwd):
    return os.path.normpath(path if os.path.isabs(path) else os.path.join(cwd, path))


def check(lines, cwd, out_dir):
    """Returns (list of problems, number of renames into out_dir checked)."""
    problems = []
    calls = list(parse(lines))
    # One trace file for every process: its order is the order strace saw the calls in, which
    # follows cause and effect across processes (a reply is sent after the calls before it).
    job_json = os.path.join(out_dir, 'job.json')
    renamed_at = [i for i, (_, k, a) in enumerate(calls)
                  if k == 'rename' and absolute(a[1], cwd) == job_json]
    store_syncs = [i for i, (_, k, a) in enumerate(calls)
                   if k == 'sync' and os.path.basename(a) in ('jobs.db', 'jobs.db-wal')]
    if renamed_at and store_syncs and store_syncs[-1] < renamed_at[-1]:
        problems.append('the job store committed for the last time before job.json was in place')
    if not store_syncs:
        problems.append('no fsync of the job store (jobs.db) seen')
    by_pid = {}
    for pid, kind, arg in calls:
        by_pid.setdefault(pid, []).append((kind, arg))
    checked = 0
    last_into_out = {}
    for pid, seq in by_pid.items():
        for i, (kind, arg) in enumerate(seq):
            if kind != 'rename':
                continue
            src, dst = absolute(arg[0], cwd), absolute(arg[1], cwd)
            if not dst.startswith(out_dir + os.sep):
                continue  # the coordinator's own files (its port file), the test's scratch
            if os.path.isdir(dst):
                continue  # a folder swapped into place: its files were checked one by one
            if os.path.basename(dst) in RUNTIME_FILES:
                continue
            checked += 1
            synced = any(k == 'sync' and a == src for k, a in seq[:i])
            if not synced:
                problems.append(f'pid {pid}: {src} renamed to {dst} with no fsync of it first')
            folder = os.path.dirname(dst)
            after_ok = False
            for k, a in seq[i + 1:]:
                if k == 'sync' and a == folder:
                    after_ok = True
                    break
                if k == 'rename':
                    break
            if not after_ok:
                problems.append(f'pid {pid}: {dst} renamed into {folder} with no fsync of the '
                                'folder before the next rename')
            if os.path.dirname(dst) == out_dir:
                last_into_out[pid] = dst
    if job_json not in last_into_out.values():
        problems.append(f'job.json was not the last file renamed into {out_dir} '
                        f'(last: {sorted(last_into_out.values())})')
    return problems, checked


def selftest():
    out = '/o'
    good = [
        '10 fsync(3</o/tiles/a.h5.partial>) = 0',
        '10 rename("/o/tiles/a.h5.partial", "/o/tiles/a.h5") = 0',
        '10 fsync(3</o/tiles>) = 0',
        '11 fsync(4</o/x.ply.partial>) = 0',
        '11 renameat2(AT_FDCWD, "/o/x.ply.partial", AT_FDCWD, "/o/x.ply", 0) = 0',
        '11 fsync(4</o>) = 0',
        '11 fsync(4</o/job.json.partial>) = 0',
        '11 rename("/o/job.json.partial", "/o/job.json") = 0',
        '11 fsync(4</o>) = 0',
        '12 fsync(5</o/.carvemap/jobs.db-wal>) = 0',
    ]
    problems, checked = check(good, '/', out)
    assert not problems and checked == 3, (problems, checked)
    no_data_sync = [l for l in good if 'a.h5.partial>' not in l]
    assert check(no_data_sync, '/', out)[0], 'missed a rename without fsync of the data'
    no_dir_sync = good[:2] + good[3:]
    assert check(no_dir_sync, '/', out)[0], 'missed a rename without fsync of the folder'
    job_first = good[:3] + good[6:9] + good[3:6]
    assert check(job_first, '/', out)[0], 'missed job.json renamed before another output'
    store_first = good[-1:] + good[:-1]
    assert check(store_first, '/', out)[0], 'missed the job store committing before job.json'
    # Threads' calls interleaved: strace splits each in two around the other's.
    split = good[:1] + ['10 rename("/o/tiles/a.h5.partial", "/o/tiles/a.h5" <unfinished ...>',
                        '11 fsync(4</o/x.ply.partial> <unfinished ...>',
                        '10 <... rename resumed>) = 0',
                        '11 <... fsync resumed>) = 0'] + good[2:3] + good[4:]
    problems, checked = check(split, '/', out)
    assert not problems and checked == 3, ('split calls', problems, checked)
    failed_call = [l.replace(') = 0', ') = -1') if 'fsync(3' in l else l for l in good]
    assert check(failed_call, '/', out)[0], 'took a failed fsync for a sync'
    print('selftest: ok')


def main():
    args = [a for a in sys.argv[1:] if a != '--selftest']
    if len(args) != 2:
        sys.exit(__doc__)
    if '--selftest' in sys.argv:
        selftest()
    carvemap, work = os.path.abspath(args[0]), os.path.abspath(args[1])
    strace = shutil.which('strace')
    if not strace:
        sys.exit('FAIL: strace not found (scripts/install-deps.sh installs it)')
    shutil.rmtree(work, ignore_errors=True)
    os.makedirs(work)
    sim = subprocess.run([carvemap, 'simulate', '--preset', 'room', '--seed', '1', '--rate-hz',
                          '5', '--beam-step-deg', '2', '--max-duration', '10', '-o',
                          os.path.join(work, 'sim')], capture_output=True, text=True)
    if sim.returncode != 0:
        sys.exit(f'FAIL: simulate\n{sim.stderr}')
    out = os.path.join(work, 'out')
    trace = os.path.join(work, 'trace.txt')
    # --seccomp-bpf: only the traced calls stop the processes, so the job runs at about its
    # normal speed and its heartbeats stay on time.
    run = subprocess.run([strace, '-f', '--seccomp-bpf', '-y', '-qq', '-s', '4096', '-o', trace,
                          '-e', 'trace=fsync,fdatasync,rename,renameat,renameat2',
                          carvemap, 'run', os.path.join(work, 'sim', 'scan.h5'), '-o', out,
                          '--workers', '1', '-q'], cwd=work, capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f'FAIL: carvemap run under strace (exit {run.returncode})\n{run.stderr}')
    with open(trace) as f:
        lines = f.readlines()
    problems, checked = check(lines, work, out)
    renamed = [a[1] for _, k, a in parse(lines) if k == 'rename']
    for kind, pattern in (('tiles', '/tiles/'), ('partial sums', '/partials/'),
                          ('meshes', '.ply'), ('job.json', 'job.json')):
        if not any(pattern in r for r in renamed):
            problems.append(f'no {kind} renamed into place ({pattern}): nothing to check')
    for p in problems:
        print('FAIL:', p)
    if problems:
        sys.exit(1)
    print(f'ok: {checked} renames into {out}, each after an fsync of its data and followed by '
          'an fsync of its folder; job.json last')


if __name__ == '__main__':
    main()
