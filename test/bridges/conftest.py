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
from bridge_rigs import CompressorRig, ROBOT_YAML  # noqa: E402


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
