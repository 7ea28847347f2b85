"""The job reads the worksite's outcome with the parts HICEM left for manual work so far (the tracker's plan, as
the job node sends it to ``sim/outcome`` and ``sim/save_outcome``), measured by a real outcome recorder; a plan the
worksite refuses does not cost the job its outcome: it is read without the plan and the refusal is kept for the
report."""
import pytest

from locem_bridge.job.tracker import JobStep, JobTracker, with_manual_plan
from locem_bridge.sim.config import load_robot, validate_site
from locem_bridge.sim.outcome import OutcomeRecorder
from locem_bridge.sim.site import Site

TAPING = JobStep("taping", "urn:p#Taping")


@pytest.fixture
def worksite():
    """A stand-in for the job node's service call: ``sim/outcome`` answered by a real recorder (one 4 m wall, its
    first joint taped from 0.3 m up) the way the worksite node answers (a refusal: RuntimeError '<service>:
    outcome refused: <why>'); the calls made are listed."""
    cfg = validate_site({
        "site": {"name": "bay", "room": {"inside": [2.0, 1.5]}, "walls": [
            {"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.0, 3.0], "height": 2.4, "panel_width": 1.2}]},
        "simulation": {"outcome": {"grid": 0.02, "tape_lateral_tolerance": 0.015, "contact_tolerance": 0.01,
                                   "spray_rate": 0.004, "spray_target_thickness": 0.001}}})
    site = Site(cfg)
    rec = OutcomeRecorder(site, load_robot()["robot"]["tools"], cfg["simulation"]["outcome"])
    wall = site.wall("wall_1")
    a, b = wall.from_wall_coords(1.2, 0.3), wall.from_wall_coords(1.2, 2.4)
    rec.record("taping_tool", True, a, b, -wall.n, 1.0)
    rec.record("taping_tool", False, b, b, -wall.n, 0.1)
    calls = []

    def call(name, **args):
        calls.append((name, args))
        try:
            return rec.summary(args.get("manual"))
        except ValueError as exc:
            raise RuntimeError("%s: outcome refused: %s" % (name, exc))
    return call, calls


def _report(tracker, task, detail):
    tracker.on_state({"process": TAPING.iri, "phase": "reporting", "action_type": "TAPE_LINE", "task": task,
                      "detail": detail})


def test_the_outcome_is_read_with_the_manual_parts_and_without_them_when_refused(worksite):
    call, calls = worksite
    tracker = JobTracker([TAPING], {"joints": 3}, say=lambda line: None)
    out, refused = with_manual_plan(call, "sim/outcome", tracker.manual_plan())       # no plan yet
    assert calls[-1] == ("sim/outcome", {"manual": {"areas": [], "joints": []}}) and refused == ""
    assert out["joints"]["wall_1_joint_1"]["coverage_reachable"] == pytest.approx(2.1 / 2.4, abs=0.01)

    tracker.begin(0)
    _report(tracker, "t1", "taped; manual work on wall_1_joint_1: part 1 (along 0..0.3 m; below the tool's reach)")
    out, refused = with_manual_plan(call, "sim/outcome", tracker.manual_plan())
    assert calls[-1][1] == {"manual": {"areas": [], "joints": [{"joint": "wall_1_joint_1", "along": [0.0, 0.3]}]}}
    joint = out["joints"]["wall_1_joint_1"]
    assert joint["manual_m"] == pytest.approx(0.3) and joint["coverage_reachable"] == pytest.approx(1.0)
    assert out["reachable"]["tape_coverage_min"] == 0.0 and refused == ""     # joints 2 and 3: untaped

    _report(tracker, "t2", "taped; manual work on wall_7_joint_1: part 1 (along 0..0.5 m)")   # not on this site
    out, refused = with_manual_plan(call, "sim/outcome", tracker.manual_plan())
    assert [c[1] for c in calls[-2:]] == [{"manual": tracker.manual_plan()}, {}]     # refused, read again without
    assert "manual.joints[1].joint 'wall_7_joint_1' is not a joint of this site" in refused
    assert out["joints"]["wall_1_joint_1"]["manual_m"] == 0.0              # measured, on the whole work



def test_a_failure_that_is_no_refusal_of_the_plan_stays_a_failure():
    def away(name, **args):
        raise RuntimeError("%s: the worksite did not answer" % name)
    with pytest.raises(RuntimeError, match="did not answer"):
        with_manual_plan(away, "sim/save_outcome", {"areas": [], "joints": []}, folder="/tmp/x")
