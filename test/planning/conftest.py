"""The shipped robot and its planning envelope, shared by the planning tests."""
import pytest

from locem_bridge.planning.reach import RobotEnvelope
from locem_bridge.robot_facts import derive
from locem_bridge.sim.config import load_robot

# the process tuning of config/hicem/plasterboard.yaml the derived facts need (lane overrun and ratio)
TUNING = {"spray": {"lane_overrun": 0.1, "lane_ratio": 0.52}, "sand": {"lane_overrun": 0.1, "lane_ratio": 0.8}}


@pytest.fixture(scope="module")
def robot():
    return load_robot()


@pytest.fixture(scope="module")
def envelope(robot):
    return RobotEnvelope.from_robot(robot["robot"], derive(robot["robot"], TUNING), overrun={"spray": 0.1, "sand": 0.1})
