"""The arm stops when its ur_rtde control client vanishes: the controller's RTDE watchdog (``setWatchdog``) against
the UR stand-in, the client a real ur_rtde RTDEControlInterface in a child process killed with ``kill -9``."""
import os
import signal
import subprocess
import sys
import time

import pytest

from ur_client_support import eventually

pytest.importorskip("rtde_control")

pytestmark = pytest.mark.slow

_CLIENT = """
import sys, time
import rtde_control
c = rtde_control.RTDEControlInterface(sys.argv[1])
hz = float(sys.argv[2])
if hz > 0:
    assert c.setWatchdog(hz)
q = [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0]
q[0] = 3.0                                  # a long, slow joint move: 3 rad at 0.05 rad/s
assert c.moveJ(q, 0.05, 1.0, True)
print("moving", flush=True)
while True:                                 # kicks at 20 Hz, as LOCEM's state polls do at 50 Hz
    if hz > 0:
        c.kickWatchdog()
    time.sleep(0.05)
"""


def _client(address, hz):
    return subprocess.Popen([sys.executable, "-c", _CLIENT, address, repr(hz)], stdout=subprocess.PIPE, text=True)


def _kill(child):
    if child.poll() is None:
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5.0)


def test_kicks_keep_the_program_running_and_a_killed_client_stops_the_arm_within_the_watchdog(ur_standin):
    child = _client(ur_standin.address, 2.0)                 # 2 Hz: stop 0.5 s after the last kick
    try:
        assert child.stdout.readline().strip() == "moving"
        state = ur_standin.get_state()
        assert state["rtde_watchdog"] == ["input_int_register_0", 2.0], state
        time.sleep(1.5)                                      # three watchdog periods of kicks
        state = ur_standin.get_state()
        assert state["moving"] and state["program"] == "rtde_control" and state["watchdog_trips"] == 0, state
        killed = time.monotonic()
        _kill(child)
        stopped = eventually(lambda: (lambda s: s if s["program"] is None and not s["moving"] else None)(
            ur_standin.get_state()), timeout=5.0)
        elapsed = time.monotonic() - killed
    finally:
        _kill(child)
    assert stopped, ur_standin.get_state()
    assert stopped["watchdog_trips"] == 1 and "RTDE watchdog" in stopped["last_error"], stopped
    assert stopped["runtime_state_name"] == "STOPPED" and stopped["rtde_watchdog"] is None
    # 0.5 s of watchdog + braking from 0.05 rad/s; measured through a child-process proxy on a busy machine
    assert elapsed <= 1.5, elapsed


def test_without_the_watchdog_a_killed_client_leaves_the_arm_moving(ur_standin):
    child = _client(ur_standin.address, 0.0)
    try:
        assert child.stdout.readline().strip() == "moving"
        _kill(child)
        time.sleep(1.5)
        state = ur_standin.get_state()
    finally:
        _kill(child)
    assert state["moving"] and state["program"] == "rtde_control" and state["watchdog_trips"] == 0, state
