"""SPRAY_AREA goes on where an interrupted one stopped: its feedback reports the raster's worked length done
('raster <m> of <m> m'), and ``skip=`` leaves exactly that much of the raster out. Through LOCEM with every bridge
against the stand-ins; the PyBullet world's thickness map shows where the spray started."""
import time

import numpy as np
import pytest

from locem_bridge.common.raster_progress import parse_progress_text
from locem_bridge.locem.registry import Interface

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow

NORMAL = "0 -1 0"
# wall_1 of the short-wall site: s = x - 1.8 along the wall; the area starts at x = 2.0 (s = 0.2), z = 0.9.
# 3 lanes (spacing 0.3 > the 0.29 m fan: a lane's spray does not reach its neighbour's row), 0.8 m each (run_in 0)
AREA = "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.3 standoff=0.3 speed=0.1 pressure=3.5 run_in=0" % NORMAL
LANE, TOTAL = 0.8, 2.4


def _ready(rig, core):
    rig.world.mount_tool("spray_gun")
    assert core.dispatcher.execute("MOUNT_TOOL spray_gun").success
    assert core.dispatcher.execute("GOTO 2.4 2.5 1.5708").success


def _row(rig, t):
    """Thickness along wall_1 (cell centres s, thickness) in the cell row nearest height ``t``."""
    m = rig.world.outcome.maps["wall_1"]
    return m.sc, m.thickness[int(np.argmin(np.abs(m.tc - t)))]


def _edge(s, row, lo, hi):
    """Where the row crosses half its plateau (the median over s in lo..hi) between lo and hi + 0.3 m."""
    plateau = float(np.median(row[(s >= lo) & (s <= hi)]))
    above = (s >= lo) & (row >= plateau / 2.0)
    return float(s[above].max()), plateau


def test_skip_leaves_out_exactly_that_length_of_the_raster_and_feedback_reports_the_point_reached(wall, core):
    rig, _ = wall
    _ready(rig, core)
    events = []
    skip = LANE + 0.3          # lane 0 (forward, s 0.2..1.0) left out; lane 1 runs backwards from s = 1.0 - 0.3
    execution = core.dispatcher.submit(AREA + " skip=%.2f" % skip, Interface.ACTION,
                                       listener=lambda e: events.append((time.monotonic(), e.message, e.progress)))
    r = execution.wait(120.0)
    assert r is not None and r.success, r
    assert r.result["skipped_m"] == pytest.approx(skip) and r.result["lanes"] == 2
    assert r.result["length_m"] == pytest.approx(TOTAL - skip)
    time.sleep(0.2)
    s, row0 = _row(rig, 0.9)
    assert row0.max() == 0.0, "lane 0 was sprayed although skip=%.2f leaves it out" % skip
    s, row1 = _row(rig, 1.2)
    edge, plateau = _edge(s, row1, 0.25, 0.6)
    assert plateau >= rig.world.outcome.target
    # the spray began 0.3 m into lane 1: within one cell (2 cm) and the valve's first switching delay (a raster's
    # first switch has no measured request time to lead by: up to ~50 ms of Modbus write under load, 2 cm at 0.4 m/s
    # of wall time)
    assert edge == pytest.approx(0.2 + LANE - 0.3, abs=0.03)
    assert rig.area_coverage("wall_1", (0.3, 0.9), (1.45, 1.55)) >= 0.98       # lane 2 whole (run_in 0: not its ends)
    # feedback: metres of the raster from its start, skipped part included, never going back, the end reported
    done = [(t, parse_progress_text(m)) for t, m, _p in events if parse_progress_text(m)]
    metres = [d[0] for _t, d in done]
    assert metres == sorted(metres) and metres[0] >= skip - 1e-6 and metres[-1] == pytest.approx(TOTAL)
    assert all(d[1] == pytest.approx(TOTAL) for _t, d in done)
    # at least 5 reports a second while spraying (the lanes at 0.1 m/s of sim time, time scale 4)
    spraying = [t for t, d in done if skip + 0.05 < d[0] < TOTAL - 0.05]
    gaps = np.diff(spraying)
    assert len(spraying) >= 5 and float(np.median(gaps)) <= 0.1, gaps
    assert sum(1 for g in gaps if g > 0.2) <= 1, gaps           # only the turn from lane 1 to lane 2 is longer


def test_skip_values_outside_the_raster_are_refused_and_nothing_moves(wall, core):
    rig, _ = wall
    _ready(rig, core)
    tcp = rig.standin.get_tcp_pose()
    r = core.dispatcher.execute(AREA + " skip=-0.1")
    assert r.code.value == "INVALID_ARGUMENT" and "skip" in r.message, r
    r = core.dispatcher.execute(AREA + " skip=2.5")
    assert r.code.value == "INVALID_ARGUMENT", r
    assert "skip 2.500 m" in r.message and "0..2.400 m" in r.message, r.message
    r = core.dispatcher.execute(AREA + " skip=nan")
    assert r.code.value == "INVALID_ARGUMENT" and "skip" in r.message, r
    # a raster already done (a cut at its very end): nothing to spray, no device switched
    r = core.dispatcher.execute(AREA + " skip=2.4")
    assert r.success and r.result["lanes"] == 0 and r.result["length_m"] == 0.0, r
    snap = rig.model.snapshot()
    assert not snap["valve_open"] and not snap["motor_on"], snap
    assert np.allclose(rig.standin.get_tcp_pose(), tcp, atol=1e-4)
    assert rig.world.outcome.maps["wall_1"].thickness.max() == 0.0
