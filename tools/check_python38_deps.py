#!/usr/bin/env python3
"""Check that every range in requirements.txt admits a wheel for Python 3.8 (Noetic on Ubuntu 20.04) without a 3.8
interpreter.

pip evaluates environment markers against the interpreter that runs it, so this script first evaluates every
requirement's marker for CPython 3.8 on x86_64 Linux itself, then asks pip, one requirement at a time, which wheel
it would pick for that target (``pip install --dry-run --no-deps --only-binary=:all: --python-version 3.8 ...``):
nothing is installed. One at a time and without dependencies because pip's resolver gives up
(``resolution-too-deep``) when it must backtrack through every release of pin for 3.8 at once; the dependencies of
the dependencies are therefore not checked here (tools/setup.sh on a 3.8 machine is the full check). It prints the
version pip would pick for each requirement and exits 0 when every range has one, 1 when one has none, 2 on bad
usage. Needs the package registry (PyPI or a mirror pip is configured for).

Run:  tools/run.sh python tools/check_python38_deps.py [requirements.txt]
"""
import json
import os
import subprocess
import sys
import tempfile
from typing import Dict, List

from packaging.markers import default_environment
from packaging.requirements import Requirement

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
TARGET = "3.8"
PLATFORMS = ["manylinux_2_31_x86_64", "manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64",
             "linux_x86_64"]


def requirements_for(path: str, python_version: str) -> List[str]:
    """The requirement lines of ``path`` whose markers hold on CPython ``python_version`` (markers stripped)."""
    env: Dict[str, str] = dict(default_environment())
    env.update(python_version=python_version, python_full_version=python_version + ".0",
               implementation_name="cpython", platform_python_implementation="CPython",
               sys_platform="linux", platform_system="Linux", platform_machine="x86_64", os_name="posix")
    kept: List[str] = []
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            text = line.split("#", 1)[0].strip()
            if not text:
                continue
            req = Requirement(text)
            if req.marker is not None and not req.marker.evaluate(env):
                continue
            req.marker = None
            kept.append(str(req))
    return kept


def main(argv: List[str]) -> int:
    if len(argv) > 1:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    path = argv[0] if argv else os.path.join(REPO, "requirements.txt")
    reqs = requirements_for(path, TARGET)
    failed: List[str] = []
    with tempfile.TemporaryDirectory() as tmp:
        for r in reqs:
            report = os.path.join(tmp, "report.json")
            cmd = [sys.executable, "-m", "pip", "install", "--quiet", "--dry-run", "--ignore-installed", "--no-deps",
                   "--target", os.path.join(tmp, "t"), "--only-binary=:all:", "--python-version", TARGET,
                   "--implementation", "cp", "--abi", "cp38", "--abi", "abi3", "--abi", "none", "--report", report]
            for p in PLATFORMS:
                cmd += ["--platform", p]
            proc = subprocess.run(cmd + [r], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                  universal_newlines=True)
            if proc.returncode != 0:
                lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("ERROR")]
                print("  %-40s -> NONE: %s" % (r, " ".join(lines)[-300:] or proc.stdout[-300:]))
                failed.append(r)
                continue
            with open(report, encoding="utf-8") as f:
                picked = [i["metadata"]["version"] for i in json.load(f)["install"]]
            print("  %-40s -> %s" % (r, ", ".join(picked)))
    if failed:
        print("FAILED: %d of %d requirements of %s have no wheel for CPython %s: %s"
              % (len(failed), len(reqs), os.path.relpath(path), TARGET, "; ".join(failed)))
        return 1
    print("OK: each of the %d requirements of %s has a wheel for CPython %s"
          % (len(reqs), os.path.relpath(path), TARGET))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
