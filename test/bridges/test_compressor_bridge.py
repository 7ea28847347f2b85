"""The compressor bridge (pymodbus client) against the compressor stand-in (pymodbus server + pressure model)."""
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from locem_bridge.bridges.commands_compressor import CompressorCommands
from locem_bridge.common.health import ERROR as HEALTH_ERROR, OK as HEALTH_OK, grade as health_level
from locem_bridge.bridges.modbus_compressor import ModbusCompressor

from bridge_rigs import wait_until


@pytest.fixture
def bridge(compressor_rig, core):
    backend = ModbusCompressor(compressor_rig.cfg)
    backend.start()
    core.install(CompressorCommands(backend))
    assert backend.wait_ready(5.0), backend.health()
    yield backend
    backend.close()


def run(core, text):
    return core.dispatcher.execute(text)


def test_pressure_is_reached_and_reported_like_the_device_measures_it(bridge, core, compressor_rig):
    assert run(core, "COMPRESSOR_ON").success
    r = run(core, "SET_PRESSURE 3.0 tolerance=0.1")
    assert r.success, r.message
    truth = compressor_rig.model.snapshot()
    assert abs(truth["pressure"] - 3.0) <= 0.12
    assert truth["setpoint"] == pytest.approx(3.0)
    g = run(core, "GET_PRESSURE")
    assert g.success
    assert g.result["pressure"] == pytest.approx(compressor_rig.model.snapshot()["pressure"], abs=0.05)
    assert g.result["setpoint"] == pytest.approx(3.0) and g.result["motor_running"] is True
    assert run(core, "SPRAY_ON").success
    assert compressor_rig.model.snapshot()["valve_open"] is True
    assert run(core, "COMPRESSOR_OFF").success
    truth = compressor_rig.model.snapshot()
    assert truth["valve_open"] is False and truth["motor_on"] is False


def test_spray_valve_stays_closed_without_pressure(bridge, core, compressor_rig):
    r = run(core, "SPRAY_ON")
    assert r.code.value == "NOT_READY" and "working band" in r.message
    assert compressor_rig.model.snapshot()["valve_open"] is False


def test_out_of_range_setpoint_never_reaches_the_device(bridge, core, compressor_rig):
    before = compressor_rig.server.requests
    r = run(core, "SET_PRESSURE 12")
    assert r.code.value == "INVALID_ARGUMENT" and "pressure" in r.message and "0 to 10" in r.message
    assert compressor_rig.model.snapshot()["setpoint"] == 0.0
    time.sleep(0.2)
    # only the 15 Hz polls (2 reads each) reached the server, no write
    assert compressor_rig.server.requests - before <= 10


@pytest.mark.parametrize("mode", ["close", "silent"])
def test_link_loss_fails_commands_and_the_device_is_made_safe_when_the_link_returns(bridge, core, compressor_rig,
                                                                                   mode):
    assert run(core, "COMPRESSOR_ON").success
    assert run(core, "SET_PRESSURE 3.0").success
    assert run(core, "SPRAY_ON").success
    assert health_level(core.dispatcher.health()["compressor"]) == HEALTH_OK
    compressor_rig.server.drop_link(duration=None, mode=mode)
    t0 = time.monotonic()
    assert wait_until(lambda: bridge.health()["link"] == "down", timeout=2.0)
    detected = time.monotonic() - t0
    assert detected < 1.0, "link loss noticed after %.2f s" % detected
    r = run(core, "SPRAY_OFF")
    assert r.code.value == "HARDWARE_ERROR" and "link" in r.message
    assert "compressor" in run(core, "STATUS").result["health"]
    assert run(core, "STATUS").result["health"]["compressor"]["link"] == "down"
    # what the node publishes on /diagnostics (LocemDevices reads core.dispatcher.health): ERROR, naming the loss
    health = core.dispatcher.health()["compressor"]
    assert health_level(health) == HEALTH_ERROR, health
    assert "does not answer" in health["last_error"] or "no answer" in health["last_error"], health
    # the device hears nobody either: its communication watchdog closes the valve and stops the motor
    assert wait_until(lambda: not compressor_rig.model.snapshot()["valve_open"]
                      and not compressor_rig.model.snapshot()["motor_on"], timeout=2.0), compressor_rig.model.snapshot()
    assert [e["cause"] for e in compressor_rig.model.history()[-2:]] == ["watchdog", "watchdog"]
    writes = bridge.safe_state_writes
    compressor_rig.server.restore_link()
    # when the link returns the bridge sees the trip, makes the device safe again and re-arms the watchdog
    assert wait_until(lambda: bridge.health()["link"] == "up", timeout=3.0)
    assert health_level(core.dispatcher.health()["compressor"]) == HEALTH_OK
    assert bridge.safe_state_writes > writes
    assert wait_until(lambda: bridge.health()["watchdog"]["trips_seen"] == 1, timeout=2.0), bridge.health()
    assert compressor_rig.server.state()["watchdog"]["tripped"] is False
    # it stays safe (nothing switches it on again by itself) and obeys again
    time.sleep(0.5)
    assert compressor_rig.model.snapshot()["motor_on"] is False
    assert run(core, "COMPRESSOR_ON").success
    assert compressor_rig.model.snapshot()["motor_on"] is True
    assert run(core, "COMPRESSOR_OFF").success


def test_spray_off_closes_the_valve_on_the_device_and_leaves_the_motor_running(bridge, core, compressor_rig):
    assert run(core, "COMPRESSOR_ON").success
    assert run(core, "SET_PRESSURE 3.0").success
    assert run(core, "SPRAY_ON").success
    assert compressor_rig.model.snapshot()["valve_open"] is True
    writes = compressor_rig.server.requests
    r = run(core, "SPRAY_OFF")
    assert r.success, r.message
    assert r.result["valve_open"] is False                      # as read back from the device
    truth = compressor_rig.model.snapshot()
    assert truth["valve_open"] is False and truth["motor_on"] is True
    assert compressor_rig.server.requests > writes
    assert run(core, "GET_PRESSURE").result["valve_open"] is False


def test_stop_closes_the_valve_and_stops_the_motor(bridge, core, compressor_rig):
    assert run(core, "COMPRESSOR_ON").success
    assert run(core, "SET_PRESSURE 3.0").success
    assert run(core, "SPRAY_ON").success
    assert run(core, "STOP").success
    truth = compressor_rig.model.snapshot()
    assert truth["valve_open"] is False and truth["motor_on"] is False


def test_set_pressure_is_cancelled_by_stop(bridge, core, compressor_rig):
    assert run(core, "COMPRESSOR_ON").success
    execution = core.dispatcher.submit("SET_PRESSURE 9.5 tolerance=0.01", interface=__import__(
        "locem_bridge.locem.registry", fromlist=["Interface"]).Interface.SERVICE)
    time.sleep(0.1)
    assert run(core, "STOP").success
    r = execution.wait(3.0)
    assert r is not None and r.code.value == "ABORTED"
    assert compressor_rig.model.snapshot()["motor_on"] is False


# -- communication watchdog and the safe state at start ------------------------------------------------------
def test_bridge_arms_the_watchdog_and_its_polls_keep_it_alive(bridge, core, compressor_rig):
    wd = compressor_rig.server.state()["watchdog"]
    assert wd["timeout_ms"] == 500 and wd["trips"] == 0
    assert run(core, "COMPRESSOR_ON").success
    assert run(core, "SET_PRESSURE 3.0").success
    assert run(core, "SPRAY_ON").success
    time.sleep(2.0)                            # only the bridge's polls reach the device meanwhile
    state = compressor_rig.server.state()
    assert state["valve_open"] and state["motor_on"] and state["watchdog"]["trips"] == 0, state
    assert bridge.health()["watchdog"] == {"timeout_s": 0.5, "device_trips": 0, "trips_seen": 0}
    # a device that lost the setting (power cycle) gets it written again
    compressor_rig.server.map.watchdog_ms = 0
    assert wait_until(lambda: compressor_rig.server.state()["watchdog"]["timeout_ms"] == 500, timeout=1.0)
    assert run(core, "COMPRESSOR_OFF").success


def test_a_fresh_bridge_makes_a_running_compressor_safe_before_it_accepts_commands(compressor_rig, core):
    model = compressor_rig.model
    model.set_setpoint(3.0)
    model.set_motor(True, cause="test")           # what a LOCEM that died while spraying leaves behind
    model.set_valve(True, cause="test")
    compressor_rig.server.drop_link(duration=None, mode="close")
    backend = ModbusCompressor(compressor_rig.cfg)
    backend.start()
    core.install(CompressorCommands(backend))
    try:
        time.sleep(0.3)
        r = run(core, "COMPRESSOR_ON")                 # before the first answer: refused with the reason
        assert r.code.value == "NOT_READY" and "safe state" in r.message, (r.code, r.message)
        assert run(core, "SPRAY_ON").code.value == "NOT_READY"
        compressor_rig.server.restore_link()
        assert backend.wait_ready(5.0), backend.health()
        state = compressor_rig.server.state()
        assert not state["valve_open"] and not state["motor_on"], state
        changes = [(e["what"], e["value"], e["cause"]) for e in state["history"] if e["cause"] != "test"]
        assert changes == [("valve_open", False, "modbus"), ("motor_on", False, "modbus")]
        assert state["watchdog"]["timeout_ms"] == 500
        assert run(core, "COMPRESSOR_ON").success
        assert model.snapshot()["motor_on"] is True
    finally:
        backend.close()


_CHILD = """
import sys, time
from locem_bridge.bridges.commands_compressor import CompressorCommands
from locem_bridge.bridges.modbus_compressor import ModbusCompressor
from locem_bridge.locem.core import LocemCore
cfg = __import__("json").loads(sys.argv[1])
backend = ModbusCompressor(cfg)
backend.start()
core = LocemCore()
core.install(CompressorCommands(backend))
assert backend.wait_ready(10.0), backend.health()
for text in ("COMPRESSOR_ON", "SET_PRESSURE 3.0", "SPRAY_ON"):
    r = core.dispatcher.execute(text)
    assert r.success, (text, r.message)
print("spraying", flush=True)
time.sleep(600)
"""


def test_bridge_process_killed_while_spraying_leaves_the_compressor_safe_within_1_s(compressor_rig):
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    child = subprocess.Popen([sys.executable, "-c", _CHILD, json.dumps(compressor_rig.cfg)], stdout=subprocess.PIPE,
                             env=env, text=True)
    try:
        assert child.stdout.readline().strip() == "spraying"
        time.sleep(1.0)                              # the child's polls alone keep the device spraying
        assert compressor_rig.model.snapshot()["valve_open"] and compressor_rig.model.snapshot()["motor_on"]
        killed = time.time()
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5.0)
        assert wait_until(lambda: not compressor_rig.model.snapshot()["motor_on"], timeout=3.0)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(5.0)
    state = compressor_rig.server.state()
    changes = {e["what"]: e for e in state["history"] if e["wall"] >= killed}
    assert changes["valve_open"]["value"] is False and changes["motor_on"]["value"] is False
    assert changes["valve_open"]["cause"] == "watchdog" and changes["motor_on"]["cause"] == "watchdog"
    delay = max(changes["valve_open"]["wall"], changes["motor_on"]["wall"]) - killed
    print("valve closed and motor off %.3f s after kill -9" % delay)
    assert delay <= 1.0, delay
    # a fresh bridge (the respawned LOCEM) finds the trip and reports it
    backend = ModbusCompressor(compressor_rig.cfg)
    backend.start()
    try:
        assert backend.wait_ready(5.0)
        assert backend.health()["watchdog"]["trips_seen"] == 1
        assert compressor_rig.server.state()["watchdog"]["tripped"] is False
    finally:
        backend.close()
