#!/usr/bin/python3
"""Structure check of deploy/Dockerfile (no Docker engine or hadolint needed).

Usage: check_dockerfile.py BUILD/carvemap

Checks: Debian 12 base images only; packages only from Debian's apt (no downloads, no extra
repositories); a build stage running CMake + Ninja like scripts/build.sh; a runtime stage
copying only the binary from the build stage, running as a numeric non-root user, with
ENTRYPOINT carvemap and an explicit HEALTHCHECK (or HEALTHCHECK NONE); the .dockerignore;
and that the runtime stage installs the Debian package of every shared library
`ldd BUILD/carvemap` lists (and no package that provides none of them, but for the job
report's JavaScript libraries, libjs-three and libjs-leaflet).
"""
import os
import re
import shlex
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
DOCKERFILE = os.path.join(ROOT, "deploy", "Dockerfile")
IGNORE = os.path.join(ROOT, "deploy", "Dockerfile.dockerignore")
DEBIAN_12 = re.compile(r"debian:(12|bookworm)(-slim)?(@sha256:[0-9a-f]{64})?")
INSTRUCTIONS = {"FROM", "RUN", "CMD", "LABEL", "EXPOSE", "ENV", "ADD", "COPY", "ENTRYPOINT",
                "VOLUME", "USER", "WORKDIR", "ARG", "ONBUILD", "STOPSIGNAL", "HEALTHCHECK",
                "SHELL", "MAINTAINER"}

errors = []


def fail(msg):
    errors.append(msg)


def parse(text):
    """[(line_no, INSTRUCTION, rest)] with continuation lines joined and comments dropped."""
    out, buf, start = [], "", 0
    for no, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if not buf and (not stripped or stripped.startswith("#")):
            continue
        if buf and stripped.startswith("#"):
            continue  # comment lines inside a continued instruction are dropped
        if not buf:
            start = no
        if stripped.endswith("\\"):
            buf += stripped[:-1] + " "
            continue
        buf += stripped
        word, _, rest = buf.partition(" ")
        out.append((start, word.upper(), rest.strip()))
        if word.upper() not in INSTRUCTIONS or word != word.upper():
            fail(f"line {start}: unknown or lower-case instruction {word!r}")
        buf = ""
    if buf:
        fail("the last instruction ends with a line continuation")
    return out


def stages(instrs):
    result = []
    for no, ins, rest in instrs:
        if ins == "FROM":
            parts = rest.split()
            name = parts[2] if len(parts) >= 3 and parts[1].upper() == "AS" else None
            result.append({"image": parts[0], "name": name, "line": no, "body": []})
        elif not result:
            if ins != "ARG":
                fail(f"line {no}: {ins} before the first FROM")
        else:
            result[-1]["body"].append((no, ins, rest))
    return result


def apt_installs(run):
    """Package names of every `apt-get install` in a RUN command."""
    pkgs = []
    for cmd in re.split(r"&&|;|\|\|", run):
        words = shlex.split(cmd)
        if "apt-get" in words and "install" in words:
            after = words[words.index("install") + 1:]
            pkgs += [w for w in after if not w.startswith("-")]
    return pkgs


def exec_form(rest):
    m = re.fullmatch(r"\[(.*)\]", rest.strip())
    if not m:
        return None
    return [s.strip().strip('"') for s in m.group(1).split(",")]


def spellings(path):
    """The path, its target, and both with and without /usr (merged /usr: dpkg knows one)."""
    out = []
    for p in (path, os.path.realpath(path)):
        out += [p, p[4:] if p.startswith("/usr/") else "/usr" + p]
    return out


def ldd_packages(binary):
    """{library path: Debian package} for every library `ldd` lists."""
    proc = subprocess.run(["ldd", binary], capture_output=True, text=True)
    if proc.returncode != 0:
        sys.exit(f"FAIL: ldd {binary}: {proc.stderr}")
    paths = []
    for line in proc.stdout.splitlines():
        line = line.strip()
        if not line or line.startswith("linux-vdso"):
            continue
        if "not found" in line:
            fail(f"ldd: {line}")
            continue
        m = re.match(r"\S+ => (/\S+)", line) or re.match(r"(/\S+)", line)
        if m:
            paths.append(m.group(1))
    # One dpkg-query for every spelling of every path (dpkg-query -S is slow per call).
    query = sorted({s for p in paths for s in spellings(p)})
    q = subprocess.run(["dpkg-query", "-S"] + query, capture_output=True, text=True)
    known = {}
    for ln in q.stdout.splitlines():
        pkgs, _, path = ln.rpartition(": ")
        known[path.strip()] = pkgs.split(",")[0].split(":")[0].strip()
    libs = {}
    for path in paths:
        pkg = next((known[s] for s in spellings(path) if s in known), None)
        if pkg is None:
            fail(f"no Debian package provides {path} (dpkg -S)")
        else:
            libs[path] = pkg
    return libs


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: check_dockerfile.py BUILD/carvemap")
    binary = sys.argv[1]
    if not os.access(binary, os.X_OK):
        sys.exit(f"FAIL: {binary} does not exist: build carvemap first (scripts/build.sh)")
    text = open(DOCKERFILE, encoding="utf-8").read()
    instrs = parse(text)
    st = stages(instrs)

    # Debian 12 images only.
    names = {s["name"] for s in st if s["name"]}
    if len(st) < 2:
        fail("need a build stage and a runtime stage")
    for s in st:
        if not DEBIAN_12.fullmatch(s["image"]):
            fail(f"line {s['line']}: FROM {s['image']}: only debian:12 / bookworm images")

    # No downloads, no foreign package sources, anywhere.
    for no, ins, rest in instrs:
        if ins == "ADD":
            if re.search(r"https?://|git@|\.git\b", rest):
                fail(f"line {no}: ADD of a URL")
            else:
                fail(f"line {no}: use COPY, not ADD")
        if ins == "RUN":
            for bad, why in ((r"\b(curl|wget)\b", "downloads with curl/wget"),
                             (r"\bdpkg\s+-i\b", "installs a .deb by hand"),
                             (r"sources\.list|apt-key|add-apt-repository|signed-by",
                              "adds package sources"),
                             (r"--allow-unauthenticated|--force-yes", "unauthenticated apt"),
                             (r"\b(pip3?|npm|gem|cargo|go)\s+(install|get)\b",
                              "installs from another registry")):
                if re.search(bad, rest):
                    fail(f"line {no}: RUN {why}")

    build, runtime = st[0], st[-1]
    # The build stage: scripts/install-deps.sh (Debian packages) and CMake + Ninja.
    runs = " && ".join(r for _, i, r in build["body"] if i == "RUN")
    if "scripts/install-deps.sh" not in runs:
        fail("build stage: install the build dependencies with scripts/install-deps.sh")
    if not ("scripts/build.sh" in runs or
            (re.search(r"\bcmake\b.*-G\s*Ninja", runs) and re.search(r"\bninja\b|--build", runs))):
        fail("build stage: build with scripts/build.sh or cmake -G Ninja + ninja")
    deps = open(os.path.join(ROOT, "scripts", "install-deps.sh"), encoding="utf-8").read()
    if re.search(r"\b(curl|wget)\b|sources\.list|apt-key|dpkg\s+-i", deps):
        fail("scripts/install-deps.sh must use Debian's apt only")

    # The runtime stage: only the binary from the build stage.
    copies = [(no, r) for no, i, r in runtime["body"] if i in ("COPY", "ADD")]
    if len(copies) != 1:
        fail(f"runtime stage: exactly one COPY (the binary), found {len(copies)}")
    for no, rest in copies:
        words = rest.split()
        src_stage = next((w.split("=", 1)[1] for w in words if w.startswith("--from=")), None)
        paths = [w for w in words if not w.startswith("--")]
        if src_stage not in names or src_stage == runtime["name"]:
            fail(f"line {no}: the runtime stage copies from {src_stage}, not the build stage")
        if len(paths) != 2 or os.path.basename(paths[0]) != "carvemap":
            fail(f"line {no}: the runtime stage copies {paths[:-1]}, not just the binary")
    rt_runs = " && ".join(r for _, i, r in runtime["body"] if i == "RUN")
    if re.search(r"\b(cmake|ninja|make|gcc|g\+\+)\b|-dev\b|build-essential", rt_runs):
        fail("runtime stage: no compilers or -dev packages")
    if not re.search(r"rm -rf /var/lib/apt/lists", rt_runs):
        fail("runtime stage: remove /var/lib/apt/lists after installing")
    if "--no-install-recommends" not in rt_runs:
        fail("runtime stage: apt-get install --no-install-recommends")

    users = [r for _, i, r in runtime["body"] if i == "USER"]
    if not users:
        fail("runtime stage: no USER")
    else:
        uid = users[-1].split(":")[0]
        if not uid.isdigit() or int(uid) == 0:
            fail(f"runtime stage: USER {users[-1]} must be a numeric non-zero UID")
    ep = [r for _, i, r in runtime["body"] if i == "ENTRYPOINT"]
    form = exec_form(ep[-1]) if ep else None
    if not form or os.path.basename(form[0]) != "carvemap":
        fail("runtime stage: ENTRYPOINT must be [\".../carvemap\"] (exec form)")
    elif copies and form[0] != copies[0][1].split()[-1]:
        fail(f"ENTRYPOINT {form[0]} is not where the binary is copied")
    hc = [r for _, i, r in runtime["body"] if i == "HEALTHCHECK"]
    if not hc:
        fail("runtime stage: state HEALTHCHECK explicitly (HEALTHCHECK NONE with the reason)")
    elif hc[-1].upper() == "NONE":
        idx = text.find("HEALTHCHECK NONE")
        before = text[:idx].splitlines()[-3:]
        if not any(line.lstrip().startswith("#") for line in before):
            fail("HEALTHCHECK NONE needs a comment saying why")

    # The build context's ignore file.
    if not os.path.isfile(IGNORE):
        fail("deploy/Dockerfile.dockerignore is missing")
    else:
        pats = {ln.strip() for ln in open(IGNORE) if ln.strip() and not ln.startswith("#")}
        for need in (".git", "build", "out"):
            if need not in pats:
                fail(f"Dockerfile.dockerignore should exclude {need}")

    # Runtime libraries: ldd ➜ dpkg -S ➜ the runtime stage's apt-get install.
    installed = set()
    for _, i, r in runtime["body"]:
        if i == "RUN":
            installed |= set(apt_installs(r))
    libs = ldd_packages(binary)
    needed = set(libs.values())
    for path, pkg in sorted(libs.items()):
        if pkg not in installed:
            fail(f"runtime stage does not install {pkg}, which provides {path} "
                 f"(`ldd {binary}`)")
    # Files, not libraries, that the binary reads at run time: the job report's viewers
    # (services/report/job_report.h copies them beside each job's outputs).
    data_packages = {"libjs-three", "libjs-leaflet"}
    for pkg in sorted(data_packages - installed):
        fail(f"runtime stage does not install {pkg}, which the job report copies from")
    for pkg in sorted(installed - needed - data_packages):
        fail(f"runtime stage installs {pkg}, which provides no library of {binary}")

    if errors:
        for e in errors:
            print(f"FAIL: {e}", file=sys.stderr)
        sys.exit(1)
    print(f"deploy/Dockerfile: {len(st)} stages, runtime installs {len(installed)} packages "
          f"covering {len(libs)} libraries of {binary}; all checks passed")


if __name__ == "__main__":
    main()
