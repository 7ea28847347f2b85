"""Robot facts (locem_bridge.robot_facts): the formulas, and the numbers HICEM's trees read for a robot file."""
import math
import os

import pytest
import yaml

from locem_bridge.hicem.config import DEFAULT_PARAMS_FILE, load_params
from locem_bridge.hicem.errors import ConfigError
from locem_bridge.robot_facts import (base_standoff, lane_spacing, load_facts, section_width, tcp_bound,
                                      work_width)
from locem_bridge.robot_file import RobotFileError, default_robot_path, load_robot

TUNING = {"spray": {"lane_ratio": 0.52, "lane_overrun": 0.10}, "sand": {"lane_ratio": 0.8, "lane_overrun": 0.10}}


def test_the_formulas():
    # base centre to wall = flange ahead of the base centre + tool length + nozzle standoff (no float noise)
    assert base_standoff(0.82, 0.18, 0.30) == 1.30 and base_standoff(0.83, 0.22, 0.0) == 1.05
    # strip from one pose: the lateral reach to either side less the room a lane needs beyond each end
    assert section_width(0.40, 0.10) == 0.60 and section_width(0.30, 0.05) == 0.50
    # lane pitch: a fraction of the worked width, rounded DOWN to whole mm (never wider than asked)
    assert lane_spacing(0.2898, 0.52) == 0.150 and lane_spacing(0.225, 0.8) == 0.180
    assert lane_spacing(0.2, 0.5999) == 0.119
    # spray fan on the wall: 2 standoff tan(half angle); a pad: its diameter; tape: its width
    assert work_width({"spray_half_angle": 0.45, "standoff": 0.3}) == round(0.6 * math.tan(0.45), 4)
    assert work_width({"pad_radius": 0.1125}) == 0.225 and work_width({"tape_width": 0.05}) == 0.05
    # LOCEM's TCP coordinate bound: reach + the longest tool
    assert tcp_bound({"arm": {"reach": 0.85}, "tools": {"a": {"tcp": [0, 0, 0.18, 0, 0, 0]},
                                                       "b": {"tcp": [0.03, 0, 0.04, 0, 0, 0]}}}) == 1.03


def test_the_shipped_robot_gives_the_numbers_the_trees_used_before():
    facts = load_facts(tuning=TUNING)
    work = {w: f.entries for w, f in facts.work.items()}
    assert {w: f.tool for w, f in facts.work.items()} == {"taping": "taping_tool", "spray": "spray_gun",
                                                          "sand": "sander"}
    assert [work[w]["base_standoff"] for w in ("taping", "spray", "sand")] == [1.05, 1.30, 1.00]
    assert work["spray"]["section_width"] == work["sand"]["section_width"] == 0.60
    assert (work["spray"]["lane_spacing"], work["sand"]["lane_spacing"]) == (0.15, 0.18)
    assert work["spray"]["tool_standoff"] == 0.30 and work["sand"]["tool_standoff"] == 0.0
    assert work["taping"]["z_range"] == [0.10, 2.00] and work["taping"]["segment_length"] == 1.20
    assert "lane_spacing" not in work["taping"]           # no tuning for it: no lanes
    assert facts.reach == 1.30 and facts.tcp_bound == 1.52


def _robot_file(tmp_path, change):
    with open(default_robot_path(), encoding="utf-8") as handle:
        doc = yaml.safe_load(handle)
    change(doc["robot"])
    doc["robot"]["base"]["eds"] = load_robot()["robot"]["base"]["eds"]      # absolute: the copy lives elsewhere
    path = tmp_path / "robot.yaml"
    path.write_text(yaml.safe_dump(doc))
    return str(path)


def test_another_robot_file_gives_hicem_its_own_numbers(tmp_path):
    """The trees' numbers follow the robot file HICEM is given: a shorter arm standing closer, reaching less."""
    def short_arm(robot):
        robot["arm"]["reach"] = 0.85
        for tool in robot["tools"].values():
            tool["wall_work"].update(flange_distance=0.55, lateral_reach=0.30, z_band=[0.3, 1.2])
            tool["wall_work"].pop("line_length", None)        # default: 2 x lateral_reach
    path = _robot_file(tmp_path, short_arm)
    bb = load_params(DEFAULT_PARAMS_FILE, robot_file=path).blackboard_entries()
    assert bb["robot.work.spray.base_standoff"] == 1.03 and bb["robot.work.taping.base_standoff"] == 0.77
    assert bb["robot.work.spray.section_width"] == 0.40 and bb["robot.work.sand.section_width"] == 0.40
    assert bb["robot.work.taping.z_range"] == [0.3, 1.2] and bb["robot.work.taping.segment_length"] == 0.60
    assert bb["robot.reach"] == 0.85 and bb["robot.tcp_bound"] == 1.07
    assert bb["robot.work.spray.lane_spacing"] == 0.15        # same gun, same tuning


def test_a_robot_with_a_lift_works_in_bands_that_ride_up_with_it():
    """The second robot: its arm reaches z_band from one lift height (measured at the lift's bottom); over the
    lift's travel the band spans z_range; areas are cut into bands of z_band's height. The shipped robot has no
    lift: no band height (one band), z_range = z_band, no LIFT."""
    bb = load_params(DEFAULT_PARAMS_FILE, robot_file=os.path.join(os.path.dirname(default_robot_path()),
                                                                  "diffdrive_ur5e.yaml")).blackboard_entries()
    assert bb["robot.lift.fitted"] is True and bb["robot.lift.range"] == [0.55, 1.45]
    for work in ("taping", "spray", "sand"):
        assert bb["robot.work.%s.z_band" % work] == [0.10, 1.45]
        assert bb["robot.work.%s.z_range" % work] == [0.10, 2.35]            # 1.45 + the 0.90 m travel
        assert bb["robot.work.%s.band_height" % work] == 1.35
    assert bb["robot.arm.transit_pose"] == "transit"         # the differential base turns in place: arm folded
    shipped = load_params(DEFAULT_PARAMS_FILE).blackboard_entries()
    assert shipped["robot.lift.fitted"] is False and shipped["robot.lift.range"] == []
    assert shipped["robot.arm.transit_pose"] == ""             # mecanum: the arm stays at wall_ready
    assert shipped["robot.work.spray.z_band"] == shipped["robot.work.spray.z_range"] == [0.10, 2.00]
    assert shipped["robot.work.spray.band_height"] == 0.0


@pytest.mark.parametrize("change,key,problem", [
    (lambda r: r["tools"]["sander"].pop("wall_work"), "robot.tools.sander.wall_work", "missing key"),
    (lambda r: r["tools"]["sander"]["wall_work"].update(work="spray"), "robot.tools.sander.wall_work.work",
     "'spray' is the work of spray_gun too; one tool per work"),
    (lambda r: r["tools"]["spray_gun"]["wall_work"].update(z_band=[2.0, 1.0]), "robot.tools.spray_gun.wall_work.z_band",
     "must be two heights"),
    (lambda r: r["tools"]["spray_gun"]["wall_work"].update(reach=1.0), "robot.tools.spray_gun.wall_work",
     "reach"),
    (lambda r: r["arm"].pop("reach"), "robot.arm.reach", "missing key"),
    (lambda r: r["arm"].update(transit_pose="tucked"), "robot.arm.transit_pose",
     "'tucked' is not a named pose of the arm"),
])
def test_a_bad_robot_fact_is_refused_naming_the_robot_file_and_key(tmp_path, change, key, problem):
    path = _robot_file(tmp_path, change)
    with pytest.raises(ConfigError) as hicem:            # HICEM's own error family, the robot file named
        load_params(DEFAULT_PARAMS_FILE, robot_file=path)
    with pytest.raises(RobotFileError) as plain:
        load_robot(path)
    for error in (hicem.value, plain.value):
        assert str(error).startswith("%s: %s" % (path, key)) and problem in str(error), str(error)
