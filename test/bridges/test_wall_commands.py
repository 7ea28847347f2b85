"""The composed plasterboard commands through LOCEM with every bridge (RTDE arm, Modbus compressor, CAN base)
against the stand-ins, with the PyBullet world measuring tape and spray on the wall."""
import math
import threading
import time

import numpy as np
import pytest

from locem_bridge.locem.registry import Interface

from bridge_rigs import WorksiteRig, rtde_payload, wait_until

pytest.importorskip("rtde_control")
pytestmark = pytest.mark.slow

JOINT = "wall_1_joint_1"      # the horizontal joint at z = 1.25 m, x 1.8 .. 3.0, y = 3.6
NORMAL = "0 -1 0"


def run(core, text):
    return core.dispatcher.execute(text)


def test_scan_reports_the_joint_and_area_in_the_contract_shape(wall, core):
    r = run(core, "SCAN")
    assert r.success, r.message
    joints = {j["id"]: j for j in r.result["joints"]}
    assert JOINT in joints and joints[JOINT]["kind"] == "horizontal"
    assert joints[JOINT]["start"][2] == pytest.approx(1.25, abs=1e-6)
    assert [a["id"] for a in r.result["areas"]] == ["wall_1_area_1"]


def test_apply_tape_along_the_joint_covers_it(wall, core):
    rig, _ = wall
    assert run(core, "APPLY_TAPE 1.8 3.6 1.25 3.0 3.6 1.25 %s" % NORMAL).code.value == "NOT_READY"
    rig.world.mount_tool("taping_tool")
    r = run(core, "MOUNT_TOOL taping_tool")
    assert r.success, r.message
    assert rig.standin.get_tcp_offset()[2] == pytest.approx(0.22)
    # the tool's payload (robot.tools.taping_tool: 3.2 kg, cog 9 cm along the flange z) is on the controller
    payload = rtde_payload(rig.address)
    assert payload["mass"] == pytest.approx(3.2) and payload["cog"] == pytest.approx([0.0, 0.0, 0.09]), payload
    r = run(core, "APPLY_TAPE_START 1.8 3.6 1.25 3.0 3.6 1.25 %s" % NORMAL)
    assert r.success, r.message
    time.sleep(0.1)
    pos, z = rig.world.tcp_pose()
    assert abs(pos[0] - 1.8) < 0.002 and abs(pos[1] - (3.6 - 0.05)) < 0.002 and abs(pos[2] - 1.25) < 0.002
    assert rig.world.outcome.joint_coverage(JOINT) == 0.0          # judging the start lays no tape
    r = run(core, "APPLY_TAPE 1.8 3.6 1.25 3.0 3.6 1.25 %s speed=0.1" % NORMAL)
    assert r.success, r.message
    time.sleep(0.2)
    coverage = rig.world.outcome.joint_coverage(JOINT)
    assert coverage >= 0.99, coverage
    assert rig.world.outcome.tape_off_joint < 0.02
    assert rig.nothing_running()


def test_get_tool_point_gives_where_the_tool_stands_in_the_map_even_after_the_controller_lost_its_tcp(wall, core):
    # after a power loss HICEM reads where the arm stopped before anything moves it (RECOVER): the tool's point in
    # the map frame, from odometry, the arm's mount and the active tool's TCP offset
    rig, _ = wall
    rig.world.mount_tool("taping_tool")
    assert run(core, "MOUNT_TOOL taping_tool").success
    assert run(core, "APPLY_TAPE_START 1.8 3.6 1.25 3.0 3.6 1.25 %s" % NORMAL).success
    time.sleep(0.1)
    # a restarted controller holds the installation's TCP (the flange), not the tool's
    assert run(core, "SET_TCP 0 0 0 0 0 0").success
    assert rig.standin.get_tcp_offset()[2] == pytest.approx(0.0)
    r = run(core, "GET_TOOL_POINT")
    assert r.success, r.message
    pos, _z = rig.world.tcp_pose()
    assert r.result["point"] == pytest.approx([1.8, 3.55, 1.25], abs=0.002)
    assert r.result["point"] == pytest.approx(list(pos), abs=0.002)
    assert r.result["axis"] == pytest.approx([0.0, 1.0, 0.0], abs=0.01)          # into the wall at y = 3.6
    assert r.result["tool"] == "taping_tool" and "taping_tool at 1.8" in r.message
    assert rig.standin.get_tcp_offset()[2] == pytest.approx(0.22)                  # the tool's TCP is set again
    assert run(core, "HOME").success


def test_spray_area_covers_the_area_and_leaves_the_valve_closed(wall, core):
    rig, _ = wall
    rig.world.mount_tool("spray_gun")
    assert run(core, "MOUNT_TOOL spray_gun").success
    # the gun needs room: the base backs off to 1.1 m from the wall (the arm base then stands 0.9 m from it)
    assert run(core, "GOTO 2.4 2.5 1.5708").success
    r = run(core, "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 standoff=0.3 speed=0.1 pressure=3.5" % NORMAL)
    assert r.success, r.message
    time.sleep(0.2)
    coverage = rig.area_coverage("wall_1", (0.2, 1.0), (0.9, 1.5))
    assert coverage >= 0.98, coverage
    # the valve is closed; the motor keeps running for the next section until COMPRESSOR_OFF (or STOP)
    assert rig.running() == ["compressor motor on"]
    assert run(core, "COMPRESSOR_OFF").success
    assert rig.nothing_running(), rig.running()


def test_compressor_link_lost_mid_spray_area_fails_within_1s_and_closes_the_valve_on_return(wall, core):
    rig, built = wall
    rig.world.mount_tool("spray_gun")
    assert run(core, "MOUNT_TOOL spray_gun").success
    assert run(core, "GOTO 2.4 2.5 1.5708").success
    execution = core.dispatcher.submit(
        "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 speed=0.1 pressure=3.5" % NORMAL, Interface.ACTION)
    assert wait_until(lambda: rig.model.snapshot()["valve_open"], timeout=30.0)
    rig.server.drop_link(duration=None, mode="silent")
    t0 = time.monotonic()
    r = execution.wait(5.0)
    took = time.monotonic() - t0
    assert r is not None and r.code.value == "HARDWARE_ERROR" and "compressor" in r.message, r
    assert took < 1.0, "answered %.2f s after the link loss" % took
    assert wait_until(lambda: not rig.standin.get_state()["moving"], timeout=2.0)
    rig.server.restore_link()
    # the link is back: valve closed and motor off by the backend itself (no COMPRESSOR_OFF / STOP sent)
    assert wait_until(lambda: not rig.model.snapshot()["valve_open"], timeout=3.0)
    assert wait_until(rig.nothing_running, timeout=3.0), rig.running()
    # HICEM's RECOVER (WALL_READY, then STATUS until every device is up) and the area again: SPRAY_AREA
    # switches the motor on by itself and sprays (a part of the area the failed pass never reached)
    assert run(core, "WALL_READY").success
    assert wait_until(lambda: all(h["link"] == "up" and h["device"] == "ok"
                                  for k, h in run(core, "STATUS").result["health"].items()
                                  if k in ("arm", "compressor", "base")), timeout=5.0)
    part = ((0.2, 0.6), (1.3, 1.5))                         # wall s (x - 1.8) and height ranges
    assert rig.area_coverage("wall_1", *part) < 0.5
    assert rig.model.snapshot()["motor_on"] is False
    r = run(core, "SPRAY_AREA 2.0 3.6 1.3 1 0 0 0.4 0.2 %s spacing=0.1 speed=0.1 pressure=3.5" % NORMAL)
    assert r.success, r.message
    time.sleep(0.2)
    coverage = rig.area_coverage("wall_1", *part)
    assert coverage >= 0.98, coverage
    assert rig.running() == ["compressor motor on"]


def test_home_switches_outputs_off_and_parks_the_arm(wall, core):
    rig, built = wall
    assert run(core, "TOOL_OUTPUT 1 true").success
    r = run(core, "HOME")
    assert r.success, r.message
    assert rig.nothing_running()
    home = built.get("arm").named_pose("home")
    assert max(abs(a - b) for a, b in zip(rig.standin.get_joint_positions(), home)) < 1e-3


def _sand(rig, core, command):
    """The sander mounted, the base 1 m from wall_1, ``command`` run; the wall's outcome maps after it."""
    rig.world.mount_tool("sander")
    assert run(core, "MOUNT_TOOL sander").success
    assert run(core, "GOTO 2.4 2.6 1.5708").success
    r = run(core, command)
    assert r.success, r.message
    time.sleep(0.2)
    return r, rig.world.outcome.maps["wall_1"]


def test_sand_area_sands_the_area_in_contact(wall, core):
    rig, _ = wall
    _r, m = _sand(rig, core, "SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 speed=0.15" % NORMAL)
    cells = m.sanded[(m.tc >= 0.9) & (m.tc <= 1.5)][:, (m.sc >= 0.2) & (m.sc <= 1.0)]
    assert cells.mean() >= 0.98, cells.mean()
    assert rig.nothing_running()


def test_sand_area_with_vertical_lanes_sands_the_area_in_upward_lanes(wall, core):
    rig, _ = wall
    r, m = _sand(rig, core, "SAND_AREA 2.0 3.6 0.9 1 0 0 0.3 0.6 %s spacing=0.1 speed=0.15 lanes=vertical" % NORMAL)
    assert r.result["lanes"] == 4, r.result              # 0.3 m across at most 0.1 m apart: 4 lanes upwards
    cells = m.sanded[(m.tc >= 0.9) & (m.tc <= 1.5)][:, (m.sc >= 0.2) & (m.sc <= 0.5)]
    assert cells.mean() >= 0.98, cells.mean()
    # upward lanes run no further than the area's height (no run-in for sanding): nothing a pad radius past it
    assert not m.sanded[(m.tc >= 1.5 + 0.1125 + 0.03)].any() and not m.sanded[(m.tc <= 0.9 - 0.1125 - 0.03)].any()
    assert rig.nothing_running()


def test_stop_is_not_delayed_by_a_silent_compressor(wall, core):
    rig, _ = wall
    rig.server.drop_link(duration=None, mode="silent")
    time.sleep(0.6)
    execution = core.dispatcher.submit("GOTO 2.4 1.2 1.5708 speed=0.8", Interface.SERVICE)
    assert wait_until(lambda: abs(rig.drives.wheel_speeds()[0]) > 3.0, timeout=10.0)
    t0 = rig.clock.now()
    assert run(core, "STOP").success
    assert wait_until(lambda: all(abs(v) < 1e-9 for v in rig.drives.wheel_speeds()), timeout=2.0, period=0.002)
    took = rig.clock.now() - t0
    assert took < 0.2 * 4, "base still %.3f s sim after STOP" % took   # time scale 4: 200 ms wall
    assert execution.wait(2.0).code.value == "ABORTED"
    rig.server.restore_link()


def test_a_restarted_locem_restores_the_mounted_tool_and_its_tcp(wall, core):
    """MOUNT_TOOL tells the listener (the LOCEM node keeps it in ~active_tool); the wall commands of a fresh
    LOCEM restore it: a tool command is not refused, and WALL_READY sets the tool's TCP before its straight
    retract even when the controller's was reset."""
    from locem_bridge.bridges.commands_wall import WallCommands
    from locem_bridge.bridges.errors import BadRequest
    rig, built = wall
    old = next(c for c in built.command_sets if isinstance(c, WallCommands))
    kept = []
    old.tool_listener = kept.append
    rig.world.mount_tool("spray_gun")
    assert run(core, "MOUNT_TOOL spray_gun").success
    assert kept == ["spray_gun"]
    old.activate_tool(None)                   # CHANGE_TOOL put it back in the rack: nothing on the flange
    assert kept == ["spray_gun", ""]
    assert run(core, "MOUNT_TOOL spray_gun").success
    fresh = WallCommands(rig.robot, arm=built.get("arm"), base=built.get("base"), compressor=built.get("compressor"),
                         scanner=built.get("scanner"))
    with pytest.raises(BadRequest):
        fresh.restore_tool("paint_roller")
    assert fresh.active_tool is None
    fresh.restore_tool("spray_gun")
    assert fresh.health()["active_tool"] == "spray_gun"
    built.get("arm").set_tcp([0.0] * 6)                      # as a restarted control script has it
    fresh._need_tool("spray_gun")                            # not refused NOT_READY
    built.get("arm").set_tcp([0.0] * 6)
    fresh._retract(_Waiter())
    assert rig.standin.get_tcp_offset()[2] == pytest.approx(rig.robot["tools"]["spray_gun"]["tcp"][2])


class _Waiter:
    def sleep(self, seconds):
        time.sleep(seconds)

    def check(self):
        pass

    def on_cancel(self, callback):
        pass

    def report(self, progress, text=""):
        pass


def test_at_time_scale_10_every_lane_is_sprayed_to_within_3_cm_of_its_ends(robot, core):
    """The whole stretch of every lane, the FIRST included, is crossed by the spray axis with the valve open: at
    time scale 10 a lane passes in a few tens of milliseconds of wall time, about as long as the path request takes
    to be answered; a raster path that started from rest right before its first lane had passed 10-15 cm of that
    lane before LOCEM's first decision (the lead-in beside the first lane lets LOCEM watch the arm from before).
    The same holds for a raster resumed part way along its last lane (a path of that one lane, with its lead-in).
    Within END_M of the lane's ends: at this time scale 6 ms of travel, a valve request's jitter on a busy 2-core
    machine with the world, the stand-ins and LOCEM in one process (a lane's first or last 1-2 cm stayed bare in
    about one run of five with 1 cm)."""
    END_M = 0.03
    from locem_bridge.bridges.commands_wall import WallCommands
    from locem_bridge.bridges.robot import build_robot
    from locem_bridge.common.raster_progress import lane_heights
    from locem_bridge.sim.outcome import PASS_GRID
    rig = WorksiteRig(robot, time_scale=10.0, arm_in_process=True)
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()

    def sprayed_whole(z: float, height: float, skip: float = 0.0) -> None:
        """SPRAY_AREA over 0.6 m of wall_1 from x 2.0 at height z; every lane left after ``skip`` is crossed."""
        r = run(core, "SPRAY_AREA 2.0 3.6 %.2f 1 0 0 0.6 %.2f %s spacing=0.1 standoff=0.3 speed=0.4 pressure=3.5 "
                      "run_in=0 skip=%.2f" % (z, height, NORMAL, skip))
        assert r.success, r.message
        time.sleep(0.2)
        m = rig.world.outcome.maps["wall_1"]
        s0, t0, _d = m.wall.to_wall_coords([2.0, 3.6, z])
        for k, h, w0, w1, _start in WallCommands._raster_lanes(lane_heights(height, 0.1), 0.6, 0.0,
                                                               skip):
            a, b = sorted(m.wall.to_wall_coords([2.0 + w, 3.6, z])[0] for w in (w0, w1))
            cols = np.arange(int(math.ceil((a + END_M) / PASS_GRID)), int((b - END_M) / PASS_GRID))
            row = int((t0 + h) / PASS_GRID)
            crossed = m.passes[row - 1:row + 2, cols].max(axis=0)      # the lane's line, +-1 cell across it
            missed = np.abs((cols[crossed == 0] + 0.5) * PASS_GRID - s0)
            assert missed.size == 0, "z %.2f lane %d: stretch points never sprayed at %s m from the area's start" % (
                z, k, np.round(missed[[0, -1]], 3))

    try:
        for command_set in built.command_sets:
            core.install(command_set)
        for kind in ("arm", "compressor", "base"):
            assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
        rig.world.mount_tool("spray_gun")
        assert run(core, "MOUNT_TOOL spray_gun").success
        assert run(core, "GOTO 2.4 2.5 1.5708").success
        sprayed_whole(0.9, 0.4)                       # five lanes
        sprayed_whole(0.5, 0.2, skip=1.3)             # resumed 0.1 m into the last of three lanes
    finally:
        built.close()
        rig.close()


def test_a_wall_command_takes_its_targets_from_the_pose_the_first_fix_after_a_stop_settles(wall, core, monkeypatch):
    """The first localisation fix after the base stopped replaces its odometry pose (by the drift of the drive):
    a wall command waits for it before it computes a target, so its targets agree. Odometry drifted 3 cm here
    and the fix comes 0.4 s into APPLY_TAPE_START: the command's TCP target is the one from the fixed pose."""
    from locem_bridge.bridges import cia402_base
    monkeypatch.setattr(cia402_base, "LOCALISATION_SILENT_S", 30.0)    # a busy machine's slow stop still counts
    rig, built = wall
    base = built.get("base")
    rig.world.mount_tool("taping_tool")
    assert run(core, "MOUNT_TOOL taping_tool").success
    x, y, th = rig.world.base_pose()
    base.set_velocity(0.05, 0.0, 0.0, hold=0.3)            # a fix while the base moves: localisation runs, the
    assert wait_until(lambda: abs(base.twist()[0]) > 0.02, timeout=3.0)
    assert not base.correct_pose(x, y, th)                 # fix is not taken (late by its latency)
    assert wait_until(lambda: abs(base.twist()[0]) < 1e-3, timeout=3.0)
    x, y, th = rig.world.base_pose()
    base.set_pose(x, y + 0.03, th)                         # odometry 3 cm off towards the wall (y), no fix yet
    taken = []

    def fix_later() -> None:
        time.sleep(0.4)
        taken.append(base.correct_pose(x, y, th))
    feeder = threading.Thread(target=fix_later, daemon=True)
    t0 = time.monotonic()
    feeder.start()
    r = run(core, "APPLY_TAPE_START 1.8 3.6 1.25 3.0 3.6 1.25 %s" % NORMAL)
    took = time.monotonic() - t0
    feeder.join(2.0)
    assert r.success, r.message
    assert taken == [True] and took >= 0.4, (taken, took)  # the command waited for the fix, which was taken
    time.sleep(0.1)
    pos, _ = rig.world.tcp_pose()                          # the TCP stands where the wall command aimed: 5 cm in
    assert abs(pos[0] - 1.8) < 0.003 and abs(pos[1] - (3.6 - 0.05)) < 0.003, pos    # front of the line's start


def test_how_long_a_wall_command_waits_for_a_fix(wall, core, monkeypatch):
    """No localisation: no wait. A source that stopped publishing (none within LOCALISATION_SILENT_S): no wait.
    Fixes coming but none taken since the stop: at most FIX_INTERVALS of their interval, then a line that says
    so. A configured source (localisation_expected) before its first fix: at most the timeout. Settled: none."""
    from locem_bridge.bridges import cia402_base
    rig, built = wall
    base = built.get("base")
    assert base.wait_localised(_Waiter(), 5.0) is None     # no fix ever came: odometry it is, at once
    base.localisation_expected = True                      # LOCEM subscribes to a localisation topic
    t0 = time.monotonic()
    late = base.wait_localised(_Waiter(), 0.3)
    assert late is not None and "no fix yet" in late and 0.25 <= time.monotonic() - t0 < 1.0, late
    x, y, th = rig.world.base_pose()
    base.set_velocity(0.05, 0.0, 0.0, hold=0.6)
    assert wait_until(lambda: abs(base.twist()[0]) > 0.02, timeout=3.0)
    for _ in range(4):                                     # fixes every 0.1 s while it moves: none taken
        assert not base.correct_pose(x, y, th)
        time.sleep(0.1)
    monkeypatch.setattr(cia402_base, "LOCALISATION_SILENT_S", 30.0)
    assert wait_until(lambda: abs(base.twist()[0]) < 1e-3, timeout=3.0)
    t0 = time.monotonic()
    late = base.wait_localised(_Waiter(), 5.0)             # 2.5 intervals of ~0.1 s, not the 5 s timeout
    assert late is not None and "the last came" in late and time.monotonic() - t0 < 1.0, late
    monkeypatch.setattr(cia402_base, "LOCALISATION_SILENT_S", 0.0)
    t0 = time.monotonic()
    assert base.wait_localised(_Waiter(), 5.0) is None and time.monotonic() - t0 < 0.5    # the source went quiet
    x, y, th = rig.world.base_pose()
    assert base.correct_pose(x, y, th)
    t0 = time.monotonic()
    assert base.wait_localised(_Waiter(), 5.0) is None and time.monotonic() - t0 < 0.5    # settled: at once
