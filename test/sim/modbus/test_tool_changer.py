"""Tool changer stand-in: a real pymodbus client against its Modbus TCP server, bound to the PyBullet world (the
arm's flange at a rack slot + lock -> the world mounts that tool; unlock at its slot -> the world parks it)."""
import os
import time

import pytest
import yaml
from pymodbus.client import ModbusTcpClient

from locem_bridge.sim.arm_source import KinematicArm
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.config import load_robot
from locem_bridge.sim.errors import SimStateError
from locem_bridge.sim.modbus.tool_changer import ToolChangerModel, WorldRack, tool_changer_server
from locem_bridge.sim.world import World

RACK = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "data",
                    "tool_changer_rack.yaml")
DEV = 2
LOCKED, UNLOCKED, BUSY, COUPLED, FAULT, AT_SLOT = range(6)


@pytest.fixture
def changer(site_cfg, port):
    with open(RACK) as fh:
        robot = load_robot(None, yaml.safe_load(fh))
    cfg = robot["robot"]["tool_changer"]
    arm = KinematicArm(robot["robot"]["arm"]["named_poses"]["home"])
    clock = SimClock(10.0)                     # lock_time 0.3 s sim -> 30 ms wall
    world = World(site_cfg, robot, clock, arm=arm, gui=False)
    model = ToolChangerModel(cfg, clock.now, WorldRack(world, cfg))
    server = tool_changer_server(model, "127.0.0.1", port, DEV)
    server.start()
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.5, retries=0)
    assert client.connect()
    yield cfg, arm, world, server, client
    client.close()
    server.stop()
    world.close()


def _inputs(client):
    rr = client.read_input_registers(0, count=6, device_id=DEV)
    assert not rr.isError(), rr
    return dict(zip(("coupled", "fault", "status", "present", "flange_slot", "operations"), rr.registers))


def _bits(client):
    rr = client.read_discrete_inputs(0, count=14, device_id=DEV)
    assert not rr.isError(), rr
    return rr.bits[:14]


def _settled(client, timeout=2.0):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        regs = _inputs(client)
        if not regs["status"] & (1 << BUSY):
            return regs
        time.sleep(0.01)
    raise AssertionError("the lock is still moving: %s" % _inputs(client))


def test_locking_at_a_slot_mounts_that_tool_in_the_world_and_unlocking_there_parks_it(changer):
    cfg, arm, world, server, client = changer
    assert _inputs(client) == {"coupled": 0, "fault": 0, "status": 1 << UNLOCKED, "present": 0b111,
                               "flange_slot": 0, "operations": 0}
    arm.set_joint_positions(cfg["rack"]["sander"]["pose"])
    assert _inputs(client)["flange_slot"] == 3 and _bits(client)[AT_SLOT]
    assert not client.write_coil(0, True, device_id=DEV).isError()
    assert world.mounted_tool is None                     # the lock takes lock_time: nothing coupled yet
    regs = _settled(client)
    assert regs["coupled"] == 3 and regs["fault"] == 0 and regs["present"] == 0b011
    bits = _bits(client)
    assert bits[LOCKED] and not bits[UNLOCKED] and bits[COUPLED] and not bits[FAULT]
    assert bits[6:9] == [True, True, False]               # slot 3's tool is on the flange now
    assert world.mounted_tool == "sander"
    assert client.read_coils(0, count=1, device_id=DEV).bits[0]
    # the coupled tool follows the flange anywhere; the lock holds it
    arm.set_joint_positions(cfg["rack"]["taping_tool"]["pose"])
    world.step()
    assert world.mounted_tool == "sander"
    # back at its own slot: unlock leaves it there
    arm.set_joint_positions(cfg["rack"]["sander"]["pose"])
    assert not client.write_coil(0, False, device_id=DEV).isError()
    regs = _settled(client)
    assert regs == {"coupled": 0, "fault": 0, "status": 1 << UNLOCKED | 1 << AT_SLOT, "present": 0b111,
                    "flange_slot": 3, "operations": 2}
    assert world.mounted_tool is None


def test_the_changer_refuses_with_a_fault_code_and_nothing_moves(changer):
    cfg, arm, world, server, client = changer
    # lock away from every slot: fault 1, still unlocked, nothing mounted
    assert not client.write_coil(0, True, device_id=DEV).isError()
    regs = _settled(client)
    assert regs["fault"] == 1 and regs["coupled"] == 0 and regs["status"] & (1 << UNLOCKED)
    assert _bits(client)[FAULT] and not client.read_coils(0, count=1, device_id=DEV).bits[0]
    assert world.mounted_tool is None
    # fault reset clears it
    assert not client.write_coil(1, True, device_id=DEV).isError()
    assert _inputs(client)["fault"] == 0
    # couple the spray gun, then try to release it at the taping tool's slot: fault 3, the gun stays on
    arm.set_joint_positions(cfg["rack"]["spray_gun"]["pose"])
    client.write_coil(0, True, device_id=DEV)
    assert _settled(client)["coupled"] == 2 and world.mounted_tool == "spray_gun"
    arm.set_joint_positions(cfg["rack"]["taping_tool"]["pose"])
    client.write_coil(0, False, device_id=DEV)
    regs = _settled(client)
    assert regs["fault"] == 3 and regs["coupled"] == 2 and regs["status"] & (1 << LOCKED)
    assert world.mounted_tool == "spray_gun"
    # away from any slot: fault 3 as well
    arm.set_joint_positions(world.robot["arm"]["named_poses"]["home"])
    client.write_coil(0, False, device_id=DEV)
    assert _settled(client)["fault"] == 3 and world.mounted_tool == "spray_gun"
    # at its own slot it goes back into the rack
    arm.set_joint_positions(cfg["rack"]["spray_gun"]["pose"])
    client.write_coil(0, False, device_id=DEV)
    regs = _settled(client)
    assert regs["coupled"] == 0 and regs["fault"] == 0 and regs["present"] == 0b111 and world.mounted_tool is None
    history = server.state()["history"]
    assert [(e["what"], e["value"]) for e in history] == [
        ("fault", 1), ("lock", 2), ("fault", 3), ("fault", 3), ("unlock", 2)]


def test_an_empty_slot_and_addresses_outside_the_map_are_refused(changer):
    cfg, arm, world, server, client = changer
    server.model.take_from_rack("sander")                 # the operator took the sander out of the rack
    assert _inputs(client)["present"] == 0b011 and not _bits(client)[8]
    arm.set_joint_positions(cfg["rack"]["sander"]["pose"])
    client.write_coil(0, True, device_id=DEV)
    regs = _settled(client)
    assert regs["fault"] == 2 and regs["coupled"] == 0 and world.mounted_tool is None
    server.model.put_in_rack("sander")
    client.write_coil(0, True, device_id=DEV)
    assert _settled(client)["coupled"] == 3 and world.mounted_tool == "sander"
    with pytest.raises(SimStateError, match="sander is on the flange"):
        server.model.put_in_rack("sander")
    # outside the map: exception 2 (there are no holding registers)
    assert client.read_holding_registers(0, count=1, device_id=DEV).isError()
    assert client.read_input_registers(6, count=1, device_id=DEV).isError()
    assert client.write_coil(2, True, device_id=DEV).isError()
    assert client.write_register(0, 1, device_id=DEV).isError()
    assert client.read_coils(0, count=1, device_id=DEV + 1).isError()        # another unit id


# -- the second robot (config/robots/diffdrive_ur5e.yaml) carries the changer ----------------------------------------
DIFF_YAML = os.path.join(os.path.dirname(RACK), "..", "..", "config", "robots", "diffdrive_ur5e.yaml")


def test_the_second_robots_worksite_runs_its_tool_changer_and_every_slot_is_clear_of_the_robot(site_cfg, port):
    import socket
    import numpy as np
    import pybullet as pb
    from locem_bridge.sim.worksite import Worksite

    host = "127.0.0.1"
    with socket.socket() as s:                           # the changer's port is the file's: take a free address
        for last in range(2, 250):
            host = "127.66.%d.%d" % (1 + os.getpid() % 250, last)
            try:
                s.bind((host, 5022))
                break
            except OSError:
                continue
    ws = Worksite(site_cfg, load_robot(DIFF_YAML), host=host, modbus_port=port, can_interface="virtual",
                  can_channel="changer-%d" % os.getpid(), with_ur=False, time_scale=10.0)
    ws.start()
    client = ModbusTcpClient(host, port=5022, timeout=0.5, retries=0)
    try:
        assert ws.endpoints()["tool_changer_modbus_tcp"] == "%s:5022 (device id 1)" % host
        cfg = ws.robot_cfg["robot"]["tool_changer"]
        slots = ws.changer.rack.slots
        assert min(np.linalg.norm(slots[a] - slots[b]) for a in slots for b in slots if a < b) > 0.1
        assert client.connect()
        world = ws.world
        for tool, slot in sorted(cfg["rack"].items(), key=lambda kv: kv[1]["slot"]):
            ws.arm.set_joint_positions(slot["pose"])
            assert client.write_coil(0, True, device_id=1).isError() is False
            end = time.monotonic() + 2.0
            while world.mounted_tool != tool and time.monotonic() < end:
                time.sleep(0.01)
            assert world.mounted_tool == tool
            with world._lock:                            # the arm and the coupled tool clear the chassis and column
                world._q = list(slot["pose"])
                world._place_robot()
                near = pb.getClosestPoints(world.arm_body, world.base_body, 0.01, physicsClientId=world._cid)
                near += pb.getClosestPoints(world.tool_bodies[tool], world.base_body, 0.01, physicsClientId=world._cid)
            assert not near, "%s at slot %d touches the robot" % (tool, slot["slot"])
            client.write_coil(0, False, device_id=1)
            end = time.monotonic() + 2.0
            while world.mounted_tool is not None and time.monotonic() < end:
                time.sleep(0.01)
            assert world.mounted_tool is None
        assert ws.tool_changer_state()["operations"] == 6
    finally:
        client.close()
        ws.stop()
