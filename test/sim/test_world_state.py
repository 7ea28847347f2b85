"""The simulated world's state survives its process (sim/world_state.py): what the tools did to the walls comes back
exactly from the snapshot and the journal (also after a crash between the two, and with a torn last line), the robot
stands where it stood with its tool; a state of another site is refused."""
import copy
import os
import shutil

import numpy as np
import pytest

from locem_bridge.sim.arm_source import KinematicArm
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.errors import SimConfigError
from locem_bridge.sim.modbus.compressor import CompressorModel
from locem_bridge.sim.world import World
from locem_bridge.sim.world_state import WorldState, recorder_arrays
from locem_bridge.sim.worksite import Worksite

import sys  # noqa: E402
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from conftest import free_port  # noqa: E402
from test_world_outcome import ManualWall, _pass, _spray_ready, _vertical  # noqa: E402


def _world(site_cfg, robot_cfg):
    wall = ManualWall()
    clock = SimClock(1.0, wall=wall)
    arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["wall_ready"])
    comp = CompressorModel(copy.deepcopy(robot_cfg["robot"]["compressor"]), clock.now)
    return World(copy.deepcopy(site_cfg), robot_cfg, clock, arm=arm, compressor=comp, gui=False), arm, comp, wall


@pytest.fixture
def make_world():
    """``make_world(site_cfg, robot_cfg)``: :func:`_world`, closed after the test."""
    made = []

    def make(site, robot):
        w = _world(site, robot)
        made.append(w[0])
        return w
    yield make
    for w in made:
        w.close()


def _robot(world):
    return {"pose": world.base_pose(), "q": list(world._q), "tool": world.mounted_tool}


def _work(world, arm, comp, wall, state, crash_before_truncate=False):
    """Spray a lane over wall_1, snapshot, tape half of joint 1, the operator tapes joint 2 by hand."""
    _spray_ready(world, comp, wall)
    _pass(world, arm, wall, [[1.4, 3.2, 1.2]], [0, 1, 0])
    comp.set_valve(True)
    _pass(world, arm, wall, [[x, 3.2, 1.2] for x in np.arange(1.4, 2.6, 0.01)], [0, 1, 0])
    comp.set_valve(False)
    _pass(world, arm, wall, [[2.6, 3.1, 1.2]], [0, 1, 0])
    journal = state.journal_files()[-1]
    before = open(journal, "rb").read()
    state.snapshot(world.outcome, _robot(world))
    assert not os.path.exists(journal)
    if crash_before_truncate:       # the crash came after the snapshot was in place, before the old journal went
        with open(journal, "wb") as fh:
            fh.write(before)
    world.remove_tool()
    world.set_base_pose(1.2, 2.5, np.pi / 2)
    world.mount_tool("taping_tool")
    _pass(world, arm, wall, [[1.2, 3.5, 0.9]], [0, 1, 0])
    arm.set_digital_output(0, True)
    _pass(world, arm, wall, _vertical(1.2, 3.6, 0.9, 1.9), [0, 1, 0])
    arm.set_digital_output(0, False)
    _pass(world, arm, wall, [[1.2, 3.5, 1.9]], [0, 1, 0])
    world.outcome.mark_manual_taping("wall_1_joint_2")
    state.note_robot(_robot(world))


def _same(a, b):
    arrays_a, rest_a = recorder_arrays(a.outcome)
    arrays_b, rest_b = recorder_arrays(b.outcome)
    assert sorted(arrays_a) == sorted(arrays_b)
    for k in arrays_a:
        assert np.array_equal(arrays_a[k], arrays_b[k]), (k, np.abs(arrays_a[k] - arrays_b[k]).max(), np.argwhere(arrays_a[k] != arrays_b[k])[:5].tolist(), np.abs(arrays_a[k]).max())
    assert rest_a == rest_b
    assert a.outcome.summary() == b.outcome.summary()


@pytest.mark.parametrize("crash_before_truncate", [False, True])
def test_the_outcome_maps_come_back_exactly_after_a_crash(site_cfg, robot_cfg, tmp_path, crash_before_truncate,
                                                        make_world):
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    state = WorldState(str(tmp_path / "state"))
    assert state.restore(a.outcome) is None          # a fresh folder
    state.attach(a.outcome)
    _work(a, arm, comp, wall, state, crash_before_truncate)
    s = a.outcome.summary()
    assert s["joints"]["wall_1_joint_1"]["coverage"] > 0.3 and s["joints_manual"] == 1
    assert a.outcome.maps["wall_1"].thickness.max() > 0
    assert state.seq > 10
    state.close()                                    # the process dies: nothing more is written
    b, *_ = make_world(site_cfg, robot_cfg)
    again = WorldState(str(tmp_path / "state"))
    robot = again.restore(b.outcome)
    assert robot["tool"] == "taping_tool" and robot["pose"] == pytest.approx([1.2, 2.5, np.pi / 2])
    assert again.replayed > 10 and again.seq == state.seq
    _same(a, b)


def test_a_torn_last_journal_line_is_dropped(site_cfg, robot_cfg, tmp_path, make_world):
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    state = WorldState(str(tmp_path / "state"))
    state.restore(a.outcome)
    state.attach(a.outcome)
    _work(a, arm, comp, wall, state)
    state.close()
    with open(state.journal_files()[-1], "ab") as fh:
        fh.write(b'{"kind":"segment","tool":"spray_gun","on":tr')    # the write the power loss cut short
    b, *_ = make_world(site_cfg, robot_cfg)
    WorldState(state.folder).restore(b.outcome)
    _same(a, b)


def test_a_state_of_another_site_is_refused_naming_the_folder_and_what_differs(site_cfg, robot_cfg, tmp_path,
                                                                             make_world):
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    other = copy.deepcopy(site_cfg)
    other["site"]["walls"][0]["height"] = 2.0
    state = WorldState(str(tmp_path / "state"))
    state.attach(a.outcome)
    _work(a, arm, comp, wall, state)
    state.close()
    b, *_ = make_world(other, robot_cfg)
    before = recorder_arrays(b.outcome)[0]["wall/wall_1/thickness"].copy()
    with pytest.raises(SimConfigError, match=r"state: the world state there was saved for another site: walls"):
        WorldState(state.folder).restore(b.outcome)
    assert not before.any() and not b.outcome.maps["wall_1"].thickness.any()   # nothing half restored


def test_a_worksite_started_again_on_its_state_folder_has_its_tool_and_pose_back(site_cfg, robot_cfg, port, tmp_path):
    folder = str(tmp_path / "world_state")

    def site():
        return Worksite(site_cfg, robot_cfg, modbus_port=port, can_interface="virtual",
                        can_channel="state-%d" % os.getpid(), with_ur=False, state_dir=folder,
                        snapshot_period_s=600)        # no snapshot: it all comes from the journal
    w = site()
    w.start()
    try:
        assert w.restored is None
        w.mount_tool("sander")
        w.world.set_base_pose(2.0, 1.5, 1.0)
        w.mark_manual_taping("wall_1_joint_3")
        import time
        deadline = time.monotonic() + 10
        while time.monotonic() < deadline and not any(b'"tool":"sander"' in open(f, "rb").read()
                                                      for f in w.state.journal_files()):
            time.sleep(0.05)
        assert not os.path.exists(os.path.join(folder, "outcome.npz"))
    finally:
        w.stop()
    w = site()
    w.start()
    try:
        assert w.restored["tool"] == "sander" and w.world.mounted_tool == "sander"
        assert w.world.base_pose() == pytest.approx([2.0, 1.5, 1.0], abs=1e-6)
        assert w.outcome()["joints_manual"] == 1
    finally:
        w.stop()
    shutil.rmtree(folder)


def test_a_journal_without_a_snapshot_of_another_site_is_refused_too(site_cfg, robot_cfg, tmp_path, make_world):
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    other = copy.deepcopy(site_cfg)
    other["site"]["walls"][0]["height"] = 2.0
    state = WorldState(str(tmp_path / "state"))
    state.attach(a.outcome)
    _spray_ready(a, comp, wall)
    comp.set_valve(True)
    _pass(a, arm, wall, [[x, 3.2, 1.2] for x in np.arange(1.4, 2.0, 0.01)], [0, 1, 0])
    state.close()
    assert not os.path.exists(os.path.join(state.folder, "outcome.npz"))
    b, *_ = make_world(other, robot_cfg)
    with pytest.raises(SimConfigError, match="saved for another site: walls"):
        WorldState(state.folder).restore(b.outcome)


def test_records_after_a_torn_line_start_their_own_line_and_a_failing_disk_stops_only_the_journal(
        site_cfg, robot_cfg, tmp_path, monkeypatch, caplog, make_world):
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    state = WorldState(str(tmp_path / "state"))
    state.attach(a.outcome)
    _work(a, arm, comp, wall, state)
    state.close()
    # the crash tore the first line of a journal file just begun (the one the next run writes on again)
    with open(os.path.join(state.folder, "outcome.journal.%012d" % (state.seq + 1)), "wb") as fh:
        fh.write(b'{"kind":"si')
    b, arm_b, comp_b, wall_b = make_world(site_cfg, robot_cfg)
    again = WorldState(state.folder)
    again.restore(b.outcome)
    again.attach(b.outcome)                                    # the second run goes on where the first stopped
    b.outcome.mark_manual_taping("wall_1_joint_3")
    # then the disk fails: the world goes on (the maps still change), only the journal stops
    import locem_bridge.sim.world_state as ws_mod

    def full_disk(fd, data):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(ws_mod.os, "write", full_disk)
    b.outcome.mark_manual_taping("wall_2_joint_1")
    assert b.outcome.manual == {"wall_1_joint_2", "wall_1_joint_3", "wall_2_joint_1"}
    monkeypatch.undo()
    again.close()
    c, *_ = make_world(site_cfg, robot_cfg)
    WorldState(state.folder).restore(c.outcome)
    assert c.outcome.manual == {"wall_1_joint_2", "wall_1_joint_3"}   # what was journaled, nothing broken
    assert "broken journal line" not in caplog.text and "cannot be written" in caplog.text
    assert np.array_equal(c.outcome.maps["wall_1"].thickness, a.outcome.maps["wall_1"].thickness)


def test_a_tool_changer_restored_with_the_world_holds_the_tool_on_the_flange(site_cfg, port, tmp_path):
    from locem_bridge.sim.config import load_robot
    robot = load_robot(os.path.join(os.path.dirname(__file__), "..", "..", "config", "robots", "diffdrive_ur5e.yaml"))
    robot["robot"]["tool_changer"]["port"] = free_port()
    folder = str(tmp_path / "world_state")

    def site():
        return Worksite(site_cfg, robot, modbus_port=port, can_interface="virtual",
                        can_channel="changer-%d" % os.getpid(), with_ur=False, state_dir=folder)
    w = site()
    w.start()
    try:
        w.world.mount_tool("spray_gun", by="the tool changer")
        w.state.note_robot({"pose": w.world.base_pose(), "q": list(w.world._q), "tool": w.world.mounted_tool,
                            "sim_time": w.clock.now()})
        sim_time = w.clock.now()
    finally:
        w.stop()
    w = site()
    w.start()
    try:
        st = w.tool_changer_state()
        assert w.world.mounted_tool == "spray_gun" and st["locked"] and st["coupled_tool"] == "spray_gun", st
        assert w.clock.now() >= sim_time                 # sim time goes on, it does not start again at 0
    finally:
        w.stop()


def _spraying_with_samples_journaled(make_world, site_cfg, robot_cfg, tmp_path):
    """A world whose state journals the arm's samples, the spray gun at the start of a lane on wall_1, robot noted
    (as the worksite notes it every 0.2 s), valve open."""
    a, arm, comp, wall = make_world(site_cfg, robot_cfg)
    state = WorldState(str(tmp_path / "state"))
    state.restore(a.outcome)
    state.attach(a.outcome)
    a.sample_journal = state
    _spray_ready(a, comp, wall)
    _pass(a, arm, wall, [[1.4, 3.2, 1.2]], [0, 1, 0])
    state.note_robot(_robot(a))
    comp.set_valve(True)
    return a, arm, wall, state


def _controller_ahead(world, arm, wall, xs):
    """The controller moves the arm along the lane through ``xs`` (0.2 m/s) without a world step; the last q."""
    q = world.joint_positions()
    for x in xs:
        q = world.ik_tcp([x, 3.2, 1.2], [0, 1, 0], q)
        wall.t += 0.01 / 0.2
        arm.set_joint_positions(q)
    return q


def _same_maps(a, b):
    arrays_a, arrays_b = recorder_arrays(a.outcome)[0], recorder_arrays(b.outcome)[0]
    for k in arrays_a:
        assert np.array_equal(arrays_a[k], arrays_b[k]), k


@pytest.mark.parametrize("snapshot_between", [False, True])
def test_arm_samples_the_world_had_not_recorded_yet_are_not_lost_with_its_process(site_cfg, robot_cfg, tmp_path,
                                                                                make_world, snapshot_between):
    """The arm's controller runs ahead of the world's steps (its measured TCP, what LOCEM reports as the work done,
    is up to a step ahead of the maps, more on a busy machine): a world killed between the two must come back with
    that part of the lane sprayed, exactly as a step would have recorded it, the arm where the last sample left it."""
    a, arm, wall, state = _spraying_with_samples_journaled(make_world, site_cfg, robot_cfg, tmp_path)
    _pass(a, arm, wall, [[x, 3.2, 1.2] for x in np.arange(1.4, 1.9, 0.01)], [0, 1, 0])
    if snapshot_between:             # a snapshot while samples wait: they go on into the next journal file
        a.step()
        state.snapshot(a.outcome, _robot(a))
    # the controller goes on; the world does not step before the kill
    q = _controller_ahead(a, arm, wall, np.arange(1.9, 2.3, 0.01))
    if snapshot_between:
        state.snapshot(a.outcome, _robot(a))
    recorded = a.outcome.maps["wall_1"].thickness.copy()
    state.close()                                  # killed: nothing more is written
    a.sample_journal = None
    a.step()                                       # what the world would have recorded had it lived on
    assert (a.outcome.maps["wall_1"].thickness > recorded).sum() > 100    # 40 cm of the lane not recorded at the kill

    again = WorldState(state.folder)
    saved = again.saved_robot()
    assert saved["q"] == pytest.approx(q) and saved["sim_time"] >= wall.t - 1e-6   # where the last sample left it
    b, arm_b, comp_b, wall_b = make_world(site_cfg, robot_cfg)
    arm_b.set_joint_positions(saved["q"])
    robot = again.restore(b.outcome)
    b.set_base_pose(*robot["pose"])
    b.mount_tool(robot["tool"])
    assert len(again.pending) == 40 and again.pen is not None
    b.resume_samples(again.pending, again.pen)
    b.step()
    _same_maps(a, b)
    # the valve is closed after the restart: the pass ends where the last sample left the arm, not where the world
    # had recorded it to
    (wall_id, end, direction, _t), = b.outcome.spray_pass_ends
    assert wall_id == "wall_1" and end[0] == pytest.approx(2.29, abs=0.011) and direction[0] == pytest.approx(1.0)


def test_a_world_killed_in_the_middle_of_its_step_records_nothing_twice(site_cfg, robot_cfg, tmp_path, make_world):
    """Killed after the step journaled its segments, before it noted which samples it had recorded: each segment's
    record says which samples it holds, so the restored world does not record them again."""
    a, arm, wall, state = _spraying_with_samples_journaled(make_world, site_cfg, robot_cfg, tmp_path)
    _controller_ahead(a, arm, wall, np.arange(1.4, 1.8, 0.01))    # the controller's samples, then one world step
    a.step()
    state.close()
    journal = state.journal_files()[-1]
    lines = open(journal, "rb").read().splitlines(keepends=True)
    assert b'"kind":"drained"' in lines[-1] and b'"kind":"segment"' in lines[-2]
    with open(journal, "wb") as fh:                # the kill came before the step's last line
        fh.write(b"".join(lines[:-1]))
    b, arm_b, *_ = make_world(site_cfg, robot_cfg)
    again = WorldState(state.folder)
    arm_b.set_joint_positions(again.saved_robot()["q"])
    robot = again.restore(b.outcome)
    assert again.pending == [] and again.pen is not None and robot["tool"] == "spray_gun"
    _same_maps(a, b)
