"""The README's two commands, as a user runs them: ``tools/setup.sh`` is idempotent (a second run on a ready
machine installs and builds nothing and names the same environment), and the main-job driver behind
``tools/main.sh`` runs the real launch to its end, shows progress, prints the report's tables and its exit status
says whether the job was completed.

Both need the environment ``tools/test.sh`` prepares (setup done, workspace sourced); under plain pytest without it
they are skipped with that reason.
"""
import json
import os
import shutil
import subprocess
import sys
import time

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
READY = os.environ.get("LOCEM_REPO") == REPO and shutil.which("roslaunch") is not None
pytestmark = pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (setup done, ROS sourced)")


def test_second_setup_run_changes_nothing_and_names_the_same_environment():
    started = time.monotonic()
    done = subprocess.run(["bash", os.path.join(REPO, "tools", "setup.sh")], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, universal_newlines=True, timeout=300)
    elapsed = time.monotonic() - started
    assert done.returncode == 0, done.stderr
    said = [line for line in done.stderr.splitlines() if line.startswith("[setup]")]
    assert said == ["[setup] distribution packages present", "[setup] Python requirements present",
                    "[setup] catkin workspace up to date"], done.stderr
    env_file = done.stdout.strip()
    assert os.path.isfile(env_file), done.stdout
    with open(env_file, encoding="utf-8") as handle:
        text = handle.read()
    assert 'export LOCEM_REPO="%s"' % REPO in text, text
    assert os.environ.get("VIRTUAL_ENV", "") and os.environ["VIRTUAL_ENV"] in text, text
    print("second setup run: %.1f s" % elapsed)


def test_main_job_driver_runs_the_launch_to_its_report(tmp_path):
    """The driver of the README's main command on the bare room (no joints, no areas: every process is
    scan -> home -> end), so the whole launch runs start to finish in well under a minute."""
    results = tmp_path / "results"
    env = dict(os.environ, ROS_HOME=str(tmp_path / "ros_home"), ROS_LOG_DIR=str(tmp_path / "log"))
    done = subprocess.run([sys.executable, "-m", "locem_bridge.ros.main_job", "--site",
                           os.path.join(REPO, "config", "sites", "bare_room.yaml"), "--results-dir", str(results),
                           "--time-scale", "10", "--timeout", "240", "--launch-arg", "state_dir:=%s" % tmp_path],
                          cwd=str(tmp_path), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          universal_newlines=True, timeout=300)
    out = done.stdout
    assert done.returncode == 0, out[-4000:]
    assert "[main] roslaunch -p" in out and "plasterboard.launch" in out, out[-4000:]
    for n, name in enumerate(("taping", "spraying", "sanding"), 1):
        assert "[%d/3 %s]" % (n, name) in out, out[-4000:]        # progress per process
        assert "| %s | succeeded |" % name in out, out[-4000:]      # the report's process table, printed
    assert "[main] job done in" in out, out[-4000:]
    report = out.rsplit("report: ", 1)[1].strip().splitlines()[0]
    assert report.startswith(str(results)) and os.path.isfile(report), report
    with open(os.path.join(os.path.dirname(report), "report.json"), encoding="utf-8") as handle:
        data = json.load(handle)
    assert [(p["name"], p["status"], p["detail"]) for p in data["processes"]] == \
        [(n, "succeeded", "nothing_to_do") for n in ("taping", "spraying", "sanding")], data["processes"]
    assert not [line for line in out.splitlines() if "Traceback" in line], out[-4000:]
