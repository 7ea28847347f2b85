"""Compressor stand-in: a real pymodbus client against the Modbus TCP server and its pressure model."""
import copy
import time

import pytest
from pymodbus.client import ModbusTcpClient

from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.compressor import CompressorModel
from locem_bridge.sim.modbus_server import CompressorServer

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
