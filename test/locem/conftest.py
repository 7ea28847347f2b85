"""A LOCEM core with two device-like command sets whose handlers drive an in-process fake device.

The fake device stands for a bridge in these ROS-free unit tests of the dispatcher's policy; the real bridges
are tested against the protocol stand-ins elsewhere.
"""
import threading
import time

import pytest

from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.errors import HardwareError
from locem_bridge.locem.registry import Arg, CommandSpec


class FakeDevice:
    """Records calls; moves take ``duration`` seconds and honour cancellation through the context."""

    def __init__(self):
        self.calls = []
        self.stops = 0
        self.release = threading.Event()

    def move(self, ctx, duration, fail=False):
        self.calls.append(("move", duration))
        ctx.on_cancel(self.stop)
        if fail:
            raise HardwareError("drive 2 reports fault 0x2310 (overcurrent)")
        ctx.sleep(duration)
        return {"moved_s": duration}

    def hang(self, ctx):
        self.calls.append(("hang",))
        self.release.wait(10.0)  # ignores the context on purpose: a driver call that blocks
        return {}

    def buggy(self, ctx):
        raise ZeroDivisionError("division by zero")

    def stop(self):
        self.stops += 1


ARM_MOVE = CommandSpec("ARM_MOVE", "Move the arm for a time.", args=(
    Arg.number("duration", "s", 0, 60, "how long"), Arg.flag("fail", "fault", default=False, keyword_only=True)),
    resources=frozenset({"arm"}), category="arm", timeout=5.0)
BASE_MOVE = CommandSpec("BASE_MOVE", "Move the base for a time.", args=(Arg.number("duration", "s", 0, 60, "how long"),),
                        resources=frozenset({"base"}), category="base", timeout=0.5)
ARM_HANG = CommandSpec("ARM_HANG", "Call a driver that blocks.", resources=frozenset({"arm"}), category="arm",
                       timeout=0.2)
BUGGY = CommandSpec("BUGGY", "A handler with a bug.", category="arm")
UNSERVED = CommandSpec("UNSERVED", "Declared, no backend.", category="arm")


class FakeSet:
    name = "fake"

    def __init__(self, device):
        self.device = device

    def specs(self):
        return [ARM_MOVE, BASE_MOVE, ARM_HANG, BUGGY, UNSERVED]

    def handlers(self):
        d = self.device
        return {"ARM_MOVE": d.move, "BASE_MOVE": lambda ctx, duration: d.move(ctx, duration),
                "ARM_HANG": d.hang, "BUGGY": d.buggy}

    def stop(self):
        self.device.stop()

    def health(self):
        return {"link": "up", "device": "ok", "last_error": ""}


@pytest.fixture
def device():
    return FakeDevice()


@pytest.fixture
def core(device):
    core = LocemCore(grace=0.3, stop_timeout=1.0)
    core.install(FakeSet(device))
    yield core
    device.release.set()
    core.close()


def _wait_until(predicate, timeout=3.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@pytest.fixture
def wait_until():
    """Poll ``predicate`` until it is true or ``timeout`` s pass; returns its last value."""
    return _wait_until
