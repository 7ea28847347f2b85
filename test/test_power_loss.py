"""A power loss in the middle of spraying, then ``tools/main.sh --resume`` (issue 20): the job goes on where it
stopped and finishes, nothing done twice, one report over both launches.

Runs ``python -m locem_bridge.ros.main_job`` (the driver behind tools/main.sh: the whole launch, automatic operator)
on the one-wall test site (test/ros/sites/one_wall.yaml: two joints, one area of several sections). When the spraying
process works its area's second section with the spray valve open (HICEM's state over ROS, the compressor stand-in's
own record of its valve through ``/sim/compressor``), every process of the run -- the driver, roslaunch, the ROS
master and every node, the simulated world with its devices -- is frozen (SIGSTOP, all at once) and killed (SIGKILL):
nothing gets to write a last word. Then ``main_job --resume`` (the latest run) must finish the job:

- taping is not run again (the report keeps its record from the first launch); every joint taped exactly once
  (PEMKRE's TAPE_LINE tasks = joints; on the world's tape pass map no joint has a stretch taped twice);
- no area section sprayed twice: the sections finished before the cut are not sprayed again and the cut one goes on
  where it stopped -- the seam where the spray stopped at the cut has no second coat (nor gap) longer than
  ``LONGEST_FLAW_M`` on the world's pass maps (a cut that came in a turn between two lanes ended no pass: said so,
  nothing to check there), and the wall's thickness stays within the job's goals (coverage >= 0.98, CV <= 0.15);
- every process succeeded, the outcome goals of the full job hold, and the report lists both launches (the first
  cut off) with the processes of both.

Needs the environment of tools/test.sh (ROS sourced). About 3 minutes.
"""
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SITE = os.path.join(REPO, "test", "ros", "sites", "one_wall.yaml")
READY = os.environ.get("LOCEM_REPO") == REPO and shutil.which("roslaunch") is not None
pytestmark = [pytest.mark.slow, pytest.mark.ros,
              pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (setup done, ROS sourced)")]

LONGEST_FLAW_M = 0.05        # no second coat (or gap) longer than this where the spray stopped at the cut
LANE_END_SPREAD_M = 0.06     # the passes ending at one edge of a section end within this of each other
SPRAYING = "https://locem-bridge.example.org/ont/plasterboard#SprayingProcess"
TIME_SCALE = 5.0            # as the whole-job rostests: the spray's thickness depends on the switching's timing
INTO_LANE_SIM_S = 0.3       # the cut comes this long (sim) after the valve opened for a lane (a lane: about 1 s)


def _descendants(pid):
    """Every process below ``pid`` (children first found by their parent in /proc)."""
    parents = {}
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open("/proc/%s/stat" % name, encoding="utf-8") as handle:
                    fields = handle.read().rsplit(")", 1)[1].split()
                parents.setdefault(int(fields[1]), []).append(int(name))
            except (OSError, IndexError, ValueError):
                pass
    found, todo = [], [pid]
    while todo:
        for child in parents.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def _freeze(pids):
    for p in pids:
        try:
            os.kill(p, signal.SIGSTOP)
        except ProcessLookupError:
            pass


def _power_loss(pid, frozen=()):
    """Freeze ``pid`` and everything below it at once (``frozen``: already frozen), then kill them all: no process
    writes a last word."""
    victims = sorted(set([pid] + _descendants(pid)) - set(frozen))
    _freeze(victims)
    victims = sorted(set(victims) | set(frozen))
    victims = sorted(set(victims + [d for p in victims for d in _descendants(p)]))
    for p in victims:
        try:
            os.kill(p, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return victims


def _alive(pid):
    try:
        with open("/proc/%d/stat" % pid, encoding="utf-8") as handle:
            return handle.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _all_gone(pids, within_s, report=False):
    """True when none of ``pids`` runs any more (zombies count as gone) within ``within_s`` s; with ``report`` the
    list of those still there."""
    deadline = time.monotonic() + within_s
    while True:
        left = [p for p in pids if _alive(p)]
        if report:
            return left
        if not left:
            return True
        if time.monotonic() >= deadline:
            return False
        time.sleep(0.1)


class Lines:
    """The driver's output, kept and searchable while it runs."""

    def __init__(self, proc):
        self.lines = []
        self.proc = proc
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def text(self):
        return "\n".join(self.lines)

    def find(self, pattern):
        for line in list(self.lines):
            found = re.search(pattern, line)
            if found:
                return found
        return None


def _driver(args, tmp_path, name):
    env = dict(os.environ, ROS_HOME=str(tmp_path / ("ros_home_" + name)), ROS_LOG_DIR=str(tmp_path / ("log_" + name)))
    return subprocess.Popen([sys.executable, "-m", "locem_bridge.ros.main_job"] + args, cwd=str(tmp_path), env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)


def _spraying_second_section(port, tmp_path, pid):
    """Wait until SPRAY_AREA works its second section with the valve open (power_loss_watch.py, a ROS client of the
    run's master, read line by line) and freeze ``pid`` and what runs below it at once (the processes found when
    the watch was armed); returns (HICEM's state, the sim time of that opening of the valve, the frozen pids)."""
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_HOME=str(tmp_path / "ros_home_watch"))
    watch = subprocess.Popen([sys.executable, os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                           "power_loss_watch.py"), SPRAYING, "300",
                              "%g" % (INTO_LANE_SIM_S / TIME_SCALE)],
                             env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1)
    seen, victims = [], []
    try:
        for line in watch.stdout:
            seen.append(line)
            if line.startswith("armed"):          # the processes to freeze, known before the moment comes
                victims = [pid] + _descendants(pid)
            if line.startswith("{"):
                _freeze(victims)                  # at once: the lane goes on while /proc is read
                moment = json.loads(line)
                return moment["hicem"], moment["opened_sim"], victims
    finally:
        watch.kill()
        watch.wait()
    raise AssertionError("the watch ended without the moment (status %s): %s" % (watch.returncode,
                                                                                "".join(seen)[-3000:]))


def test_power_loss_mid_spraying_then_resume_finishes_with_nothing_done_twice(tmp_path):
    results = tmp_path / "results"
    port = 11800 + os.getpid() % 200
    first = _driver(["--site", SITE, "--results-dir", str(results), "--time-scale", "%g" % TIME_SCALE,
                     "--timeout", "600", "--port", str(port)], tmp_path, "first")
    out1 = Lines(first)
    try:
        hicem, opened_sim, frozen = _spraying_second_section(port, tmp_path, first.pid)
    except BaseException:
        _power_loss(first.pid)
        first.wait()
        raise AssertionError("first launch:\n" + out1.text()[-6000:])
    killed = _power_loss(first.pid, frozen)
    first.wait()
    print("[power_loss] cut at %s: HICEM %s, the valve open since sim %.2f s; %d processes killed" % (
        time.strftime("%H:%M:%S"), hicem, opened_sim, len(killed)))
    run = out1.find(r"\[main\] run (\S+): devices").group(1)
    assert not os.path.exists(str(results / run / "report.json")), "the cut run wrote a report"
    assert out1.find(r"\[1/3 taping\] taping succeeded"), out1.text()[-4000:]
    assert _all_gone(killed, within_s=10.0), "still running after SIGKILL: %s" % _all_gone(killed, 0.0, report=True)

    second = _driver(["--results-dir", str(results), "--resume", "--timeout", "600"], tmp_path, "second")
    out2 = Lines(second)
    code = second.wait(timeout=700)
    time.sleep(0.5)
    text = out2.text()
    print(text[-3000:])
    assert code == 0, text[-6000:]
    assert "[main] resuming run %s" % run in text, text[-3000:]
    assert not out2.find(r"\[1/3 taping\] (starting|resuming) taping"), "taping ran again:\n" + text[-4000:]
    assert out2.find(r"\[2/3 spraying\] resuming spraying"), text[-4000:]

    with open(str(results / run / "report.json"), encoding="utf-8") as handle:
        report = json.load(handle)
    assert [(p["name"], p["status"]) for p in report["processes"]] == \
        [("taping", "succeeded"), ("spraying", "succeeded"), ("sanding", "succeeded")], report["processes"]
    launches = report["launches"]
    assert len(launches) == 2 and launches[0]["ended"].startswith("cut off") and launches[1]["ended"] == "completed", \
        launches
    assert report["ended"]["reason"] == "completed", report["ended"]
    assert report["timing"]["wall_clock_total_s"] > report["timing"]["wall_clock_s"], report["timing"]

    o = report["outcome"]
    # no joint taped twice: one TAPE_LINE task per joint in PEMKRE's log, no stretch taped twice on the world's map
    tape_tasks = sum(int(float(k["count"])) for k in report["kpis"] if k.get("actionType") == "TAPE_LINE")
    assert tape_tasks == o["joints_total"] == 2, (tape_tasks, o["joints_total"])
    for jid, joint in o["joints"].items():
        assert joint["taped"] and joint["coverage"] >= 0.99 and joint["double_m"] <= 0.02, (jid, joint)
    # no section sprayed twice: the seam where the spray stopped at the cut, and the wall's thickness
    wall = o["walls"]["wall_1"]
    print("[power_loss] wall: coverage %.4f, CV %.4f; valve opened at sim %.3f s before the cut; seams %s" % (
        wall["spray_coverage"], wall["thickness_cv"], opened_sim, o["spray_seams"]))
    assert wall["spray_coverage"] >= 0.98 and wall["thickness_cv"] <= 0.15, wall
    # the pass the cut ended: the first to end after the valve opened for it
    seams = [x for x in o["spray_seams"] if x.get("sim_time") is not None and x["sim_time"] >= opened_sim]
    assert seams, "no spray pass ended inside the area after sim %.2f s: %s" % (opened_sim, o["spray_seams"])
    seam = min(seams, key=lambda x: x["sim_time"])
    # a cut that came in a turn (the lane finished, the valve closed) ended no pass: the pass found then ended at
    # its lane's end, where the other passes of that edge of the section end too (at most LANE_END_SPREAD_M apart);
    # the resumed raster starts its next lane. A pass the cut ended stands alone in the middle of a lane.
    at_lane_end = [x for x in o["spray_seams"] if x is not seam and x["area"] == seam["area"]
                   and abs(x["s"] - seam["s"]) <= LANE_END_SPREAD_M]
    assert seam["gap_m"] <= LONGEST_FLAW_M, seam
    if at_lane_end:
        print("[power_loss] the cut came in a turn: the pass ended at its lane's end (s %.3f m, as %d other passes); "
              "no second coat of the cut to check" % (seam["s"], len(at_lane_end)))
    else:
        assert seam["double_m"] <= LONGEST_FLAW_M, seam
    assert o["sand_coverage"] >= 0.98 and o["collisions"] == 0, o
