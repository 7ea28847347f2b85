"""The one robot-file loader: the bridges, the simulator, the pre-flight and the main job read a robot file through
locem_bridge.robot_file.load_robot, so a bad file is the same one line whoever loads it, in each caller's own
error type."""
import os

import pytest
import yaml

from locem_bridge.bridges.config import load_robot_config
from locem_bridge.bridges.errors import BridgeConfigError
from locem_bridge.common.config_errors import ConfigError
from locem_bridge.config_check import check_files
from locem_bridge.robot_file import RobotFileError, default_robot_path, load_robot
from locem_bridge.sim import config as sim_config
from locem_bridge.sim.errors import SimConfigError


def _bad_copy(tmp_path, mutate):
    with open(default_robot_path()) as handle:
        data = yaml.safe_load(handle)
    mutate(data)
    eds = os.path.join(os.path.dirname(default_robot_path()), "cia402_drive.eds")
    (tmp_path / "cia402_drive.eds").write_bytes(open(eds, "rb").read())
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_every_layer_refuses_a_bad_robot_file_with_the_same_line_in_its_own_error_type(tmp_path):
    path = _bad_copy(tmp_path, lambda d: d["robot"]["compressor"].update(port=70000))
    line = "%s: robot.compressor.port: 70000 is out of range (allowed: <= 65535)" % path
    for loader, error in ((load_robot, RobotFileError), (sim_config.load_robot, SimConfigError),
                          (load_robot_config, BridgeConfigError), (lambda p: check_files(robot=p), ConfigError)):
        with pytest.raises(error) as caught:
            loader(path)
        assert str(caught.value) == line and isinstance(caught.value, ConfigError)


def test_overrides_are_checked_with_the_file_and_named_as_their_source(tmp_path):
    path = _bad_copy(tmp_path, lambda d: None)
    with pytest.raises(SimConfigError) as caught:
        sim_config.load_robot(path, {"base": {"drives": {"can": {"interface": "pcan"}}}})
    assert str(caught.value) == ("%s (with overrides): robot.base.drives.can.interface: 'pcan' is not allowed "
                                 "(allowed: virtual, udp_multicast, socketcan)" % path)
    robot = load_robot(path, {"compressor": {"port": 5021}})["robot"]
    assert robot["compressor"]["port"] == 5021 and robot["base"]["eds"] == str(tmp_path / "cia402_drive.eds")
    assert load_robot_config(path, {"compressor": {"port": 5021}})["compressor"] == robot["compressor"]


# -- the second robot: a differential base and a lift ------------------------------------------------------------
DIFF_YAML = os.path.join(os.path.dirname(default_robot_path()), "diffdrive_ur5e.yaml")


def _bad_diff(tmp_path, mutate):
    with open(DIFF_YAML) as handle:
        data = yaml.safe_load(handle)
    mutate(data)
    folder = os.path.dirname(DIFF_YAML)
    for eds in ("cia402_drive.eds", "cia402_lift.eds"):
        (tmp_path / eds).write_bytes(open(os.path.join(folder, eds), "rb").read())
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(data))
    return str(path)


def test_the_second_robot_file_loads_with_a_differential_base_and_a_lift():
    robot = load_robot(DIFF_YAML)["robot"]
    assert robot["base"]["kind"] == "differential" and len(robot["base"]["drives"]["wheels"]) == 2
    assert robot["lift"]["range"] == [0.55, 1.45] and robot["lift"]["eds"].endswith("cia402_lift.eds")
    assert "lift" not in load_robot()["robot"]                 # the shipped robot has none


@pytest.mark.parametrize("mutate,line", [
    (lambda d: d["robot"]["base"]["wheel"].update(half_track=0.26),
     "robot.base.wheel.half_track: is not a key of a differential base (allowed: radius, width, separation)"),
    (lambda d: d["robot"]["base"]["wheel"].pop("separation"), "robot.base.wheel.separation: missing"),
    (lambda d: d["robot"]["base"]["drives"]["wheels"].append({"name": "third", "node_id": 3, "polarity": 1}),
     "robot.base.drives.wheels: must list 2 wheels for a differential base, found 3 (allowed: left, right)"),
    (lambda d: d["robot"]["base"].update(kind="omni"), "robot.base.kind: 'omni' is not allowed"),
    (lambda d: d["robot"]["lift"]["drive"].update(node_id=2),
     "robot.lift.drive.node_id: 2 is taken on the base's CAN bus"),
    (lambda d: d["robot"]["lift"].update(range=[1.2, 0.6]), "robot.lift.range: [1.2, 0.6] is not a range of heights"),
    (lambda d: d["robot"]["arm"]["mount"].update(xyz=[0.12, 0.0, 1.8]),
     "robot.arm.mount.xyz: 1.8 is outside the lift's range"),
    (lambda d: d["robot"]["lift"].update(speed=0.1), "robot.lift.speed: unknown key"),
])
def test_an_inconsistent_differential_base_or_lift_is_refused_naming_the_key(tmp_path, mutate, line):
    path = _bad_diff(tmp_path, mutate)
    with pytest.raises(RobotFileError) as caught:
        load_robot(path)
    assert line in str(caught.value), str(caught.value)


def _with_changer(d, **changes):
    rack_file = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "tool_changer_rack.yaml")
    with open(rack_file) as handle:
        d["robot"]["tool_changer"] = yaml.safe_load(handle)["tool_changer"]
    for key, value in changes.items():
        d["robot"]["tool_changer"][key] = value


@pytest.mark.parametrize("changes,line", [
    ({"rack": {"taping_tool": {"slot": 1, "pose": [0.0] * 6}, "drill": {"slot": 2, "pose": [0.0] * 6}}},
     "robot.tool_changer.rack.drill: 'drill' is not a tool of this robot (robot.tools) (allowed: sander, spray_gun, "
     "taping_tool)"),
    ({"rack": {"taping_tool": {"slot": 1, "pose": [0.0] * 6}, "sander": {"slot": 1, "pose": [0.0] * 6}}},
     "robot.tool_changer.rack.taping_tool.slot: slot 1 is sander's already; one tool per slot"),
    ({"rack": {"sander": {"slot": 9, "pose": [0.0] * 6}}},
     "robot.tool_changer.rack.sander.slot: 9 is out of range (allowed: <= 8)"),
    ({"rack": {"sander": {"slot": 1, "pose": [0.0] * 5}}},
     "robot.tool_changer.rack.sander.pose: must be a list of 6 finite numbers, found [0.0, 0.0, 0.0, 0.0, 0.0]"),
    ({"safe_pose": "nowhere"},
     "robot.tool_changer.safe_pose: 'nowhere' is not allowed (allowed: home, scan, stow, tool_change, wall_ready)"),
    ({"port": 5020}, "robot.tool_changer.port: 127.0.0.1:5020 is the compressor's address; the tool changer is a "
                     "device of its own"),
    ({"gripper": 1}, "robot.tool_changer.gripper: unknown key (allowed: device_id, host, lock_timeout, port, "
                     "protocol, rack, safe_pose, sim, timeout)"),
])
def test_a_bad_tool_changer_section_is_refused_with_file_and_key(tmp_path, changes, line):
    path = _bad_copy(tmp_path, lambda d: _with_changer(d, **changes))
    with pytest.raises(RobotFileError) as caught:
        load_robot(path)
    assert str(caught.value) == "%s: %s" % (path, line)


def test_the_shipped_robot_has_no_tool_changer_and_the_test_rack_loads():
    assert "tool_changer" not in load_robot()["robot"]
    rack_file = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data", "tool_changer_rack.yaml")
    with open(rack_file) as handle:
        tc = load_robot(None, yaml.safe_load(handle))["robot"]["tool_changer"]
    assert {t: s["slot"] for t, s in tc["rack"].items()} == {"taping_tool": 1, "spray_gun": 2, "sander": 3}
    assert tc["sim"] == {"lock_time": 0.3, "slot_tolerance": 0.01} and tc["lock_timeout"] == 3.0
