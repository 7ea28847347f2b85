"""Fixtures of the UR stand-in tests.

Every test gets its own loopback address (ur_rtde's ports are fixed), so tests and other people's runs can go in
parallel. The stand-in runs in a child process (ur_rtde keeps the GIL while it blocks), and every test is bounded
by faulthandler's watchdog, which works even while a ur_rtde call holds the GIL.
"""
import faulthandler
import itertools
import os
import socket
import sys

import pytest

_SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))),
                    "src")
if _SRC not in sys.path:
    sys.path.insert(0, _SRC)
_HERE = os.path.dirname(os.path.abspath(__file__))     # ur_client_support, shared by the client tests
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

TEST_TIME_LIMIT_S = 120
_counter = itertools.count(1)


def _address_free(addr: str) -> bool:
    for port in (29999, 30003, 30004):
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((addr, port))
            except OSError:
                return False
    return True


def next_address() -> str:
    """A loopback address whose three UR ports are free: 127.61.<pid-derived>.<counter>."""
    third = 1 + os.getpid() % 250
    for _ in range(250):
        n = next(_counter)
        addr = "127.61.%d.%d" % (third, 1 + (n - 1) % 250)
        if _address_free(addr):
            return addr
    raise RuntimeError("no free loopback address for a UR stand-in")


@pytest.fixture(autouse=True)
def _hard_time_limit():
    faulthandler.dump_traceback_later(TEST_TIME_LIMIT_S, exit=True)
    yield
    faulthandler.cancel_dump_traceback_later()


@pytest.fixture
def ur_address() -> str:
    return next_address()


@pytest.fixture
def ur_standin(ur_address):
    """A UR stand-in process at time scale 10 on a fresh address; yields the StandInProcess proxy."""
    from locem_bridge.sim.ur.process import StandInProcess
    proc = StandInProcess(ur_address, time_scale=10.0).start()
    yield proc
    proc.close()
