"""The job node (``rosrun locem_bridge plasterboard_job``) on a private ROS master, stopped by SIGINT (what
roslaunch sends at shutdown) before any other node of the job is up: it still writes report.json and report.md,
saying the launch shut down before the job started, every step not run and the outcome not measured -- without
any other node alive to ask. Needs the environment of tools/test.sh (skipped otherwise, like test/ros); no fixed
ports: the master takes a free one and nothing else is started."""
import json
import os
import shutil
import signal
import subprocess
import time

import pytest

from locem_bridge.ros.processes import RosProcesses

READY = bool(os.environ.get("LOCEM_REPO")) and shutil.which("rosrun") is not None
pytestmark = [pytest.mark.ros, pytest.mark.slow,
              pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (ROS + catkin workspace)")]


def test_sigint_before_the_job_started_still_writes_the_report(tmp_path):
    results = tmp_path / "results"
    procs = RosProcesses(log_dir=str(tmp_path / "logs"))
    procs.env["ROS_HOME"] = str(tmp_path / "ros_home")
    procs.env["ROS_LOG_DIR"] = str(tmp_path / "ros_log")
    try:
        procs.start_master()
        node = procs.spawn(["rosrun", "locem_bridge", "plasterboard_job", "__name:=job",
                            "_results_dir:=%s" % results], "job")
        end = time.monotonic() + 60                            # up, waiting for HICEM and the worksite
        while "/job" not in subprocess.run(["rosnode", "list"], env=procs.env, capture_output=True,
                                           text=True).stdout.split():
            assert time.monotonic() < end and node.poll() is None, "the job node never registered"
            time.sleep(0.2)
        os.killpg(node.pid, signal.SIGINT)
        try:
            code = node.wait(20)
        except subprocess.TimeoutExpired:
            pytest.fail("the job node did not end within 20 s of SIGINT")
    finally:
        procs.close()
    out = open(str(tmp_path / "logs" / "job.log")).read()
    assert code == 1, out
    assert "Traceback" not in out, out
    with open(str(results / "latest" / "report.json"), encoding="utf-8") as handle:
        report = json.load(handle)
    ended = report["ended"]
    assert ended["reason"] == "shutdown" and ended["early"] is True, ended
    assert "SIGINT" in ended["detail"] and "before the job started" in ended["detail"], ended
    assert ended["not_run"] == ["taping", "spraying", "sanding"] and report["processes"] == []
    assert report["outcome"]["measured"] is False
    assert any("sim/save_outcome" in item for item in ended["unread"]), ended["unread"]
    md = open(str(results / "latest" / "report.md")).read()
    assert "**Ended: shutdown** (early)" in md and "Not run: taping, spraying, sanding" in md
    assert "[job] ended: shutdown (early)" in out
