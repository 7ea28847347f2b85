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


@pytest.fixture(scope="session")
def site_cfg():
    from locem_bridge.sim.config import load_site
    return load_site()


@pytest.fixture
def free_port_factory():
    """Call it for as many free loopback ports as a test needs."""
    return free_port
