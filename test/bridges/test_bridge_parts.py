"""Device-free parts of the bridges: geometry, mecanum kinematics, configuration errors, the backend table, the
declarations (units and ranges in HELP), and the frame chain map -> UR base used by the wall commands."""
import math
import os

import numpy as np
import pytest

from locem_bridge.bridges import backends, commands_arm, commands_base, commands_compressor, commands_wall
from locem_bridge.bridges.config import load_robot_config, need
from locem_bridge.bridges.errors import BadRequest, BridgeConfigError
from locem_bridge.bridges.geometry import arm_base_in_footprint, planar, tool_frame_facing
from locem_bridge.common.config_keys import deep_merge
from locem_bridge.common.geometry import invert, matrix_to_pose, matrix_to_rotvec, pose_to_matrix, rotvec_to_matrix
from locem_bridge.common.base_kinematics import MecanumKinematics
from locem_bridge.locem.catalogue import all_specs
from locem_bridge.locem.core import LocemCore
from locem_bridge.robot_file import load_robot

from bridge_rigs import ROBOT_YAML


@pytest.mark.parametrize("rv", [[0, 0, 0], [0.1, -0.2, 0.3], [0, math.pi, 0], [2.2214, -2.2214, 0], [0, 0, -3.1]])
def test_rotation_vector_round_trip(rv):
    m = rotvec_to_matrix(rv)
    assert np.allclose(m.T.dot(m), np.eye(3), atol=1e-9)
    assert np.allclose(rotvec_to_matrix(matrix_to_rotvec(m)), m, atol=1e-6)


def test_tool_frame_points_into_the_wall_with_a_horizontal_x_axis():
    f = tool_frame_facing([1.0, 3.6, 1.2], [0.0, -1.0, 0.0])
    assert np.allclose(f[:3, 2], [0, 1, 0]) and abs(f[2, 0]) < 1e-12
    with pytest.raises(ValueError):
        tool_frame_facing([0, 0, 0], [0, 0, 0])


def test_map_to_ur_base_chain_matches_the_configured_mount():
    robot = load_robot_config(ROBOT_YAML)
    mount = robot["arm"]["mount"]
    t = planar(2.4, 1.6, math.pi / 2).dot(arm_base_in_footprint(mount["xyz"], mount["rpy"]))
    # the UR base sits 0.2 m ahead of base_footprint (+y in map when facing +y), 1.05 m up, x axis backwards
    assert np.allclose(t[:3, 3], [2.4, 1.8, 1.05], atol=1e-9)
    assert np.allclose(t[:3, 0], [0, -1, 0], atol=1e-9)
    pose = [0.1, -0.2, 0.3, 0.0, 3.0, 0.0]
    assert np.allclose(matrix_to_pose(invert(t).dot(t).dot(pose_to_matrix(pose))), pose, atol=1e-9)


def test_mecanum_inverse_and_forward_agree_and_limits_scale_the_twist():
    kin = MecanumKinematics(0.1275, 0.236, 0.2605)
    for twist in ((0.3, 0.0, 0.0), (0.0, -0.2, 0.0), (0.1, 0.2, 0.5)):
        assert np.allclose(kin.twist(kin.wheel_speeds(*twist)), twist)
    vx, vy, wz = kin.scale_to_limit(5.0, 0.0, 0.0, 20.0)
    assert max(abs(w) for w in kin.wheel_speeds(vx, vy, wz)) == pytest.approx(20.0)
    assert vy == 0.0 and wz == 0.0


def test_config_errors_name_the_key_and_the_allowed_values(tmp_path):
    robot = load_robot_config(ROBOT_YAML, {"compressor": {"port": 5021}})
    assert robot["compressor"]["port"] == 5021 and robot["compressor"]["host"] == "127.0.0.1"
    with pytest.raises(BridgeConfigError, match=r"robot.compressor.timeout: 'slow' must be a finite number"):
        need({"timeout": "slow"}, "timeout", float, where="robot.compressor")
    with pytest.raises(BridgeConfigError, match=r"robot.arm.controller.host: missing key"):
        need({"controller": {}}, "controller.host", str, where="robot.arm")
    bad = tmp_path / "bad.yaml"
    bad.write_text("robot: [1, 2]\n")
    with pytest.raises(BridgeConfigError) as exc:
        load_robot_config(str(bad))
    assert str(exc.value) == "%s: robot: must be of type mapping, found [1, 2]" % bad
    assert deep_merge({"a": {"b": 1, "c": 2}}, {"a": {"b": 3}}) == {"a": {"b": 3, "c": 2}}


def test_the_bridges_load_robot_files_through_the_one_validation_the_simulator_uses(tmp_path):
    """A file (plus overrides) the bridges would misread does not load: one line naming file, key and problem."""
    with pytest.raises(BridgeConfigError) as exc:
        load_robot_config(ROBOT_YAML, {"arm": {"controller": {"rtde_port": 30014}}})
    assert str(exc.value).startswith("%s (with overrides): robot.arm.controller.rtde_port: 30014 cannot be used: ur_rtde always dials "
                                     "the UR ports 29999 (dashboard), 30003 (script) and 30004 (RTDE); another robot "
                                     "takes another address (host) (allowed: 30004)" % ROBOT_YAML)
    with pytest.raises(BridgeConfigError, match=r"robot.arm.deadline.scale: 0.0 is out of range"):
        load_robot_config(ROBOT_YAML, {"arm": {"deadline": {"scale": 0.0}}})
    with pytest.raises(BridgeConfigError, match=r"robot.base.drives.wheels\[0\].nodeid: unknown key \(allowed: name, "
                                                 r"node_id, polarity\)"):
        load_robot_config(ROBOT_YAML, {"base": {"drives": {"wheels": [{"name": "w%d" % i, "nodeid": i, "polarity": 1}
                                                                      for i in range(1, 5)]}}})
    with pytest.raises(BridgeConfigError, match=r"robot.scanner.backend: 'lidar' is not allowed \(allowed: sim\)"):
        load_robot_config(ROBOT_YAML, {"scanner": {"backend": "lidar"}})
    robot = load_robot_config(ROBOT_YAML)
    assert os.path.isabs(robot["base"]["eds"]) and os.path.isfile(robot["base"]["eds"])   # resolved at load
    # optional keys the bridges read are known keys (a new one goes into robot_file.ROBOT_KEYS with its check)
    robot = load_robot_config(ROBOT_YAML, {"compressor": {"watchdog_timeout": 1.0, "timeout": 0.3},
                                           "arm": {"deadline": {"scale": 2.0, "margin": 3.0}},
                                           "base": {"deadline": {"scale": 2.0}, "control_rate": 40.0,
                                                    "drives": {"master_node_id": 100, "stop_deceleration": 150.0}}})
    assert robot["compressor"]["watchdog_timeout"] == 1.0 and robot["arm"]["deadline"]["scale"] == 2.0
    with pytest.raises(BridgeConfigError, match=r"robot.compressor.watchdog_timeout: 0.0 is out of range"):
        load_robot_config(ROBOT_YAML, {"compressor": {"watchdog_timeout": 0.0}})
    # the ranges a bridge applies when it is built are checked at load too (main.sh's pre-flight sees them)
    with pytest.raises(BridgeConfigError, match=r"robot.base.control_rate: 2.0 is out of range \(allowed: >= 5.0\)"):
        load_robot_config(ROBOT_YAML, {"base": {"control_rate": 2}})
    with pytest.raises(BridgeConfigError, match=r"robot.arm.controller.rtde_frequency: 1000.0 is out of range"):
        load_robot_config(ROBOT_YAML, {"arm": {"controller": {"rtde_frequency": 1000}}})


def test_motion_deadline_settings_are_checked_and_default_to_the_documented_values():
    from locem_bridge.bridges.cia402_base import Cia402Base
    from locem_bridge.bridges.config import resolve_path
    from locem_bridge.bridges.ur_arm import MOTION_MARGIN_S, UrRtdeArm
    robot = load_robot_config(ROBOT_YAML)
    arm = UrRtdeArm(robot["arm"])
    assert (arm.deadline_scale, arm.deadline_margin) == (1.0, MOTION_MARGIN_S)
    eds = resolve_path(robot, robot["base"]["eds"])
    base = Cia402Base(robot["base"], eds)
    assert (base.deadline_scale, base.deadline_margin) == (1.0, 5.0)
    # the robot YAML: 100 ms producer heartbeat x consumer factor 2 -> a drive is silent after 200 ms
    assert base.hb_timeout == pytest.approx(0.2)
    with pytest.raises(BridgeConfigError, match=r"robot.arm.deadline.scale: 0.0 is out of range \(allowed: 0.01 .. 100"):
        UrRtdeArm(deep_merge(robot["arm"], {"deadline": {"scale": 0.0}}))
    with pytest.raises(BridgeConfigError, match=r"robot.base.deadline.margin: 'long' must be a finite number"):
        Cia402Base(deep_merge(robot["base"], {"deadline": {"margin": "long"}}), eds)


def test_backend_table_names_what_exists():
    assert backends.backend_class("compressor", "modbus_tcp").__name__ == "ModbusCompressor"
    with pytest.raises(BridgeConfigError, match="no arm backend named 'kuka'; known: ur_rtde"):
        backends.backend_class("arm", "kuka")
    with pytest.raises(BridgeConfigError, match="unknown device kind 'lidar'"):
        backends.backend_class("lidar", "x")


def test_every_bridge_command_is_declared_once_with_units_and_ranges():
    specs = all_specs()
    names = [s.name for s in specs]
    assert len(names) == len(set(names))
    robot = load_robot()["robot"]
    bridge = [s for m in (commands_base, commands_compressor) for s in m.SPECS] + \
        list(commands_arm.specs_for(robot)) + list(commands_wall.specs_for(robot))
    for spec in bridge:
        assert spec.name in names
        for arg in spec.args:
            if arg.type.value == "float":
                assert arg.minimum is not None and arg.maximum is not None, (spec.name, arg.name)
    expected = {"MOVE_J", "MOVE_L", "MOVE_PATH", "MOVE_HOME", "STOP_ARM", "GET_JOINTS", "GET_TCP_POSE", "SET_TCP",
                "SET_PAYLOAD", "TOOL_OUTPUT", "RESET_ARM", "COMPRESSOR_ON", "COMPRESSOR_OFF", "SET_PRESSURE",
                "GET_PRESSURE", "SPRAY_ON", "SPRAY_OFF", "GOTO", "GOTO_TAG", "MOVE_BASE_REL", "STOP_BASE", "GET_POSE",
                "SCAN", "MOUNT_TOOL", "APPLY_TAPE_START", "APPLY_TAPE", "SPRAY_AREA", "SAND_AREA", "HOME"}
    assert expected <= set(names)


def test_help_and_bad_input_for_bridge_commands_without_hardware(core):
    for spec in commands_arm.specs_for(load_robot()["robot"]):
        core.registry.declare(spec)
    r = core.dispatcher.execute("HELP MOVE_L")
    assert r.success and "a number from 0.001 to 1 m/s" in r.message
    r = core.dispatcher.execute("MOVE_L 0.4 0.1 0.5 0 3.14 0 speed=2")
    assert r.code.value == "INVALID_ARGUMENT" and "speed" in r.message
    r = core.dispatcher.execute("MOVE_L 0.4 0.1 nan 0 3.14 0")
    assert r.code.value == "INVALID_ARGUMENT" and "'z'" in r.message
    r = core.dispatcher.execute("MOVE_L 0.4 0.1 0.5 0 3.14 0")
    assert r.code.value == "NOT_READY"          # declared, no arm on this LOCEM
    spec = commands_arm.MOVE_J
    bound = core.dispatcher.bind("MOVE_J 0 0 0 0 0 0 speed=0.5 accel=1")
    assert bound.timeout == pytest.approx(spec.deadline(bound.values)) and bound.timeout > 2 * math.pi / 0.5
    assert commands_wall.APPLY_TAPE.deadline({"x0": 0, "y0": 0, "z0": 0, "x1": 1.2, "y1": 0, "z1": 0,
                                              "speed": 0.1}) == pytest.approx(72.0)


def test_a_robots_registry_takes_reach_and_tools_from_its_robot_file(core, robot):
    """Robot facts come from the robot file: the TCP bound (reach + longest tool) of the arm commands' pose
    arguments and MOVE_PATH's waypoints, and MOUNT_TOOL's choices; a UR5e-class reach narrows them."""
    shipped = {s.name: s for s in all_specs()}
    assert [a.maximum for a in shipped["MOVE_L"].args[:3]] == [pytest.approx(1.30 + 0.22)] * 3
    assert shipped["MOUNT_TOOL"].args[0].choices == tuple(robot["tools"]) == ("taping_tool", "spray_gun", "sander")
    short = load_robot(overrides={"arm": {"reach": 0.85}})["robot"]
    specs = {s.name: s for s in all_specs(short)}
    assert specs["SET_TCP"].args[0].maximum == pytest.approx(0.85 + 0.22)
    small = LocemCore(grace=0.5, stop_timeout=2.0)
    try:
        for cores, spec_set in ((core, shipped), (small, specs)):
            for spec in spec_set.values():
                cores.registry.declare(spec)
        assert core.dispatcher.execute("MOVE_L 1.2 0.1 0.5 0 3.14 0").code.value == "NOT_READY"   # in range
        r = small.dispatcher.execute("MOVE_L 1.2 0.1 0.5 0 3.14 0")
        assert r.code.value == "INVALID_ARGUMENT" and "-1.07 to 1.07" in r.message, r.message
        assert "1.07" in small.dispatcher.execute("HELP MOVE_L").message
    finally:
        small.close()
    with pytest.raises(BadRequest, match="allowed -1.07 to 1.07 m"):
        commands_arm.parse_waypoints("1.2:0.2:0.4:0:3.14:0", 1.07)
    assert commands_arm.parse_waypoints("1.2:0.2:0.4:0:3.14:0")[0][0] == 1.2      # the shipped bound


def test_move_path_waypoints_are_checked():
    pts = commands_arm.parse_waypoints("0.5:0.2:0.4:0:3.14:0/0.5:0.3:0.4:0:3.14:0")
    assert len(pts) == 2 and pts[1][1] == 0.3
    with pytest.raises(BadRequest, match="waypoint 2 'x' must be 6 numbers"):
        commands_arm.parse_waypoints("0.5:0.2:0.4:0:3.14:0/x")
    with pytest.raises(BadRequest, match="position out of range"):
        commands_arm.parse_waypoints("5:0.2:0.4:0:3.14:0")


def test_the_base_bridge_refuses_a_can_bus_it_cannot_use_with_its_own_errors(robot):
    """The base bridge opens its bus through locem_bridge.common.can_bus, as the simulated drives do: a bus the
    robot file may not name is a configuration error (NOT_READY, key and allowed list), a bus that cannot be
    opened is a link down (HARDWARE_ERROR), and nothing was started."""
    import copy

    from locem_bridge.bridges.cia402_base import Cia402Base
    from locem_bridge.bridges.config import resolve_path
    from locem_bridge.bridges.errors import LinkDown

    eds = resolve_path(robot, robot["base"]["eds"])
    cfg = copy.deepcopy(robot["base"])
    cfg["drives"]["can"] = {"interface": "pcan", "channel": "PCAN_USBBUS1", "bitrate": 1000000}
    base = Cia402Base(cfg, eds)
    with pytest.raises(BridgeConfigError) as caught:
        base.start()
    assert caught.value.code.value == "NOT_READY" and caught.value.key == "robot.base.drives.can.interface"
    assert "(allowed: virtual, udp_multicast, socketcan)" in str(caught.value) and base.network is None
    cfg["drives"]["can"] = {"interface": "socketcan", "channel": "nosuchcan7", "bitrate": 1000000}
    base = Cia402Base(cfg, eds)
    with pytest.raises(LinkDown) as down:
        base.start()
    assert down.value.code.value == "HARDWARE_ERROR" and down.value.device == "base"
    assert str(down.value).startswith("CAN bus socketcan nosuchcan7 cannot be opened: ") and base.network is None
