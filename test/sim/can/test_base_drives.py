"""Base drive stand-ins: canopen's BaseNode402 master against the simulated CiA 402 drives, base motion in
PyBullet (ground truth) through the mecanum kinematics, faults and malformed frames."""
import copy
import logging
import math
import time
import uuid

import can
import canopen
import pytest
from canopen.nmt import NmtError

from locem_bridge.sim.arm_source import KinematicArm
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.config import resolve_relative
from locem_bridge.common.can_bus import open_bus
from locem_bridge.sim.can.drives import DriveSet
from locem_bridge.common.base_kinematics import MecanumKinematics
from locem_bridge.sim.world import World


def _drives_cfg(robot_cfg, interface="virtual", channel=None, port=None):
    cfg = copy.deepcopy(robot_cfg["robot"]["base"]["drives"])
    cfg["can"] = {"interface": interface, "channel": channel or "sim-%s" % uuid.uuid4().hex[:8], "bitrate": 1000000}
    if port is not None:
        cfg["can"]["port"] = port
    return cfg


@pytest.fixture
def base_rig(site_cfg, robot_cfg, request):
    cfg = _drives_cfg(robot_cfg)
    eds = resolve_relative(robot_cfg, robot_cfg["robot"]["base"]["eds"])
    clock = SimClock(getattr(request, "param", 1.0))
    drives = DriveSet(cfg, eds, clock.now, max_wheel_speed=robot_cfg["robot"]["base"]["limits"]["max_wheel_speed"])
    drives.start()
    arm = KinematicArm(robot_cfg["robot"]["arm"]["named_poses"]["stow"])
    world = World(copy.deepcopy(site_cfg), robot_cfg, clock, arm=arm, drives=drives, gui=False)
    world.start()
    net = canopen.Network()
    net.NOTIFIER_CYCLE = 0.1
    net.connect(interface="virtual", channel=cfg["can"]["channel"])
    nodes = []
    for w in cfg["wheels"]:
        node = canopen.BaseNode402(w["node_id"], eds)
        net.add_node(node)
        nodes.append(node)
    yield world, drives, net, nodes, cfg
    net.disconnect()
    world.close()
    drives.stop()


def _enable(node):
    node.nmt.wait_for_heartbeat(1.0)
    node.setup_402_state_machine()
    node.nmt.state = "OPERATIONAL"
    node.op_mode = "PROFILED VELOCITY"
    node.state = "OPERATION ENABLED"


def _command(nodes, cfg, wheel_speeds):
    scale = cfg["velocity_units_per_rad_s"]
    for node, w, speed in zip(nodes, cfg["wheels"], wheel_speeds):
        node.rpdo[2]["Target velocity"].raw = int(round(w["polarity"] * speed * scale))
        node.rpdo[2].transmit()


def _wait_still(drives, timeout=3.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(abs(v) < 1e-9 for v in drives.wheel_speeds()):
            time.sleep(0.1)       # one more world step
            return True
        time.sleep(0.02)
    return False


def test_master_enables_every_drive_and_base_moves_commanded_distance(base_rig, robot_cfg):
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
        assert node.state == "OPERATION ENABLED"
        assert node.op_mode == "PROFILED VELOCITY"
    wh = robot_cfg["robot"]["base"]["wheel"]
    kin = MecanumKinematics(wh["radius"], wh["half_wheelbase"], wh["half_track"])
    for vx, vy, distance in ((0.25, 0.0, 0.30), (0.0, 0.2, 0.20)):
        x0, y0, yaw0 = world.base_pose()
        speed = math.hypot(vx, vy)
        t_move = distance / speed                              # computed time at the commanded speed
        t0 = time.monotonic()
        _command(nodes, cfg, kin.wheel_speeds(vx, vy, 0.0))
        time.sleep(t_move)
        t1 = time.monotonic()
        _command(nodes, cfg, [0.0] * 4)
        # the distance actually commanded: speed x time between the start and the stop command (a loaded
        # machine may sleep longer than asked; that is the test's timing, not the simulator's accuracy)
        commanded = speed * (t1 - t0)
        assert _wait_still(drives)
        x1, y1, yaw1 = world.base_pose()
        # robot faces +y (yaw = pi/2): body x -> map +y, body y -> map -x
        moved_fwd = (x1 - x0) * math.cos(yaw0) + (y1 - y0) * math.sin(yaw0)
        moved_left = -(x1 - x0) * math.sin(yaw0) + (y1 - y0) * math.cos(yaw0)
        assert moved_fwd == pytest.approx(commanded if vx else 0.0, abs=0.01)
        assert moved_left == pytest.approx(commanded if vy else 0.0, abs=0.01)
        assert yaw1 == pytest.approx(yaw0, abs=0.01)
    # position feedback (TPDO2) agrees with the wheel angle the base moved with
    node = nodes[0]
    node.tpdo[2].wait_for_reception(1.0)
    counts = node.tpdo_values[0x6064]
    assert counts == pytest.approx(drives.drives[0].angle * cfg["counts_per_rad"], abs=cfg["counts_per_rad"] * 0.01)


@pytest.mark.parametrize("base_rig", [4.0], indirect=True)
def test_time_scale_runs_the_base_faster_while_can_keeps_wall_clock_rates(base_rig, robot_cfg):
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
    scale = world.clock.time_scale
    wh = robot_cfg["robot"]["base"]["wheel"]
    kin = MecanumKinematics(wh["radius"], wh["half_wheelbase"], wh["half_track"])
    x0, y0, _ = world.base_pose()
    distance, v = 0.8, 0.4
    t0 = time.monotonic()
    _command(nodes, cfg, kin.wheel_speeds(v, 0.0, 0.0))
    time.sleep(distance / v / scale)                   # 0.5 s of wall time = 2 s of sim time
    t1 = time.monotonic()
    _command(nodes, cfg, [0.0] * 4)
    assert _wait_still(drives)
    x1, y1, _ = world.base_pose()
    assert math.hypot(x1 - x0, y1 - y0) == pytest.approx(v * scale * (t1 - t0), abs=0.01)
    # the cyclic TPDO keeps its wall-clock period (event timer 20 ms), independent of the time scale
    pdo = nodes[0].tpdo[1]
    stamps = []
    for _ in range(10):
        assert pdo.wait_for_reception(0.5) is not None
        stamps.append(time.monotonic())
    period = (stamps[-1] - stamps[0]) / 9
    assert period == pytest.approx(cfg["tpdo_period_ms"] / 1000.0, rel=0.3)


def test_drive_fault_is_visible_to_master_and_resettable(base_rig):
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
    drives.drives[1].inject_fault(0x2310)
    nodes[1].emcy.wait(0x2310, timeout=1.0)
    assert any(e.code == 0x2310 for e in nodes[1].emcy.log)
    nodes[1].check_statusword(0.5)
    assert nodes[1].state == "FAULT"
    assert nodes[1].sdo[0x603F].raw == 0x2310
    assert nodes[0].state == "OPERATION ENABLED"            # the others keep running
    nodes[1].state = "OPERATION ENABLED"                    # fault reset walk of BaseNode402
    assert nodes[1].state == "OPERATION ENABLED"
    assert nodes[1].sdo[0x603F].raw == 0


def test_heartbeat_loss_is_visible_to_master_and_node_reboots(base_rig):
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
    consumer_timeout = cfg["heartbeat_ms"] / 1000.0 * cfg["consumer_timeout_factor"]
    assert nodes[2].nmt.wait_for_heartbeat(consumer_timeout) == "OPERATIONAL"
    drives.drives[2].inject_heartbeat_loss()
    time.sleep(consumer_timeout)
    with pytest.raises(NmtError):
        nodes[2].nmt.wait_for_heartbeat(consumer_timeout)
    assert time.time() - nodes[2].nmt.timestamp > consumer_timeout     # the consumer sees the age grow
    assert nodes[3].nmt.wait_for_heartbeat(consumer_timeout) == "OPERATIONAL"   # others unaffected
    drives.drives[2].restore()
    assert nodes[2].nmt.wait_for_heartbeat(1.0) == "PRE-OPERATIONAL"          # rebooted
    nodes[2].nmt.state = "OPERATIONAL"
    nodes[2].state = "OPERATION ENABLED"
    assert nodes[2].state == "OPERATION ENABLED"


def test_malformed_frames_are_ignored_logged_and_drives_keep_working(base_rig, caplog):
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
    bad = can.Bus(interface="virtual", channel=cfg["can"]["channel"])
    try:
        with caplog.at_level(logging.WARNING, logger="locem_bridge.sim.can.drives"):
            for arb, data in ((0x601, b"\x40\x41"),           # SDO request of 2 bytes
                              (0x000, b"\x01"),               # NMT of 1 byte
                              (0x000, b"\x77\x01"),           # unknown NMT command
                              (0x301, b"\x10\x00"),           # RPDO2 (target velocity) with 2 of 4 bytes
                              (0x201, b"\x0f\x00\x03\x00\x00")):   # RPDO1 too long
                bad.send(can.Message(arbitration_id=arb, data=data, is_extended_id=False))
            time.sleep(0.3)
        assert drives.drives[0].refused >= 4
        assert "malformed" in caplog.text
        assert drives.drives[0].snapshot()["velocity"] == 0.0           # the short velocity RPDO did nothing
        assert nodes[0].sdo[0x6041].raw & 0x6F == 0x27                 # still OPERATION ENABLED, SDO answers
        _command(nodes, cfg, [1.0, 1.0, 1.0, 1.0])
        time.sleep(0.3)
        assert drives.wheel_speeds()[0] == pytest.approx(1.0, abs=1e-6)
        _command(nodes, cfg, [0.0] * 4)
    finally:
        bad.shutdown()


def test_drives_on_udp_multicast_answer_a_master_in_another_bus_instance(robot_cfg, port):
    cfg = _drives_cfg(robot_cfg, interface="udp_multicast", channel="239.74.163.2", port=port)
    eds = resolve_relative(robot_cfg, robot_cfg["robot"]["base"]["eds"])
    drives = DriveSet(cfg, eds, SimClock(1.0).now)
    drives.start()
    net = canopen.Network(open_bus(cfg["can"]))       # the master filters its own echoes the same way
    net.NOTIFIER_CYCLE = 0.1
    try:
        net.connect()
        node = canopen.BaseNode402(cfg["wheels"][0]["node_id"], eds)
        net.add_node(node)
        _enable(node)
        assert node.state == "OPERATION ENABLED"
    finally:
        net.disconnect()
        drives.stop()


def test_master_can_remap_an_rpdo_over_sdo(base_rig):
    world, drives, net, nodes, cfg = base_rig
    node = nodes[0]
    node.nmt.wait_for_heartbeat(1.0)
    node.setup_402_state_machine()
    # move the target velocity RPDO (RPDO2) to another COB-ID, as a master's PDO configuration would
    new_cob = 0x400 + node.id
    node.rpdo[2].cob_id = new_cob
    node.rpdo[2].save()
    assert node.sdo[0x1401][1].raw & 0x7FF == new_cob
    node.nmt.state = "OPERATIONAL"
    node.op_mode = "PROFILED VELOCITY"
    node.state = "OPERATION ENABLED"
    node.rpdo[2]["Target velocity"].raw = 1500
    node.rpdo[2].transmit()
    time.sleep(0.3)
    assert drives.drives[0].snapshot()["velocity"] == pytest.approx(1.5, abs=1e-6)
    node.rpdo[2]["Target velocity"].raw = 0
    node.rpdo[2].transmit()


def test_velocity_actual_value_0x606c_follows_the_wheel_by_sdo_and_tpdo(base_rig):
    """0x606C (velocity actual value) reports the wheel's actual velocity, not an echo of the target 0x60FF: it
    ramps up, matches the commanded velocity once the ramp is done (by SDO and in TPDO2, which maps it), and is 0
    after the stop."""
    world, drives, net, nodes, cfg = base_rig
    for node in nodes:
        _enable(node)
    scale = cfg["velocity_units_per_rad_s"]
    speed = 3.0                                                    # rad/s at every wheel, forward
    # a slow ramp on drive 1 (0.5 rad/s^2: 6 s to full speed): mid-ramp, the actual value is below the target
    default_accel = nodes[0].sdo[0x6083].raw
    nodes[0].sdo[0x6083].raw = int(0.5 * scale)
    t0 = time.monotonic()
    _command(nodes, cfg, [speed] * 4)
    time.sleep(0.3)
    ramping = nodes[0].sdo[0x606C].raw
    elapsed = time.monotonic() - t0
    assert 0 < ramping < 0.8 * speed * scale, "mid-ramp 0x606C %r after %.2f s" % (ramping, elapsed)
    assert ramping <= 0.5 * elapsed * scale + 10                   # no faster than the ramp allows
    nodes[0].sdo[0x6083].raw = default_accel                       # the rest of the ramp at the default
    # at speed: every drive reports the commanded velocity (drive sign = polarity), by SDO and in TPDO2
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and nodes[0].sdo[0x606C].raw != speed * scale:
        time.sleep(0.1)
    for node, w, d in zip(nodes, cfg["wheels"], drives.drives):
        expected = w["polarity"] * speed * scale
        assert node.sdo[0x606C].raw == pytest.approx(expected, abs=1), node.id
        assert node.sdo[0x60FF].raw == expected
        assert node.tpdo[2].wait_for_reception(1.0) is not None
        assert node.tpdo_values[0x606C] == pytest.approx(expected, abs=1), node.id
        assert node.tpdo[2]["Velocity actual value"].raw == pytest.approx(expected, abs=1)
        assert d.snapshot()["velocity"] * scale == pytest.approx(expected, abs=1)    # the stand-in's own state
    # the position feedback advances at that velocity (counts per s = velocity x counts_per_rad)
    p0, ta = nodes[1].sdo[0x6064].raw, time.monotonic()
    time.sleep(0.5)
    p1, tb = nodes[1].sdo[0x6064].raw, time.monotonic()
    rate = (p1 - p0) / (tb - ta) / cfg["counts_per_rad"]
    assert rate == pytest.approx(-speed, rel=0.2)                  # front_right: polarity -1
    # stop: 0 by SDO and in the next TPDO of every drive
    _command(nodes, cfg, [0.0] * 4)
    assert _wait_still(drives, timeout=10.0)
    for node in nodes:
        assert node.sdo[0x606C].raw == 0
        assert node.tpdo[2].wait_for_reception(1.0) is not None
        assert node.tpdo_values[0x606C] == 0
