"""Configuration validation (clear errors naming key, value and what is allowed), clock, mecanum kinematics,
and the command-line entry point refusing a bad file."""
import copy
import os
import subprocess
import sys

import pytest
import yaml

from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.config import load_robot, load_site, validate_robot, validate_site
from locem_bridge.sim.errors import SimConfigError
from locem_bridge.common.base_kinematics import MecanumKinematics
from locem_bridge.sim.site import Site

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")


def _raw(path):
    with open(path) as fh:
        return yaml.safe_load(fh)


def test_shipped_default_site_keeps_joints_and_areas_above_the_skirting():
    site = Site(load_site())
    assert len(site.work_walls) == 2
    for wall in site.work_walls:
        vertical = [j for j in wall.joints if j.kind == "vertical"]
        assert len(vertical) == 3                                            # 3.0 m wall, 0.75 m panels
        assert all(abs(j.start[2] - 0.1) < 1e-9 and abs(j.end[2] - wall.height) < 1e-9 for j in vertical)
        assert [(round(a.t0, 6), round(a.t0 + a.height, 6)) for a in wall.areas] == [(0.1, 2.0)]


def test_skirting_moves_joint_feet_and_default_areas_and_bounds_horizontal_joints(site_cfg):
    data = copy.deepcopy(site_cfg)
    wall = data["site"]["walls"][1]                      # wall_2: no explicit areas
    wall["skirting"] = 0.2
    site = Site(validate_site(data))
    w2 = site.wall("wall_2")
    assert all(abs(j.start[2] - 0.2) < 1e-9 for j in w2.joints if j.kind == "vertical")
    assert [(round(a.t0, 6), round(a.height, 6)) for a in w2.areas] == [(0.2, 2.3)]
    wall["horizontal_joints"] = [0.15]
    with pytest.raises(SimConfigError) as exc:
        validate_site(data)
    assert "above the skirting" in str(exc.value)


def test_default_site_has_joints_from_panel_width_and_horizontal_joints(site_cfg):
    site = Site(site_cfg)
    w1 = site.wall("wall_1")
    vertical = [j for j in w1.joints if j.kind == "vertical"]
    assert [round(j.start[0], 6) for j in vertical] == [1.2, 2.4, 3.6]      # 4.8 m wall, 1.2 m panels
    assert [j.kind for j in w1.joints].count("horizontal") == 1
    assert len(site.work_walls) >= 2 and all(w.n[1] <= 0 for w in [w1])
    assert [a.id for a in w1.areas] == ["wall_1_area_1", "wall_1_area_2"]


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["site"]["walls"][0].pop("height"), "site.walls[0].height: missing key"),
    (lambda d: d["site"]["walls"][0].update(height=-1), "site.walls[0].height: -1.0 is out of range (allowed: >= 0.1)"),
    (lambda d: d["site"]["walls"][0].update(id="1wall"), "not a valid feature id"),
    (lambda d: d["site"]["walls"][1].update(id="wall_1"), "used twice"),
    (lambda d: d["site"]["walls"][0].update(horizontal_joints=[3.0]), "horizontal_joints[0]: 3.0 is not a height above the skirting"),
    (lambda d: d["simulation"].update(time_scale="fast"), "simulation.time_scale: must be a finite number, found 'fast'"),
    (lambda d: d["site"]["walls"][0].update(p1=[0.0, 3.6]), "apart (allowed: >= 0.1 m)"),
])
def test_bad_site_files_are_refused_with_a_clear_message(mutate, message, test_site_path):
    data = _raw(test_site_path)
    mutate(data)
    with pytest.raises(SimConfigError) as exc:
        validate_site(data)
    assert message in str(exc.value)


@pytest.mark.parametrize("mutate, message", [
    (lambda d: d["robot"]["base"]["drives"]["wheels"][1].update(node_id=1), "wheels[1].node_id: 1 is used twice"),
    (lambda d: d["robot"]["base"]["drives"]["can"].update(interface="pcan"), "allowed: virtual, udp_multicast"),
    (lambda d: d["robot"]["base"]["drives"]["wheels"].pop(), "must list 4 wheels"),
    (lambda d: d["robot"]["tools"]["sander"]["switch"].update(index=9), "switch.index: 9 is out of range (allowed: <= 7)"),
    (lambda d: d["robot"]["tools"].pop("spray_gun"), "robot.tools.spray_gun: missing key"),
    (lambda d: d["robot"]["tools"]["taping_tool"].update(tcp=[0, 0, 0.2]), "list of 6 finite numbers"),
])
def test_bad_robot_files_are_refused_with_a_clear_message(mutate, message):
    from locem_bridge.robot_file import default_robot_path
    data = _raw(default_robot_path())
    mutate(data)
    with pytest.raises(SimConfigError) as exc:
        validate_robot(data, os.path.dirname(default_robot_path()))
    assert message in str(exc.value)


def _write(tmp_path, name, data):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return str(path)


def _robot_copy(tmp_path, mutate):
    """The shipped robot file, changed by ``mutate``, written next to a copy of its EDS (relative paths)."""
    from locem_bridge.robot_file import default_robot_path
    data = _raw(default_robot_path())
    mutate(data)
    eds = os.path.join(os.path.dirname(default_robot_path()), "cia402_drive.eds")
    (tmp_path / "cia402_drive.eds").write_bytes(open(eds, "rb").read())
    return _write(tmp_path, "robot.yaml", data)


def test_a_bad_site_file_is_one_line_naming_file_key_problem_and_allowed_values(tmp_path, test_site_path):
    data = _raw(test_site_path)
    data["site"]["walls"][0]["material"] = "brick"
    path = _write(tmp_path, "site.yaml", data)
    with pytest.raises(SimConfigError) as exc:
        load_site(path)
    assert str(exc.value) == ("%s: site.walls[0].material: 'brick' is not allowed (allowed: plasterboard, concrete)"
                              % path)
    assert (exc.value.file, exc.value.key) == (path, "site.walls[0].material")


@pytest.mark.parametrize("mutate, key", [
    (lambda d: d["simulation"].update(outcomes={"grid": 0.05}), "simulation.outcomes"),
    (lambda d: d["site"]["walls"][0].update(panel_widht=0.6), "site.walls[0].panel_widht"),
    (lambda d: d.update(robot={}), "robot"),
])
def test_unknown_site_keys_are_refused_by_name(tmp_path, test_site_path, mutate, key):
    data = _raw(test_site_path)
    mutate(data)
    path = _write(tmp_path, "site.yaml", data)
    with pytest.raises(SimConfigError) as exc:
        load_site(path)
    assert str(exc.value).startswith("%s: %s: unknown key (allowed: " % (path, key))


def test_a_misspelt_device_section_is_refused_instead_of_leaving_the_device_out(tmp_path):
    def misspell(d):
        d["robot"]["compresor"] = d["robot"].pop("compressor")
    path = _robot_copy(tmp_path, misspell)
    with pytest.raises(SimConfigError) as exc:
        load_robot(path)
    assert str(exc.value) == ("%s: robot.compresor: unknown key (allowed: arm, base, compressor, lift, name, namespace, "
                              "pedestal, scanner, tool_changer, tools)" % path)


def test_relative_paths_resolve_against_the_robot_file_and_a_missing_one_is_named(tmp_path):
    path = _robot_copy(tmp_path, lambda d: None)
    assert load_robot(path)["robot"]["base"]["eds"] == str(tmp_path / "cia402_drive.eds")
    path = _robot_copy(tmp_path, lambda d: d["robot"]["base"].update(eds="drives/x.eds"))
    with pytest.raises(SimConfigError) as exc:
        load_robot(path)
    assert str(exc.value) == ("%s: robot.base.eds: %s does not exist (relative paths are read from the robot "
                              "file's folder)" % (path, tmp_path / "drives" / "x.eds"))
    path = _robot_copy(tmp_path, lambda d: d["robot"]["arm"].update(description={"urdf": "arm/ur10e.urdf"}))
    with pytest.raises(SimConfigError) as exc:
        load_robot(path)
    assert str(exc.value).startswith("%s: robot.arm.description.urdf: %s does not exist" % (path, tmp_path / "arm"
                                                                                             / "ur10e.urdf"))


@pytest.mark.parametrize("key, port", [("rtde_port", 30014), ("dashboard_port", 29998), ("script_port", 30013)])
def test_controller_ports_ur_rtde_cannot_dial_are_refused(tmp_path, key, port):
    path = _robot_copy(tmp_path, lambda d: d["robot"]["arm"]["controller"].update({key: port}))
    with pytest.raises(SimConfigError) as exc:
        load_robot(path)
    line = str(exc.value)
    assert line.startswith("%s: robot.arm.controller.%s: %d cannot be used: ur_rtde always dials" % (path, key, port))
    assert "another robot takes another address" in line and "\n" not in line
    # the same refusal for a port given as an override (a launch's robot_overrides)
    with pytest.raises(SimConfigError, match="ur_rtde always dials"):
        load_robot(_robot_copy(tmp_path, lambda d: None), {"arm": {"controller": {key: port}}})


def test_command_line_refuses_a_bad_site_file_and_exits_2(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("site: {name: x, walls: []}\n")
    env = dict(os.environ, PYTHONPATH=SRC)
    res = subprocess.run([sys.executable, "-m", "locem_bridge.sim", "--site", str(bad), "--no-ur"],
                         capture_output=True, text=True, timeout=60, env=env)
    assert res.returncode == 2
    assert "%s: site.walls: must list at least one wall" % bad in res.stderr


def test_clock_scales_sim_time_and_keeps_it_continuous_when_the_scale_changes():
    wall = [100.0]
    clock = SimClock(4.0, wall=lambda: wall[0])
    wall[0] += 2.0
    assert clock.now() == pytest.approx(8.0)
    clock.time_scale = 0.5
    wall[0] += 2.0
    assert clock.now() == pytest.approx(9.0)
    with pytest.raises(SimConfigError, match="time_scale"):
        clock.time_scale = 0.0


def test_mecanum_forward_and_inverse_kinematics_agree():
    kin = MecanumKinematics(0.1275, 0.236, 0.2605)
    for twist in ((0.3, 0.0, 0.0), (0.0, -0.2, 0.0), (0.0, 0.0, 0.7), (0.1, 0.2, -0.3)):
        w = kin.wheel_speeds(*twist)
        assert kin.twist(w) == pytest.approx(twist)
    fl, fr, rl, rr = kin.wheel_speeds(0.0, 0.2, 0.0)       # sideways left: front-left and rear-right run back
    assert fl < 0 and rr < 0 and fr > 0 and rl > 0
