"""SCAN ``obstacles`` in HICEM: walls that are no work surface (concrete) are checked, stored as the latest scan's
list (no features, never forwarded to PEMKRE) and kept off by GetWallReach's plan."""
import copy
import math

import numpy as np
import pytest
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from hicem_rig import params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler, validate_scan
from locem_bridge.hicem.datastore import DataManager, MemoryStore, PruneRule, SqliteStore
from locem_bridge.hicem.errors import ScanFormatError
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

# a concrete wall 1.81 m in front of wall_1 (y = 1.19), under x 1.5..2.5: the spray base (1.3 m off the wall,
# chassis 0.978 m long: its rear 1.789 m off) would stand 0.021 m from it, within the 0.05 m clearance
BEHIND = {"id": "wall_3", "p0": [2.5, 1.19], "p1": [1.5, 1.19], "height": 2.5}


def _with(*obstacles):
    scan = copy.deepcopy(SITE)
    scan["obstacles"] = [copy.deepcopy(o) for o in obstacles]
    return scan


class Sink:
    def __init__(self):
        self.updates = []

    def report_world(self, update):
        self.updates.append(copy.deepcopy(update))


def test_validate_scan_accepts_obstacles_and_defaults_to_none():
    assert validate_scan(SITE)["obstacles"] == []
    out = validate_scan(_with(BEHIND, {"id": "column_1", "p0": [1, 0], "p1": [1, 1], "height": 3}))
    assert out["obstacles"] == [BEHIND, {"id": "column_1", "p0": [1.0, 0.0], "p1": [1.0, 1.0], "height": 3.0}]
    assert validate_scan(_with())["obstacles"] == []


@pytest.mark.parametrize("mutate,msg", [
    (lambda s: s.update(obstacles={"id": "wall_3"}), "SCAN.obstacles must be a list"),
    (lambda s: s["obstacles"].append("wall_4"), "SCAN.obstacles[1] must be an object"),
    (lambda s: s["obstacles"][0].update(id="3rd"), "SCAN.obstacles[0].id must match"),
    (lambda s: s["obstacles"][0].update(id="wall_1"), "SCAN.obstacles[0].id 'wall_1' appears twice"),
    (lambda s: s["obstacles"][0].update(p0=[1.0]), "SCAN.obstacles[0].p0 must be a list of 2 numbers"),
    (lambda s: s["obstacles"][0].update(p1=[1.0, float("nan")]), "SCAN.obstacles[0].p1[1] must be a finite number"),
    (lambda s: s["obstacles"][0].update(p1=[2.5, 1.19]), "SCAN.obstacles[0]: p0 and p1 are the same point"),
    (lambda s: s["obstacles"][0].pop("height"), "SCAN.obstacles[0].height must be a finite number"),
    (lambda s: s["obstacles"][0].update(height=0.0), "SCAN.obstacles[0].height must be > 0"),
])
def test_validate_scan_refuses_bad_obstacles_naming_the_key(mutate, msg):
    scan = _with(BEHIND)
    mutate(scan)
    with pytest.raises(ScanFormatError) as ei:
        validate_scan(scan)
    assert msg in str(ei.value)


def test_the_latest_obstacles_are_stored_and_never_reach_pemkre(tmp_path):
    store = DataManager(MemoryStore(), SqliteStore(str(tmp_path / "h.sqlite")), ["features", "scan", "outbox"],
                        [PruneRule("features", below=("scan_seq", "scan", "latest_seq"))])
    sink = Sink()
    hdh = DataHandler(store, sink)
    assert hdh.obstacles() == []                                        # nothing scanned yet
    hdh.ingest_scan(_with(BEHIND))
    assert hdh.obstacles() == [BEHIND]
    assert store.persistent.value("scan", "obstacles") == [BEHIND]     # survives a restart with the features
    assert hdh.features("obstacle") == [] and "wall_3" not in {e.key for e in store.entries("features")}
    (update,) = sink.updates
    assert set(update) == {"stamp", "walls", "joints", "areas"}        # PEMKRE: features only
    assert "wall_3" not in str(update)
    # only the obstacles moved: nothing for PEMKRE, the store has the latest list
    moved = dict(BEHIND, p0=[2.6, 1.19])
    res = hdh.ingest_scan(_with(moved))
    assert res.new == [] and res.changed == [] and len(sink.updates) == 1
    assert hdh.obstacles() == [moved]
    hdh.ingest_scan(SITE)                                               # a scan that sees none
    assert hdh.obstacles() == []
    # a bad obstacle refuses the whole scan: nothing stored
    hdh.ingest_scan(_with(BEHIND))
    with pytest.raises(ScanFormatError):
        hdh.ingest_scan(_with(dict(BEHIND, height=-1)))
    assert hdh.obstacles() == [BEHIND]


def _plan(hdh):
    ctx = NodeContext(locem=LocemDouble(), store=hdh.store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=OperatorDesk(), data_handler=hdh)
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">'
                    '<GetWallReach feature_id="wall_1_area_1" work="spray" plan="{plan}"/></BehaviorTree></root>')
    tree = lib.build("T", ctx, bb)
    assert tree.tick() == Status.SUCCESS, ctx.failures
    return bb.get("plan")


def test_get_wall_reach_keeps_the_base_off_the_scanned_obstacles():
    hdh = DataHandler(DataManager())
    hdh.ingest_scan(SITE)
    free = _plan(hdh)
    # nothing behind the robot: a base anywhere in front of x 1.5..2.5 (wall_1 runs along x from 0)
    assert any(a <= 1.5 and 2.5 <= b for a, b in free["base"])
    hdh.ingest_scan(_with(BEHIND))              # the same walls: the plan cache must see the obstacle too
    plan = _plan(hdh)
    assert plan["base"] != free["base"]
    # the chassis (0.776 m wide) keeps the 0.05 m clearance from the obstacle's ends 1.5 and 2.5 along the wall
    keep = 0.776 / 2 + 0.05
    for a, b in plan["base"]:
        assert b <= 1.5 - keep + 0.02 or a >= 2.5 + keep - 0.02, plan["base"]
    # what the spray gun reaches (0.3 m to either side of a free base) leaves the middle manual
    assert not any(a <= 2.0 <= b for a, b in plan["tool"])
    assert any("no free base pose" in why for _iv, why in plan["why"])
    hdh.ingest_scan(SITE)                       # the obstacle gone (latest scan): the plan as before
    assert _plan(hdh)["base"] == free["base"]


def _gap(x, y, theta, length, width, a, b):
    """Distance of the chassis at ``(x, y, theta)`` from the segment a-b (0: they meet), sampled every 5 mm."""
    c, s = math.cos(theta), math.sin(theta)
    fwd, side = np.array([c, s]) * length / 2.0, np.array([-s, c]) * width / 2.0
    centre = np.array([x, y])
    corners = [centre + fwd + side, centre - fwd + side, centre - fwd - side, centre + fwd - side]
    outline = np.concatenate([np.linspace(p, q, 200) for p, q in zip(corners, corners[1:] + corners[:1])])
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    t = np.clip((outline - a) @ (b - a) / ((b - a) @ (b - a)), 0.0, 1.0)
    d = float(np.min(np.linalg.norm(outline - (a + t[:, None] * (b - a)), axis=1)))
    rel = (np.array([a, b]) - centre) @ np.array([[c, -s], [s, c]])     # the segment's ends in the chassis frame
    inside = np.any((np.abs(rel[:, 0]) <= length / 2.0) & (np.abs(rel[:, 1]) <= width / 2.0))
    return 0.0 if inside else d


def test_bay_21_no_planned_spray_base_on_wall_1_backs_into_the_concrete_wall_behind():
    """The whole job's finding: on generated bay 21 the planned spray pose for wall_1_area_3 put the chassis' rear
    corner into the concrete wall_3 (no corner of wall_1, not among the scanned plasterboard walls)."""
    from locem_bridge.sim.bays import generate_bay
    from locem_bridge.sim.config import load_robot, validate_site
    from locem_bridge.sim.perception import WallScanner
    from locem_bridge.sim.site import Site
    doc = validate_site(generate_bay(21))
    site = Site(copy.deepcopy(doc))
    noise = doc["simulation"]["perception"]["position_noise"]
    scan = WallScanner(site, load_robot()["robot"]["scanner"], noise, 21).scan(site.robot_start)
    assert [o["id"] for o in scan["obstacles"]] == ["wall_3", "wall_4"]
    entries = params().blackboard_entries()
    length, width = entries["robot.base.footprint"]
    standoff = entries["robot.work.spray.base_standoff"]
    w3 = site.wall("wall_3")
    wall = next(w for w in scan["walls"] if w["id"] == "wall_1")
    p0, n = np.array(wall["p0"]), np.array(wall["normal"][:2])
    u = (np.array(wall["p1"]) - p0) / np.linalg.norm(np.array(wall["p1"]) - p0)
    heading = math.atan2(-n[1], -n[0])

    def gaps(report):
        """The chassis' distance from the true wall_3 at every free base centre GetWallReach plans on wall_1 (as
        GetAreaRaster drives it: base_standoff in front of the scanned wall, facing it), every 1 cm."""
        hdh = DataHandler(DataManager())
        hdh.ingest_scan(report)
        ctx = NodeContext(locem=LocemDouble(), store=hdh.store,
                          health=HealthMonitor([ModuleSpec("locem", crucial=True)]), operator=OperatorDesk(),
                          data_handler=hdh)
        bb = Blackboard()
        bb.update(entries)
        lib = TreeLibrary()
        lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">'
                        '<GetWallReach feature_id="wall_1_area_3" work="spray" plan="{plan}"/>'
                        '</BehaviorTree></root>')
        assert lib.build("T", ctx, bb).tick() == Status.SUCCESS, ctx.failures
        out = {}
        for a, b in bb.get("plan")["base"]:
            for s in list(np.arange(a, b, 0.01)) + [b]:
                x, y = p0 + s * u + standoff * n
                out[float(s)] = _gap(x, y, heading, length, width, w3.p0, w3.p1)
        return out

    blind = gaps({k: v for k, v in scan.items() if k != "obstacles"})
    # wall_1_area_3 lies 1.5..2.12 m along wall_1: without the obstacles bases in front of it touch wall_3
    assert min(g for s, g in blind.items() if 1.5 <= s <= 2.12) < 0.005
    seeing = gaps(scan)
    assert seeing and max(seeing) < max(blind) - 0.2
    # every free base keeps the clearance from the true wall_3 (less the scan's noise on its ends)
    assert min(seeing.values()) >= entries["cfg.plan.clearance"] - 4 * noise, min(seeing.values())
