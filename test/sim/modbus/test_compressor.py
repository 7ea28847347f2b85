"""Compressor stand-in: a real pymodbus client against the Modbus TCP server and its pressure model."""
import copy
import time

import pytest
from pymodbus.client import ModbusTcpClient

from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.modbus.compressor import CompressorModel
from locem_bridge.sim.modbus.modbus_server import CompressorServer

DEV = 1


@pytest.fixture
def served(robot_cfg, port):
    cfg = copy.deepcopy(robot_cfg["robot"]["compressor"])
    clock = SimClock(time_scale=10.0)         # tau = 2 s sim -> 0.2 s wall
    model = CompressorModel(cfg, clock.now)
    server = CompressorServer(model, "127.0.0.1", port, DEV)
    server.start()
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.5, retries=0)
    assert client.connect()
    yield model, server, client
    client.close()
    server.stop()


def _pressure(client):
    rr = client.read_input_registers(0, count=4, device_id=DEV)
    assert not rr.isError(), rr
    return rr.registers[0] / 100.0, rr.registers


def _wait_pressure(client, target, tol, timeout):
    deadline = time.monotonic() + timeout
    p = None
    while time.monotonic() < deadline:
        p, _ = _pressure(client)
        if abs(p - target) <= tol:
            return p
        time.sleep(0.05)
    return p


def test_client_drives_compressor_to_set_pressure(served):
    model, server, client = served
    assert not client.write_register(0, 450, device_id=DEV).isError()       # 4.50 bar
    time.sleep(0.3)
    p, _ = _pressure(client)
    assert p == 0.0                                                          # motor still off: no pressure
    assert not client.write_coil(0, True, device_id=DEV).isError()
    p = _wait_pressure(client, 4.5, 0.02, timeout=5.0)
    assert abs(p - 4.5) <= 0.02
    regs = client.read_input_registers(0, count=4, device_id=DEV).registers
    assert regs[1] > 0                                       # motor current flows
    assert regs[2] == 0                                      # no fault
    di = client.read_discrete_inputs(0, count=4, device_id=DEV).bits[:4]
    assert di == [True, False, True, False]                  # running, valve closed, in range, no fault
    assert client.read_holding_registers(0, count=1, device_id=DEV).registers == [450]
    # opening the valve drops the pressure by the modelled drop
    client.write_coil(1, True, device_id=DEV)
    p = _wait_pressure(client, 3.5, 0.03, timeout=5.0)
    assert abs(p - 3.5) <= 0.03
    assert model.spraying()
    # motor off: pressure decays
    client.write_coil(0, False, device_id=DEV)
    p = _wait_pressure(client, 0.0, 0.05, timeout=5.0)
    assert p <= 0.05


def test_bad_requests_get_exception_codes_and_server_keeps_running(served):
    model, server, client = served
    rr = client.read_holding_registers(5, count=1, device_id=DEV)
    assert rr.isError() and rr.exception_code == 2
    rr = client.read_input_registers(2, count=5, device_id=DEV)
    assert rr.isError() and rr.exception_code == 2
    rr = client.write_register(0, 5000, device_id=DEV)                   # 50 bar > max_setpoint 10 bar
    assert rr.isError() and rr.exception_code == 3
    rr = client.write_coil(7, True, device_id=DEV)
    assert rr.isError() and rr.exception_code == 2
    rr = client.read_coils(40, count=1, device_id=DEV)
    assert rr.isError() and rr.exception_code == 2
    assert server.refused >= 3
    assert model.setpoint == 0.0
    # still answering normal requests
    assert not client.write_register(0, 300, device_id=DEV).isError()
    assert client.read_holding_registers(0, count=1, device_id=DEV).registers == [300]


def test_overpressure_fault_trips_and_resets(served):
    model, server, client = served
    client.write_register(0, 500, device_id=DEV)
    client.write_coil(0, True, device_id=DEV)
    _wait_pressure(client, 5.0, 0.05, timeout=5.0)
    model.inject_overpressure()
    deadline = time.monotonic() + 5.0
    code = 0
    while time.monotonic() < deadline and code == 0:
        code = client.read_input_registers(2, count=1, device_id=DEV).registers[0]
        time.sleep(0.05)
    assert code == 1                                                 # overpressure latched
    assert client.read_discrete_inputs(0, count=4, device_id=DEV).bits[0] is False   # motor stopped
    p = _wait_pressure(client, 0.0, 0.5, timeout=5.0)                # pressure decays with the motor off
    assert p < 9.0
    client.write_coil(2, True, device_id=DEV)                        # fault reset
    assert client.read_input_registers(2, count=1, device_id=DEV).registers[0] == 0


@pytest.mark.parametrize("mode", ["close", "silent"])
def test_link_drop_and_return(served, mode):
    model, server, client = served
    assert not client.read_input_registers(0, count=1, device_id=DEV).isError()
    server.drop_link(duration=None, mode=mode)
    failed = False
    try:
        rr = client.read_input_registers(0, count=1, device_id=DEV)
        failed = rr.isError()
    except Exception:
        failed = True
    assert failed
    server.restore_link()
    deadline = time.monotonic() + 5.0
    ok = False
    while time.monotonic() < deadline and not ok:
        try:
            client.close()
            client.connect()
            ok = not client.read_input_registers(0, count=1, device_id=DEV).isError()
        except Exception:
            time.sleep(0.1)
    assert ok


def test_link_drop_with_duration_comes_back_by_itself(served):
    model, server, client = served
    t0 = time.monotonic()
    server.drop_link(duration=0.6, mode="close")
    assert server.link_state == "dropped_close"
    ok = False
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and not ok:
        try:
            client.close()
            ok = client.connect() and not client.read_input_registers(0, count=1, device_id=DEV).isError()
        except Exception:
            ok = False
        if not ok:
            time.sleep(0.05)
    assert ok
    assert time.monotonic() - t0 >= 0.5
    assert server.link_state == "up"


# -- communication watchdog -----------------------------------------------------------------------------------
def _spray(client, model):
    """Motor on, pressure up, valve open (what a spraying LOCEM leaves)."""
    assert not client.write_register(0, 300, device_id=DEV).isError()
    assert not client.write_coil(0, True, device_id=DEV).isError()
    assert abs(_wait_pressure(client, 3.0, 0.05, timeout=5.0) - 3.0) <= 0.05
    assert not client.write_coil(1, True, device_id=DEV).isError()
    assert model.snapshot()["valve_open"] and model.snapshot()["motor_on"]


def _status(client):
    regs = client.read_input_registers(0, count=5, device_id=DEV).registers
    return {"tripped": bool(regs[3] & 16), "trips": regs[4], "valve_open": bool(regs[3] & 2),
            "motor_running": bool(regs[3] & 1)}


def test_watchdog_is_off_at_power_up_and_silence_changes_nothing(served):
    model, server, client = served
    assert client.read_holding_registers(0, count=2, device_id=DEV).registers == [0, 0]
    _spray(client, model)
    time.sleep(0.6)
    assert model.snapshot()["valve_open"] and model.snapshot()["motor_on"]
    assert server.state()["watchdog"]["trips"] == 0


def test_requests_keep_the_watchdog_alive_and_silence_trips_it(served):
    model, server, client = served
    assert not client.write_register(1, 200, device_id=DEV).isError()          # 200 ms
    assert client.read_holding_registers(1, count=1, device_id=DEV).registers == [200]
    _spray(client, model)
    # regular traffic (reads of any table) refreshes it: 1 s of polls at 10 Hz, still spraying
    end = time.monotonic() + 1.0
    while time.monotonic() < end:
        assert not client.read_coils(0, count=2, device_id=DEV).isError()
        last_request = time.time()
        time.sleep(0.1)
    assert model.snapshot()["valve_open"] and model.snapshot()["motor_on"]
    assert server.state()["watchdog"]["trips"] == 0
    # silence: the device stops itself, valve first, within timeout + check period (+ scheduling slack)
    deadline = time.monotonic() + 2.0
    while time.monotonic() < deadline and (model.snapshot()["valve_open"] or model.snapshot()["motor_on"]):
        time.sleep(0.01)
    state = server.state()
    assert not state["valve_open"] and not state["motor_on"], state
    trip = [e for e in state["history"] if e["cause"] == "watchdog"]
    assert [(e["what"], e["value"]) for e in trip] == [("valve_open", False), ("motor_on", False)]
    assert 0.2 <= trip[0]["wall"] - last_request <= 0.2 + 0.25, (trip, last_request)
    assert state["watchdog"]["tripped"] and state["watchdog"]["trips"] == 1
    # the next client sees why: status bit 4, discrete input 4, the trip counter
    assert _status(client) == {"tripped": True, "trips": 1, "valve_open": False, "motor_running": False}
    assert client.read_discrete_inputs(4, count=1, device_id=DEV).bits[0] is True
    # it trips once per silence, and stays latched until the timeout is written again
    time.sleep(0.5)
    assert server.state()["watchdog"]["trips"] == 2               # the read above ended the first silence
    assert not client.write_register(1, 200, device_id=DEV).isError()
    assert _status(client)["tripped"] is False and _status(client)["trips"] == 2
    # nothing restarted by itself
    assert not model.snapshot()["motor_on"]


def test_watchdog_trips_while_the_link_is_dropped(served):
    model, server, client = served
    client.write_register(1, 300, device_id=DEV)
    _spray(client, model)
    server.drop_link(duration=None, mode="silent")         # requests held: they never reach the device
    t0 = time.monotonic()
    try:
        client.read_input_registers(0, count=1, device_id=DEV)
    except Exception:
        pass
    while time.monotonic() - t0 < 2.0 and model.snapshot()["motor_on"]:
        time.sleep(0.01)
    assert not model.snapshot()["motor_on"] and not model.snapshot()["valve_open"]
    assert server.state()["watchdog"]["tripped"]
    server.restore_link()


def test_bad_watchdog_values_are_refused_and_nothing_is_half_applied(served):
    model, server, client = served
    for value in (1, 49, 60001):
        rr = client.write_register(1, value, device_id=DEV)
        assert rr.isError() and rr.exception_code == 3, value
    rr = client.write_registers(0, [300, 10], device_id=DEV)           # good set-point, bad timeout
    assert rr.isError() and rr.exception_code == 3
    assert client.read_holding_registers(0, count=2, device_id=DEV).registers == [0, 0]
    assert not client.write_registers(0, [300, 60000], device_id=DEV).isError()
    assert client.read_holding_registers(0, count=2, device_id=DEV).registers == [300, 60000]
    assert not client.write_register(1, 0, device_id=DEV).isError()           # off again
    assert server.state()["watchdog"]["timeout_ms"] == 0
