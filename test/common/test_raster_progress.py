"""Where a tool point stands on a SPRAY_AREA raster (common.raster_progress.raster_point), in the same metres of
worked length LOCEM's skip= and feedback use: HICEM resumes a section cut by a power loss where the arm stopped."""
import numpy as np
import pytest

from locem_bridge.bridges.commands_wall import WallCommands
from locem_bridge.common.raster_progress import lane_heights, raster_point

# a section on a wall facing -y (normal towards the robot), 1.2 m wide, 0.5 m high, lanes 0.1 m apart
ORIGIN, U, NORMAL = [2.0, 3.6, 0.9], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0]
WIDTH, HEIGHT, SPACING, RUN_IN, STANDOFF = 1.2, 0.5, 0.1, 0.05, 0.3
LANE = WIDTH + 2 * RUN_IN


def _tcp(along, up, off=STANDOFF):
    """The TCP ``along`` m from the origin along u, ``up`` above it, ``off`` in front of the wall."""
    return list(np.asarray(ORIGIN) + np.asarray(U) * along + np.array([0.0, 0.0, 1.0]) * up + np.asarray(NORMAL) * off)


def _at(point, **kw):
    return raster_point(point, ORIGIN, U, WIDTH, HEIGHT, NORMAL, SPACING, RUN_IN, STANDOFF, **kw)


def test_the_start_of_every_lane_locem_works_after_a_skip_maps_back_to_that_skip():
    # LOCEM's own lanes after skip= (WallCommands._raster_lanes): the TCP where each remaining lane's worked stretch
    # begins stands at exactly that many metres of the raster
    heights = lane_heights(HEIGHT, SPACING)
    assert len(heights) == 6
    for skip in (0.0, 0.3, LANE - 0.2, LANE + 0.01, 2.5 * LANE, 5 * LANE + 0.7):
        lanes = WallCommands._raster_lanes(heights, WIDTH, RUN_IN, skip)
        k, t, w0, _w1, start_m = lanes[0]
        assert start_m == pytest.approx(skip)
        assert _at(_tcp(w0, t)) == pytest.approx(skip, abs=1e-9), (skip, k)
        for k, t, w0, _w1, start_m in lanes[1:]:              # the lanes after it begin at their whole start
            assert _at(_tcp(w0, t)) == pytest.approx(start_m, abs=1e-9)


def test_forward_and_backward_lanes_count_the_worked_length_behind_the_tool():
    assert _at(_tcp(0.4, 0.0)) == pytest.approx(0.45)                      # lane 0 runs along u
    assert _at(_tcp(0.4, 0.1)) == pytest.approx(LANE + (WIDTH + RUN_IN - 0.4))   # lane 1 runs back
    assert _at(_tcp(0.4, 0.1 + 0.02)) == pytest.approx(LANE + 0.85)        # within a quarter spacing of the lane
    # in a run-up before the stretch: its start (the tool is still off); past its end: its end
    assert _at(_tcp(-0.3, 0.0)) == pytest.approx(0.0)
    assert _at(_tcp(WIDTH + 0.3, 0.2)) == pytest.approx(2 * LANE + LANE)


def test_a_point_on_no_lane_has_no_raster_point():
    assert _at(_tcp(0.4, 0.05)) is None                          # half way between two lanes: a turn
    assert _at(_tcp(0.4, 0.0, off=STANDOFF + 0.2)) is None        # off the wall (the arm retracted)
    assert _at(_tcp(0.4, 0.0, off=STANDOFF + 0.04)) == pytest.approx(0.45)   # within depth of the standoff
    assert _at(_tcp(WIDTH + 1.5, 0.0)) is None                    # beyond a run-up past the section
    assert _at(_tcp(0.4, 0.7)) is None                            # above the top lane
    assert raster_point(_tcp(0.4, 0.0), ORIGIN, [0, 0, 0], WIDTH, HEIGHT, NORMAL, SPACING, RUN_IN, STANDOFF) is None
