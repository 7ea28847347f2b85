"""SCAN stand-in: visible features from the base pose, contract shape, configured noise."""
import copy
import math

import numpy as np
import pytest

from locem_bridge.sim.config import load_site
from locem_bridge.sim.perception import WallScanner
from locem_bridge.sim.site import Site


def test_scan_facing_wall_1_returns_its_joints_exactly_without_noise(site_cfg, robot_cfg):
    site = Site(site_cfg)
    sc = WallScanner(site, robot_cfg["robot"]["scanner"], position_noise=0.0)
    out = sc.scan([2.4, 1.6, math.pi / 2], stamp=3.0)
    assert out["stamp"] == 3.0
    assert set(out) == {"stamp", "walls", "joints", "areas", "obstacles"}
    ids = {j["id"] for j in out["joints"]}
    assert {"wall_1_joint_1", "wall_1_joint_2", "wall_1_joint_3", "wall_1_joint_4"} <= ids
    truth = {j.id: j for j in site.joints}
    j2 = next(j for j in out["joints"] if j["id"] == "wall_1_joint_2")
    assert j2 == {"id": "wall_1_joint_2", "wall": "wall_1", "kind": "vertical", "start": [2.4, 3.6, 0.0],
                  "end": [2.4, 3.6, 2.5], "width": 0.05}
    for j in out["joints"]:
        if j["kind"] == "vertical":
            assert np.allclose(j["start"], truth[j["id"]].start) and np.allclose(j["end"], truth[j["id"]].end)
    w1 = next(w for w in out["walls"] if w["id"] == "wall_1")
    assert w1["normal"] == [0.0, -1.0, 0.0] and w1["p0"] == [0.0, 3.6]
    assert {a["id"] for a in out["areas"]} >= {"wall_1_area_1", "wall_1_area_2"}
    assert all(w["id"] in ("wall_1", "wall_2") for w in out["walls"])     # concrete walls are no work surface


def test_scan_sees_only_what_is_in_range_and_field_of_view(site_cfg, robot_cfg):
    site = Site(site_cfg)
    cfg = copy.deepcopy(robot_cfg["robot"]["scanner"])
    cfg["fov"] = math.radians(60)
    cfg["range"] = 2.5
    sc = WallScanner(site, cfg)
    out = sc.scan([2.4, 1.6, math.pi / 2])               # looking at wall_1 centre, narrow cone
    vert = {j["id"] for j in out["joints"] if j["kind"] == "vertical"}
    assert vert == {"wall_1_joint_2"}                     # x = 1.2 and 3.6 are outside +-30 deg
    horiz = next(j for j in out["joints"] if j["kind"] == "horizontal")
    assert 1.0 < horiz["start"][0] < 2.4 < horiz["end"][0] < 3.8      # clipped to the visible part
    assert [w["id"] for w in out["walls"]] == ["wall_1"]
    away = sc.scan([2.4, 1.6, -math.pi / 2])              # back to wall_1: nothing plasterboard in view
    assert away["joints"] == [] and away["walls"] == []


def test_scan_noise_stays_within_configured_sigma(site_cfg, robot_cfg):
    site = Site(site_cfg)
    sigma = 0.005
    sc = WallScanner(site, robot_cfg["robot"]["scanner"], position_noise=sigma, seed=7)
    truth = {j.id: j for j in site.joints}
    errs = []
    for _ in range(50):
        out = sc.scan([2.4, 1.6, math.pi / 2])
        for j in out["joints"]:
            if j["kind"] == "vertical" and j["wall"] == "wall_1":
                errs.append(np.subtract(j["start"], truth[j["id"]].start))
    errs = np.array(errs)
    assert np.abs(errs).max() <= 5 * sigma
    along = errs[:, [0, 2]]                              # wall_1: along the wall (x) and in height (z)
    assert 0.7 * sigma < along.std() < 1.3 * sigma       # the configured sigma, not more, not less
    assert np.abs(errs[:, 1]).max() == pytest.approx(0.0, abs=1e-9)   # joints stay on the wall plane


def test_site_without_joints_scans_walls_and_areas_only(robot_cfg):
    from locem_bridge.common.paths import checkout_root
    import os
    site = Site(load_site(os.path.join(checkout_root(), "config", "sites", "no_joints.yaml")))
    out = WallScanner(site, robot_cfg["robot"]["scanner"]).scan(site.robot_start)
    assert out["joints"] == []
    assert [w["id"] for w in out["walls"]] == ["wall_1"]
    assert out["areas"][0]["width"] == pytest.approx(3.0) and out["areas"][0]["height"] == pytest.approx(2.5)


def _wall_work(site, robot_cfg, site_cfg):
    """An OutcomeRecorder of the site and helpers that pass the spray gun / the sander over wall_1 (through record)."""
    from locem_bridge.sim.outcome import OutcomeRecorder
    rec = OutcomeRecorder(site, robot_cfg["robot"]["tools"], site_cfg["simulation"]["outcome"])
    wall = next(w for w in site.work_walls if w.id == "wall_1")
    standoff = robot_cfg["robot"]["tools"]["spray_gun"]["standoff"]

    def spray(s0, s1, t0, t1, spacing=0.1, speed=0.1):   # horizontal lanes, nozzle at the standoff, aimed at the wall
        for t in np.arange(t0, t1 + 1e-9, spacing):
            p0 = wall.from_wall_coords(s0, t) + standoff * wall.n
            p1 = wall.from_wall_coords(s1, t) + standoff * wall.n
            rec.record("spray_gun", True, p0, p1, -wall.n, (s1 - s0) / speed)

    def sand(s0, s1, t0, t1, spacing=0.2):                # pad on the surface
        for t in np.arange(t0, t1 + 1e-9, spacing):
            rec.record("sander", True, wall.from_wall_coords(s0, t), wall.from_wall_coords(s1, t), -wall.n, 1.0)
    return rec, spray, sand


def test_scan_reports_each_area_finish_from_the_recorded_outcome(site_cfg, robot_cfg):
    from locem_bridge.sim.perception import FINISHED_FRACTION, area_coverage
    site = Site(site_cfg)
    rec, spray, sand = _wall_work(site, robot_cfg, site_cfg)
    sc = WallScanner(site, robot_cfg["robot"]["scanner"], outcome=rec)
    pose = [2.4, 1.6, math.pi / 2]

    def finishes():
        return {a["id"]: a["finish"] for a in sc.scan(pose)["areas"]}
    assert finishes() == {"wall_1_area_1": "bare", "wall_1_area_2": "bare", "wall_2_area_1": "bare"}
    spray(-0.1, 2.5, 0.0, 2.5)                            # all of area_1 (s 0..2.4), a fringe of area_2
    a1, a2 = next(w for w in site.work_walls if w.id == "wall_1").areas
    cov1, cov2 = area_coverage(rec, a1), area_coverage(rec, a2)
    assert cov1[0] >= FINISHED_FRACTION and 0.0 < cov2[0] < 0.2
    # the per-area numbers add up to the recorder's own per-wall coverage (two equal areas)
    assert (cov1[0] + cov2[0]) / 2 == pytest.approx(rec.summary()["walls"]["wall_1"]["spray_coverage"])
    assert finishes() == {"wall_1_area_1": "sprayed", "wall_1_area_2": "bare", "wall_2_area_1": "bare"}
    spray(2.4, 4.9, 0.0, 2.3)                             # area_2 short of its top strip: under 98 %, still bare
    assert 0.9 < area_coverage(rec, a2)[0] < FINISHED_FRACTION
    assert finishes()["wall_1_area_2"] == "bare"
    spray(2.4, 4.9, 2.4, 2.5)
    assert finishes()["wall_1_area_2"] == "sprayed"
    sand(0.0, 2.4, 0.0, 2.5)
    assert area_coverage(rec, a1)[1] >= FINISHED_FRACTION
    assert finishes() == {"wall_1_area_1": "sanded", "wall_1_area_2": "sprayed", "wall_2_area_1": "bare"}
    # without a recorder the scan leaves finish out (the contract default applies)
    plain = WallScanner(site, robot_cfg["robot"]["scanner"]).scan(pose)
    assert all("finish" not in a for a in plain["areas"]) and plain["areas"]


def test_sanded_bare_board_is_not_reported_sanded(site_cfg, robot_cfg):
    from locem_bridge.sim.perception import FINISHED_FRACTION, area_coverage
    site = Site(site_cfg)
    rec, spray, sand = _wall_work(site, robot_cfg, site_cfg)
    sand(0.0, 2.4, 0.0, 2.5)
    a1 = next(w for w in site.work_walls if w.id == "wall_1").areas[0]
    spray_cov, sand_cov = area_coverage(rec, a1)
    assert spray_cov == 0.0 and sand_cov >= FINISHED_FRACTION
    out = WallScanner(site, robot_cfg["robot"]["scanner"], outcome=rec).scan([2.4, 1.6, math.pi / 2])
    assert next(a for a in out["areas"] if a["id"] == "wall_1_area_1")["finish"] == "bare"


def test_scan_reports_the_concrete_walls_as_obstacles_exact_without_noise(site_cfg, robot_cfg):
    site = Site(site_cfg)
    sc = WallScanner(site, robot_cfg["robot"]["scanner"], position_noise=0.0)
    out = sc.scan([2.4, 1.6, math.pi / 2])
    # the scanner sees all round (fov 2 pi): the concrete wall_3 behind the robot and wall_4 beside it
    assert out["obstacles"] == [{"id": "wall_3", "p0": [4.8, 0.0], "p1": [0.0, 0.0], "height": 2.5},
                                {"id": "wall_4", "p0": [0.0, 0.0], "p1": [0.0, 3.6], "height": 2.5}]
    assert {w["id"] for w in out["walls"]} == {"wall_1", "wall_2"}       # no work surface: not among the walls
    # the ground truth says the same
    assert site.to_contract()["obstacles"] == out["obstacles"]
    # visibility like a plasterboard wall: in range and field of view, facing the sensor
    cfg = copy.deepcopy(robot_cfg["robot"]["scanner"])
    cfg["fov"] = math.radians(60)
    cfg["range"] = 2.5
    narrow = WallScanner(site, cfg).scan([2.4, 1.6, math.pi / 2])           # looking at wall_1: nothing concrete
    assert "obstacles" not in narrow                                         # the contract's default: none
    back = WallScanner(site, cfg).scan([2.4, 1.6, -math.pi / 2])
    assert [o["id"] for o in back["obstacles"]] == ["wall_3"]


def test_obstacles_carry_the_position_noise_and_leave_the_features_noise_as_it_was(site_cfg, robot_cfg):
    site = Site(site_cfg)
    sigma = 0.005
    cfg = robot_cfg["robot"]["scanner"]
    errs = []
    sc = WallScanner(site, cfg, position_noise=sigma, seed=7)
    for _ in range(50):
        for o in sc.scan([2.4, 1.6, math.pi / 2])["obstacles"]:
            w = site.wall(o["id"])
            errs += [np.subtract(o["p0"], w.p0), np.subtract(o["p1"], w.p1)]
    errs = np.array(errs)
    assert np.abs(errs).max() < 5 * sigma and 0.5 * sigma < errs.std() < 1.5 * sigma
    # the obstacles' noise is drawn from a generator of its own: the walls, joints and areas are as noisy as
    # from a scanner that reports no obstacles, with the same seed
    class Blind(WallScanner):
        def _obstacles(self, sensor, heading):
            return []
    blind = Blind(site, cfg, position_noise=sigma, seed=7).scan([2.4, 1.6, math.pi / 2])
    seeing = WallScanner(site, cfg, position_noise=sigma, seed=7).scan([2.4, 1.6, math.pi / 2])
    assert "obstacles" not in blind and [o["id"] for o in seeing["obstacles"]] == ["wall_3", "wall_4"]
    assert {k: blind[k] for k in ("walls", "joints", "areas")} == {k: seeing[k] for k in ("walls", "joints", "areas")}
