"""The RECOVER tree (trees/RECOVER.xml) and its CheckDevicesUp condition: against the LOCEM test double (STATUS
answers scripted: devices down, then up; never up), and against the real LOCEM core with the real compressor
bridge (pymodbus) whose link to the compressor stand-in is dropped and restored."""
import os
import re
import sys
import threading
import time
from typing import Any, Dict, Optional

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from hicem_rig import TREES, params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.interfaces import CommandHandle, LocemClient, LocemReply
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

LIB = TreeLibrary()
LIB.load_directory(TREES)
UP = {"link": "up", "device": "ok", "last_error": ""}


def _down(error="no answer from the compressor for 0.62 s"):
    return {"arm": dict(UP), "base": dict(UP), "wall": dict(UP),
            "compressor": {"link": "down", "device": "unknown", "last_error": error}}


def _cfg_blackboard() -> Blackboard:
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    return bb


def run_tree(tree_id: str, locem: LocemClient, ticks: int = 2000, period: float = 0.0, **overrides: Any):
    store = DataManager()
    hdh = DataHandler(store)
    hdh.ingest_scan(SITE)
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=OperatorDesk(), data_handler=hdh)
    bb = Blackboard()
    bb.update(params(**overrides).blackboard_entries())
    bb.set("param_robot", "robot")
    tree = LIB.build(tree_id, ctx, bb)
    st = Status.RUNNING
    for _ in range(ticks):
        st = tree.tick()
        if st != Status.RUNNING:
            break
        time.sleep(period)
    if st == Status.RUNNING:
        tree.halt()
    return st, bb, ctx


# ------------------------------------------------------------------------------------------ against the double --
def test_the_tree_file_is_documented_and_takes_its_numbers_from_the_parameters():
    text = open(os.path.join(TREES, "RECOVER.xml"), encoding="utf-8").read()
    header = re.search(r"<!--(.*?)-->", text, re.S)
    assert header and header.group(1).strip().startswith("RECOVER:")
    assert LIB.main_trees[os.path.abspath(os.path.join(TREES, "RECOVER.xml"))] == "RECOVER"
    assert "{@cfg.recover.attempts}" in text and "{@cfg.recover.poll_s}" in text
    raw = params().raw["recover"]
    assert raw["attempts"] >= 1 and raw["poll_s"] > 0


def test_devices_down_then_up_recovers():
    locem = LocemDouble()
    locem.health_script = [_down(), _down()]                  # two STATUS answers with the compressor down
    st, bb, ctx = run_tree("RECOVER", locem)
    assert st == Status.SUCCESS, ctx.failures
    poll = params().raw["recover"]["poll_s"]
    wait = "WAIT %s" % ("%g" % poll)
    assert locem.sent == ["WALL_READY", "STATUS", wait, "STATUS", wait, "STATUS"]
    assert bb.get("task_detail") == "recovered"
    # the reasons of the two failed polls were recorded, naming the device and its error
    reasons = [r for n, r in ctx.failures if n == "devices_up"]
    assert len(reasons) == 2 and "compressor: link down, device unknown (no answer from the compressor" in reasons[0]


def test_devices_never_up_fails_after_the_configured_attempts():
    locem = LocemDouble()
    locem.health = _down()
    st, bb, ctx = run_tree("RECOVER", locem)
    assert st == Status.FAILURE
    attempts = params().raw["recover"]["attempts"]
    assert locem.sent.count("STATUS") == attempts and locem.sent[0] == "WALL_READY"
    assert ctx.last_failure()[0] == "devices_up" and "compressor: link down" in ctx.last_failure()[1]
    assert bb.get_default("task_detail", None) is None
    # the number of attempts is data: three from the parameters, three STATUS reads
    locem = LocemDouble()
    locem.health = _down()
    st, _, _ = run_tree("RECOVER", locem, recover__attempts=3)
    assert st == Status.FAILURE and locem.sent.count("STATUS") == 3 and locem.sent.count("WAIT 1") == 3


def test_a_failed_retract_fails_before_any_poll():
    locem = LocemDouble()
    locem.fail_next["WALL_READY"] = LocemReply(False, "HARDWARE_ERROR", "arm link is down")
    st, _, ctx = run_tree("RECOVER", locem)
    assert st == Status.FAILURE and locem.sent == ["WALL_READY"]
    assert "arm link is down" in ctx.last_failure()[1]


@pytest.mark.parametrize("health,devices,ok,fragment", [
    ({"compressor": {"link": "up", "device": "fault: overpressure", "last_error": "E12"}}, "", False,
     "compressor: device fault: overpressure (E12)"),
    ({"base": {"link": "up", "device": "ok", "last_error": "", "fault": "heartbeat lost"}}, "", False,
     "base: fault heartbeat lost"),
    ({"arm": {"link": "connecting", "device": "unknown", "last_error": ""}, "compressor": dict(UP)}, "compressor",
     True, ""),
    ({"arm": {"link": "connecting", "device": "unknown", "last_error": ""}, "compressor": dict(UP)}, "", False,
     "arm: link connecting"),
    ({"compressor": dict(UP)}, "compressor;arm", False, "arm: not in STATUS (it reports compressor)"),
    ({}, "", False, "STATUS reports no device at all"),
])
def test_check_devices_up_reads_the_status_health(health, devices, ok, fragment):
    locem = LocemDouble()
    locem.health = health
    xml = ('<root BTCPP_format="4"><BehaviorTree ID="T"><Sequence>'
           '<SendLocemCommand command="STATUS" result="{status}"/>'
           '<CheckDevicesUp name="check" status="{status}" devices="%s"/>'
           '</Sequence></BehaviorTree></root>' % devices)
    lib = TreeLibrary()
    lib.load_string(xml)
    ctx = NodeContext(locem=locem)
    tree = lib.build("T", ctx, _cfg_blackboard())
    st = tree.tick()
    assert (st == Status.SUCCESS) is ok, ctx.failures
    if fragment:
        assert fragment in ctx.last_failure()[1]


def test_a_status_result_without_health_is_a_clear_failure():
    locem = LocemDouble()
    xml = ('<root BTCPP_format="4"><BehaviorTree ID="T"><Sequence>'
           '<SendLocemCommand command="GET_POSE" result="{status}"/>'
           '<CheckDevicesUp name="check" status="{status}"/>'
           '</Sequence></BehaviorTree></root>')
    lib = TreeLibrary()
    lib.load_string(xml)
    ctx = NodeContext(locem=locem)
    assert lib.build("T", ctx, _cfg_blackboard()).tick() == Status.FAILURE
    assert "has no 'health' object (got ['pose', 'twist'])" in ctx.last_failure()[1]


# ------------------------------------------------------------------- against the real LOCEM and compressor --
class _Done(CommandHandle):
    def __init__(self, command: str, reply: LocemReply) -> None:
        self.command, self._reply = command, reply

    def done(self) -> bool:
        return True

    def reply(self) -> Optional[LocemReply]:
        return self._reply

    def cancel(self) -> None:
        pass


class _ExecutionHandle(CommandHandle):
    def __init__(self, command: str, execution: Any) -> None:
        self.command, self.execution = command, execution

    def done(self) -> bool:
        return self.execution.done

    def reply(self) -> Optional[LocemReply]:
        r = self.execution.wait(0)
        if not self.execution.done or r is None:
            return None
        return LocemReply(r.success, r.code.value, r.message, r.result)

    def cancel(self) -> None:
        self.execution.cancel("cancelled by HICEM")


class CoreClient(LocemClient):
    """HICEM's LocemClient over an in-process LOCEM core (the ROS action interface without ROS). This rig has no
    arm: WALL_READY is answered OK here; every other command goes to the real core."""

    def __init__(self, core: Any) -> None:
        self.core = core
        self.sent = []
        self.health_seen = []

    def send(self, command: str) -> CommandHandle:
        from locem_bridge.locem.errors import LocemError
        from locem_bridge.locem.registry import Interface
        self.sent.append(command)
        if command == "WALL_READY":
            return _Done(command, LocemReply(True, "OK", "no arm in this rig"))
        try:
            ex = self.core.dispatcher.submit(command, Interface.ACTION)
        except LocemError as exc:
            return _Done(command, LocemReply(False, exc.code.value, exc.message))
        if command == "STATUS":
            self.health_seen.append(ex.wait(5.0).result["health"]["compressor"]["link"])
        return _ExecutionHandle(command, ex)


@pytest.fixture
def real_locem():
    bridges = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "bridges")
    if bridges not in sys.path:
        sys.path.insert(0, bridges)
    from bridge_rigs import ROBOT_YAML, CompressorRig, wait_until
    from locem_bridge.bridges.commands_compressor import CompressorCommands
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.bridges.modbus_compressor import ModbusCompressor
    from locem_bridge.locem.core import LocemCore
    rig = CompressorRig(load_robot_config(ROBOT_YAML))
    core = LocemCore(grace=0.5, stop_timeout=2.0)
    backend = ModbusCompressor(rig.cfg)
    backend.start()
    core.install(CompressorCommands(backend))
    try:
        assert backend.wait_ready(5.0), backend.health()
        yield rig, core, backend, wait_until
    finally:
        backend.close()
        core.close()
        rig.close()


def test_recover_waits_for_the_real_compressor_link_to_come_back(real_locem):
    rig, core, backend, wait_until = real_locem
    rig.server.drop_link(duration=None, mode="close")
    assert wait_until(lambda: backend.health()["link"] == "down", timeout=3.0)
    timer = threading.Timer(0.8, rig.server.restore_link)
    timer.start()
    client = CoreClient(core)
    try:
        st, bb, ctx = run_tree("RECOVER", client, ticks=2000, period=0.01, recover__attempts=40, recover__poll_s=0.1)
    finally:
        timer.cancel()
    assert st == Status.SUCCESS, ctx.failures
    assert client.health_seen[0] == "down" and client.health_seen[-1] == "up"
    assert client.sent.count("STATUS") >= 2 and "WAIT 0.1" in client.sent
    assert bb.get("task_detail") == "recovered"


def test_recover_gives_up_when_the_real_compressor_stays_down(real_locem):
    rig, core, backend, wait_until = real_locem
    rig.server.drop_link(duration=None, mode="close")
    assert wait_until(lambda: backend.health()["link"] == "down", timeout=3.0)
    client = CoreClient(core)
    try:
        st, _, ctx = run_tree("RECOVER", client, ticks=2000, period=0.01, recover__attempts=4, recover__poll_s=0.05)
    finally:
        rig.server.restore_link()
    assert st == Status.FAILURE
    assert client.sent.count("STATUS") == 4 and set(client.health_seen) == {"down"}
    assert "devices not ready: compressor: link down" in ctx.last_failure()[1]
