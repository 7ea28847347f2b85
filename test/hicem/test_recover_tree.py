"""The RECOVER tree (trees/RECOVER.xml) and its nodes (WaitForDevices, CheckSafetyStop, CheckDevicesUp, the refusal
of WaitForOperator): against the LOCEM test double (LOCEM not answering, then NOT_READY, links down then up; an
arm in a latched protective stop that only RESET_ARM clears; an operator who resets or cannot clear it), and
against the real LOCEM core with the real compressor bridge (pymodbus) whose link to the compressor stand-in is
dropped and restored. The double-based runs tick the tree on a simulated clock (0.05 s per tick), so waiting
for a minute costs no wall time."""
import os
import re
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from hicem_rig import TREES, params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.config import DEFAULT_PARAMS_FILE
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager
from locem_bridge.hicem.errors import LocemCallError, TreeLoadError
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.interfaces import CommandHandle, LocemClient, LocemReply
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

LIB = TreeLibrary()
LIB.load_directory(TREES)
UP = {"link": "up", "device": "ok", "last_error": ""}
PROTECTIVE = {"link": "up", "device": "safety stop: protective stop (safety mode 3)", "safety_mode": "PROTECTIVE_STOP",
              "last_error": "protective stop (safety mode 3) latched; RESET_ARM after the cause is removed"}
TICK_S = 0.05                      # simulated seconds per tick


def _down(error="no answer from the compressor for 0.62 s"):
    return {"arm": dict(UP), "base": dict(UP), "wall": dict(UP),
            "compressor": {"link": "down", "device": "unknown", "last_error": error}}


def _all_up():
    return {"arm": dict(UP), "base": dict(UP), "wall": dict(UP), "compressor": dict(UP)}


def _cfg_blackboard() -> Blackboard:
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    return bb


class SimClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class Run:
    """One RECOVER run: status, blackboard, context, the prompts opened, the simulated seconds it took."""

    def __init__(self, status: Status, bb: Blackboard, ctx: NodeContext, prompts: List[Any], seconds: float):
        self.status, self.bb, self.ctx, self.prompts, self.seconds = status, bb, ctx, prompts, seconds


def run_tree(tree_id: str, locem: LocemClient, ticks: int = 20000, operator: Optional[Callable[[Any], str]] = None,
             period: Optional[float] = None, **overrides: Any) -> Run:
    """Tick ``tree_id`` on a simulated clock (``period``: on the real clock, sleeping that long between ticks);
    ``operator(prompt)`` answers each prompt the tree opens."""
    store = DataManager()
    hdh = DataHandler(store)
    hdh.ingest_scan(SITE)
    clock = SimClock()
    now = clock if period is None else time.monotonic
    desk = OperatorDesk(clock=now)
    prompts: List[Any] = []
    desk.add_listener(lambda event, p: prompts.append(p) if event == "opened" else None)
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=desk, data_handler=hdh, clock=now)
    bb = Blackboard()
    bb.update(params(**overrides).blackboard_entries())
    bb.set("param_robot", "robot")
    tree = LIB.build(tree_id, ctx, bb)
    st = Status.RUNNING
    t0 = now()
    for _ in range(ticks):
        st = tree.tick()
        if st != Status.RUNNING:
            break
        for p in desk.open_prompts():
            if operator is not None:
                desk.reply(p.id, operator(p))
        if period is None:
            clock.t += TICK_S
        else:
            time.sleep(period)
    if st == Status.RUNNING:
        tree.halt()
    return Run(st, bb, ctx, prompts, now() - t0)


class RestartingLocem(LocemDouble):
    """The double as HICEM sees a LOCEM that restarts: ``absent`` sends fail (no action server), then
    ``not_ready`` STATUS answers NOT_READY (making its devices safe), then the health script."""

    def __init__(self, absent: int = 0, not_ready: int = 0, **kw: Any) -> None:
        super().__init__(**kw)
        self.absent, self.not_ready = absent, not_ready

    def send(self, command: str):
        if self.absent > 0:
            self.absent -= 1
            self.log("(no LOCEM) " + command)
            raise LocemCallError("LOCEM action server /locem/command_action is not available", "NOT_READY")
        if command == "STATUS" and self.not_ready > 0:
            self.not_ready -= 1
            self.fail_next["STATUS"] = LocemReply(False, "NOT_READY", "LOCEM is starting: devices to safe state")
        return super().send(command)


class ArmStopLocem(LocemDouble):
    """The double with the arm in a latched protective stop: every motion is refused (HARDWARE_ERROR) and STATUS
    reports it until RESET_ARM."""

    def __init__(self, **kw: Any) -> None:
        super().__init__(**kw)
        self.health = _all_up()
        self.health["arm"] = dict(PROTECTIVE)

    def send(self, command: str):
        name = command.split()[0]
        if name == "RESET_ARM":
            self.health["arm"] = dict(UP)
        elif name in ("WALL_READY", "GOTO", "SAND_AREA", "SPRAY_AREA") and self.health["arm"] != UP:
            self.fail_next[name] = LocemReply(False, "HARDWARE_ERROR", "arm protective stop (safety mode 3) is "
                                              "latched; remove the cause and send RESET_ARM")
        return super().send(command)


# ------------------------------------------------------------------------------------------ against the double --
def test_the_tree_file_is_documented_and_takes_its_numbers_from_the_parameters():
    text = open(os.path.join(TREES, "RECOVER.xml"), encoding="utf-8").read()
    header = re.search(r"<!--(.*?)-->", text, re.S)
    assert header and header.group(1).strip().startswith("RECOVER:")
    assert LIB.main_trees[os.path.abspath(os.path.join(TREES, "RECOVER.xml"))] == "RECOVER"
    for key in ("links_timeout_s", "ready_timeout_s", "poll_s"):
        assert "{@cfg.recover.%s}" % key in text
        assert params().raw["recover"][key] > 0
    yaml_text = open(DEFAULT_PARAMS_FILE, encoding="utf-8").read()
    assert re.search(r"links_timeout_s: [0-9.]+ +# s,", yaml_text), "links_timeout_s has no unit comment"


def test_devices_down_then_up_recovers_before_the_arm_moves():
    locem = LocemDouble()
    locem.health_script = [_down(), _down()]                  # two STATUS answers with the compressor down
    run = run_tree("RECOVER", locem)
    assert run.status == Status.SUCCESS, run.ctx.failures
    # nothing but STATUS until the links are up; then STATUS for readiness, then the arm moves
    assert locem.sent == ["STATUS", "STATUS", "STATUS", "STATUS", "WALL_READY"]
    poll = params().raw["recover"]["poll_s"]
    assert 2 * poll <= run.seconds < 2 * poll + 0.5          # read every poll_s on HICEM's clock, not LOCEM WAIT
    assert run.bb.get("task_detail") == "recovered"
    assert run.prompts == []


def test_recover_waits_for_a_restarting_locem_then_for_its_links():
    # LOCEM gone for 3 reads (action server absent), NOT_READY twice (making its devices safe), compressor link
    # still down once, then every link up: RECOVER waits through all of it and only then sends WALL_READY
    locem = RestartingLocem(absent=3, not_ready=2)
    locem.health_script = [_down("connecting")]
    run = run_tree("RECOVER", locem)
    assert run.status == Status.SUCCESS, run.ctx.failures
    assert locem.sent == ["(no LOCEM) STATUS"] * 3 + ["STATUS"] * 5 + ["WALL_READY"]
    poll = params().raw["recover"]["poll_s"]
    assert 6 * poll <= run.seconds < 6 * poll + 0.5
    reasons = [r for n, r in run.ctx.failures if n == "links_up"]
    assert reasons == []                                        # waiting is not failing


def test_devices_never_up_fails_after_the_configured_time_without_moving_the_arm():
    locem = LocemDouble()
    locem.health = _down()
    run = run_tree("RECOVER", locem)
    assert run.status == Status.FAILURE
    limit = params().raw["recover"]["links_timeout_s"]
    assert limit < run.seconds <= limit + 0.2
    assert "WALL_READY" not in locem.sent and set(locem.sent) == {"STATUS"}
    node, reason = run.ctx.last_failure()
    assert node == "links_up" and "after %g s" % limit in reason and "compressor: link down" in reason
    assert run.bb.get_default("task_detail", None) is None
    # the limit is data
    locem = RestartingLocem(absent=10 ** 6)
    run = run_tree("RECOVER", locem, recover__links_timeout_s=3.0)
    assert run.status == Status.FAILURE and 3.0 < run.seconds <= 3.2
    assert "LOCEM does not answer (LOCEM action server /locem/command_action is not available)" in \
        run.ctx.last_failure()[1]


def test_a_status_that_is_never_answered_is_cancelled_and_read_again():
    locem = LocemDouble(durations={"STATUS": 3600.0})
    run = run_tree("RECOVER", locem, recover__links_timeout_s=4.0)
    assert run.status == Status.FAILURE
    assert "LOCEM did not answer STATUS within 1 s" in run.ctx.last_failure()[1]
    assert locem.sent.count("STATUS") >= 3 and locem.sent.count("CANCEL STATUS") == locem.sent.count("STATUS")
    assert locem.running() == []


def test_a_device_fault_after_the_links_are_up_is_waited_for_then_fails_with_its_reason():
    locem = LocemDouble()
    fault = _all_up()
    fault["compressor"] = {"link": "up", "device": "fault: overpressure", "last_error": "E12"}
    locem.health = fault
    run = run_tree("RECOVER", locem)
    assert run.status == Status.FAILURE and "WALL_READY" not in locem.sent
    node, reason = run.ctx.last_failure()
    assert node == "devices_ready" and "compressor: device fault: overpressure (E12)" in reason
    limit = params().raw["recover"]["ready_timeout_s"]
    assert limit < run.seconds <= limit + 0.2


def test_a_protective_stop_becomes_a_prompt_whose_reset_clears_it_with_reset_arm():
    locem = ArmStopLocem()
    answered = []
    run = run_tree("RECOVER", locem, operator=lambda p: answered.append(p) or "reset")
    assert run.status == Status.SUCCESS, run.ctx.failures
    assert [p.kind for p in run.prompts] == ["safety_stop"]
    prompt = run.prompts[0]
    assert prompt.text.startswith("protective stop (safety mode 3): check the arm, then reset")
    assert prompt.choices == ("reset", "cannot_clear") and prompt.state == "answered"
    # the arm is not moved before the operator's answer; RESET_ARM comes right after it, WALL_READY after that
    assert locem.sent == ["STATUS", "RESET_ARM", "STATUS", "WALL_READY"]
    assert run.bb.get("task_detail") == "recovered"
    assert run.ctx.operator.interventions == 1


def test_an_operator_who_cannot_clear_the_stop_fails_recover_with_that_reason():
    locem = ArmStopLocem()
    run = run_tree("RECOVER", locem, operator=lambda p: "cannot_clear")
    assert run.status == Status.FAILURE
    assert locem.sent == ["STATUS"]                          # no reset, no motion
    node, reason = run.ctx.last_failure()
    assert node == "ask_reset"
    assert reason == ("operator answered cannot_clear to: protective stop (safety mode 3): check the arm, then "
                      "reset. Answer reset, or cannot_clear if the cause cannot be removed.")


def test_a_reset_the_controller_refuses_fails_recover():
    locem = ArmStopLocem()
    locem.fail_next["RESET_ARM"] = LocemReply(False, "HARDWARE_ERROR", "RESET_ARM: the arm did not come back "
                                              "(safety PROTECTIVE_STOP); is the cause removed?")
    run = run_tree("RECOVER", locem, operator=lambda p: "reset")
    assert run.status == Status.FAILURE and locem.sent == ["STATUS", "RESET_ARM"]
    assert "is the cause removed?" in run.ctx.last_failure()[1]


def test_a_failed_retract_fails_after_the_devices_are_up():
    locem = LocemDouble()
    locem.fail_next["WALL_READY"] = LocemReply(False, "HARDWARE_ERROR", "arm link is down")
    run = run_tree("RECOVER", locem)
    assert run.status == Status.FAILURE and locem.sent == ["STATUS", "STATUS", "WALL_READY"]
    assert "arm link is down" in run.ctx.last_failure()[1]


def test_a_refusal_that_is_not_a_choice_is_refused_when_the_tree_is_loaded():
    xml = ('<root BTCPP_format="4"><BehaviorTree ID="T"><WaitForOperator kind="k" text="t" choices="yes;no" '
           'refuse="never" answer="{a}"/></BehaviorTree></root>')
    with pytest.raises(TreeLoadError, match="refuse lists never, which is not among the choices yes;no"):
        TreeLibrary().load_string(xml)


@pytest.mark.parametrize("health,found", [
    ({"arm": dict(PROTECTIVE)}, "protective stop (safety mode 3)"),
    ({"arm": {"link": "up", "device": "safety stop: robot emergency stop (safety mode 7)"}},
     "robot emergency stop (safety mode 7)"),
    ({"arm": dict(UP)}, None),
    ({"arm": {"link": "down", "device": "unknown"}}, None),
    ({"compressor": dict(UP)}, None),
])
def test_check_safety_stop_reads_the_arm_health(health, found):
    locem = LocemDouble()
    locem.health = health
    xml = ('<root BTCPP_format="4"><BehaviorTree ID="T"><Sequence>'
           '<SendLocemCommand command="STATUS" result="{status}"/>'
           '<CheckSafetyStop name="check" device="arm" status="{status}" stop="{stop}"/>'
           '</Sequence></BehaviorTree></root>')
    lib = TreeLibrary()
    lib.load_string(xml)
    ctx = NodeContext(locem=locem)
    bb = _cfg_blackboard()
    st = lib.build("T", ctx, bb).tick()
    assert (st == Status.SUCCESS) is (found is not None), ctx.failures
    if found:
        assert bb.get("stop") == found


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
        run = run_tree("RECOVER", client, ticks=2000, period=0.01, recover__links_timeout_s=4.0, recover__poll_s=0.1)
        st, bb, ctx = run.status, run.bb, run.ctx
    finally:
        timer.cancel()
    assert st == Status.SUCCESS, ctx.failures
    assert client.health_seen[0] == "down" and client.health_seen[-1] == "up"
    assert client.sent.count("STATUS") >= 2 and client.sent[-1] == "WALL_READY"
    assert "WALL_READY" not in client.sent[:-1]               # the arm moves only once the link is back
    assert 0.7 < run.seconds < 3.0
    assert bb.get("task_detail") == "recovered"


def test_recover_gives_up_when_the_real_compressor_stays_down(real_locem):
    rig, core, backend, wait_until = real_locem
    rig.server.drop_link(duration=None, mode="close")
    assert wait_until(lambda: backend.health()["link"] == "down", timeout=3.0)
    client = CoreClient(core)
    try:
        run = run_tree("RECOVER", client, ticks=2000, period=0.01, recover__links_timeout_s=0.5, recover__poll_s=0.1)
        st, ctx = run.status, run.ctx
    finally:
        rig.server.restore_link()
    assert st == Status.FAILURE
    assert 4 <= client.sent.count("STATUS") <= 7 and set(client.health_seen) == {"down"}
    assert "WALL_READY" not in client.sent
    assert "devices not ready: compressor: link down" in ctx.last_failure()[1]
