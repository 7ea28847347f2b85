"""UrControllerStandIn: the public face of the UR controller stand-in (see the package docstring for the API)."""
import ipaddress
import logging
import threading
import time
from typing import Callable, List, Optional, Sequence, Tuple

import numpy as np

from .arm import ArmCore, ArmSnapshot
from .dashboard import Dashboard
from .errors import ConfigurationError
from .force import ContactProvider, PlaneContact
from .kinematics import ArmKinematics
from .servers import NetLoop

LOG = logging.getLogger("locem_bridge.sim.ur")

DASHBOARD_PORT, SCRIPT_PORT, RTDE_PORT = 29999, 30003, 30004
DEFAULT_Q = (0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0)


#: s of controller time the arm is moved by in one step (a cycle that catches up on many moves in several)
MAX_STEP_S = 0.05

class UrControllerStandIn:
    """A protocol-level UR e-Series controller on one loopback address (dashboard, script and RTDE servers).

    Lifecycle: construct (nothing is bound), :meth:`start` (binds the three ports, starts the I/O thread and the
    control thread), :meth:`stop` (closes every socket, joins both threads). ``start`` may be called again after
    ``stop``: the arm keeps its joint positions, IO and safety state, as a robot whose controller rebooted; the
    control program is gone (runtime STOPPED) and clients must ``reconnect()``.
    """

    def __init__(self, address: str = "127.0.0.1", time_scale: float = 1.0, model: str = "ur10e",
                 q0: Sequence[float] = DEFAULT_Q, control_rate: float = 500.0,
                 controller_version: Tuple[int, int, int, int] = (5, 11, 1, 108318),
                 serial_number: str = "20235500001", robot_model: str = "UR10",
                 ports: Optional[dict] = None) -> None:
        try:
            ip = ipaddress.ip_address(address)
        except ValueError:
            raise ConfigurationError("address %r is not an IPv4 address (e.g. 127.0.0.2)" % (address,))
        if ip.version != 4:
            raise ConfigurationError("address %r: only IPv4 addresses are supported" % (address,))
        if not (isinstance(time_scale, (int, float)) and np.isfinite(time_scale) and time_scale > 0):
            raise ConfigurationError("time_scale must be a finite number > 0 (1.0 = real time), got %r"
                                     % (time_scale,))
        if not (10.0 <= control_rate <= 1000.0):
            raise ConfigurationError("control_rate must be within [10, 1000] Hz, got %r" % (control_rate,))
        q0 = list(q0)
        if len(q0) != 6 or not all(np.isfinite(q0)):
            raise ConfigurationError("q0 must hold 6 finite joint positions in rad, got %r" % (q0,))
        self.address = address
        self.time_scale = float(time_scale)
        self.control_rate = float(control_rate)
        self.controller_version = tuple(int(v) for v in controller_version)
        self.polyscope_version = ".".join(str(v) for v in self.controller_version)
        self.ports = dict(dashboard=DASHBOARD_PORT, script=SCRIPT_PORT, rtde=RTDE_PORT)
        if ports:
            unknown = set(ports) - set(self.ports)
            if unknown:
                raise ConfigurationError("unknown port names %s (allowed: dashboard, script, rtde)" % sorted(unknown))
            self.ports.update(ports)
        self.kinematics = ArmKinematics(model)
        self.arm = ArmCore(self.kinematics, q0, serial_number=serial_number, control_rate=self.control_rate)
        self.dashboard = Dashboard(self.arm, self.polyscope_version, robot_model, self.arm.log_refused)
        self._net: Optional[NetLoop] = None
        self._thread: Optional[threading.Thread] = None
        self._stop_evt = threading.Event()
        self._cycles_before = 0      # cycles of earlier runs (the controller clock continues across restarts)
        self.overruns = 0
        self.skipped_cycles = 0
        self.cycle_count = 0

    # ------------------------------------------------------------------------------------------------ lifecycle
    @property
    def running(self) -> bool:
        return self._thread is not None

    def start(self) -> "UrControllerStandIn":
        """Bind the ports and start serving. Raises ListenError (address, port, reason) when a port is taken."""
        if self._thread is not None:
            return self
        net = NetLoop(self.address, self.ports, self.control_rate, self.controller_version,
                      dashboard_handler=self.dashboard.answer, script_handler=self._on_script,
                      input_handler=self.arm.apply_inputs, refuse=self.arm.log_refused)
        net.start()
        self._net = net
        self._stop_evt.clear()
        self._thread = threading.Thread(target=self._control_loop, name="ur-standin-ctl-%s" % self.address,
                                        daemon=True)
        self._thread.start()
        LOG.info("UR stand-in listening on %s (dashboard %d, script %d, RTDE %d), time scale %g",
                 self.address, self.ports["dashboard"], self.ports["script"], self.ports["rtde"], self.time_scale)
        return self

    def stop(self) -> None:
        """Close every socket and join the threads (idempotent). The running control program ends."""
        self._stop_evt.set()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        if self._net is not None:
            self._net.close()
            self._net = None
        with self.arm.lock:
            self.arm.stop_program()
            self.arm.motion = None
            self.arm.qd = np.zeros(6)

    def __enter__(self) -> "UrControllerStandIn":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # ------------------------------------------------------------------------------------------------ control loop
    def _control_loop(self) -> None:
        period = 1.0 / self.control_rate
        arm = self.arm
        stop = self._stop_evt
        nxt = time.perf_counter() + period
        tick = 0
        while not stop.is_set():
            delay = nxt - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            now = time.perf_counter()
            cycles = 1
            if now - nxt > 5 * period:
                # Fell far behind (machine busy): drop the missed cycles but stay on the period grid, so later
                # packages are on time again; the controller clock skips them too (visible in "timestamp").
                skipped = int((now - nxt) / period)
                self.overruns += 1
                self.skipped_cycles += skipped
                nxt += skipped * period
                tick += skipped
                cycles += skipped
            nxt += period
            # the arm moves on by the cycles the controller clock (RTDE "timestamp") counts, as a real
            # controller's exact cycles do: a cycle that woke up late and the ones that then catch up on the grid
            # share the time between them. Moved by each cycle's wall time instead, the arm ran ahead of the
            # stamps by every late cycle's delay: speeds a client measured from the stamps came out at up to 2.4
            # times the true one (at a time scale of 10 the valve opened in the turn before a lane)
            # (a long catch-up in steps of at most MAX_STEP_S: each step's motion is its clock's time)
            clock, left = (self._cycles_before + tick) * period, cycles * period
            try:
                while True:
                    step = min(left, MAX_STEP_S)
                    left -= step
                    arm.tick(step, self.time_scale, clock - left)
                    if left <= 1e-12:
                        break
            except Exception:
                LOG.exception("UR stand-in: control cycle failed")
            net = self._net
            if net is not None:
                values = arm.values
                for c in net.rtde_clients:
                    if c.started:
                        c.stream(values, tick)
            tick += 1
            self.cycle_count = tick
        self._cycles_before += tick

    def _on_script(self, text: str) -> None:
        self.arm.load_script(text)

    # ------------------------------------------------------------------------------------------------ world API
    def get_joint_positions(self) -> List[float]:
        """Actual joint positions (rad), shoulder_pan .. wrist_3."""
        with self.arm.lock:
            return self.arm.q.tolist()

    def get_joint_velocities(self) -> List[float]:
        """Actual joint velocities (rad/s of motion time)."""
        with self.arm.lock:
            return (self.arm.qd * self.arm.speed_fraction).tolist()

    def get_tcp_pose(self) -> List[float]:
        """Actual TCP pose [x, y, z, rx, ry, rz] in the arm base frame (current TCP offset applied)."""
        with self.arm.lock:
            return list(self.arm.values["actual_TCP_pose"])

    def get_tcp_offset(self) -> List[float]:
        with self.arm.lock:
            return self.kinematics.tcp_pose()

    def get_standard_digital_outputs(self) -> List[bool]:
        """Standard digital outputs DO0..DO7."""
        bits = self.arm.std_do
        return [bool(bits >> i & 1) for i in range(8)]

    def get_configurable_digital_outputs(self) -> List[bool]:
        bits = self.arm.conf_do
        return [bool(bits >> i & 1) for i in range(8)]

    def get_tool_digital_outputs(self) -> List[bool]:
        """Tool digital outputs TO0, TO1."""
        bits = self.arm.tool_do
        return [bool(bits >> i & 1) for i in range(2)]

    def set_standard_digital_input(self, index: int, value: bool) -> None:
        """Drive a standard digital input DI0..DI7 (seen by clients in actual_digital_input_bits)."""
        if not 0 <= index < 8:
            raise ConfigurationError("standard digital input index must be 0..7, got %r" % (index,))
        with self.arm.lock:
            self.arm.std_di = (self.arm.std_di & ~(1 << index)) | (int(bool(value)) << index)
            self.arm._update_io_values()

    def set_tool_digital_input(self, index: int, value: bool) -> None:
        if not 0 <= index < 2:
            raise ConfigurationError("tool digital input index must be 0..1, got %r" % (index,))
        with self.arm.lock:
            self.arm.tool_di = (self.arm.tool_di & ~(1 << index)) | (int(bool(value)) << index)
            self.arm._update_io_values()

    def get_state(self) -> dict:
        """Modes and flags: robot_mode, safety_mode, runtime_state (ints) and their names, last_error; ``moving``,
        ``motion_time`` (the controller's sim time, s) and ``last_moving_time`` (motion_time at the end of the last
        control cycle in which the arm moved); ``rtde_watchdog`` ([variable, min Hz] or None) and ``watchdog_trips``
        (programs it stopped, see :mod:`.arm`)."""
        from .arm import ROBOT_MODE_NAMES, RUNTIME_NAMES, SAFETY_MODE_NAMES
        a = self.arm
        with a.lock:
            return {"robot_mode": a.robot_mode, "robot_mode_name": ROBOT_MODE_NAMES.get(a.robot_mode),
                    "safety_mode": a.safety_mode, "safety_mode_name": SAFETY_MODE_NAMES.get(a.safety_mode),
                    "runtime_state": a.runtime_state, "runtime_state_name": RUNTIME_NAMES.get(a.runtime_state),
                    "program": a.program.name if a.program else None, "moving": a.is_moving(),
                    "motion_time": a.motion_time, "last_moving_time": a.last_moving_time,
                    "last_error": a.last_error, "watchdog_trips": a.watchdog_trips,
                    "rtde_watchdog": list(a.rtde_watchdog) if a.rtde_watchdog else None}

    @property
    def refused(self) -> List[str]:
        """What the stand-in refused (bad input), oldest first (last 200)."""
        return list(self.arm.refused)

    def set_joint_positions(self, q: Sequence[float]) -> None:
        """Teleport the arm (setup only; refused while the arm moves)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise ConfigurationError("q must hold 6 finite joint positions in rad")
        with self.arm.lock:
            if self.arm.is_moving():
                raise ConfigurationError("cannot set joint positions while the arm moves")
            self.arm.q = q.copy()
            self.arm._q_dirty = True

    def inject_protective_stop(self, reason: str = "injected") -> None:
        """Protective stop now (e.g. the world detected a collision): the arm stops, the program pauses."""
        self.arm.protective_stop(reason)

    def inject_emergency_stop(self, reason: str = "injected") -> None:
        """Press the emergency stop: program stops, the arm powers off."""
        self.arm.emergency_stop(reason)

    def release_emergency_stop(self) -> None:
        """Release the emergency stop button (then dashboard: close safety popup, power on, brake release)."""
        self.arm.release_emergency_stop()

    # ------------------------------------------------------------------------------------------------ contact
    def set_contact_provider(self, provider: Optional[ContactProvider], stiffness: Optional[float] = None) -> None:
        """Surfaces the tool can touch: ``provider(tcp_pose) -> None | (depth, outward normal)`` in the UR base
        frame, called on the control thread once per cycle (keep it short); None removes contact. ``stiffness``
        (N/m) of the contact spring (default 20000)."""
        if provider is not None and not callable(provider):
            raise ConfigurationError("contact provider must be callable(tcp_pose) -> None | (depth, normal)")
        if stiffness is not None and not (isinstance(stiffness, (int, float)) and np.isfinite(stiffness)
                                          and stiffness > 0):
            raise ConfigurationError("contact stiffness must be a finite number > 0 N/m, got %r" % (stiffness,))
        with self.arm.lock:
            self.arm.contact_provider = provider
            if stiffness is not None:
                self.arm.contact_stiffness = float(stiffness)
            if provider is None:
                self.arm.raw_force = np.zeros(3)
                self.arm._update_force_values()

    def set_contact_planes(self, planes: Sequence[dict], stiffness: Optional[float] = None) -> None:
        """Flat contact surfaces ``[{"point": [x, y, z], "normal": [nx, ny, nz], "radius": r?}, ...]`` in the UR
        base frame (normal out of the solid); [] removes them. Usable through :class:`.process.StandInProcess`."""
        self.set_contact_provider(PlaneContact(planes) if planes else None, stiffness)

    def get_tcp_force(self) -> List[float]:
        """``actual_TCP_force`` as streamed: contact force on the tool (N, base axes) minus the FT zero."""
        with self.arm.lock:
            return list(self.arm.values["actual_TCP_force"])

    def get_force_mode(self) -> Optional[dict]:
        """The active force mode's parameters and the TCP offset it built up, or None."""
        with self.arm.lock:
            fm = self.arm.force
            if fm is None:
                return None
            out = fm.describe()
            out["offset"] = self.arm.force_offset.tolist()
            return out

    def add_step_listener(self, fn: Callable[[ArmSnapshot], None]) -> None:
        """Call ``fn(snapshot)`` after every control cycle, on the control thread (keep it short, < 0.5 ms)."""
        with self.arm.lock:
            self.arm.listeners = self.arm.listeners + [fn]

    def remove_step_listener(self, fn: Callable[[ArmSnapshot], None]) -> None:
        with self.arm.lock:
            self.arm.listeners = [f for f in self.arm.listeners if f is not fn]
