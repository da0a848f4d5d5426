#!/usr/bin/env python3
"""The job report (OUT/index.html) in a real browser: Debian's Chromium, headless, WebGL drawn
by its software renderer (SwiftShader).

`carvemap report OUT` rebuilds the page; `carvemap serve OUT` serves the folder on 127.0.0.1;
Chromium loads the page and then:
  - no console error, no uncaught exception, no file that failed to load (in Chromium's log,
    and as the page itself counted them in #status's data-errors);
  - the page's #status says it finished: the floor plan shown, the 3D model loaded with one
    node per object of job.json, the rooms table with one row per room of job.json;
  - the 3D canvas is not blank: the page reads its pixels back (data-canvas-lit, the share of
    pixels not the background), and the screenshot, kept as an artifact, is not one colour.

Usage: report_test.py --carvemap BIN --out OUT_DIR --screenshot PNG
"""
import argparse
import html.parser
import json
import os
import re
import shutil
import socket
import subprocess
import sys
import time

CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--window-size=1300,1400",
                  "--virtual-time-budget=20000", "--enable-logging=stderr", "--v=0"]


def fail(msg):
    print("FAIL:", msg, file=sys.stderr)
    sys.exit(1)


class StatusParser(html.parser.HTMLParser):
    """The attributes of the element with id="status" in a dumped DOM."""

    def __init__(self):
        super().__init__()
        self.status = None

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if attrs.get("id") == "status":
            self.status = attrs


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def chromium(url, extra):
    browser = shutil.which("chromium")
    if not browser:
        fail("chromium is not installed (scripts/install-deps.sh installs Debian's chromium)")
    r = subprocess.run([browser] + CHROMIUM_FLAGS + extra + [url], capture_output=True,
                       text=True, timeout=180)
    return r.stdout, r.stderr


def console_problems(stderr):
    """Console errors, uncaught exceptions and failed loads in Chromium's log."""
    problems = []
    for line in stderr.splitlines():
        if ":CONSOLE" not in line:
            continue
        if re.search(r"Uncaught|Failed to load|TypeError|ReferenceError|SyntaxError|"
                     r"\"Error|ERROR:CONSOLE", line):
            problems.append(line.strip())
    return problems


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--carvemap", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--screenshot", required=True)
    args = ap.parse_args()
    job = json.load(open(os.path.join(args.out, "job.json")))

    r = subprocess.run([args.carvemap, "report", args.out], capture_output=True, text=True)
    if r.returncode != 0:
        fail(f"carvemap report: {r.stderr}")
    port = free_port()
    server = subprocess.Popen([args.carvemap, "serve", args.out, "--listen",
                               f"127.0.0.1:{port}"], stdout=subprocess.PIPE, text=True)
    try:
        line = server.stdout.readline()
        if "serving" not in line:
            fail(f"carvemap serve did not start: {line!r}")
        url = f"http://127.0.0.1:{port}/index.html"

        dom, log = chromium(url, ["--dump-dom"])
        problems = console_problems(log)
        parser = StatusParser()
        parser.feed(dom)
        status = parser.status or {}
        print("status:", json.dumps(status))
        if problems:
            fail("the page logged errors:\n  " + "\n  ".join(problems[:10]))
        want_rooms = len(job.get("rooms", []))
        want_objects = len(job.get("objects", []))
        checks = [
            (status.get("data-ready") == "yes", "the page's script did not finish"),
            (status.get("data-errors") == "0",
             f"the page saw {status.get('data-errors')} errors: {status.get('data-error-list')}"),
            (status.get("data-plan") == "shown", "no floor plan shown"),
            (status.get("data-model") == "loaded", f"3D model: {status.get('data-model')}"),
            (status.get("data-rooms") == str(want_rooms),
             f"{status.get('data-rooms')} rooms in the table, job.json has {want_rooms}"),
            (status.get("data-object-nodes") == str(want_objects),
             f"{status.get('data-object-nodes')} object nodes, job.json has {want_objects}"),
            (float(status.get("data-canvas-lit", 0)) > 0.02,
             f"the 3D canvas is blank ({status.get('data-canvas-lit')} of it drawn)"),
        ]
        for ok, why in checks:
            if not ok:
                fail(why)

        if os.path.exists(args.screenshot):
            os.remove(args.screenshot)
        _, log = chromium(url, [f"--screenshot={args.screenshot}"])
        if not os.path.isfile(args.screenshot):
            fail("no screenshot written")
        from PIL import Image
        shot = Image.open(args.screenshot).convert("RGB")
        colours = shot.getcolors(maxcolors=1 << 20)
        if colours is not None and len(colours) < 50:
            fail(f"the screenshot has {len(colours)} colours: blank")
        print(f"report: {want_rooms} rooms, {want_objects} objects, canvas "
              f"{float(status['data-canvas-lit']):.0%} drawn; screenshot {args.screenshot}")
    finally:
        server.terminate()
        try:
            server.wait(timeout=10)
        except subprocess.TimeoutExpired:
            server.kill()
    return 0


if __name__ == "__main__":
    sys.exit(main())
