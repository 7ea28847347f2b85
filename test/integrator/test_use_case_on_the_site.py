"""The integrator's use case (``use_case/``: Turtle + tree XML + job YAML, nothing of it in the package) run the
way an integrator runs it: ``tools/main.sh --ontologies DIR --trees DIR --job FILE`` (its driver ``python -m
locem_bridge.ros.main_job``) on the simulated default site: the whole launch, the real nodes and device stand-ins.

What it achieves physically, measured on the world's ground truth (the worksite's tape record per joint, in the
run report): one sample joint per plasterboard wall -- the first the scan reports on it -- is taped over its whole
length (the two pieces of SPOT_TAPE_JOINT, taped from the joint's middle up and down, meet without a gap:
coverage >= 0.99), every other joint is untouched (coverage 0), no collision; the only operator intervention is
the tool mount of the shipped GET_TOOL. PEMKRE's execution log (the report's KPI rows) shows two SPOT_TAPE_JOINT
tasks, both succeeded. The PEMKRE node matches every task to the robot's resource model, generated from the
shipped trees plus the use case's folder: the run gets past start_process only because that model offers the
use case's tree as the skill for its task (without the folder it is refused, test_integrator_folders.py).
One launch, about 30 s of wall clock at time scale 10.

Needs the environment ``tools/test.sh`` prepares; starts device stand-ins: run it under the heavy lock
(``flock /tmp/locem-heavy.lock bash tools/test.sh test/integrator/test_use_case_on_the_site.py``).
"""
import json
import os
import shutil
import subprocess
import sys

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
USE_CASE = os.path.join(REPO, "test", "integrator", "use_case")
READY = os.environ.get("LOCEM_REPO") == REPO and shutil.which("roslaunch") is not None
pytestmark = [pytest.mark.ros,
              pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (setup done, ROS sourced)")]


def test_spot_taping_from_the_integrators_folders_on_the_default_site(tmp_path):
    env = dict(os.environ, ROS_HOME=str(tmp_path / "ros_home"), ROS_LOG_DIR=str(tmp_path / "log"))
    done = subprocess.run([sys.executable, "-m", "locem_bridge.ros.main_job", "--ontologies", USE_CASE,
                           "--trees", USE_CASE, "--job", os.path.join(USE_CASE, "job.yaml"),
                           "--results-dir", str(tmp_path / "results"), "--time-scale", "10", "--timeout", "300",
                           "--launch-arg", "state_dir:=%s" % tmp_path],
                          cwd=str(tmp_path), env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                          universal_newlines=True, timeout=360)
    out = done.stdout
    assert done.returncode == 0, out[-4000:]
    assert "extra_ontology_dirs:=%s" % USE_CASE in out and "extra_trees_dirs:=%s" % USE_CASE in out, out[-4000:]
    assert "[1/1 spot_taping] SPOT_TAPE_JOINT" in out, out[-4000:]
    report = out.rsplit("report: ", 1)[1].strip().splitlines()[0]
    with open(os.path.join(os.path.dirname(report), "report.json"), encoding="utf-8") as handle:
        data = json.load(handle)
    assert [(p["name"], p["status"], p["detail"]) for p in data["processes"]] == \
        [("spot_taping", "succeeded", "completed")], data["processes"]
    settings = data["settings"]                 # the report says which folders and job the run read
    assert (settings["extra_ontology_dirs"], settings["extra_trees_dirs"], settings["job"]) == \
        (USE_CASE, USE_CASE, os.path.join(USE_CASE, "job.yaml")), settings
    outcome = data["outcome"]
    joints = outcome["joints"]
    print("measured: %s; wall clock %.0f s (process %.1f s)" % (
        ", ".join("%s %.3f" % (j, v["coverage"]) for j, v in sorted(joints.items())),
        data["timing"]["wall_clock_s"], data["processes"][0]["duration_s"]))
    taped = {j for j, v in joints.items() if v["coverage"] >= 0.99}
    assert taped == {"wall_1_joint_1", "wall_2_joint_1"}, joints              # one sample per wall, whole length
    assert all(v["coverage"] == 0.0 for j, v in joints.items() if j not in taped), joints   # the rest untouched
    assert outcome["collisions"] == 0 and outcome["operator_interventions"] == 1, outcome
    rows = {r["actionType"]: r for r in data["kpis"]}
    assert (rows["SPOT_TAPE_JOINT"]["count"], rows["SPOT_TAPE_JOINT"]["succeeded"]) == ("2", "2"), data["kpis"]
    assert not [line for line in out.splitlines() if "Traceback" in line], out[-4000:]
