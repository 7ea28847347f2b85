"""Dashboard server (29999): the command set and answers of a PolyScope 5 controller."""
import re
import socket

import pytest

from locem_bridge.sim.ur import UrControllerStandIn


@pytest.fixture
def dash(ur_address):
    ctl = UrControllerStandIn(ur_address, time_scale=10.0).start()
    s = socket.create_connection((ur_address, 29999), timeout=2.0)
    f = s.makefile("rb")
    assert f.readline() == b"Connected: Universal Robots Dashboard Server\n"

    def ask(line: str) -> str:
        s.sendall(line.encode() + b"\n")
        return f.readline().decode().rstrip("\n")

    ask.ctl = ctl
    yield ask
    s.close()
    ctl.stop()


def test_identity_queries(dash):
    assert re.search(r"\d+\.\d+\.\d+\.\d+", dash("PolyscopeVersion"))
    assert dash("get serial number").isdigit()
    assert dash("get robot model") == "UR10"
    assert dash("is in remote control") == "true"
    assert dash("running") == "Program running: false"
    assert dash("programState") == "STOPPED <unnamed>"


def test_power_cycle_and_brakes(dash):
    assert dash("power off") == "Powering off"
    assert dash("robotmode") == "Robotmode: POWER_OFF"
    assert dash("brake release") == "Brake releasing"           # power comes on, then the brakes release
    assert dash("robotmode") == "Robotmode: RUNNING"
    assert dash("power off") == "Powering off"
    assert dash("power on") == "Powering on"
    assert dash("robotmode") == "Robotmode: IDLE"
    assert dash("brake release") == "Brake releasing"
    assert dash("robotmode") == "Robotmode: RUNNING"


def test_program_control_and_safety(dash):
    ctl = dash.ctl
    assert dash("play") == "Failed to execute: play"            # nothing loaded
    assert dash("pause") == "Failed to execute: pause"
    assert dash("stop") == "Stopped"
    ctl.inject_protective_stop("test")
    assert dash("safetymode") == "Safetymode: PROTECTIVE_STOP"
    assert dash("safetystatus") == "Safetystatus: PROTECTIVE_STOP"
    assert dash("unlock protective stop").startswith("Cannot unlock protective stop until 5s after occurrence.")
    with ctl.arm.lock:
        ctl.arm.motion_time += 5.0                               # 5 s of motion time later
    assert dash("unlock protective stop") == "Protective stop releasing"
    assert dash("safetystatus") == "Safetystatus: NORMAL"
    ctl.inject_emergency_stop("test")
    assert dash("safetystatus") == "Safetystatus: ROBOT_EMERGENCY_STOP"
    assert dash("close safety popup") == "closing safety popup"
    assert dash("safetystatus") == "Safetystatus: ROBOT_EMERGENCY_STOP"   # the button is still pressed
    ctl.release_emergency_stop()
    assert dash("close safety popup") == "closing safety popup"
    assert dash("safetystatus") == "Safetystatus: NORMAL"
    assert dash("robotmode") == "Robotmode: POWER_OFF"
    assert dash("popup hello") == "showing popup"
    assert dash("close popup") == "closing popup"
    assert dash("quit") == "Disconnected"
