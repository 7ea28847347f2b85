"""Fixtures of the bridge tests: the REAL client libraries against the worksite stand-ins, started in-process
(compressor Modbus server, CiA 402 drives on a python-can bus) or in a child process (UR controller, because
ur_rtde holds the GIL while it blocks). Each test gets its own ports / loopback address / CAN channel."""
import faulthandler
import os
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from locem_bridge.bridges.config import load_robot_config  # noqa: E402
from locem_bridge.locem.core import LocemCore  # noqa: E402
from bridge_rigs import CompressorRig, ROBOT_YAML, WorksiteRig  # noqa: E402


@pytest.fixture(autouse=True)
def _hard_time_limit():
    faulthandler.dump_traceback_later(150, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


@pytest.fixture
def robot():
    return load_robot_config(ROBOT_YAML)


@pytest.fixture
def core():
    core = LocemCore(grace=0.5, stop_timeout=2.0)
    yield core
    core.close()


@pytest.fixture
def compressor_rig(robot):
    rig = CompressorRig(robot)
    yield rig
    rig.close()


@pytest.fixture
def site(robot):
    """Every stand-in on one sim clock (WorksiteRig) and the robot built from the YAML with their addresses."""
    from locem_bridge.bridges.robot import build_robot
    rig = WorksiteRig(robot)
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    built.start()
    yield rig, built
    built.close()
    rig.close()


@pytest.fixture
def wall(site, core):
    """:func:`site` with every command set installed in ``core`` and every backend up."""
    rig, built = site
    for command_set in built.command_sets:
        core.install(command_set)
    for kind in ("arm", "compressor", "base"):
        assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
    return rig, built
