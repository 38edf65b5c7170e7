#!/usr/bin/env python3
"""Resolve the locked dependencies with wheels only, for every supported platform and Python.

Nothing is installed: for each (platform, Python) of TARGETS, `uv pip compile --only-binary :all:`
resolves the versions pinned in uv.lock (all extras and groups) as an installer on that machine
would. A dependency without a wheel there (so a student's install would need a compiler, or fail)
fails the check, on the day it is added. First, `uv lock --check` makes sure uv.lock matches
pyproject.toml, so what is checked is what CI installs.

Usage: python3 .ci/check_wheels.py            (needs `uv` and https://pypi.org; exit 0 when all resolve)
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INDEX = "https://pypi.org/simple/"
PYTHONS = ("3.11", "3.12", "3.13")  # pyproject's requires-python
PLATFORMS = {  # uv's --python-platform names, with the oldest OS a wheel must run on
    "Linux x86_64": "x86_64-manylinux_2_28",  # glibc 2.28: Debian 10, Ubuntu 20.04, RHEL 8
    "macOS arm64": "aarch64-apple-darwin",  # macOS 14 (MACOS below), which every Apple silicon Mac runs
    "Windows x86_64": "x86_64-pc-windows-msvc",
}
# pybullet-arm64 3.2.8's cp313 wheel is macosx_14_0_arm64 (its cp311/cp312 wheels: universal2, 10.9/10.13)
MACOS = "14.0"
TARGETS = [(name, plat, py) for name, plat in PLATFORMS.items() for py in PYTHONS]


def run(cmd: list[str]) -> subprocess.CompletedProcess:
    env = {**os.environ, "MACOSX_DEPLOYMENT_TARGET": MACOS}
    return subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, env=env)


def last_error(p: subprocess.CompletedProcess) -> str:
    """uv's reason, without its hints: the lines that say what is missing."""
    lines = [ln.strip() for ln in (p.stderr or p.stdout).splitlines() if ln.strip()]
    keep = [ln for ln in lines if not ln.startswith(("hint:", "help:", "Using ", "Resolved "))]
    return " / ".join(keep[:4]) or f"exit {p.returncode}"


def main() -> int:
    if shutil.which("uv") is None:
        print("check_wheels: uv is not installed (python3 -m pip install uv)", file=sys.stderr)
        return 2
    try:
        urllib.request.urlopen(INDEX + "pip/", timeout=30).close()
    except OSError as e:
        print(
            f"check_wheels: cannot reach the package index {INDEX} ({e}); this check needs it",
            file=sys.stderr,
        )
        return 2

    lock = run(["uv", "lock", "--check"])
    if lock.returncode != 0:
        print(f"FAIL uv.lock: {last_error(lock)}\n  (run `uv lock` and commit uv.lock)")
        return 1
    print("ok   uv.lock matches pyproject.toml")

    with tempfile.TemporaryDirectory() as tmp:
        pins = Path(tmp) / "pins.txt"
        exp = run(
            ["uv", "export", "--frozen", "--all-extras", "--all-groups", "--no-hashes",
             "--no-emit-project", "--no-header", "--format", "requirements-txt", "-o", str(pins)]
        )  # fmt: skip
        if exp.returncode != 0:
            print(f"FAIL uv export: {last_error(exp)}")
            return 1
        failed, out = [], Path(tmp) / "resolved.txt"
        for name, plat, py in TARGETS:
            p = run(
                ["uv", "pip", "compile", str(pins), "--only-binary", ":all:", "--python-platform", plat,
                 "--python-version", py, "--index-url", INDEX, "--no-header", "--quiet", "-o", str(out)]
            )  # fmt: skip
            if p.returncode == 0:
                n = sum(1 for ln in out.read_text().splitlines() if "==" in ln)
                print(f"ok   {name:15s} Python {py}: {n} packages, all wheels")
            else:
                failed.append((name, py))
                print(f"FAIL {name:15s} Python {py}: {last_error(p)}")
    if failed:
        print(f"check_wheels: {len(failed)} of {len(TARGETS)} platforms have no wheel for some dependency")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
