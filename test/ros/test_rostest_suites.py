"""Runs every rostest suite in this folder (a real master, the real nodes) and reports each as one pytest test.

The suites need the catkin workspace built and sourced, which ``tools/test.sh`` does; run through plain pytest
without it they are skipped with that reason.
"""
import glob
import os
import re
import shutil
import subprocess

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
SUITES = sorted(glob.glob(os.path.join(HERE, "*.test")))
READY = bool(os.environ.get("LOCEM_REPO")) and shutil.which("rostest") is not None

pytestmark = [pytest.mark.ros, pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh")]


@pytest.mark.parametrize("suite", SUITES, ids=[os.path.basename(s)[:-5] for s in SUITES])
def test_rostest_suite(suite, tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path / "ros_home"), ROS_LOG_DIR=str(tmp_path / "log"))
    done = subprocess.run(["rostest", "locem_bridge", os.path.basename(suite)], cwd=HERE, env=env,
                          capture_output=True, text=True, timeout=600)
    output = re.sub(r"\x1b\[[0-9;]*m", "", done.stdout + done.stderr)
    for report in sorted(glob.glob(str(tmp_path / "ros_home" / "test_results" / "**" / "*.xml"), recursive=True)):
        with open(report, encoding="utf-8", errors="replace") as handle:
            output += "\n--- %s\n%s" % (os.path.basename(report), handle.read())
    summary = re.search(r"SUMMARY\s*\n\s*\* RESULT: (\w+)\s*\n\s*\* TESTS: (\d+)\s*\n\s*\* ERRORS: (\d+)\s*\n"
                        r"\s*\* FAILURES: (\d+)", output)
    assert summary, "rostest printed no summary (exit %d):\n%s" % (done.returncode, output[-6000:])
    result, tests, errors, failures = summary.group(1), int(summary.group(2)), int(summary.group(3)), \
        int(summary.group(4))
    assert tests > 0, "suite ran no test:\n" + output[-4000:]
    assert result == "SUCCESS" and errors == 0 and failures == 0 and done.returncode == 0, output[-8000:]
