"""The emulated UR controller core: arm state, safety, IO, RTDE registers and the ur_rtde control program.

No sockets here. :class:`ArmCore` is stepped by the controller's control thread (:meth:`ArmCore.tick`) and mutated
by the network thread (RTDE inputs, dashboard commands, uploaded scripts) under :attr:`ArmCore.lock`.

The ur_rtde control script is not interpreted: when it is uploaded, :class:`ControlProgram` serves the same register
protocol in Python (input_int_register_0 = command id, input_int_register_1 = async flag, input_double_register_*
= parameters; output_int_register_0 = 1 ready / 2 done, output_int_register_1 = boolean results,
output_int_register_2 = async progress word, output_double_register_0..5 = vector results), with the register
offset (0, or 24 for ``FLAG_UPPER_RANGE_REGISTERS``) read from the uploaded script. Command 45 runs the path that
ur_rtde injected into the script's ``exec_move_path`` (:mod:`.script_path`, :mod:`.blended`); commands 6 / 7 / 8
are force mode, its end and the FT-sensor zero (:mod:`.force`): while force mode runs, the motion generators follow
nominal joints and the actual joints add the compliant TCP offset.

State machines (values as in the UR RTDE guide / ur_rtde enums):
- robot_mode: POWER_OFF (3) --power on--> IDLE (5) --brake release--> RUNNING (7); power off returns to 3.
- runtime_state: STOPPED (1) --control script uploaded--> PLAYING (2) --protective stop--> PAUSED (4)
  --unlock protective stop / play--> PLAYING; stopScript, dashboard ``stop``, an emergency stop or a script runtime
  error (e.g. no IK solution) --> STOPPED.
- safety_mode: NORMAL (1), PROTECTIVE_STOP (3), ROBOT_EMERGENCY_STOP (7).

RTDE watchdog (URScript ``rtde_set_watchdog(variable, min_frequency, "stop")``, what ur_rtde's ``setWatchdog``
(command 35, frequency in the first double register) makes its control script call): once set, every input data
package that carries the control script's command register (``input_int_register_0``, or 24 with the upper range)
feeds it, e.g. ur_rtde's ``kickWatchdog`` (command 0); when none arrives for 1 / min_frequency wall seconds (the
link is real time, whatever the time scale) the program is stopped (runtime STOPPED, the arm brakes as on any
program stop) and the reason is kept in ``last_error``. A client that vanishes (killed, unplugged) stops feeding
it. As on the real controller, every watchdog is removed when the program stops; a new program must set it again.
"""
import logging
import math
import threading
import time
from collections import namedtuple
from typing import Callable, Dict, List, Optional, Sequence

import numpy as np
import pinocchio as pin

from .blended import PathMove
from .errors import KinematicsError, ScriptRuntimeError
from .force import DEFAULT_STIFFNESS, ContactProvider, ForceMode, contact_force
from .kinematics import ArmKinematics, pose_to_se3, se3_to_pose
from .motion import (CartesianSpeed, CartesianStop, JointMove, JointSpeed, JointStop, LinearMove, Motion, ServoJ,
                     tcp_twist)
from .rtde_vars import OUTPUT_VARIABLES, default_value
from .script_path import parse_move_path

LOG = logging.getLogger("locem_bridge.sim.ur")

# robot modes
ROBOT_MODE_POWER_OFF, ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING = 3, 5, 7
ROBOT_MODE_NAMES = {-1: "NO_CONTROLLER", 0: "DISCONNECTED", 1: "CONFIRM_SAFETY", 2: "BOOTING", 3: "POWER_OFF",
                    4: "POWER_ON", 5: "IDLE", 6: "BACKDRIVE", 7: "RUNNING", 8: "UPDATING_FIRMWARE"}
# safety modes
SAFETY_NORMAL, SAFETY_PROTECTIVE_STOP, SAFETY_ROBOT_EMERGENCY_STOP = 1, 3, 7
SAFETY_MODE_NAMES = {1: "NORMAL", 2: "REDUCED", 3: "PROTECTIVE_STOP", 4: "RECOVERY", 5: "SAFEGUARD_STOP",
                     6: "SYSTEM_EMERGENCY_STOP", 7: "ROBOT_EMERGENCY_STOP", 8: "VIOLATION", 9: "FAULT",
                     10: "VALIDATE_JOINT_ID", 11: "UNDEFINED_SAFETY_MODE"}
# runtime states
RUNTIME_STOPPING, RUNTIME_STOPPED, RUNTIME_PLAYING, RUNTIME_PAUSING, RUNTIME_PAUSED = 0, 1, 2, 3, 4
RUNTIME_NAMES = {0: "STOPPING", 1: "STOPPED", 2: "PLAYING", 3: "PAUSING", 4: "PAUSED", 5: "RESUMING"}
# joint modes
JOINT_MODE_POWER_OFF, JOINT_MODE_RUNNING, JOINT_MODE_IDLE = 239, 253, 255
# safety status bits
SSB_NORMAL, SSB_PROTECTIVE, SSB_ROBOT_ESTOP, SSB_ESTOP, SSB_STOPPED_BY_SAFETY = 0, 2, 6, 7, 10

#: seconds (motion time) after a protective stop before ``unlock protective stop`` is accepted, as on PolyScope 5
PROTECTIVE_STOP_UNLOCK_DELAY = 5.0
#: deceleration (rad/s^2) of a category-2 stop (protective stop, program stop)
SAFETY_STOP_DECELERATION = 20.0

#: outside force mode the contact force reading (actual_TCP_force) is refreshed every this many control cycles
CONTACT_READING_DIVIDER = 10

# command ids of the ur_rtde control script
CMD_NONE, CMD_MOVEJ, CMD_MOVEJ_IK, CMD_MOVEL, CMD_MOVEL_FK = 0, 1, 2, 3, 4
CMD_FORCE_MODE, CMD_FORCE_MODE_STOP = 6, 7
#: deceleration (m/s^2) of the stopl(10) in the control script's force_mode_stop
FORCE_MODE_STOP_DECELERATION = 10.0
CMD_ZERO_FT, CMD_SPEEDJ, CMD_SPEEDL, CMD_SERVOJ = 8, 9, 10, 11
CMD_SPEED_STOP, CMD_SERVO_STOP, CMD_SET_PAYLOAD = 15, 16, 17
CMD_GET_STEPTIME, CMD_GET_TARGET_WAYPOINT, CMD_SET_TCP, CMD_GET_IK_ARGS, CMD_PROTECTIVE_STOP = 26, 28, 29, 30, 31
CMD_STOPL, CMD_STOPJ, CMD_SET_WATCHDOG, CMD_POSE_SAFE, CMD_JOINTS_SAFE, CMD_JOINT_TORQUES = 33, 34, 35, 36, 37, 38
CMD_POSE_TRANS, CMD_GET_TCP_OFFSET, CMD_FK_DEFAULT, CMD_FK_ARGS, CMD_IK_DEFAULT, CMD_IS_STEADY = 39, 40, 43, 44, 46, 47
CMD_MOVE_PATH = 45
CMD_STOP_SCRIPT = 255
#: commands the control script treats as realtime (processed every cycle, answered "ready" at once)
REALTIME_COMMANDS = frozenset((24, 11, 9, 10, 6, 25, 26, 27, 38, 58, 66, 67, 68, 69, 70, 71))

ArmSnapshot = namedtuple("ArmSnapshot", "motion_time q qd tcp_pose tcp_speed standard_digital_out "
                                        "configurable_digital_out tool_digital_out robot_mode safety_mode "
                                        "runtime_state moving")
ArmSnapshot.__doc__ = "State handed to step listeners once per control cycle (motion_time in seconds)."


class ControlProgram:
    """The ur_rtde control script, emulated: register protocol state of one uploaded program."""

    def __init__(self, name: str, reg_offset_int: int, reg_offset_float: int) -> None:
        self.name = name
        self.off_i = reg_offset_int
        self.off_f = reg_offset_float
        self.executing = False
        self.blocking: Optional[Motion] = None   # motion a synchronous command waits for
        self.async_motion: Optional[Motion] = None
        self.async_wr_count = 0
        self.async_op_id = 0
        self.path: list = []                     # the move path injected into exec_move_path (see script_path)
        self.path_error: Optional[str] = None


class ArmCore:
    """State and behaviour of the emulated controller (see module docstring). Thread-safe via ``lock``."""

    def __init__(self, kinematics: ArmKinematics, q0: Sequence[float], serial_number: str = "20235500001",
                 control_rate: float = 500.0) -> None:
        self.kin = kinematics
        self.lock = threading.RLock()
        self.control_rate = control_rate
        self.serial_number = serial_number
        self.values: Dict[str, tuple] = {n: default_value(t) for n, t in OUTPUT_VARIABLES.items()}
        self.in_int = [0] * 48
        self.in_double = [0.0] * 48
        self._out_int_names = ["output_int_register_%d" % i for i in range(48)]
        self._out_double_names = ["output_double_register_%d" % i for i in range(48)]
        self.q = np.array(q0, dtype=float)
        self.qd = np.zeros(6)
        self.motion: Optional[Motion] = None
        self.program: Optional[ControlProgram] = None
        self.runtime_state = RUNTIME_STOPPED
        self.robot_mode = ROBOT_MODE_RUNNING
        self.safety_mode = SAFETY_NORMAL
        self.estop_pressed = False
        self.safety_popup = False
        self.protective_stop_time = 0.0
        self.motion_time = 0.0
        #: motion_time at the end of the last control cycle in which the arm moved (ground truth for stop tests)
        self.last_moving_time = 0.0
        self.speed_fraction = 1.0
        self.std_do = 0          # standard digital outputs 0..7
        self.conf_do = 0         # configurable digital outputs 0..7
        self.tool_do = 0         # tool digital outputs 0..1
        self.std_di = 0
        self.conf_di = 0
        self.tool_di = 0
        self.analog_out = [0.0, 0.0]
        self.payload_mass = 0.0
        self.payload_cog = [0.0, 0.0, 0.0]
        self.external_wrench = (0.0,) * 6
        # contact and force mode (see .force): provider of the surfaces, spring stiffness, the active force mode,
        # the TCP offset it has built up, the nominal joints the motion generators follow meanwhile, FT zero
        self.contact_provider: Optional[ContactProvider] = None
        self.contact_stiffness = DEFAULT_STIFFNESS
        self.force: Optional[ForceMode] = None
        self._contact_cycle = 0
        self.force_offset = np.zeros(3)
        self._q_nom: Optional[np.ndarray] = None
        self.raw_force = np.zeros(3)
        self.ft_zero = np.zeros(3)
        self.remote_control = True
        self.last_error = ""
        self.refused: List[str] = []
        self.listeners: List[Callable[[ArmSnapshot], None]] = []
        self._tcp_se3 = self.kin.fk_se3(self.q)
        self._prev_tcp: Optional[pin.SE3] = None
        self._twist = np.zeros(6)
        self._q_dirty = True
        self.controller_time = 0.0   # controller clock: control cycles x period (RTDE "timestamp")
        self._modes_dirty = True
        self.rtde_watchdog: Optional[tuple] = None   # (input variable, min frequency Hz) of rtde_set_watchdog
        self._watchdog_fed = 0.0                      # time.monotonic() of the last package carrying it
        self.watchdog_trips = 0
        self._update_outputs(0.0)

    # ------------------------------------------------------------------------------------------------ helpers
    def log_refused(self, what: str) -> None:
        """Record and log something the controller refused (bad input); keeps the last 200 entries."""
        LOG.warning("UR stand-in refused: %s", what)
        self.refused.append(what)
        del self.refused[:-200]

    def set_out_int(self, i: int, v: int) -> None:
        self.values[self._out_int_names[i]] = (int(v),)

    def set_out_double(self, i: int, v: float) -> None:
        self.values[self._out_double_names[i]] = (float(v),)

    def out_int(self, i: int) -> int:
        return self.values[self._out_int_names[i]][0]

    @property
    def tcp_pose(self) -> List[float]:
        return se3_to_pose(self._tcp_se3)

    def is_moving(self) -> bool:
        return self.motion is not None or bool(np.any(np.abs(self.qd) > 1e-9))

    # ------------------------------------------------------------------------------------------------ RTDE inputs
    def apply_inputs(self, pairs: List[tuple]) -> None:
        """Apply one decoded input data package (list of (name, value))."""
        with self.lock:
            d = {}
            watched = self.rtde_watchdog[0] if self.rtde_watchdog is not None else None
            for name, value in pairs:
                if name == watched:
                    self._watchdog_fed = time.monotonic()
                if name.startswith("input_int_register_"):
                    self.in_int[int(name[19:])] = value
                    self.values[name] = (value,)
                elif name.startswith("input_double_register_"):
                    self.in_double[int(name[22:])] = value
                    self.values[name] = (value,)
                elif name.startswith("input_bit_register"):
                    self.values[name] = (value,)
                else:
                    d[name] = value
            if not d:
                return
            if "standard_digital_output_mask" in d:
                m = d["standard_digital_output_mask"]
                self.std_do = (self.std_do & ~m) | (d.get("standard_digital_output", 0) & m)
            if "configurable_digital_output_mask" in d:
                m = d["configurable_digital_output_mask"]
                self.conf_do = (self.conf_do & ~m) | (d.get("configurable_digital_output", 0) & m)
            if "tool_digital_output_mask" in d:
                m = d["tool_digital_output_mask"] & 0x3
                self.tool_do = (self.tool_do & ~m) | (d.get("tool_digital_output", 0) & m)
            if "speed_slider_mask" in d and d["speed_slider_mask"] & 1:
                f = float(d.get("speed_slider_fraction", 1.0))
                if math.isfinite(f):
                    self.speed_fraction = min(1.0, max(0.0, f))
                    self._modes_dirty = True
            if "standard_analog_output_mask" in d:
                m = d["standard_analog_output_mask"]
                for i in (0, 1):
                    if m & (1 << i):
                        self.analog_out[i] = float(d.get("standard_analog_output_%d" % i, 0.0))
                self.values["standard_analog_output0"] = (self.analog_out[0],)
                self.values["standard_analog_output1"] = (self.analog_out[1],)
            if "external_force_torque" in d:
                self.external_wrench = tuple(d["external_force_torque"])
            self._update_io_values()

    def _update_io_values(self) -> None:
        self.values["actual_digital_output_bits"] = (self.std_do | (self.conf_do << 8) | (self.tool_do << 16),)
        self.values["actual_digital_input_bits"] = (self.std_di | (self.conf_di << 8) | (self.tool_di << 16),)

    # ------------------------------------------------------------------------------------------------ scripts
    def load_script(self, text: str) -> str:
        """A complete URScript program arrived on the script port. Returns what happened (for the log)."""
        with self.lock:
            first = text.lstrip().split("\n", 1)[0].strip()
            name = first[4:].split("(", 1)[0].strip() if first.startswith("def ") or first.startswith("sec ") else ""
            if self.robot_mode != ROBOT_MODE_RUNNING or self.safety_mode != SAFETY_NORMAL:
                self.log_refused("program %r not started: robot is %s / %s" % (
                    name, ROBOT_MODE_NAMES.get(self.robot_mode), SAFETY_MODE_NAMES.get(self.safety_mode)))
                return "refused"
            # a new program replaces the running one, as on the real controller
            self._stop_program(None)
            if name == "rtde_control" or "rtde_cmd()" in text:
                off_i = _script_int(text, "reg_offset_int")
                off_f = _script_int(text, "reg_offset_float")
                self.program = ControlProgram(name or "rtde_control", off_i, off_f)
                self.program.path, self.program.path_error = parse_move_path(text)
                self.runtime_state = RUNTIME_PLAYING
                self.in_int[off_i] = 0
                self._async_write(self.program, -1)
                self.set_out_int(off_i, 1)   # signal_ready()
                self._modes_dirty = True
                LOG.info("UR stand-in: control program %r running (register offset %d)", name, off_i)
                return "running"
            LOG.info("UR stand-in: URScript program %r accepted but not interpreted (only the ur_rtde control "
                     "script is emulated); it ends at once", name or first[:40])
            return "ignored"

    def _stop_program(self, reason: Optional[str]) -> None:
        self.rtde_watchdog = None          # every watchdog is removed on program stop
        prog = self.program
        if prog is not None and prog.async_motion is not None:
            self._async_write(prog, -1)
        self.program = None
        self._end_force_mode()
        if self.runtime_state != RUNTIME_STOPPED:
            self.runtime_state = RUNTIME_STOPPED
            self._modes_dirty = True
        if self.motion is not None or np.any(self.qd != 0):
            self.motion = JointStop(self.qd, SAFETY_STOP_DECELERATION)
        if reason:
            self.last_error = reason
            LOG.error("UR stand-in: program halted: %s", reason)

    # ------------------------------------------------------------------------------------------------ safety
    def protective_stop(self, reason: str = "injected") -> None:
        with self.lock:
            if self.safety_mode in (SAFETY_ROBOT_EMERGENCY_STOP, SAFETY_PROTECTIVE_STOP):
                return          # already stopped: a persisting cause does not restart the unlock delay
            LOG.warning("UR stand-in: protective stop (%s)", reason)
            self.last_error = "protective stop: %s" % reason
            self.safety_mode = SAFETY_PROTECTIVE_STOP
            self.protective_stop_time = self.motion_time
            self.safety_popup = True
            self._end_force_mode()
            if self.motion is not None or np.any(self.qd != 0):
                # an arm at rest stays at rest: no stop motion (it would report "moving" until the next cycle)
                self.motion = JointStop(self.qd, SAFETY_STOP_DECELERATION)
            prog = self.program
            if prog is not None:
                if prog.async_motion is not None:
                    self._async_write(prog, -1)
                    prog.async_motion = None
                prog.blocking = None
                prog.executing = True     # the interrupted command is not re-run after resume
                self.runtime_state = RUNTIME_PAUSED
            self._modes_dirty = True

    def unlock_protective_stop(self) -> str:
        with self.lock:
            if self.safety_mode == SAFETY_PROTECTIVE_STOP:
                waited = self.motion_time - self.protective_stop_time
                if waited < PROTECTIVE_STOP_UNLOCK_DELAY:
                    return ("Cannot unlock protective stop until 5s after occurrence. Always inform yourself about "
                            "the reason for the protective stop before unlocking.")
                self.safety_mode = SAFETY_NORMAL
                self.safety_popup = False
                if self.program is not None and self.runtime_state == RUNTIME_PAUSED:
                    self.runtime_state = RUNTIME_PLAYING
                self._modes_dirty = True
            return "Protective stop releasing"

    def emergency_stop(self, reason: str = "injected") -> None:
        with self.lock:
            LOG.warning("UR stand-in: emergency stop (%s)", reason)
            self.last_error = "emergency stop: %s" % reason
            self.estop_pressed = True
            self.safety_mode = SAFETY_ROBOT_EMERGENCY_STOP
            self.safety_popup = True
            self._stop_program(None)
            # category 1 stop: decelerate, then power is removed
            self.motion = JointStop(self.qd, SAFETY_STOP_DECELERATION)
            self.robot_mode = ROBOT_MODE_POWER_OFF
            self._modes_dirty = True

    def release_emergency_stop(self) -> None:
        """Release the (emulated) emergency stop button; the dashboard must still close the popup and power on."""
        with self.lock:
            self.estop_pressed = False

    def close_safety_popup(self) -> None:
        with self.lock:
            if self.safety_mode == SAFETY_ROBOT_EMERGENCY_STOP and not self.estop_pressed:
                self.safety_mode = SAFETY_NORMAL
                self._modes_dirty = True
            self.safety_popup = False

    def power_on(self) -> None:
        with self.lock:
            if self.robot_mode == ROBOT_MODE_POWER_OFF and self.safety_mode == SAFETY_NORMAL:
                self.robot_mode = ROBOT_MODE_IDLE
                self._modes_dirty = True

    def power_off(self) -> None:
        with self.lock:
            self._stop_program(None)
            self.motion = None
            self.qd = np.zeros(6)
            self.robot_mode = ROBOT_MODE_POWER_OFF
            self._modes_dirty = True

    def brake_release(self) -> None:
        with self.lock:
            if self.robot_mode == ROBOT_MODE_POWER_OFF and self.safety_mode == SAFETY_NORMAL:
                self.robot_mode = ROBOT_MODE_IDLE
            if self.robot_mode == ROBOT_MODE_IDLE and self.safety_mode == SAFETY_NORMAL:
                self.robot_mode = ROBOT_MODE_RUNNING
            self._modes_dirty = True

    def stop_program(self) -> bool:
        """Dashboard ``stop``. False when nothing was running (the dashboard then reports a failure)."""
        with self.lock:
            if self.runtime_state == RUNTIME_STOPPED:
                return False
            self._stop_program(None)
            return True

    def pause_program(self) -> bool:
        with self.lock:
            if self.runtime_state != RUNTIME_PLAYING:
                return False
            self.runtime_state = RUNTIME_PAUSED
            self._end_force_mode()          # the arm stops where it is; the program's force_mode() is not resumed
            self.motion = JointStop(self.qd, SAFETY_STOP_DECELERATION)
            if self.program is not None:
                self.program.blocking = None
                self.program.executing = True
            self._modes_dirty = True
            return True

    def play_program(self) -> bool:
        with self.lock:
            if (self.runtime_state == RUNTIME_PAUSED and self.program is not None
                    and self.safety_mode == SAFETY_NORMAL and self.robot_mode == ROBOT_MODE_RUNNING):
                self.runtime_state = RUNTIME_PLAYING
                self._modes_dirty = True
                return True
            return False

    # ------------------------------------------------------------------------------------------------ control step
    def tick(self, wall_dt: float, time_scale: float, controller_time: float = 0.0) -> None:
        """One control cycle: run the control program, advance motion by ``wall_dt * time_scale * slider``.

        ``controller_time`` is the controller clock (cycle count x period) reported as RTDE ``timestamp``.
        """
        listeners = self.listeners
        with self.lock:
            self.controller_time = controller_time
            dt = wall_dt * time_scale
            self.motion_time += dt
            mdt = dt * self.speed_fraction
            prog = self.program
            wd = self.rtde_watchdog
            if prog is not None and wd is not None and time.monotonic() - self._watchdog_fed > 1.0 / wd[1]:
                self.watchdog_trips += 1
                why = ("RTDE watchdog: no update of %s for %.2f s (min %.3g Hz): program stopped"
                       % (wd[0], time.monotonic() - self._watchdog_fed, wd[1]))
                LOG.warning("UR stand-in: %s", why)
                self._stop_program(why)
                prog = None
            if prog is not None and self.runtime_state == RUNTIME_PLAYING:
                try:
                    self._program_cycle(prog)
                except (ScriptRuntimeError, KinematicsError, ValueError) as exc:
                    self._stop_program(str(exc))
            m = self.motion
            nominal = self._q_nom is not None
            if m is not None and mdt > 0:
                try:
                    q, qd = m.step(mdt, self._q_nom if nominal else self.q, self.qd)
                except KinematicsError as exc:
                    self._motion_error(str(exc))
                else:
                    if nominal:
                        self._q_nom = q
                    else:
                        self.q, self.qd = q, qd
                    self._q_dirty = True
                    if isinstance(m, PathMove) and m.progress != m.reported_progress:
                        self._path_progress(m)
                    if m.done:
                        self._motion_finished(m)
            elif m is None and self._q_dirty:
                self.qd = np.zeros(6)
            if self.force is not None and mdt > 0:
                self._force_step(mdt)
            self._contact_cycle += 1
            if self.contact_provider is not None and (self.force is not None or self._contact_cycle
                                                      % CONTACT_READING_DIVIDER == 0):
                # every cycle in force mode; otherwise the streamed force reading is refreshed every
                # CONTACT_READING_DIVIDER-th cycle (50 Hz), which keeps a world provider off the 500 Hz path
                self.raw_force = contact_force(self.contact_provider, se3_to_pose(self.kin.fk_se3(self.q)),
                                               self.contact_stiffness)
                self._update_force_values()
            if self.is_moving():
                self.last_moving_time = self.motion_time
            self._update_outputs(dt)
            snap = None
            if listeners:
                snap = ArmSnapshot(self.motion_time, self.q.copy(), self.qd * self.speed_fraction,
                                   self.values["actual_TCP_pose"],
                                   self.values["actual_TCP_speed"], self.std_do, self.conf_do, self.tool_do,
                                   self.robot_mode, self.safety_mode, self.runtime_state, self.motion is not None)
        if snap is not None:
            for fn in list(listeners):
                try:
                    fn(snap)
                except Exception:  # a listener must never stop the controller
                    LOG.exception("UR stand-in: step listener %r failed", fn)

    def _trajectory_twist(self) -> np.ndarray:
        """The TCP twist in trajectory time (the measured twist divided by the speed slider)."""
        f = self.speed_fraction
        return self._twist / f if f > 1e-9 else np.zeros(6)

    def _motion_error(self, reason: str) -> None:
        self.qd = np.zeros(6)
        self.motion = None
        self.protective_stop(reason)

    def _motion_finished(self, m: Motion) -> None:
        if self.motion is m:
            self.motion = None
            if isinstance(m, (JointStop, CartesianStop)) or m.kind in ("movej", "movel", "path"):
                self.qd = np.zeros(6)
        prog = self.program
        if prog is not None and prog.async_motion is m:
            prog.async_motion = None
            self._async_write(prog, -1)

    # ------------------------------------------------------------------------------------------------ force mode
    def _force_step(self, dt: float) -> None:
        """One admittance cycle: move the TCP along the compliant axes by the force error (see .force)."""
        if self._q_nom is None:
            self._q_nom = self.q.copy()
        tcp = self.kin.fk_se3(self.q)
        applied = -contact_force(self.contact_provider, se3_to_pose(tcp), self.contact_stiffness)
        self.force_offset = self.force_offset + self.force.step(applied, dt, self.contact_stiffness)
        target = self.kin.fk_se3(self._q_nom)
        target = pin.SE3(target.rotation, target.translation + self.force_offset)
        qn = self.kin.ik_se3(target, self.q, max_iter=50, tol=1e-11)
        if qn is None:
            self._motion_error("force mode: TCP target not reachable (singularity or workspace limit)")
            return
        self.qd = (qn - self.q) / dt
        self.q = qn
        self._q_dirty = True

    def _end_force_mode(self) -> None:
        """Leave force mode where the arm is (the nominal joints become the actual ones)."""
        self.force = None
        self._q_nom = None
        self.force_offset = np.zeros(3)

    def _update_force_values(self) -> None:
        f = self.raw_force - self.ft_zero
        self.values["actual_TCP_force"] = (float(f[0]), float(f[1]), float(f[2]), 0.0, 0.0, 0.0)
        self.values["tcp_force_scalar"] = (float(np.linalg.norm(f)),)
        self.values["ft_raw_wrench"] = (float(self.raw_force[0]), float(self.raw_force[1]),
                                        float(self.raw_force[2]), 0.0, 0.0, 0.0)

    def _path_progress(self, m: PathMove) -> None:
        """signal_async_progress(i) of the injected path: written whenever the path approaches a new waypoint
        (also for a synchronous path, as the script does; then nothing writes "finished" afterwards)."""
        m.reported_progress = m.progress
        prog = self.program
        if prog is not None and m.progress >= 0 and (prog.async_motion is m or prog.blocking is m):
            self._async_write(prog, m.progress)

    def _update_outputs(self, dt: float) -> None:
        """Refresh the streamed values. Internal ``qd`` runs in trajectory time (motion time x speed slider); the
        reported velocities are per second of motion time, i.e. scaled by the slider as on a real UR."""
        v = self.values
        v["timestamp"] = (self.controller_time,)
        if self._q_dirty:
            self._q_dirty = bool(np.any(self.qd != 0))
            qt = tuple(self.q.tolist())
            qdt = tuple((self.qd * self.speed_fraction).tolist())
            v["actual_q"] = v["target_q"] = qt
            v["actual_qd"] = v["target_qd"] = qdt
            cur = self.kin.fk_se3(self.q)
            self._twist = tcp_twist(self._tcp_se3, cur, dt) if dt > 0 else np.zeros(6)
            if not np.any(self.qd != 0):
                self._twist = np.zeros(6)
            self._tcp_se3 = cur
            pose = tuple(se3_to_pose(cur))
            v["actual_TCP_pose"] = v["target_TCP_pose"] = pose
            v["actual_TCP_speed"] = v["target_TCP_speed"] = tuple(self._twist.tolist())
            v["elbow_position"] = tuple(self.kin.elbow_position())
        if self._modes_dirty:
            self._modes_dirty = False
            self._update_mode_values()

    def _update_mode_values(self) -> None:
        v = self.values
        v["robot_mode"] = (self.robot_mode,)
        v["safety_mode"] = v["safety_status"] = (self.safety_mode,)
        jm = {ROBOT_MODE_RUNNING: JOINT_MODE_RUNNING, ROBOT_MODE_IDLE: JOINT_MODE_IDLE}.get(self.robot_mode,
                                                                                          JOINT_MODE_POWER_OFF)
        v["joint_mode"] = (jm,) * 6
        ssb = 0
        if self.safety_mode == SAFETY_NORMAL:
            ssb |= 1 << SSB_NORMAL
        elif self.safety_mode == SAFETY_PROTECTIVE_STOP:
            ssb |= (1 << SSB_PROTECTIVE) | (1 << SSB_STOPPED_BY_SAFETY)
        elif self.safety_mode == SAFETY_ROBOT_EMERGENCY_STOP:
            ssb |= (1 << SSB_ROBOT_ESTOP) | (1 << SSB_ESTOP) | (1 << SSB_STOPPED_BY_SAFETY)
        v["safety_status_bits"] = (ssb,)
        v["runtime_state"] = (self.runtime_state,)
        rsb = 0
        if self.robot_mode in (ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING):
            rsb |= 1
        if self.runtime_state == RUNTIME_PLAYING:
            rsb |= 2
        v["robot_status_bits"] = (rsb,)
        powered = self.robot_mode in (ROBOT_MODE_IDLE, ROBOT_MODE_RUNNING)
        v["speed_scaling"] = (self.speed_fraction if powered else 0.0,)
        v["target_speed_fraction"] = (self.speed_fraction,)
        v["actual_main_voltage"] = (48.0,)
        v["actual_robot_voltage"] = (48.0 if powered else 0.0,)
        v["actual_joint_voltage"] = ((48.0 if powered else 0.0),) * 6
        v["joint_temperatures"] = (32.0,) * 6
        v["tool_temperature"] = (31.0,)
        v["tool_output_voltage"] = (24,)
        v["tool_mode"] = (jm if powered else JOINT_MODE_POWER_OFF,)
        v["payload"] = (self.payload_mass,)
        v["payload_cog"] = tuple(self.payload_cog)
        self._update_io_values()

    # ------------------------------------------------------------------------------------------------ program
    def _async_write(self, prog: ControlProgram, value: int) -> None:
        """write_async_progress_register of the control script (bit layout kept for ur_rtde)."""
        prog.async_wr_count = 0 if prog.async_wr_count >= 127 else prog.async_wr_count + 1
        if value == 0:
            prog.async_op_id = 0 if prog.async_op_id >= 127 else prog.async_op_id + 1
        reg = prog.async_wr_count * 65536 + prog.async_op_id * 16777216
        if value >= 0:
            reg += (value & 0x7FFF) + 32768
        self.set_out_int(prog.off_i + 2, reg)

    def _program_cycle(self, prog: ControlProgram) -> None:
        if prog.blocking is not None:
            if prog.blocking is self.motion and not prog.blocking.done:
                return
            prog.blocking = None
            self.set_out_int(prog.off_i, 2)          # signal_done_with_cmd()
            return
        cmd = self.in_int[prog.off_i]
        if cmd in REALTIME_COMMANDS:
            self._process(prog, cmd)
            self.set_out_int(prog.off_i, 1)
        elif cmd == CMD_NONE:
            prog.executing = False
            self.set_out_int(prog.off_i, 1)
        elif not prog.executing:
            prog.executing = True
            if self._process(prog, cmd) and prog.blocking is None and self.program is prog:
                self.set_out_int(prog.off_i, 2)

    def _f(self, prog: ControlProgram, i: int) -> float:
        return self.in_double[prog.off_f + i]

    def _vec(self, prog: ControlProgram, i: int) -> np.ndarray:
        o = prog.off_f + i
        return np.array(self.in_double[o:o + 6], dtype=float)

    def _write_vec(self, prog: ControlProgram, vec: Sequence[float]) -> None:
        for i, val in enumerate(vec):
            self.set_out_double(prog.off_f + i, val)

    def _start_motion(self, prog: ControlProgram, m: Motion, asynchronous: bool) -> None:
        self._stop_async_move(prog)
        self.motion = m
        if asynchronous:
            prog.async_motion = m
            self._async_write(prog, 0)
            if m.done:
                self._motion_finished(m)
        elif not m.done:
            prog.blocking = m

    def _stop_async_move(self, prog: ControlProgram) -> None:
        if prog.async_motion is not None:
            prog.async_motion = None
            self._async_write(prog, -1)

    def _check_target(self, q: np.ndarray) -> None:
        if np.any(q < self.kin.lower) or np.any(q > self.kin.upper) or not np.all(np.isfinite(q)):
            raise ScriptRuntimeError("joint target %s outside the joint limits" % (np.round(q, 4).tolist(),))

    def _process(self, prog: ControlProgram, cmd: int) -> bool:
        """Execute one command; returns False when the command ends the program (stopScript)."""
        kin = self.kin
        asyn = self.in_int[prog.off_i + 1] == 1
        # motions start from the joints the generators follow: in force mode the nominal ones (the actual joints
        # add the compliant offset, see _force_step)
        q_cmd = self.q if self._q_nom is None else self._q_nom
        if cmd in (CMD_MOVEJ, CMD_MOVEJ_IK, CMD_MOVEL, CMD_MOVEL_FK):
            v, a = self._f(prog, 6), self._f(prog, 7)
            if not (v > 0 and a > 0 and math.isfinite(v) and math.isfinite(a)):
                raise ScriptRuntimeError("move: speed and acceleration must be positive (v=%r, a=%r)" % (v, a))
            x = self._vec(prog, 0)
            if cmd == CMD_MOVEJ:
                self._check_target(x)
                m = JointMove(q_cmd, x, v, a)
            elif cmd == CMD_MOVEJ_IK:
                q1 = np.array(kin.ik(x.tolist(), q_cmd.tolist()))
                m = JointMove(q_cmd, q1, v, a)
            elif cmd == CMD_MOVEL:
                m = LinearMove(kin, q_cmd, pose_to_se3(x), v, a)
            else:
                self._check_target(x)
                m = LinearMove(kin, q_cmd, kin.fk_se3(x), v, a)
            self._start_motion(prog, m, asyn)
        elif cmd == CMD_FORCE_MODE:
            o_i = prog.off_i
            fm = ForceMode(self._vec(prog, 0), self.in_int[o_i + 2:o_i + 8], self._vec(prog, 6),
                           self.in_int[o_i + 1], self._vec(prog, 12))
            if self.force is None:
                self._q_nom = self.q.copy()
                self.force_offset = np.zeros(3)
            self.force = fm
        elif cmd == CMD_FORCE_MODE_STOP:
            self._end_force_mode()
            if self.motion is not None or np.any(self.qd != 0):
                m = CartesianStop(kin, self.q, self._trajectory_twist(), FORCE_MODE_STOP_DECELERATION)
                self._start_motion(prog, m, False)
        elif cmd == CMD_MOVE_PATH:
            if prog.path_error:
                raise ScriptRuntimeError(prog.path_error)
            m = PathMove(kin, q_cmd, prog.path)        # checks the whole path first: nothing moves on an error
            self._start_motion(prog, m, asyn)
        elif cmd == CMD_SPEEDJ:
            self._stop_async_move(prog)
            qd, a = self._vec(prog, 0), self._f(prog, 6)
            if isinstance(self.motion, JointSpeed):
                self.motion.target, self.motion.a = qd, a
            else:
                self.motion = JointSpeed(qd, a)
        elif cmd == CMD_SPEEDL:
            self._stop_async_move(prog)
            xd, a = self._vec(prog, 0), self._f(prog, 6)
            if type(self.motion) is CartesianSpeed:
                self.motion.retarget(xd, a)
            else:
                self.motion = CartesianSpeed(kin, q_cmd, self._trajectory_twist(), xd, a)
        elif cmd == CMD_SERVOJ:
            self._stop_async_move(prog)
            target, t = self._vec(prog, 0), self._f(prog, 8)
            if isinstance(self.motion, ServoJ):
                self.motion.retarget(target, t)
            else:
                self.motion = ServoJ(target, t, kin.velocity_limit)
        elif cmd in (CMD_SPEED_STOP, CMD_SERVO_STOP, CMD_STOPL, CMD_STOPJ):
            a = self._f(prog, 0)
            if not (a > 0 and math.isfinite(a)):
                raise ScriptRuntimeError("stop: deceleration must be positive (got %r)" % a)
            cart = cmd in (CMD_STOPL, CMD_SERVO_STOP) or (cmd == CMD_SPEED_STOP
                                                          and isinstance(self.motion, CartesianSpeed))
            m = CartesianStop(kin, q_cmd, self._trajectory_twist(), a) if cart else JointStop(self.qd, a)
            stop_async = cmd in (CMD_STOPL, CMD_STOPJ) and asyn
            self._start_motion(prog, m, stop_async)
        elif cmd == CMD_SET_TCP:
            kin.set_tcp(self._vec(prog, 0).tolist())
            self._q_dirty = True
        elif cmd == CMD_SET_PAYLOAD:
            self.payload_mass = self._f(prog, 0)
            cog = [self._f(prog, 1), self._f(prog, 2), self._f(prog, 3)]
            if any(cog):
                self.payload_cog = cog
            self._modes_dirty = True
        elif cmd in (CMD_GET_IK_ARGS, CMD_IK_DEFAULT):
            x = self._vec(prog, 0).tolist()
            qnear = self._vec(prog, 6).tolist() if cmd == CMD_GET_IK_ARGS else self.q.tolist()
            self._write_vec(prog, kin.ik(x, qnear))
        elif cmd == CMD_FK_DEFAULT:
            self._write_vec(prog, kin.fk(self.q))
        elif cmd == CMD_FK_ARGS:
            self._write_vec(prog, kin.fk(self._vec(prog, 0), self._vec(prog, 6).tolist()))
        elif cmd == CMD_GET_TCP_OFFSET:
            self._write_vec(prog, kin.tcp_pose())
        elif cmd == CMD_POSE_TRANS:
            p = pose_to_se3(self._vec(prog, 0)) * pose_to_se3(self._vec(prog, 6))
            self._write_vec(prog, se3_to_pose(p))
        elif cmd == CMD_GET_TARGET_WAYPOINT:
            self._write_vec(prog, self.tcp_pose)
        elif cmd == CMD_IS_STEADY:
            self.set_out_int(prog.off_i + 1, 0 if self.is_moving() else 1)
        elif cmd == CMD_JOINTS_SAFE:
            q = self._vec(prog, 0)
            ok = bool(np.all(q >= kin.lower) and np.all(q <= kin.upper))
            self.set_out_int(prog.off_i + 1, 1 if ok else 0)
        elif cmd == CMD_POSE_SAFE:
            try:
                kin.ik(self._vec(prog, 0).tolist(), self.q.tolist())
                ok = True
            except KinematicsError:
                ok = False
            self.set_out_int(prog.off_i + 1, 1 if ok else 0)
        elif cmd == CMD_GET_STEPTIME:
            self.set_out_double(prog.off_f, 1.0 / self.control_rate)
        elif cmd == CMD_JOINT_TORQUES:
            self._write_vec(prog, [0.0] * 6)
        elif cmd == CMD_ZERO_FT:
            self.ft_zero = self.raw_force.copy()
            self._update_force_values()
        elif cmd == CMD_SET_WATCHDOG:
            freq = float(self.in_double[prog.off_f])
            if not (math.isfinite(freq) and freq > 0.0):
                raise ScriptRuntimeError("rtde_set_watchdog: min_frequency must be > 0 (got %r)" % freq)
            self.rtde_watchdog = ("input_int_register_%d" % prog.off_i, freq)
            self._watchdog_fed = time.monotonic()
            LOG.info("UR stand-in: RTDE watchdog on %s at %.3g Hz (stop)", self.rtde_watchdog[0], freq)
        elif cmd == CMD_PROTECTIVE_STOP:
            self.protective_stop("protective_stop() requested by the control script")
            return False
        elif cmd == CMD_STOP_SCRIPT:
            LOG.info("UR stand-in: control script stopped by stopScript")
            self._stop_program(None)
            return False
        else:
            raise ScriptRuntimeError("command %d is not implemented by the UR stand-in" % cmd)
        return True


def _script_int(text: str, var: str) -> int:
    """Read ``global <var> = <int>`` from an uploaded script (0 when absent or not a number)."""
    key = "global %s =" % var
    i = text.find(key)
    if i < 0:
        return 0
    rest = text[i + len(key):].split("\n", 1)[0].split("#", 1)[0].strip()
    try:
        val = int(rest)
    except ValueError:
        return 0
    return val if val in (0, 24) else 0
