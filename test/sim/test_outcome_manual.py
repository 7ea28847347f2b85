"""The outcome measured on the parts the robot was to work: HICEM leaves what the robot cannot reach to the hand
(planned manual parts of areas and joints); the worksite's numbers then count the robot on the rest, find work done
deep inside the manual parts, and the pictures draw them. A plan that does not fit the site is refused."""
import itertools
import json
import os

import numpy as np
import pytest

from locem_bridge.sim.config import validate_site
from locem_bridge.sim.outcome import MANUAL_EDGE, PLANNED, OutcomeRecorder
from locem_bridge.sim.site import Site
from locem_bridge.sim.worksite import Worksite

AREA = "wall_1_area_1"


def _site():
    """wall_1: 4 x 2.4 m, one area (the whole wall), vertical joints at 1.2, 2.4, 3.6 m (wall_1_joint_1..3), a
    horizontal joint at 1.2 m (wall_1_joint_4); wall_2: a 1 m wall beside it."""
    return validate_site({
        "site": {"name": "bay", "room": {"inside": [2.0, 1.5]}, "walls": [
            {"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.0, 3.0], "height": 2.4, "panel_width": 1.2,
             "horizontal_joints": [1.2]},
            {"id": "wall_2", "p0": [4.0, 3.0], "p1": [4.0, 2.0], "height": 2.4, "panel_width": 0.6}]},
        "simulation": {"outcome": {"grid": 0.02, "tape_lateral_tolerance": 0.015, "contact_tolerance": 0.01,
                                   "spray_rate": 0.004, "spray_target_thickness": 0.001}}})


@pytest.fixture
def bay(robot_cfg):
    cfg = _site()
    site = Site(cfg)
    tools = robot_cfg["robot"]["tools"]
    rec = OutcomeRecorder(site, tools, cfg["simulation"]["outcome"])
    wall = site.wall("wall_1")
    standoff = tools["spray_gun"]["standoff"]

    def spray(s0, s1, t0, t1, spacing=0.15, speed=0.5):
        """Horizontal lanes as HICEM sprays them (lane spacing about half the fan, 0.5 m/s), nozzle at the standoff
        aimed at the wall; the gun closes after the last lane."""
        for t in np.arange(t0, t1 + 1e-9, spacing):
            p0 = wall.from_wall_coords(s0, t) + standoff * wall.n
            p1 = wall.from_wall_coords(s1, t) + standoff * wall.n
            rec.record("spray_gun", True, p0, p1, -wall.n, abs(s1 - s0) / speed)
        rec.record("spray_gun", False, p1, p1, -wall.n, 0.1)

    def stroke(tool, s0, s1, t0, t1):
        """One stroke of ``tool`` on the wall surface from (s0, t0) to (s1, t1), switched on, then off."""
        a, b = wall.from_wall_coords(s0, t0), wall.from_wall_coords(s1, t1)
        rec.record(tool, True, a, b, -wall.n, 1.0)
        rec.record(tool, False, b, b, -wall.n, 0.1)
    return rec, wall, spray, stroke


def test_an_area_sprayed_except_its_manual_strip_is_fully_covered_where_the_robot_was_to_work(bay):
    rec, wall, spray, _ = bay
    spray(-0.1, 3.4, 0.0, 2.4)                     # lanes up to the strip the plan leaves to the hand
    manual = {"areas": [{"work": "spray", "area": AREA, "along": [3.4, 4.0], "height": [0.0, 2.4]}]}
    s = rec.summary(manual)
    w = s["walls"]["wall_1"]
    assert w["spray_coverage"] == pytest.approx(3.4 / 4.0, abs=0.01)          # the strip counts as not sprayed
    assert w["spray_coverage_reachable"] >= 0.995                              # the robot's part is covered
    other = s["walls"]["wall_2"]["work_area_m2"]                               # wall_2: nothing sprayed
    robots = w["work_area_m2"] - w["spray_manual_m2"]
    assert s["reachable"]["spray_coverage"] == pytest.approx(w["spray_coverage_reachable"] * robots / (robots + other))
    assert w["spray_manual_m2"] == pytest.approx(0.6 * 2.4, abs=0.05)
    assert w["sand_manual_m2"] == 0.0                                          # the plan is for spraying only
    assert w["thickness_cv_reachable"] < 0.1
    assert s["manual_touched"] == {"tape_m": 0.0, "spray_m2": 0.0, "sand_m2": 0.0}   # the fan's edge is no fault
    assert s["reachable"]["spray_thickness_cv"] == pytest.approx(max(
        x["thickness_cv_reachable"] for x in s["walls"].values()))
    # a lane sprayed deep in the manual strip: work where the robot cannot reach
    spray(3.55, 3.9, 1.2, 1.2)
    touched = rec.summary(manual)["manual_touched"]
    assert 0.01 < touched["spray_m2"] < 0.35 * 2 * 0.15
    assert touched["tape_m"] == 0.0 and touched["sand_m2"] == 0.0


def test_sanding_up_to_a_manual_band_is_no_fault_and_sanding_in_it_is(bay, robot_cfg):
    rec, wall, _, stroke = bay
    pad = robot_cfg["robot"]["tools"]["sander"]["pad_radius"]
    for t in np.arange(0.0, 2.0 + 1e-9, 0.18):                # pad rows up to the band above the tool's reach
        stroke("sander", 0.0, 4.0, t, t)
    stroke("sander", 0.0, 4.0, 2.0, 2.0)                       # the last row's pad centre on the band's edge
    manual = {"areas": [{"work": "sand", "area": AREA, "along": [0.0, 4.0], "height": [2.0, 2.4]}]}
    s = rec.summary(manual)
    w = s["walls"]["wall_1"]
    assert w["sand_coverage_reachable"] >= 0.995 and w["sand_coverage"] < 0.93
    assert w["sand_manual_m2"] == pytest.approx(4.0 * 0.4, abs=0.1)
    w2 = s["walls"]["wall_2"]                                  # the pad at the corner touched wall_2 too
    robots = w["work_area_m2"] - w["sand_manual_m2"]
    assert s["reachable"]["sand_coverage"] == pytest.approx(
        (w["sand_coverage_reachable"] * robots + w2["sand_coverage"] * w2["work_area_m2"]) / (robots + w2["work_area_m2"]))
    assert s["manual_touched"]["sand_m2"] == 0.0               # the pad's reach past the edge is expected
    assert 2.0 + pad + MANUAL_EDGE < 2.3
    stroke("sander", 1.0, 2.0, 2.3, 2.3)                       # the pad deep in the band
    assert rec.summary(manual)["manual_touched"]["sand_m2"] > 0.05


def test_tape_is_measured_on_the_robots_part_of_a_joint_and_found_inside_its_manual_part(bay):
    rec, wall, _, stroke = bay
    stroke("taping_tool", 1.2, 1.2, 0.4, 2.4)                  # wall_1_joint_1 from 0.4 m up
    stroke("taping_tool", 2.4, 2.4, 0.0, 2.4)                  # wall_1_joint_2 whole
    manual = {"joints": [{"joint": "wall_1_joint_1", "along": [0.0, 0.4]},
                         {"joint": "wall_1_joint_3", "along": [0.0, 2.4]}]}     # wholly manual
    s = rec.summary(manual)
    j1, j3 = s["joints"]["wall_1_joint_1"], s["joints"]["wall_1_joint_3"]
    assert j1["coverage"] == pytest.approx(2.0 / 2.4, abs=0.01) and j1["coverage_reachable"] == pytest.approx(1.0)
    assert j1["manual_m"] == pytest.approx(0.4) and j3["manual_m"] == pytest.approx(2.4)
    assert j3["coverage_reachable"] is None
    assert s["joints"]["wall_1_joint_2"]["manual_m"] == 0.0
    robot = [s["joints"][j]["coverage_reachable"] for j in sorted(s["joints"]) if j != "wall_1_joint_3"]
    assert s["reachable"]["tape_coverage"] == pytest.approx(np.mean(robot))     # joint 3 is no robot joint
    assert s["reachable"]["tape_coverage_min"] == pytest.approx(min(robot))
    assert s["manual_touched"]["tape_m"] == 0.0
    stroke("taping_tool", 1.2, 1.2, 0.1, 0.4)                  # tape laid into the manual part
    stroke("taping_tool", 3.6, 3.6, 1.0, 1.5)                  # and into the wholly manual joint
    s = rec.summary(manual)
    assert s["manual_touched"]["tape_m"] == pytest.approx((0.4 - 0.1 - 0.02) + 0.5, abs=0.03)
    assert s["joints"]["wall_1_joint_3"]["coverage_reachable"] is None


def test_a_joint_taped_by_hand_is_no_robot_joint_and_an_all_manual_site_has_no_reachable_tape(bay):
    rec, wall, _, stroke = bay
    stroke("taping_tool", 1.2, 1.2, 0.0, 2.4)
    rec.mark_manual_taping("wall_1_joint_2")
    s = rec.summary()
    assert s["joints"]["wall_1_joint_2"]["coverage_reachable"] == 0.0
    assert s["reachable"]["tape_coverage_min"] == 0.0          # joint 3, 4 and wall_2's are untaped
    everything = {"joints": [{"joint": j, "along": [0.0, 5.0]} for j in s["joints"]]}
    s = rec.summary(everything)
    assert s["reachable"]["tape_coverage"] is None and s["reachable"]["tape_coverage_min"] is None
    assert s["manual_touched"]["tape_m"] == pytest.approx(2.4, abs=0.02)   # all of joint 1: nowhere reachable


def test_without_manual_parts_every_reachable_figure_is_the_plain_one(bay):
    rec, wall, spray, stroke = bay
    spray(0.5, 2.5, 0.3, 1.8)
    stroke("sander", 0.2, 3.0, 1.0, 1.0)
    stroke("taping_tool", 1.2, 1.2, 0.0, 1.7)
    stroke("taping_tool", 0.0, 3.1, 1.2, 1.2)
    for s in (rec.summary(), rec.summary({"areas": [], "joints": []}), rec.summary({})):
        for j in s["joints"].values():
            assert j["coverage_reachable"] == j["coverage"] and j["manual_m"] == 0.0
        for w in s["walls"].values():
            assert w["spray_coverage_reachable"] == w["spray_coverage"]
            assert w["sand_coverage_reachable"] == w["sand_coverage"]
            assert w["thickness_cv_reachable"] == w["thickness_cv"]
            assert w["spray_manual_m2"] == 0.0 and w["sand_manual_m2"] == 0.0
        r = s["reachable"]
        assert 0.0 < s["spray_coverage"] < 1.0 and 0.0 < s["sand_coverage"] < 1.0 and 0.0 < s["tape_coverage"] < 1.0
        assert (r["spray_coverage"], r["sand_coverage"], r["tape_coverage"]) == \
            (s["spray_coverage"], s["sand_coverage"], s["tape_coverage"])
        assert r["tape_coverage_min"] == min(j["coverage"] for j in s["joints"].values())
        assert r["spray_thickness_cv"] == max(w["thickness_cv"] for w in s["walls"].values()) > 0.0
        assert s["manual_touched"] == {"tape_m": 0.0, "spray_m2": 0.0, "sand_m2": 0.0}


@pytest.mark.parametrize("manual, words", [
    (["wall_1_area_1"], ['manual must be an object {"areas": [...], "joints": [...]}, got list']),
    ({"areas": [], "walls": []}, ["unknown key(s) 'walls'", "allowed: areas, joints"]),
    ({"areas": {"area": AREA}}, ["manual.areas must be a list of {work, area, along, height}, got dict"]),
    ({"areas": [{"work": "paint", "area": AREA, "along": [0, 1], "height": [0, 1]}]},
     ["manual.areas[0].work 'paint' is not one of spray, sand"]),
    ({"areas": [{"work": "spray", "area": "wall_9_area_1", "along": [0, 1], "height": [0, 1]}]},
     ["manual.areas[0].area 'wall_9_area_1' is not an area of this site", "known: wall_1_area_1, wall_2_area_1"]),
    ({"areas": [{"work": "sand", "area": AREA, "along": [1.0, 0.5], "height": [0, 1]}]},
     ["manual.areas[0].along must be [a, b], two numbers with a <= b", "got [1.0, 0.5]"]),
    ({"areas": [{"work": "sand", "area": AREA, "along": [0, 1], "height": "low"}]},
     ["manual.areas[0].height must be [a, b]", "metres above the floor"]),
    ({"areas": [{"work": "sand", "area": AREA, "height": [0, 1]}]}, ["manual.areas[0] misses along"]),
    ({"joints": [{"joint": "wall_1_joint_9", "along": [0, 1]}]},
     ["manual.joints[0].joint 'wall_1_joint_9' is not a joint of this site", "known: wall_1_joint_1"]),
    ({"joints": [{"joint": "wall_1_joint_1", "along": [0, float("nan")]}]},
     ["manual.joints[0].along must be [a, b]", "from the joint's start"]),
])
def test_a_plan_that_does_not_fit_the_site_is_refused_naming_what_is_wrong(bay, tmp_path, manual, words):
    rec = bay[0]
    for call in (lambda: rec.summary(manual), lambda: rec.save_pictures(str(tmp_path), manual=manual)):
        with pytest.raises(ValueError) as info:
            call()
        for w in words:
            assert w in str(info.value)
    assert not os.listdir(str(tmp_path))                   # nothing drawn for a refused plan


def _overlap(a, b):
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _planned(img, box):
    x0, y0, x1, y1 = box
    return (img[y0:y1, x0:x1] == np.array(PLANNED)).all(axis=-1).mean()


def test_pictures_draw_the_planned_manual_parts_with_their_legend_entry(bay, tmp_path):
    from PIL import Image
    rec, wall, spray, _ = bay
    spray(-0.1, 3.4, 0.0, 2.4)
    manual = {"areas": [{"work": "spray", "area": AREA, "along": [3.4, 4.0], "height": [0.0, 2.4]},
                        {"work": "sand", "area": AREA, "along": [0.0, 4.0], "height": [2.0, 2.4]}],
              "joints": [{"joint": "wall_1_joint_1", "along": [0.0, 0.4]}]}
    px = 100.0
    lay = rec.picture_layout("wall_1", px, manual)
    assert "planned" in {k for k, _ in lay.swatches}
    assert "manual (planned)" in [t.text for t in lay.texts if t.role == "legend"]
    boxes = [t.box for t in lay.texts] + [b for _, b in lay.swatches] + list(lay.panels)
    for a, b in itertools.combinations(boxes, 2):
        assert not _overlap(a, b), (a, b)
    w, h = lay.size
    assert all(0 <= x0 and 0 <= y0 and x1 <= w and y1 <= h for x0, y0, x1, y1 in boxes)
    assert "planned" not in {k for k, _ in rec.picture_layout("wall_2", px, manual).swatches}   # none on wall_2
    assert "planned" not in {k for k, _ in rec.picture_layout("wall_1", px).swatches}

    rec.save_pictures(str(tmp_path / "manual"), px, manual)
    rec.save_pictures(str(tmp_path / "plain"), px)
    img = np.asarray(Image.open(str(tmp_path / "manual" / "wall_1.png")).convert("RGB")).astype(int)
    plain = np.asarray(Image.open(str(tmp_path / "plain" / "wall_1.png")).convert("RGB")).astype(int)
    assert img.shape[:2] == (h, w)
    (j0, y0, _, y1), (x1, _, _, _), (x2, _, _, _) = lay.panels

    def box(x_off, s0, s1, t0, t1, inset=3):
        return (int(x_off + s0 * px) + inset, int(y1 - t1 * px) + inset, int(x_off + s1 * px) - inset,
                int(y1 - t0 * px) - inset)
    strip, band = box(x1, 3.4, 4.0, 0.0, 2.4), box(x2, 0.0, 4.0, 2.0, 2.4)
    assert 0.05 < _planned(img, strip) < 0.5                    # hatched: the thickness shows between the lines
    assert 0.05 < _planned(img, band) < 0.5
    assert _planned(img, box(x1, 0.2, 3.2, 0.2, 2.2)) == 0.0    # the robot's part of the spray panel: not hatched
    assert _planned(img, box(x2, 0.2, 3.8, 0.2, 1.8)) == 0.0
    tape = box(j0, 1.2, 1.2, 0.0, 0.4, inset=0)                 # the manual stretch of joint 1, bottom 0.4 m
    stretch = img[tape[1] + 3:tape[3] - 3, tape[0] - 1:tape[0] + 2]
    assert (stretch == np.array(PLANNED)).all(axis=-1).mean() > 0.9
    assert _planned(plain, (0, 0, w, plain.shape[0])) == 0.0    # no plan, nothing drawn as planned


@pytest.fixture
def ws(site_cfg, robot_cfg, port):
    w = Worksite(site_cfg, robot_cfg, modbus_port=port, can_interface="virtual",
                 can_channel="manual-%d" % os.getpid(), with_ur=False)
    w.start()
    yield w
    w.stop()


def test_the_worksite_measures_and_draws_with_the_plan_it_is_given(ws, tmp_path):
    scan = ws.scan()
    area, joint = scan["areas"][0], scan["joints"][0]
    manual = {"areas": [{"work": "spray", "area": area["id"], "along": [0.0, 0.5], "height": [0.0, 1.0]}],
              "joints": [{"joint": joint["id"], "along": [0.0, 0.3]}]}
    plain = ws.outcome()
    assert plain["reachable"]["spray_coverage"] == plain["spray_coverage"] == 0.0
    out = ws.save_outcome(str(tmp_path), manual)
    saved = json.loads((tmp_path / "outcome.json").read_text())
    assert saved["joints"][joint["id"]]["manual_m"] == pytest.approx(0.3)
    assert saved["walls"][area["wall"]]["spray_manual_m2"] == pytest.approx(0.5 * 1.0, abs=0.05)
    assert saved["manual_touched"] == {"tape_m": 0.0, "spray_m2": 0.0, "sand_m2": 0.0}
    assert out["pictures"] == ["wall_1.png", "wall_2.png"]
    assert ws.outcome(manual)["joints"][joint["id"]]["manual_m"] == pytest.approx(0.3)
    with pytest.raises(ValueError, match="not an area of this site"):
        ws.outcome({"areas": [{"work": "spray", "area": "nowhere", "along": [0, 1], "height": [0, 1]}]})
