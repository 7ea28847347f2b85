import os
"""Fixtures of the worksite tests: free loopback ports and the project configuration files."""
import socket

import pytest


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


@pytest.fixture
def port() -> int:
    return free_port()


@pytest.fixture(scope="session")
def robot_cfg():
    from locem_bridge.sim.config import load_robot
    return load_robot()


TEST_SITE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sites", "room_4p8.yaml")


@pytest.fixture(scope="session")
def site_cfg():
    """The simulator tests' own site (test/sim/sites/room_4p8.yaml), independent of the shipped default."""
    from locem_bridge.sim.config import load_site
    return load_site(TEST_SITE)


@pytest.fixture(scope="session")
def test_site_path():
    return TEST_SITE


@pytest.fixture
def free_port_factory():
    """Call it for as many free loopback ports as a test needs."""
    return free_port
