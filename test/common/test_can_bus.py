"""The one way the base bridge and the simulated drives open a CAN bus: real python-can buses, the sender never
sees its own frames (udp_multicast echoes them, the filter drops them), other senders' frames arrive, and a bus
that is not allowed or cannot be opened is refused with a message naming it and what is allowed."""
import os
import random
import subprocess
import sys

import can
import pytest

from locem_bridge.common.can_bus import CAN_INTERFACES, CanInterfaceError, CanOpenError, open_bus

SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")


def _frame(can_id, *data):
    return can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=False)


@pytest.fixture
def udp_cfg():
    # a group and port of this test's own (other tests use 239.74.163.x / 239.74.177.x)
    return {"interface": "udp_multicast", "channel": "239.74.201.%d" % random.randint(1, 250),
            "port": random.randint(45100, 45900)}


def test_udp_multicast_buses_drop_their_own_echo_and_pass_the_others_frames(udp_cfg):
    a, b = open_bus(udp_cfg), open_bus(udp_cfg)
    try:
        a.send(_frame(0x201, 1, 2, 3))
        got = b.recv(2.0)
        assert got is not None and got.arbitration_id == 0x201 and bytes(got.data) == b"\x01\x02\x03"
        assert a.recv(0.3) is None                     # its own frame came back on the socket and was dropped
        b.send(_frame(0x181, 9))
        got = a.recv(2.0)
        assert got is not None and got.arbitration_id == 0x181 and bytes(got.data) == b"\x09"
        assert b.recv(0.3) is None
        a.send(_frame(0x201, 1, 2, 3))                 # the same frame again is still delivered to the other bus
        got = b.recv(2.0)
        assert got is not None and got.arbitration_id == 0x201
        assert a.recv(0.3) is None
    finally:
        a.shutdown()
        b.shutdown()


def test_virtual_buses_behave_like_a_controller_too():
    cfg = {"interface": "virtual", "channel": "test_can_bus_%d" % os.getpid()}
    a, b = open_bus(cfg), open_bus(cfg)
    try:
        a.send(_frame(0x601, 0x40, 0x41, 0x60))
        got = b.recv(1.0)
        assert got is not None and got.arbitration_id == 0x601
        assert a.recv(0.2) is None
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.parametrize("interface", ["pcan", "", None, "UDP_MULTICAST"])
def test_an_interface_outside_the_list_is_refused_naming_what_is_allowed(interface):
    with pytest.raises(CanInterfaceError) as caught:
        open_bus({"interface": interface, "channel": "can0"})
    assert str(caught.value) == ("robot.base.drives.can.interface: %r is not a CAN interface this package opens "
                                 "(allowed: virtual, udp_multicast, socketcan)" % (interface,))
    assert caught.value.allowed == CAN_INTERFACES == ("virtual", "udp_multicast", "socketcan")


def test_a_bus_that_cannot_be_opened_says_which_bus_in_one_line():
    with pytest.raises(CanOpenError) as caught:
        open_bus({"interface": "socketcan", "channel": "nosuchcan7", "bitrate": 500000})
    text = str(caught.value)
    assert text.startswith("CAN bus socketcan nosuchcan7 cannot be opened: ") and "\n" not in text


def test_importing_the_module_does_not_load_python_can():
    out = subprocess.run([sys.executable, "-c", "import sys, locem_bridge.common.can_bus; print('can' in sys.modules)"],
                         env=dict(os.environ, PYTHONPATH=SRC), stdout=subprocess.PIPE, universal_newlines=True,
                         check=True)
    assert out.stdout.strip() == "False"


def test_no_module_outside_common_opens_a_can_bus_of_its_own():
    """One way to open the bus: a python-can ``Bus(...)`` or a ``BusABC`` subclass elsewhere in the package is a
    second opener (with its own interface list and echo handling) and fails here."""
    import ast
    package = os.path.join(SRC, "locem_bridge")
    offenders = []
    for folder, _, files in os.walk(package):
        for name in files:
            path = os.path.join(folder, name)
            if not name.endswith(".py") or path == os.path.join(package, "common", "can_bus.py"):
                continue
            for node in ast.walk(ast.parse(open(path, encoding="utf-8").read(), path)):
                called = node.func if isinstance(node, ast.Call) else None
                if isinstance(called, ast.Attribute) and called.attr == "Bus" or \
                        isinstance(node, ast.ClassDef) and any("BusABC" in ast.dump(b) for b in node.bases):
                    offenders.append("%s:%d" % (os.path.relpath(path, SRC), node.lineno))
    assert not offenders, "CAN buses opened outside locem_bridge.common.can_bus: %s" % ", ".join(offenders)
