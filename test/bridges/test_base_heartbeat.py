"""The base drives stop by themselves when their master dies: the drive stand-ins consume the base bridge's
heartbeat (0x1016), the bridge (canopen master, python-can ``udp_multicast``) runs in a child process killed with
``kill -9`` while the base drives at speed."""
import copy
import json
import os
import signal
import subprocess
import sys
import time

from locem_bridge.bridges.cia402_base import Cia402Base
from locem_bridge.bridges.config import resolve_path
from locem_bridge.sim.clock import SimClock
from locem_bridge.sim.can.drives import ENABLED, QUICK_STOP, DriveSet

from bridge_rigs import free_port, wait_until

_MASTER = """
import json, sys, time
from locem_bridge.bridges.cia402_base import Cia402Base
cfg, eds = json.loads(sys.argv[1]), sys.argv[2]
base = Cia402Base(cfg, eds)
base.start()
assert base.wait_ready(20.0), base.health()
base.set_velocity(0.3, 0.0, 0.0, hold=600.0)
print("driving", flush=True)
time.sleep(600)
"""


def _speeds(drives):
    out = []
    for d in drives.drives:
        with d._lock:
            d.update()
            out.append((d.state, d.velocity))
    return out


def test_drives_stop_when_their_master_is_killed_and_a_fresh_master_enables_them_again(robot):
    base_cfg = copy.deepcopy(robot["base"])
    base_cfg["drives"]["can"] = {"interface": "udp_multicast", "channel": "239.74.172.%d" % (1 + os.getpid() % 250),
                                 "port": free_port()}
    eds = resolve_path(robot, base_cfg["eds"])
    drives = DriveSet(base_cfg["drives"], eds, SimClock(1.0).now)
    drives.start()
    src = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    child = subprocess.Popen([sys.executable, "-c", _MASTER, json.dumps(base_cfg), eds], stdout=subprocess.PIPE,
                             env=env, text=True)
    try:
        assert child.stdout.readline().strip() == "driving"
        assert wait_until(lambda: all(s == ENABLED and abs(v) > 1.0 for s, v in _speeds(drives)), timeout=5.0), \
            _speeds(drives)
        assert all(d.consumer == (127, 0.5) for d in drives.drives), [d.consumer for d in drives.drives]
        time.sleep(1.0)                                     # the master's heartbeat keeps them going
        assert all(d.consumer_trips == 0 for d in drives.drives)
        killed = time.monotonic()
        os.kill(child.pid, signal.SIGKILL)
        child.wait(5.0)
        stopped = wait_until(lambda: all(s == QUICK_STOP and v == 0.0 for s, v in _speeds(drives)), timeout=5.0)
        elapsed = time.monotonic() - killed
        assert stopped, _speeds(drives)
        assert all(d.consumer_trips == 1 for d in drives.drives)
        # 0.5 s consumer timeout + braking at stop_deceleration + one TPDO cycle; loaded machine slack
        assert elapsed <= 1.0, elapsed
        # a fresh master (the respawned LOCEM) enables them again, standing still
        base = Cia402Base(base_cfg, eds)
        base.start()
        try:
            assert base.wait_ready(20.0), base.health()
            assert wait_until(lambda: all(s == ENABLED and v == 0.0 for s, v in _speeds(drives)), timeout=3.0), \
                _speeds(drives)
        finally:
            base.close()
    finally:
        if child.poll() is None:
            child.kill()
            child.wait(5.0)
        drives.stop()
