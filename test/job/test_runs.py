"""Separate runs on one machine (locem_bridge.job.runs): each run gets device addresses nothing else uses, or a
one-line refusal that names what is taken and by which run. "Taken" is simulated with real sockets bound on
loopback addresses of the 127.76.x.x range (no other test uses it) and with real registry files of live and
dead processes."""
import json
import os
import socket
import subprocess
import sys
import threading

import pytest

from locem_bridge.job.runs import (DeviceAddresses, NoFreeAddresses, RunRegistry, addresses_of, probe,
                                   slot_addresses)
from locem_bridge.robot_file import load_robot

# a base on its own loopback address and CAN port range, so these tests never meet a running job's devices
BASE = DeviceAddresses(host="127.76.0.1", ur_ports=(29999, 30003, 30004), modbus_port=5020,
                       can_interface="udp_multicast", can_channel="239.74.176.2", can_port=44713)


def listen(host, port):
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind((host, port))
    sock.listen(1)
    return sock


def can_bus_like(port):
    """A UDP socket as python-can's udp_multicast bus opens one (SO_REUSEADDR, bound on every address)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    sock.bind(("", port))
    return sock


@pytest.fixture
def registry(tmp_path):
    return RunRegistry(str(tmp_path / "runs"))


def test_the_robot_files_addresses_are_slot_zero_and_later_slots_move_address_and_can_channel():
    base = addresses_of(load_robot()["robot"])
    assert base == DeviceAddresses("127.0.0.1", (29999, 30003, 30004), 5020, "udp_multicast", "239.74.163.2", 43113)
    assert slot_addresses(base, 0) == base
    second = slot_addresses(base, 1)
    assert (second.host, second.ur_ports, second.modbus_port) == ("127.0.0.2", (29999, 30003, 30004), 5020)
    assert (second.can_channel, second.can_port) == ("239.74.163.3", 43114)
    # the overrides put a robot file on these addresses, for LOCEM and the stand-ins alike
    assert second.overrides() == {"arm": {"controller": {"host": "127.0.0.2"}},
                                  "compressor": {"host": "127.0.0.2", "port": 5020},
                                  "base": {"drives": {"can": {"interface": "udp_multicast",
                                                              "channel": "239.74.163.3", "port": 43114}}}}
    assert second.describe() == ("UR 127.0.0.2:29999/30003/30004, Modbus 127.0.0.2:5020, "
                                 "CAN udp_multicast 239.74.163.3:43114")


def test_real_hardware_addresses_have_one_slot_only():
    real = DeviceAddresses("192.168.1.10", (29999, 30003, 30004), 502, "socketcan", "can0", 0)
    assert slot_addresses(real, 0) == real
    assert slot_addresses(real, 1) is None
    on_socketcan = DeviceAddresses("127.0.0.1", (29999, 30003, 30004), 5020, "socketcan", "vcan0", 0)
    assert slot_addresses(on_socketcan, 1) is None


def test_probe_names_each_taken_port_and_nothing_when_free():
    free = slot_addresses(BASE, 3)
    assert probe(free) == []
    ur = listen(free.host, 30004)
    modbus = listen(free.host, 5020)
    bus = can_bus_like(free.can_port)
    try:
        assert probe(free) == ["UR rtde 127.76.0.4:30004", "Modbus 127.76.0.4:5020",
                               "CAN udp_multicast 239.74.176.5:44716"]
    finally:
        for sock in (ur, modbus, bus):
            sock.close()
    assert probe(free) == []


def test_a_second_run_gets_other_addresses_and_a_released_slot_is_taken_again(registry):
    first = registry.claim("20261124-101500", BASE, pid=os.getpid())
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        second = registry.claim("20261124-101500", BASE, pid=child.pid)
        assert (first.slot, second.slot) == (0, 1)
        assert first.addresses.host != second.addresses.host
        assert first.addresses.can_port != second.addresses.can_port
        assert second.run == "20261124-101500-2"          # same start second: another run folder name
        assert sorted(e.run for e in registry.live()) == ["20261124-101500", "20261124-101500-2"]
        registry.release(first.run)
        third = registry.claim("20261124-101501", BASE, pid=os.getpid())
        assert third.slot == 0
    finally:
        child.kill()
        child.wait()


def test_entries_of_dead_runs_are_ignored_and_removed(registry):
    child = subprocess.Popen([sys.executable, "-c", "pass"])
    child.wait()
    registry.claim("dead-run", BASE, pid=child.pid)
    assert registry.live() == []
    entry = registry.claim("next-run", BASE, pid=os.getpid())
    assert entry.slot == 0
    assert sorted(os.listdir(registry.folder)) == [".lock", "next-run.json"]


def test_a_reused_pid_does_not_keep_a_dead_run_alive(registry):
    entry = registry.claim("old-run", BASE, pid=os.getpid())
    path = os.path.join(registry.folder, "old-run.json")
    with open(path, encoding="utf-8") as handle:
        data = json.load(handle)
    data["pid_start"] = "1"                 # the pid now belongs to a process started at another time
    with open(path, "w", encoding="utf-8") as handle:
        json.dump(data, handle)
    assert entry.pid_start and registry.live() == []


def test_addresses_in_use_outside_the_registry_are_skipped(registry):
    squatter = listen(BASE.host, 29999)     # e.g. a rostest's UR stand-in on the robot file's address
    try:
        entry = registry.claim("run", BASE, pid=os.getpid())
    finally:
        squatter.close()
    assert entry.slot == 1 and entry.addresses.host == "127.76.0.2"


def test_no_free_slot_refuses_with_one_line_naming_the_runs_and_the_ports(registry):
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    busy = can_bus_like(slot_addresses(BASE, 1).can_port)
    try:
        registry.claim("first-run", BASE, pid=child.pid)
        with pytest.raises(NoFreeAddresses) as caught:
            registry.claim("second-run", BASE, pid=os.getpid(), max_slots=2)
        assert [e.run for e in registry.live()] == ["first-run"]     # the refused run left nothing behind
    finally:
        busy.close()
        child.kill()
        child.wait()
    message = str(caught.value)
    assert "\n" not in message
    assert message == ("no free device addresses for a new run (2 slots tried): 127.76.0.1 taken by run first-run "
                       "(pid %d); 127.76.0.2 in use by a program outside the run registry "
                       "(CAN udp_multicast 239.74.176.3:44714)" % child.pid)


def test_runs_claiming_at_the_same_moment_get_different_slots(tmp_path):
    """Eight threads (a registry lock per open file, as separate processes have) claim at once."""
    folder = str(tmp_path / "runs")
    children = [subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]) for _ in range(8)]
    slots, errors = [], []

    def claim(pid):
        try:
            slots.append(RunRegistry(folder).claim("run", BASE, pid=pid).slot)
        except Exception as exc:            # collected and asserted below
            errors.append(exc)
    try:
        threads = [threading.Thread(target=claim, args=(c.pid,)) for c in children]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
    finally:
        for c in children:
            c.kill()
            c.wait()
    assert errors == []
    assert sorted(slots) == list(range(8))
