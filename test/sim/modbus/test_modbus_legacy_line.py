"""Compressor Modbus stand-in on both pymodbus lines: 3.16 (this environment) and 3.6.9 (Noetic's Python 3.8 line).

One scenario (:func:`run_scenario`) drives ``CompressorServer`` with a real pymodbus TCP client of the installed
version: set pressure and reach it, spray valve, overpressure fault and reset, exception 2 for addresses outside
the map, exception 3 for a set-point out of range, exception 4 for another unit id, ``close`` / ``silent`` /
timed link drops and recovery, bind errors. It returns what the device answered (``semantics``, compared
with :data:`EXPECTED_SEMANTICS` on both lines, so both lines are shown to answer alike) and what the client
library did (``client``: keyword names, answer classes, exceptions on link loss, reconnect behaviour), which the
tests print for the bridge's owner.

* pymodbus 3.16: the scenario runs in-process.
* pymodbus 3.6.9: a second virtual environment (``$LOCEM_HOME/venv-pymodbus36``, default
  ``~/.cache/locem_bridge/venv-pymodbus36``, made once from /usr/bin/python3 with
  ``pip install pymodbus==3.6.9 numpy PyYAML`` and reused) runs this file as a script with ``PYTHONPATH=src``.
  The test is skipped only when that install fails because PyPI cannot be reached.

This module imports only the standard library at module level, so the 3.6.9 environment (no pytest) can run it.
"""
from __future__ import annotations

import argparse
import copy
import fcntl
import inspect
import json
import os
import shutil
import subprocess
import sys
import time
import traceback
from typing import Any, Callable, Dict, List, Optional

DEV = 1
REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
LEGACY_VERSION = "3.6.9"
LEGACY_PACKAGES = ["pymodbus==%s" % LEGACY_VERSION, "numpy", "PyYAML"]

# What the device answers, from the register map of locem_bridge.sim.modbus.compressor (identical on both lines).
EXPECTED_SEMANTICS: List[List[Any]] = [
    ["motor off: pressure", 0.0],
    ["settled: discrete inputs (running, valve, in range, fault)", [True, False, True, False]],
    ["settled: holding register 0 (cbar)", [450]],
    ["settled: fault code, status bits", [0, 0b0101]],
    ["settled: coils 0..2", [True, False, False]],
    ["valve open: coil 1 alone", [True]],
    ["valve open: discrete inputs", [True, True, True, False]],
    ["valve open: spraying", True],
    ["valve open: status bits", 0b0111],
    ["overpressure: fault code", 1],
    ["overpressure: discrete inputs (running, fault)", [False, True]],
    ["fault reset: answer is an error", False],
    ["fault reset: fault code", 0],
    ["fault reset: motor running again", True],
    ["bits past the map end read 0: discrete inputs 4..7 of 0..7", [False, False, False, False]],
    ["read holding 5: exception", 2],
    ["read input 2..6: exception", 2],
    ["write coil 7: exception", 2],
    ["read coil 40: exception", 2],
    ["read discrete input 5: exception", 2],
    ["write coils 1..3: exception", 2],
    ["write holding 0..2: exception", 2],
    ["set-point 50 bar: exception", 3],
    ["set-point 50 bar (fc 16): exception", 3],
    ["unit id 2: exception", 4],
    ["refused requests left the set-point (bar)", 4.5],
    ["close drop: link state", "dropped_close"],
    ["close drop: request fails", True],
    ["close drop: served again after restore_link", True],
    ["silent drop: link state", "dropped_silent"],
    ["silent drop: request fails", True],
    ["silent drop: served again after restore_link", True],
    ["timed drop: back by itself, link state", "up"],
    ["second server on the same port: refused with", "DeviceStandInError"],
]


# --------------------------------------------------------------------------------------------- the scenario
def _outcome(call: Callable[[], Any]) -> Dict[str, Any]:
    """Run one client call; describe what came back (answer or raised exception) and how long it took."""
    t0 = time.monotonic()
    try:
        reply = call()
    except Exception as exc:  # the library's behaviour is what we record
        return {"raised": "%s.%s" % (type(exc).__module__, type(exc).__name__), "ok": False,
                "ms": round((time.monotonic() - t0) * 1000)}
    error = bool(reply.isError())
    return {"returned": "%s.%s" % (type(reply).__module__, type(reply).__name__), "ok": not error,
            "exception_code": getattr(reply, "exception_code", None) if error else None,
            "ms": round((time.monotonic() - t0) * 1000)}


def run_scenario(host: str, port: int, comp_cfg: Dict[str, Any], log: Callable[[str], None] = lambda s: None
                 ) -> Dict[str, Any]:
    """Drive the stand-in with the installed pymodbus client; raise AssertionError on a wrong answer."""
    import pymodbus
    from pymodbus.client import ModbusTcpClient

    from locem_bridge.sim.modbus import modbus_server
    from locem_bridge.sim.clock import SimClock
    from locem_bridge.sim.modbus.compressor import CompressorModel
    from locem_bridge.sim.errors import DeviceStandInError

    semantics: List[List[Any]] = []
    client_facts: Dict[str, Any] = {}
    out = {"pymodbus": pymodbus.__version__, "python": sys.version.split()[0],
           "server_class": modbus_server.CompressorServer.__name__,
           "legacy_api": modbus_server.LEGACY_API, "semantics": semantics, "client": client_facts}

    def note(step: str, value: Any) -> None:
        semantics.append([step, value])
        log("%s: %r" % (step, value))

    read_params = inspect.signature(ModbusTcpClient.read_input_registers).parameters
    kw = "device_id" if "device_id" in read_params else "slave"
    client_facts["unit keyword"] = kw
    client_facts["unit keyword default"] = read_params[kw].default
    client_facts["count parameter kind"] = read_params["count"].kind.name
    init_params = inspect.signature(ModbusTcpClient.__init__).parameters
    client_facts["ModbusTcpClient.__init__ named parameters"] = [
        n for n, p in init_params.items() if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY) and n != "self"]
    ids = {kw: DEV}

    clock = SimClock(time_scale=10.0)                   # tau = 2 s sim -> 0.2 s wall
    model = CompressorModel(copy.deepcopy(comp_cfg), clock.now)
    server = modbus_server.CompressorServer(model, host, port, DEV)
    server.start()
    client = ModbusTcpClient(host, port=port, timeout=0.5, retries=0)
    try:
        assert client.connect(), "client cannot connect to the stand-in on %s:%d" % (host, port)

        def regs(address: int, count: int) -> List[int]:
            rr = client.read_input_registers(address, count=count, **ids)
            assert not rr.isError(), rr
            return list(rr.registers)

        def dis() -> List[bool]:
            rr = client.read_discrete_inputs(0, count=4, **ids)
            assert not rr.isError(), rr
            return list(rr.bits[:4])

        def wait(cond: Callable[[], bool], timeout: float, what: str) -> None:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                if cond():
                    return
                time.sleep(0.05)
            raise AssertionError("%s not reached within %.1f s (model %r)" % (what, timeout, model.snapshot()))

        def code(rr: Any) -> Optional[int]:
            return rr.exception_code if rr.isError() else None

        # -- set pressure and reach it ---------------------------------------------------------------------
        assert not client.write_register(0, 450, **ids).isError()                      # 4.50 bar
        time.sleep(0.2)
        note("motor off: pressure", regs(0, 1)[0] / 100.0)
        assert not client.write_coil(0, True, **ids).isError()
        wait(lambda: abs(regs(0, 1)[0] - 450) <= 2, 5.0, "4.50 bar")
        note("settled: discrete inputs (running, valve, in range, fault)", dis())
        note("settled: holding register 0 (cbar)", list(client.read_holding_registers(0, count=1, **ids).registers))
        r = regs(0, 4)
        assert r[1] > 0, "no motor current while running: %r" % r
        note("settled: fault code, status bits", r[2:])
        note("settled: coils 0..2", list(client.read_coils(0, count=3, **ids).bits[:3]))
        # -- spray valve -----------------------------------------------------------------------------------
        assert not client.write_coil(1, True, **ids).isError()
        wait(lambda: abs(regs(0, 1)[0] - 350) <= 3, 5.0, "3.50 bar with the valve open")
        note("valve open: coil 1 alone", list(client.read_coils(1, count=1, **ids).bits[:1]))
        note("valve open: discrete inputs", dis())
        note("valve open: spraying", model.spraying())
        note("valve open: status bits", regs(3, 1)[0])
        assert not client.write_coil(1, False, **ids).isError()
        # -- overpressure fault and reset ------------------------------------------------------------------
        model.inject_overpressure()
        wait(lambda: regs(2, 1)[0] != 0, 5.0, "overpressure fault")
        note("overpressure: fault code", regs(2, 1)[0])
        d = dis()
        note("overpressure: discrete inputs (running, fault)", [d[0], d[3]])
        wait(lambda: regs(0, 1)[0] < model.overpressure_limit * 100 - 50, 5.0, "pressure below the limit")
        reset = client.write_coil(2, True, **ids)
        client_facts["write_coil(2, True) answer"] = {"class": type(reset).__name__,
                                                      "value": getattr(reset, "value", None),
                                                      "bits": list(getattr(reset, "bits", []) or [])}
        note("fault reset: answer is an error", reset.isError())
        note("fault reset: fault code", regs(2, 1)[0])
        note("fault reset: motor running again", dis()[0])
        wait(lambda: regs(2, 1)[0] == 0 and dis()[0], 2.0, "motor running after reset")
        d8 = list(client.read_discrete_inputs(0, count=8, **ids).bits[:8])
        assert d8[0] is True and d8[3] is False, d8                   # running, no fault
        note("bits past the map end read 0: discrete inputs 4..7 of 0..7", d8[4:])
        # -- refused requests ------------------------------------------------------------------------------
        refused0 = server.refused
        bad = client.read_holding_registers(5, count=1, **ids)
        client_facts["exception answer"] = {"class": "%s.%s" % (type(bad).__module__, type(bad).__name__),
                                            "isError": bad.isError(), "exception_code": bad.exception_code,
                                            "function_code": bad.function_code}
        note("read holding 5: exception", code(bad))
        note("read input 2..6: exception", code(client.read_input_registers(2, count=5, **ids)))
        note("write coil 7: exception", code(client.write_coil(7, True, **ids)))
        note("read coil 40: exception", code(client.read_coils(40, count=1, **ids)))
        note("read discrete input 5: exception", code(client.read_discrete_inputs(5, count=1, **ids)))
        note("write coils 1..3: exception", code(client.write_coils(1, [True, False, True], **ids)))
        note("write holding 0..2: exception", code(client.write_registers(0, [100, 200, 300], **ids)))
        note("set-point 50 bar: exception", code(client.write_register(0, 5000, **ids)))
        note("set-point 50 bar (fc 16): exception", code(client.write_registers(0, [5000], **ids)))
        note("unit id 2: exception", code(client.read_input_registers(0, count=1, **{kw: DEV + 1})))
        note("refused requests left the set-point (bar)", model.setpoint)
        assert server.refused - refused0 == 9, "refused counted %d, expected 9" % (server.refused - refused0)
        assert list(client.read_holding_registers(0, count=1, **ids).registers) == [450]   # still serving

        # -- link drops ------------------------------------------------------------------------------------
        def read() -> Any:
            return client.read_input_registers(0, count=1, **ids)

        def recovers(timeout: float) -> bool:
            deadline = time.monotonic() + timeout
            while time.monotonic() < deadline:
                try:
                    client.close()
                    if client.connect() and not read().isError():
                        return True
                except Exception:
                    pass
                time.sleep(0.05)
            return False

        for mode in ("close", "silent"):
            assert not read().isError()
            server.drop_link(duration=None, mode=mode)
            note("%s drop: link state" % mode, server.link_state)
            first = _outcome(read)
            second = _outcome(read)
            client_facts["%s drop: 1st request while down" % mode] = first
            client_facts["%s drop: 2nd request while down" % mode] = second
            client_facts["%s drop: connected flag while down" % mode] = bool(getattr(client, "connected", None))
            note("%s drop: request fails" % mode, not first["ok"] and not second["ok"])
            server.restore_link()
            time.sleep(0.1)
            # what the same client object does next, without close()/connect()
            after = [_outcome(read) for _ in range(3)]
            client_facts["%s drop: 3 requests after restore, no explicit reconnect" % mode] = after
            note("%s drop: served again after restore_link" % mode, recovers(5.0))
        t0 = time.monotonic()
        server.drop_link(duration=0.6, mode="close")
        assert server.link_state == "dropped_close"
        assert recovers(5.0), "timed close drop did not come back"
        assert time.monotonic() - t0 >= 0.5, "link came back before its duration"
        note("timed drop: back by itself, link state", server.link_state)
        # -- lifecycle -------------------------------------------------------------------------------------
        twin = modbus_server.CompressorServer(model, host, port, DEV)
        try:
            twin.start(timeout=3.0)
            note("second server on the same port: refused with", "nothing")
            twin.stop()
        except DeviceStandInError as exc:
            note("second server on the same port: refused with", type(exc).__name__)
            assert "%s:%d" % (host, port) in str(exc), str(exc)
        try:
            server.start()
            raise AssertionError("start() twice did not raise")
        except DeviceStandInError:
            pass
    finally:
        client.close()
        server.stop()
        server.stop()                                   # idempotent
    assert server.link_state == "down"
    return out


def _print_facts(out: Dict[str, Any]) -> None:
    print("\npymodbus %s (python %s), server class %s" % (out["pymodbus"], out["python"], out["server_class"]))
    for key, value in out["client"].items():
        print("  %-60s %s" % (key, json.dumps(value)))


def _compare(out: Dict[str, Any]) -> None:
    got = {step: value for step, value in out["semantics"]}
    want = {step: value for step, value in EXPECTED_SEMANTICS}
    wrong = {k: (got.get(k, "<missing>"), v) for k, v in want.items() if got.get(k, "<missing>") != v}
    assert not wrong, "pymodbus %s answers differ (got, expected): %r" % (out["pymodbus"], wrong)
    assert [s for s, _ in out["semantics"]] == [s for s, _ in EXPECTED_SEMANTICS]


# --------------------------------------------------------------------------------- the 3.6.9 environment
_NETWORK_SIGNS = ("NewConnectionError", "Failed to establish a new connection", "Temporary failure in name resolution",
                  "Name or service not known", "Network is unreachable", "No route to host", "ConnectTimeoutError",
                  "Read timed out", "ProxyError", "Could not fetch URL", "Connection refused", "SSLError")


def _cache_home() -> str:
    if os.environ.get("LOCEM_HOME"):
        return os.environ["LOCEM_HOME"]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "locem_bridge")


def _venv_ok(python: str) -> bool:
    if not os.access(python, os.X_OK):
        return False
    probe = subprocess.run([python, "-c", "import pymodbus, yaml; print(pymodbus.__version__)"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=60)
    return probe.returncode == 0 and probe.stdout.strip() == LEGACY_VERSION


def legacy_python(skip: Callable[[str], None]) -> str:
    """Interpreter of the pymodbus 3.6.9 venv, created on first use (under a file lock, bounded in time)."""
    home = _cache_home()
    os.makedirs(home, exist_ok=True)
    venv = os.path.join(home, "venv-pymodbus36")
    python = os.path.join(venv, "bin", "python")
    marker = os.path.join(venv, ".locem-pymodbus36")
    with open(os.path.join(home, "venv-pymodbus36.lock"), "w") as lock:
        deadline = time.monotonic() + 600.0
        while True:
            try:
                fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise AssertionError("another run holds %s.lock for more than 600 s" % venv)
                time.sleep(0.5)
        if os.path.isfile(marker) and _venv_ok(python):
            return python
        shutil.rmtree(venv, ignore_errors=True)
        made = subprocess.run(["/usr/bin/python3", "-m", "venv", venv], stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, universal_newlines=True, timeout=180)
        assert made.returncode == 0, "cannot create %s: %s" % (venv, made.stdout[-2000:])
        pip = subprocess.run([python, "-m", "pip", "install", "-q", "--disable-pip-version-check", "--timeout", "30",
                              "--retries", "2"] + LEGACY_PACKAGES, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             universal_newlines=True, timeout=600)
        if pip.returncode != 0:
            shutil.rmtree(venv, ignore_errors=True)
            signs = [line.strip() for line in pip.stdout.splitlines() if any(s in line for s in _NETWORK_SIGNS)]
            if signs:
                skip("PyPI unreachable, cannot install %s into %s: %s" % (" ".join(LEGACY_PACKAGES), venv, signs[0]))
            raise AssertionError("pip install %s failed:\n%s" % (" ".join(LEGACY_PACKAGES), pip.stdout[-3000:]))
        assert _venv_ok(python), "%s does not import pymodbus %s after the install" % (venv, LEGACY_VERSION)
        with open(marker, "w") as handle:
            handle.write(" ".join(LEGACY_PACKAGES) + "\n")
        return python


# ------------------------------------------------------------------------------------------------- tests
def test_pymodbus_316_line_in_process(robot_cfg, port):
    from locem_bridge.sim.modbus import modbus_server

    assert not modbus_server.LEGACY_API
    assert modbus_server.CompressorServer is modbus_server.Pymodbus316CompressorServer
    out = run_scenario("127.0.0.1", port, robot_cfg["robot"]["compressor"])
    _print_facts(out)
    assert out["client"]["unit keyword"] == "device_id"
    _compare(out)


def test_pymodbus_369_line_in_a_second_venv(robot_cfg, port):
    import pytest

    python = legacy_python(pytest.skip)
    env = dict(os.environ, PYTHONPATH=os.path.join(REPO, "src"))
    for var in ("VIRTUAL_ENV", "PYTHONHOME", "ROS_PACKAGE_PATH"):
        env.pop(var, None)
    proc = subprocess.run([python, os.path.abspath(__file__), "--port", str(port)], cwd=REPO, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, universal_newlines=True, timeout=180)
    assert proc.returncode == 0, "scenario failed on pymodbus %s:\n%s" % (LEGACY_VERSION, proc.stderr[-4000:])
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    _print_facts(out)
    assert out["pymodbus"] == LEGACY_VERSION
    assert out["legacy_api"] is True and out["server_class"] == "LegacyCompressorServer"
    assert out["client"]["unit keyword"] == "slave"
    _compare(out)


def test_legacy_adapter_refuses_the_wrong_pymodbus_line():
    import pytest

    with pytest.raises(ImportError, match=r"needs pymodbus 3\.6\.x \(installed: 3\.16"):
        import locem_bridge.sim.modbus.modbus_legacy  # noqa: F401


# ----------------------------------------------------------------------------------- script entry point
def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description="compressor Modbus stand-in scenario with the installed pymodbus")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, required=True)
    parser.add_argument("--verbose", action="store_true", help="log each answer to stderr")
    args = parser.parse_args(argv)
    import logging

    logging.basicConfig(level=logging.ERROR, stream=sys.stderr)
    from locem_bridge.sim.config import load_robot

    try:
        out = run_scenario(args.host, args.port, load_robot()["robot"]["compressor"],
                           log=(lambda s: print(s, file=sys.stderr)) if args.verbose else (lambda s: None))
    except Exception:
        traceback.print_exc()
        return 1
    print(json.dumps(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
