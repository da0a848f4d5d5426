"""The README's "Python" example, as written there: its code blocks run in a scratch folder (the
scan from numpy arrays, `carvemap validate` and `carvemap run` on it, the outputs loaded); the
client's block, which needs a server of your own, is only compiled."""
import os
import re
import subprocess
import sys

from conftest import REPO, SITE, run_carvemap


def python_section():
    with open(os.path.join(REPO, "README.md"), encoding="utf-8") as f:
        text = f.read()
    section = re.search(r"^## Python\n(.*?)^## ", text, re.S | re.M)
    assert section, "README.md has no section '## Python'"
    return re.findall(r"^```(\w+)\n(.*?)^```", section.group(1), re.S | re.M)


def run_python(code, cwd):
    r = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                       env=dict(os.environ, PYTHONPATH=SITE, PYTHONDONTWRITEBYTECODE="1"),
                       timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    return r.stdout


def test_readme_example(tmp_path, carvemap_bin):
    blocks = python_section()
    kinds = [kind for kind, _ in blocks]
    assert kinds == ["sh", "python", "sh", "python", "python"], kinds
    install, write, commands, load, client = (code for _, code in blocks)
    assert "pip install --no-build-isolation --no-index ./python" in install
    run_python(write, tmp_path)
    assert (tmp_path / "out" / "box_room" / "scan.h5").is_file()
    for line in commands.strip().splitlines():
        words = line.split()
        assert words[0] == "build/carvemap", line
        r = run_carvemap(*words[1:], cwd=tmp_path, timeout=300)
        if words[1] == "validate":
            assert r.stdout.strip().endswith("valid"), r.stdout
    printed = run_python(load, tmp_path)
    assert re.search(r"^level 0: floor -?0\.0\d m, ceiling 2\.[56]\d m$", printed, re.M), printed
    assert re.search(r"^  room 0: \d+\.\d m², outline \d+ points$", printed, re.M), printed
    compile(client, "README client example", "exec")
