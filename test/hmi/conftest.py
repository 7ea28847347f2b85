"""Fixtures of the HMI tests: a real HmiServer on a free loopback port over the scripted HICEM test double."""
import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from hicem_double import ScriptedHicemDouble  # noqa: E402
from locem_bridge.hmi import HmiServer  # noqa: E402


@pytest.fixture
def double():
    return ScriptedHicemDouble()


@pytest.fixture
def server(double):
    srv = HmiServer(double, "127.0.0.1", 0, poll_period_s=0.05, picture_period_s=0.1, kpi_period_s=0.1,
                    heartbeat_s=1.0, shutdown_poll_s=0.05)
    srv.start()
    try:
        yield srv
    finally:
        srv.close()
