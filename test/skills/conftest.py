"""Shared fixtures of the resource-model tests: the shipped robot file and trees, and copies to spoil."""
import os
import shutil
import sys

import pytest

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

from skills_testkit import ROBOT, TREES  # noqa: E402


@pytest.fixture(scope="session")
def shipped_model():
    from locem_bridge.skills import build_resource_model
    return build_resource_model(ROBOT, [TREES])


@pytest.fixture
def robot_copy(tmp_path):
    """A copy of the shipped robot folder (the robot file reads its EDS beside it): returns the YAML's path."""
    folder = tmp_path / "robots"
    shutil.copytree(os.path.dirname(ROBOT), str(folder))
    return str(folder / os.path.basename(ROBOT))


@pytest.fixture
def trees_copy(tmp_path):
    """A copy of the shipped trees folder: returns its path."""
    folder = tmp_path / "trees"
    shutil.copytree(TREES, str(folder))
    return str(folder)
