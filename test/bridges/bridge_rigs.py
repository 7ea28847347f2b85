"""Stand-in rigs and helpers shared by the bridge tests and the benchmark (not a test module)."""
import itertools
import os
import socket
import time

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
ROBOT_YAML = os.path.join(REPO, "config", "robots", "rbkairos_ur10e.yaml")
#: a tool changer section for the shipped robot (overrides), the tests' own
TOOL_CHANGER_RACK = os.path.join(REPO, "test", "data", "tool_changer_rack.yaml")

_counter = itertools.count(1)


def free_port(host="127.0.0.1"):
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def wait_until(predicate, timeout=5.0, period=0.01):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(period)
    return predicate()


class CompressorRig:
    """The compressor stand-in (model + pymodbus 3.16 server) on a free port, sim time scaled."""

    def __init__(self, robot, time_scale=10.0):
        from locem_bridge.sim.clock import SimClock
        from locem_bridge.sim.modbus.compressor import CompressorModel
        from locem_bridge.sim.modbus.modbus_server import CompressorServer
        self.clock = SimClock(time_scale)
        self.cfg = dict(robot["compressor"])
        self.cfg["port"] = free_port()
        self.model = CompressorModel(self.cfg, self.clock.now)
        self.server = CompressorServer(self.model, "127.0.0.1", self.cfg["port"], self.cfg["device_id"])
        self.server.start()

    def close(self):
        self.server.stop()




def _address_free(addr, ports=(29999, 30003, 30004)):
    for port in ports:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind((addr, port))
            except OSError:
                return False
    return True


def next_ur_address():
    """A loopback address whose three UR ports are free: 127.64.<pid-derived>.<counter>."""
    third = 1 + os.getpid() % 250
    for _ in range(250):
        n = next(_counter)
        addr = "127.64.%d.%d" % (third, 1 + (n - 1) % 250)
        if _address_free(addr):
            return addr
    raise RuntimeError("no free loopback address for a UR stand-in")


_PAYLOAD_READER = """
import json, sys
import rtde_receive
r = rtde_receive.RTDEReceiveInterface(sys.argv[1])
print(json.dumps({"mass": r.getPayload(), "cog": list(r.getPayloadCog())}))
r.disconnect()
"""


def rtde_payload(address, timeout=30.0):
    """The payload the UR controller at ``address`` reports in its RTDE outputs ``payload`` / ``payload_cog``, read
    by a plain ur_rtde RTDEReceiveInterface in a child process (ur_rtde holds the GIL while it connects, which
    would stall the in-process stand-ins of a rig)."""
    import json
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", _PAYLOAD_READER, address], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, universal_newlines=True, timeout=timeout, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def arm_cfg(robot, address):
    cfg = dict(robot["arm"])
    cfg["controller"] = dict(cfg["controller"], host=address)
    return cfg


class BaseRig:
    """The four CiA 402 drive stand-ins on a fresh python-can ``virtual`` channel plus the PyBullet world (ground
    truth of the base pose), sim time scaled."""

    def __init__(self, robot, site_cfg=None, time_scale=1.0, world=True):
        import copy
        import uuid
        from locem_bridge.sim.arm_source import KinematicArm
        from locem_bridge.sim.clock import SimClock
        from locem_bridge.sim.config import load_site
        from locem_bridge.sim.can.drives import DriveSet
        from locem_bridge.sim.world import World
        from locem_bridge.bridges.config import resolve_path
        self.cfg = copy.deepcopy(robot["base"])
        self.cfg["drives"]["can"] = {"interface": "virtual", "channel": "bridge-%s" % uuid.uuid4().hex[:8]}
        self.eds = resolve_path(robot, robot["base"]["eds"])
        self.clock = SimClock(time_scale)
        self.drives = DriveSet(self.cfg["drives"], self.eds, self.clock.now,
                               max_wheel_speed=self.cfg["limits"]["max_wheel_speed"])
        self.drives.start()
        self.world = None
        if world:
            site = copy.deepcopy(site_cfg or load_site())
            self.world = World(site, {"robot": robot}, self.clock, arm=KinematicArm(robot["arm"]["named_poses"]["stow"]),
                               drives=self.drives, gui=False)
            self.world.start()

    def still(self):
        return all(abs(v) < 1e-9 for v in self.drives.wheel_speeds())

    def close(self):
        if self.world is not None:
            self.world.close()
        self.drives.stop()


def last_motion(drives, t_from, t_to, step=0.001):
    """Ground truth of the wheels: sim time of the last instant in ``[t_from, t_to]`` (a grid of ``step`` s of sim
    time) at which any wheel of ``drives`` (a DriveSet) turned, from each drive's recorded motion segments
    (``Cia402Drive.states_at``, exact whatever the time scale); ``t_from`` when none turned after it. The true
    standstill lies within one ``step`` after the returned time."""
    assert 0.0 <= t_to - t_from <= 600.0, "last_motion over %r .. %r s sim: not a stop window" % (t_from, t_to)
    n = max(1, int(round((t_to - t_from) / step)))
    times = [t_from + (t_to - t_from) * k / n for k in range(n + 1)]
    last = t_from
    for d in drives.drives:
        for t, (v, _) in zip(times, d.states_at(times)):
            if abs(v) > 1e-9 and t > last:
                last = t
    return last


def sim_time_of(clock, wall_stamp):
    """Sim time of ``clock`` (a SimClock) at the wall-clock instant ``wall_stamp`` (``time.time()`` seconds)."""
    return clock.now() - clock.wall_to_sim(time.time() - wall_stamp)


class HeartbeatWatch:
    """A python-can listener on the rig's CAN channel that records when each drive's heartbeat (0x700 + node id)
    was last sent (the bus's send timestamp, wall clock ``time.time()``)."""

    def __init__(self, can_cfg):
        import threading
        import can
        self.last = {}
        self._bus = can.Bus(interface=can_cfg["interface"], channel=can_cfg["channel"], receive_own_messages=False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            msg = self._bus.recv(0.01)
            if msg is not None and 0x701 <= msg.arbitration_id <= 0x77F:
                self.last[msg.arbitration_id - 0x700] = msg.timestamp

    def close(self):
        self._stop.set()
        self._thread.join(1.0)
        self._bus.shutdown()


SHORT_WALL = os.path.join(os.path.dirname(os.path.abspath(__file__)), "sites", "short_wall.yaml")


class StandInArmSource:
    """The world's view of the arm: joint positions and digital outputs read from the UR stand-in process
    (what the PyBullet world mirrors; the bridge under test talks RTDE to the same stand-in)."""

    def __init__(self, standin):
        self.standin = standin

    def joint_positions(self):
        return self.standin.get_joint_positions()

    def digital_output(self, index):
        return bool(self.standin.get_standard_digital_outputs()[index])


def robot_with_changer(port=None):
    """The shipped robot plus the tests' tool changer section (test/data/tool_changer_rack.yaml), on ``port``
    (default: a free one)."""
    import yaml
    from locem_bridge.bridges.config import load_robot_config
    with open(TOOL_CHANGER_RACK) as handle:
        overrides = yaml.safe_load(handle)
    overrides["tool_changer"]["port"] = port or free_port()
    return load_robot_config(ROBOT_YAML, overrides)


class ToolChangerRig:
    """The tool changer stand-in (model + Modbus server) bound to a PyBullet world whose arm is a settable
    :class:`~locem_bridge.sim.arm_source.KinematicArm` (the flange goes to a rack slot by setting its joints)."""

    def __init__(self, robot, time_scale=10.0):
        from locem_bridge.sim.arm_source import KinematicArm
        from locem_bridge.sim.clock import SimClock
        from locem_bridge.sim.config import load_site
        from locem_bridge.sim.modbus.tool_changer import ToolChangerModel, WorldRack, tool_changer_server
        from locem_bridge.sim.world import World
        self.cfg = robot["tool_changer"]
        self.clock = SimClock(time_scale)
        self.arm = KinematicArm(robot["arm"]["named_poses"]["home"])
        self.world = World(load_site(SHORT_WALL), {"robot": robot}, self.clock, arm=self.arm, gui=False)
        self.model = ToolChangerModel(self.cfg, self.clock.now, WorldRack(self.world, self.cfg))
        self.server = tool_changer_server(self.model, "127.0.0.1", self.cfg["port"], self.cfg["device_id"])
        self.server.start()

    def to_slot(self, tool):
        self.arm.set_joint_positions(self.cfg["rack"][tool]["pose"])

    def close(self):
        self.server.stop()
        self.world.close()


class WorksiteRig:
    """Every stand-in the wall commands need, on one sim clock: UR controller (child process), compressor
    (Modbus server), four drives (virtual CAN) and the PyBullet world measuring the outcome.

    ``arm_in_process``: the UR controller runs in this process, as in the worksite stand-in of a launch, and the
    world sees every control cycle (where the tool switched along the path, to the controller's 2 ms); in a child
    process the world reads the arm at its own steps (50 Hz: 8 cm of travel at 0.4 m/s and time scale 10)."""

    def __init__(self, robot, site_path=SHORT_WALL, time_scale=4.0, overrides=None, arm_in_process=False):
        import copy
        import uuid
        from locem_bridge.sim.clock import SimClock
        from locem_bridge.sim.modbus.compressor import CompressorModel
        from locem_bridge.sim.config import load_site
        from locem_bridge.sim.can.drives import DriveSet
        from locem_bridge.sim.modbus.modbus_server import CompressorServer
        from locem_bridge.sim.ur.process import StandInProcess
        from locem_bridge.sim.world import World
        from locem_bridge.bridges.config import resolve_path
        self.site_path = site_path
        self.site = load_site(site_path)
        self.clock = SimClock(time_scale)
        from locem_bridge.common.config_keys import deep_merge
        self.robot = copy.deepcopy(robot)
        if overrides:                          # the addresses the LOCEM node under test was given
            self.robot = deep_merge(self.robot, overrides)
        else:
            self.robot["arm"]["controller"]["host"] = next_ur_address()
            self.robot["compressor"]["port"] = free_port()
            self.robot["base"]["drives"]["can"] = {"interface": "virtual",
                                                   "channel": "wall-%s" % uuid.uuid4().hex[:8]}
        self.address = self.robot["arm"]["controller"]["host"]
        # model ur10 / ur5: the kinematics of the URDF the world draws (robot.arm.description), so both agree
        model = "ur5" if str(robot["arm"].get("model", "")).startswith("ur5") else "ur10"
        if arm_in_process:
            from locem_bridge.sim.arm_source import UrArmSource
            from locem_bridge.sim.ur import UrControllerStandIn
            self.standin = UrControllerStandIn(self.address, time_scale=time_scale, model=model,
                                               q0=robot["arm"]["named_poses"]["home"]).start()
            arm_source = UrArmSource(self.standin)
        else:
            self.standin = StandInProcess(self.address, time_scale=time_scale, model=model,
                                          q0=robot["arm"]["named_poses"]["home"]).start()
            arm_source = StandInArmSource(self.standin)
        self.model = CompressorModel(self.robot["compressor"], self.clock.now)
        self.server = CompressorServer(self.model, "127.0.0.1", self.robot["compressor"]["port"],
                                       self.robot["compressor"]["device_id"])
        self.server.start()
        self.drives = DriveSet(self.robot["base"]["drives"], resolve_path(robot, robot["base"]["eds"]), self.clock.now,
                               max_wheel_speed=self.robot["base"]["limits"]["max_wheel_speed"])
        self.drives.start()
        self.world = World(copy.deepcopy(self.site), {"robot": self.robot}, self.clock,
                           arm=arm_source, drives=self.drives, compressor=self.model, gui=False)
        self.changer = self.changer_server = None
        if "tool_changer" in self.robot:          # the tool changer stand-in, its rack on the world's arm
            from locem_bridge.sim.modbus.tool_changer import ToolChangerModel, WorldRack, tool_changer_server
            tc = self.robot["tool_changer"]
            self.changer = ToolChangerModel(tc, self.clock.now, WorldRack(self.world, tc))
            self.changer_server = tool_changer_server(self.changer, "127.0.0.1", tc["port"], tc["device_id"])
            self.changer_server.start()
        self.world.start()

    def running(self):
        """What is still running on any device (empty: nothing): arm motion, force mode, digital outputs on,
        spray valve open, compressor motor on, wheels turning."""
        state = self.standin.get_state()
        compressor = self.model.snapshot()
        out = []
        if state["moving"]:
            out.append("arm moving")
        if self.standin.get_force_mode() is not None:
            out.append("arm force mode")
        outputs = self.standin.get_standard_digital_outputs()
        if any(outputs):
            out.append("digital outputs %s" % [i for i, v in enumerate(outputs) if v])
        if compressor["valve_open"]:
            out.append("spray valve open")
        if compressor["motor_on"]:
            out.append("compressor motor on")
        speeds = self.drives.wheel_speeds()
        if any(abs(v) >= 1e-9 for v in speeds):
            out.append("wheels %s" % [round(v, 4) for v in speeds])
        return out

    def nothing_running(self):
        """No arm motion, no force mode, no digital output on, valve closed, compressor motor off, wheels still."""
        return not self.running()

    def area_coverage(self, wall_id, s_range, t_range):
        m = self.world.outcome.maps[wall_id]
        cells = m.thickness[(m.tc >= t_range[0]) & (m.tc <= t_range[1])][:, (m.sc >= s_range[0]) & (m.sc <= s_range[1])]
        return float((cells >= self.world.outcome.target).mean())

    def close(self):
        if self.changer_server is not None:
            self.changer_server.stop()
        self.world.close()
        self.drives.stop()
        self.server.stop()
        if hasattr(self.standin, "close"):
            self.standin.close()
        else:
            self.standin.stop()
