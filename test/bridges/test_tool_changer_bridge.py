"""Tool changer backend (real pymodbus client) against the tool changer stand-in bound to the PyBullet world:
lock / unlock confirmed by the device, the coupled tool id, the device's interlocks as HARDWARE_ERROR, link loss
(HARDWARE_ERROR) and return (the safe state holds the coupled tool before any command)."""
import pytest

from locem_bridge.bridges.backends import backend_class
from locem_bridge.bridges.errors import DeviceFault, LinkDown, NotConnected
from locem_bridge.bridges.interfaces import PlainWaiter
from locem_bridge.common.locem_codes import Code

from bridge_rigs import ToolChangerRig, robot_with_changer, wait_until


@pytest.fixture
def changer_rig():
    robot = robot_with_changer()
    rig = ToolChangerRig(robot)
    backend = backend_class("tool_changer", "modbus_tcp")(robot["tool_changer"])
    yield rig, backend
    backend.close()
    rig.close()


def test_lock_couples_the_tool_of_the_slot_and_unlock_puts_it_back(changer_rig):
    rig, changer = changer_rig
    with pytest.raises(NotConnected, match="not in its safe state yet"):
        changer.read()                                    # not started: NOT_READY, nothing sent
    changer.start()
    assert changer.wait_ready(5.0), changer.health()
    state = changer.read()
    assert state["coupled_tool"] == "" and state["unlocked"] and not state["locked"]
    assert state["present"] == {"taping_tool": True, "spray_gun": True, "sander": True}
    assert changer.slots == {"taping_tool": 1, "spray_gun": 2, "sander": 3}
    rig.to_slot("spray_gun")
    locked = changer.lock(PlainWaiter())
    assert locked["locked"] and locked["coupled_tool_id"] == 2 and locked["coupled_tool"] == "spray_gun"
    assert locked["present"]["spray_gun"] is False and locked["flange_slot"] == 2
    assert rig.world.mounted_tool == "spray_gun"
    assert 0.0 < locked["duration_s"] < changer.lock_timeout      # the lock took its time (sim lock_time)
    assert wait_until(lambda: changer.health().get("coupled_tool") == "spray_gun", 2.0), changer.health()
    unlocked = changer.unlock(PlainWaiter())
    assert unlocked["unlocked"] and unlocked["coupled_tool_id"] == 0 and unlocked["present"]["spray_gun"]
    assert rig.world.mounted_tool is None


def test_the_devices_interlocks_answer_hardware_error_naming_the_fault(changer_rig):
    rig, changer = changer_rig
    changer.start()
    assert changer.wait_ready(5.0)
    with pytest.raises(DeviceFault, match=r"refused to lock: fault 1 \(not at a slot\), flange at no rack slot") \
            as caught:
        changer.lock(PlainWaiter())
    assert caught.value.code == Code.HARDWARE_ERROR and rig.world.mounted_tool is None
    rig.to_slot("taping_tool")
    assert changer.lock(PlainWaiter())["coupled_tool"] == "taping_tool"
    rig.to_slot("sander")
    with pytest.raises(DeviceFault, match=r"refused to unlock: fault 3 \(not at the tool's slot\), flange at slot 3"):
        changer.unlock(PlainWaiter())
    assert rig.world.mounted_tool == "taping_tool" and changer.read()["locked"]


def test_link_loss_is_hardware_error_and_on_return_the_coupled_tool_is_held_first(changer_rig):
    rig, changer = changer_rig
    changer.start()
    assert changer.wait_ready(5.0)
    rig.to_slot("sander")
    changer.lock(PlainWaiter())
    writes = changer.safe_state_writes
    rig.server.drop_link(mode="close")
    assert wait_until(lambda: changer.health()["link"] == "down", 3.0), changer.health()
    for call in (changer.read, lambda: changer.unlock(PlainWaiter())):
        with pytest.raises(LinkDown) as caught:
            call()
        assert caught.value.code == Code.HARDWARE_ERROR
    assert rig.world.mounted_tool == "sander"             # the device holds its tool through the loss
    rig.server.restore_link()
    assert wait_until(lambda: changer.health()["link"] == "up", 5.0), changer.health()
    assert changer.safe_state_writes == writes + 1       # the lock commanded closed again before "up"
    state = changer.read()
    assert state["locked"] and state["coupled_tool"] == "sander" and rig.world.mounted_tool == "sander"
    assert rig.server.state()["locked"]
    # and commands work again
    assert changer.unlock(PlainWaiter())["coupled_tool"] == "" and rig.world.mounted_tool is None


def test_a_new_backend_finds_the_coupled_tool_and_holds_it(changer_rig):
    """A LOCEM started while a tool is coupled (e.g. after a crash): the device is the truth, the tool stays."""
    rig, first = changer_rig
    first.start()
    assert first.wait_ready(5.0)
    rig.to_slot("spray_gun")
    first.lock(PlainWaiter())
    first.close()
    second = backend_class("tool_changer", "modbus_tcp")(dict(rig.cfg))
    try:
        second.start()
        assert second.wait_ready(5.0)
        assert second.safe_state_writes == 1
        assert second.cached()["coupled_tool"] == "spray_gun" and second.cached()["locked"]
        assert rig.world.mounted_tool == "spray_gun"
    finally:
        second.close()
