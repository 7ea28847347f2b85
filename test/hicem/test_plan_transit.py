"""PlanTransit: large turns are made at the transit point, not next to a wall (DriveSafely / DriveToWall)."""
import math

import pytest
from py_trees.common import Status

from test_nodes import Rig

CFG = {"cfg.site.locations": {"home": [1.4, 1.4, 0.7854]}, "cfg.site.max_turn_near_walls": 0.5,
       "robot.arm.transit_pose": ""}
BODY = '<PlanTransit here="{here}" goal="{goal}" transit="{@cfg.site.locations.home}" waypoints="{w}"/>'


def plan(here, goal, rig=None):
    rig = rig or Rig(BODY, cfg=CFG)
    rig.bb.set("here", here)
    rig.bb.set("goal", goal)
    status = rig.tree.tick()
    return status, (rig.bb.get("w") if status == Status.SUCCESS else None)


def test_a_small_turn_goes_straight_to_the_goal():
    status, w = plan([0.6, 1.7, 1.5708], [1.2, 1.7, 1.5708 + 0.3])
    assert status == Status.SUCCESS and w == [[1.2, 1.7, 1.5708 + 0.3]]


def test_a_large_turn_is_made_at_the_transit_point_and_get_pose_results_are_read():
    # from the last section of wall_1 to the first of wall_2: a quarter turn next to the corner
    status, w = plan({"pose": [2.4, 1.7, math.pi / 2], "twist": [0, 0, 0]}, [1.7, 2.4, 0.0])
    assert status == Status.SUCCESS
    assert w == [[1.4, 1.4, math.pi / 2], [1.4, 1.4, 0.0], [1.7, 2.4, 0.0]]
    # going home (the goal is the transit point): out keeping the heading, then the turn there, nothing twice
    status, w = plan([2.4, 1.7, math.pi / 2], [1.4, 1.4, 0.7854])
    assert w == [[1.4, 1.4, math.pi / 2], [1.4, 1.4, 0.7854]]


def test_a_robot_whose_arm_folds_for_driving_turns_on_the_way_without_the_detour():
    # the differential robot turns in place on every move; folded, its chassis alone sweeps
    rig = Rig(BODY, cfg=dict(CFG, **{"robot.arm.transit_pose": "transit"}))
    status, w = plan({"pose": [2.4, 1.7, math.pi / 2], "twist": [0, 0, 0]}, [1.7, 2.4, 0.0], rig)
    assert status == Status.SUCCESS and w == [[1.7, 2.4, 0.0]]


def test_bad_poses_are_refused_with_what_was_given():
    rig = Rig(BODY, cfg=CFG)
    status, _ = plan([1.0, 2.0], [1.0, 2.0, 0.0], rig)       # the port error is the action's failure reason
    assert status == Status.FAILURE and "here and goal must be [x, y, theta]" in rig.reason()
    assert "got [1.0, 2.0]" in rig.reason()


ARM = '<CheckArmTransit pose="{@robot.arm.transit_pose}" here="{here}" waypoints="{w}"/>'


def folds(transit_pose, here, waypoints):
    rig = Rig(ARM, cfg={"robot.arm.transit_pose": transit_pose})
    rig.bb.set("here", here)
    rig.bb.set("w", waypoints)
    return rig.tree.tick()


def test_the_arm_folds_for_driving_only_on_a_robot_with_a_transit_pose_and_only_when_the_base_moves():
    here = {"pose": [0.6, 1.78, math.pi / 2], "twist": [0, 0, 0]}
    sideways = [[1.2, 1.78, math.pi / 2]]                 # a differential base turns in place for this
    assert folds("transit", here, sideways) == Status.SUCCESS
    assert folds("transit", here, [[0.6, 1.78, math.pi / 2 + 0.3]]) == Status.SUCCESS      # a turn alone
    assert folds("transit", here, [[0.605, 1.78, math.pi / 2 + 0.01]]) == Status.FAILURE   # within tolerance
    assert folds("", here, sideways) == Status.FAILURE    # the shipped mecanum robot: the arm stays out
    # without waypoints (after DriveSafely: back to wall_ready) only the robot fact counts
    assert Rig('<CheckArmTransit pose="transit"/>').tree.tick() == Status.SUCCESS


def test_bad_waypoints_for_the_fold_are_refused_with_what_was_given():
    rig = Rig(ARM, cfg={"robot.arm.transit_pose": "transit"})
    rig.bb.set("here", [0.6, 1.78, 0.0])
    rig.bb.set("w", [[1.2, 1.78]])
    assert rig.tree.tick() == Status.FAILURE and "every waypoint must be [x, y, theta]" in rig.reason()
