"""The whole simulated worksite: PyBullet world plus every device stand-in, composed from configuration.

ROS-free on purpose: ``python3 -m locem_bridge.sim`` runs it directly, and the ROS node ``sim_worksite`` wraps
the same class. Lifecycle: ``Worksite(site_cfg, robot_cfg, **overrides)`` (nothing started) -> :meth:`start`
(clock, compressor model + Modbus TCP server, CAN drives, UR controller stand-in, world loop; returns the
endpoints) -> :meth:`stop` (reverse order, idempotent). Overrides change addresses without editing files:
``host`` (one loopback address for the UR stand-in and the Modbus server, e.g. ``127.0.0.2`` for a second
robot), ``modbus_port``, ``can_interface``, ``can_channel``, ``can_port``, ``time_scale``, ``gui``, ``with_ur``,
``heartbeat_process`` (drive heartbeats from a helper process; default: on ``udp_multicast``/``socketcan``, see
:mod:`.heartbeat`), ``arm_pose`` (named pose the arm starts in; default ``home``).

A robot file with a ``tool_changer`` section gets the tool changer stand-in too (:mod:`.modbus.tool_changer`, its own
Modbus TCP server on ``robot.tool_changer.port``): it mounts and parks tools in the world as its lock couples and
releases them at the rack slots (:meth:`tool_changer_state`). Operator calls (tools are changed by a person on the
real site): :meth:`mount_tool`, :meth:`remove_tool`, :meth:`mark_manual_taping`. Perception: :meth:`scan`. Results: :meth:`outcome` (numbers) and
:meth:`save_outcome` (``outcome.json`` + one PNG per wall), both given the parts planned for manual work if any.
"""
from __future__ import annotations

import copy
import json
import logging
import os
import threading
from typing import Any, Dict, List, Optional

from .arm_source import KinematicArm, UrArmSource
from .clock import SimClock
from .modbus.compressor import CompressorModel
from .config import load_robot, load_site, resolve_relative
from .can.drives import DriveSet, lift_drive
from .errors import DeviceStandInError, SimConfigError, SimStateError
from .modbus.modbus_server import CompressorServer
from .modbus.tool_changer import ToolChangerModel, WorldRack, tool_changer_server
from .world import World, resolve_arm_urdf
from .world_state import WorldState, snapshot_loop

log = logging.getLogger(__name__)


class Worksite:
    """World + stand-ins of one robot (see the module docstring)."""

    def __init__(self, site_cfg: Optional[Dict[str, Any]] = None, robot_cfg: Optional[Dict[str, Any]] = None,
                 host: Optional[str] = None, modbus_port: Optional[int] = None, can_interface: Optional[str] = None,
                 can_channel: Optional[str] = None, can_port: Optional[int] = None,
                 time_scale: Optional[float] = None, gui: Optional[bool] = None, with_ur: bool = True,
                 ur_ports: Optional[Dict[str, int]] = None, protective_stop_on_collision: bool = True,
                 heartbeat_process: Optional[bool] = None, arm_pose: Optional[str] = None,
                 state_dir: Optional[str] = None, snapshot_period_s: float = 10.0) -> None:
        self.site_cfg = copy.deepcopy(site_cfg if site_cfg is not None else load_site())
        self.robot_cfg = copy.deepcopy(robot_cfg if robot_cfg is not None else load_robot())
        robot = self.robot_cfg["robot"]
        sim = self.site_cfg["simulation"]
        if time_scale is not None:
            sim["time_scale"] = float(time_scale)
        if gui is not None:
            sim["gui"] = bool(gui)
        if host is not None:
            robot["arm"]["controller"]["host"] = host
            robot["compressor"]["host"] = host
            if "tool_changer" in robot:
                robot["tool_changer"]["host"] = host
        if modbus_port is not None:
            robot["compressor"]["port"] = int(modbus_port)
        can_cfg = robot["base"]["drives"]["can"]
        if can_interface is not None:
            can_cfg["interface"] = can_interface
        if can_channel is not None:
            can_cfg["channel"] = can_channel
        if can_port is not None:
            can_cfg["port"] = int(can_port)
        self.with_ur = with_ur
        self.ur_ports = ur_ports
        self.protective_stop_on_collision = protective_stop_on_collision
        self.heartbeat_process = heartbeat_process
        poses = robot["arm"]["named_poses"]
        if arm_pose is not None and arm_pose not in poses:
            raise SimConfigError("arm_pose %r is not a named pose of robot.arm.named_poses, allowed: %s"
                                 % (arm_pose, ", ".join(sorted(poses))))
        self.arm_pose = arm_pose
        #: folder keeping the world's state across a crash (:mod:`.world_state`); None: nothing kept
        self.state_dir = state_dir
        self.snapshot_period_s = float(snapshot_period_s)
        self.state: Optional[WorldState] = None
        self.restored: Optional[Dict[str, Any]] = None   # the saved robot state found at start (None: fresh)
        self._state_stop = threading.Event()
        self._state_thread: Optional[threading.Thread] = None
        self.clock: Optional[SimClock] = None
        self.compressor: Optional[CompressorModel] = None
        self.modbus: Optional[CompressorServer] = None
        self.changer: Optional[ToolChangerModel] = None
        self.changer_server: Any = None
        self.drives: Optional[DriveSet] = None
        self.lift: Any = None
        self.ur: Any = None
        self.arm: Any = None
        self.world: Optional[World] = None

    # -- lifecycle ---------------------------------------------------------------------------------------------
    def start(self) -> Dict[str, Any]:
        """Start everything; returns :meth:`endpoints`. On failure everything started so far is stopped; a
        stand-in that cannot bind raises :class:`DeviceStandInError` naming the address and port."""
        if self.world is not None:
            raise SimStateError("worksite already started")
        robot = self.robot_cfg["robot"]
        sim = self.site_cfg["simulation"]
        try:
            saved: Dict[str, Any] = {}
            if self.state_dir is not None:
                self.state = WorldState(self.state_dir)
                saved = self.state.saved_robot()
            # sim time goes on from where the saved world stood (the spray passes' stamps of both runs in order)
            self.clock = SimClock(sim["time_scale"], start=float(saved.get("sim_time") or 0.0))
            comp = robot["compressor"]
            self.compressor = CompressorModel(comp, self.clock.now)
            self.modbus = CompressorServer(self.compressor, comp["host"], comp["port"], comp["device_id"])
            self.modbus.start()
            dcfg = robot["base"]["drives"]
            eds = resolve_relative(self.robot_cfg, robot["base"]["eds"])
            if "lift" in robot:              # the lift's drive is a node on the base's bus
                self.lift = lift_drive(robot, resolve_relative(self.robot_cfg, robot["lift"]["eds"]), self.clock.now)
            self.drives = DriveSet(dcfg, eds, self.clock.now,
                                   max_wheel_speed=robot["base"]["limits"]["max_wheel_speed"],
                                   heartbeat_process=self.heartbeat_process,
                                   others=[self.lift] if self.lift is not None else [])
            self.drives.start()
            arm_cfg = robot["arm"]
            q0 = arm_cfg["named_poses"].get(self.arm_pose or "home", [0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
            if saved.get("q"):
                q0 = [float(x) for x in saved["q"]]      # the arm stood there when the power went
            if self.with_ur:
                self.ur = self._make_ur(arm_cfg, q0, sim["time_scale"])
                self._start_ur()
                self.arm = UrArmSource(self.ur)
            else:
                self.arm = KinematicArm(q0)
            self.world = World(self.site_cfg, self.robot_cfg, self.clock, arm=self.arm, drives=self.drives,
                               compressor=self.compressor, lift=self.lift)
            if self.state is not None:               # before the tool changer: it sees the tool on the flange
                self._restore_state(self.state, self.world)
            tc = robot.get("tool_changer")
            if tc is not None:                   # the changer's rack slots are flange positions of the world's arm
                self.changer = ToolChangerModel(tc, self.clock.now, WorldRack(self.world, tc))
                self.changer_server = tool_changer_server(self.changer, tc["host"], tc["port"], tc["device_id"])
                self.changer_server.start()
            if self.ur is not None:              # the arm feels the walls (force mode, actual_TCP_force)
                self.ur.set_contact_provider(self.world.wall_contact)
            if self.ur is not None and self.protective_stop_on_collision:
                self.world.on_collision.append(self._protective_stop)
            self.world.start()
        except Exception:
            self.stop()
            raise
        eps = self.endpoints()
        log.info("worksite started: %s", json.dumps(eps))
        return eps

    def _restore_state(self, state: WorldState, world: World) -> None:
        """The saved maps, base pose and tool back into ``world``, then journal it and snapshot it periodically."""
        with world._lock:
            robot = state.restore(world.outcome)
            if robot:
                if robot.get("pose"):
                    world.set_base_pose(*robot["pose"])
                if robot.get("tool"):
                    world.mount_tool(robot["tool"], by="the saved world state")
            if world.mounted_tool is not None:
                world.resume_samples(state.pending, state.pen)
            else:
                state.drop_pending()
            state.attach(world.outcome)
            world.sample_journal = state
        self.restored = robot
        if robot is not None:
            log.warning("world state restored from %s (%d journal records replayed, %d arm samples not yet recorded "
                        "go on): base %s, tool %s", state.folder, state.replayed, len(state.pending),
                        robot.get("pose"), robot.get("tool"))

        last_q: List[List[float]] = [[]]

        def take(whole: bool) -> bool:
            """Note the robot; with ``whole``, a snapshot too, unless the arm moved since the last tick or a tool
            works now (False: try again at the next tick)."""
            with world._lock:
                # the arm where the controller has it (its samples may be ahead of what the world recorded)
                q = world._last_sample if world._last_sample is not None else world._q
                robot = {"pose": world.base_pose(), "q": list(q), "tool": world.mounted_tool,
                         "sim_time": world.clock.now()}
                moved, last_q[0] = robot["q"] != last_q[0], robot["q"]
                working = whole and (moved or world.tool_active() or any(world.outcome._active.values()))
                captured = state.capture(world.outcome, robot) if whole and not working else None
                if captured is None:
                    state.note_robot(robot)
            if captured is not None:
                state.write(captured)
            return not working
        self._state_stop = threading.Event()
        self._state_thread = snapshot_loop(state, take, self.snapshot_period_s, self._state_stop)

    def _make_ur(self, arm_cfg: Dict[str, Any], q0: List[float], time_scale: float) -> Any:
        try:
            from .ur import UrControllerStandIn
        except ImportError as exc:  # the UR stand-in is optional for the rest of the site
            raise DeviceStandInError("UR controller stand-in not available (%s); run with with_ur=False" % exc)
        ctl = arm_cfg["controller"]
        ports = {"dashboard": int(ctl.get("dashboard_port", 29999)), "script": int(ctl.get("script_port", 30003)),
                 "rtde": int(ctl.get("rtde_port", 30004))}
        if self.ur_ports:
            ports.update(self.ur_ports)
        urdf, _ = resolve_arm_urdf(arm_cfg)
        return UrControllerStandIn(address=ctl["host"], time_scale=time_scale, model=urdf, q0=q0, ports=ports)

    def _start_ur(self) -> None:
        from .ur import UrStandInError
        try:
            self.ur.start()
        except UrStandInError as exc:        # e.g. a port taken: one line naming address and port
            raise DeviceStandInError(str(exc)) from exc

    def _protective_stop(self, event: Dict[str, Any]) -> None:
        if event["part"].startswith("arm"):
            self.ur.inject_protective_stop("collision: %s with %s" % (event["part"], event["wall"]))

    def stop(self) -> None:
        """Stop every part (reverse order of start; idempotent). The world state folder is left as a crash leaves
        it (the journal holds everything since the last snapshot)."""
        self._state_stop.set()
        if self._state_thread is not None:
            self._state_thread.join(timeout=10.0)
            self._state_thread = None
        if self.world is not None:
            self.world.close()
            self.world = None
        if self.state is not None:               # after the world: what it did until it stopped is journaled
            self.state.close()
            self.state = None
        if self.ur is not None:
            try:
                self.ur.stop()
            finally:
                self.ur = None
        if self.drives is not None:
            self.drives.stop()
            self.drives = None
        self.lift = None
        if self.changer_server is not None:
            self.changer_server.stop()
            self.changer_server = None
        if self.modbus is not None:
            self.modbus.stop()
            self.modbus = None

    def __enter__(self) -> "Worksite":
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.stop()

    # -- information -------------------------------------------------------------------------------------------
    def endpoints(self) -> Dict[str, Any]:
        """Where each stand-in listens (for the operator and for the bridges' configuration)."""
        robot = self.robot_cfg["robot"]
        out: Dict[str, Any] = {}
        if self.modbus is not None:
            out["compressor_modbus_tcp"] = "%s:%d (device id %d)" % (self.modbus.host, self.modbus.port,
                                                                      self.modbus.device_id)
        if self.changer_server is not None:
            out["tool_changer_modbus_tcp"] = "%s:%d (device id %d)" % (
                self.changer_server.host, self.changer_server.port, self.changer_server.device_id)
        if self.drives is not None:
            can_cfg = robot["base"]["drives"]["can"]
            out["base_drives_can"] = "%s channel %s%s, node ids %s" % (
                can_cfg["interface"], can_cfg["channel"], (" port %d" % can_cfg["port"]) if "port" in can_cfg else "",
                [d.node_id for d in self.drives.drives])
            if self.lift is not None:
                out["lift_drive_can"] = "same bus, node id %d (profile position)" % self.lift.node_id
        if self.ur is not None:
            out["ur_controller"] = "%s dashboard %d, script %d, RTDE %d" % (
                self.ur.address, self.ur.ports["dashboard"], self.ur.ports["script"], self.ur.ports["rtde"])
        if self.clock is not None:
            out["time_scale"] = self.clock.time_scale
        return out

    def compressor_state(self) -> Dict[str, Any]:
        """The compressor stand-in's own view: state, link, watchdog and valve / motor history (wall + sim time)."""
        if self.modbus is None:
            raise SimStateError("the worksite runs no compressor stand-in")
        return self.modbus.state()

    def tool_changer_state(self) -> Dict[str, Any]:
        """The tool changer stand-in's own view: lock, coupled tool, rack slots, fault, link, lock/unlock history."""
        if self.changer_server is None:
            raise SimStateError("the worksite runs no tool changer stand-in (the robot file has no tool_changer)")
        return self.changer_server.state()

    def _need_world(self) -> World:
        if self.world is None:
            raise SimStateError("worksite is not running; call start() first")
        return self.world

    # -- operator and perception -------------------------------------------------------------------------------
    def mount_tool(self, name: str) -> None:
        self._need_world().mount_tool(name)

    def remove_tool(self) -> Optional[str]:
        return self._need_world().remove_tool()

    def mark_manual_taping(self, joint_id: str) -> None:
        w = self._need_world()
        with w._lock:
            w.outcome.mark_manual_taping(joint_id)

    def scan(self) -> Dict[str, Any]:
        return self._need_world().scan()

    # -- fault injection --------------------------------------------------------------------------------------
    FAULTS = ("compressor_overpressure", "compressor_motor", "compressor_link_drop", "tool_changer_link_drop",
              "drive_fault",
              "drive_heartbeat_loss", "arm_protective_stop", "arm_emergency_stop")

    def inject_fault(self, kind: str, **kw: Any) -> None:
        """Inject a fault. ``kind`` is one of :attr:`FAULTS`; keyword arguments:
        ``compressor_link_drop``, ``tool_changer_link_drop``: ``duration`` (wall s, None = until :meth:`clear_fault`),
        ``mode`` close|silent;
        ``drive_fault``: ``node_id``, ``error_code`` (default 0x2310); ``drive_heartbeat_loss``: ``node_id``;
        ``arm_*``: ``reason``."""
        self._need_world()
        if kind == "compressor_overpressure":
            self.compressor.inject_overpressure()
        elif kind == "compressor_motor":
            self.compressor.inject_motor_fault()
        elif kind == "compressor_link_drop":
            self.modbus.drop_link(duration=kw.get("duration"), mode=kw.get("mode", "close"))
        elif kind == "tool_changer_link_drop":
            self.tool_changer_state()            # refuses when there is none
            self.changer_server.drop_link(duration=kw.get("duration"), mode=kw.get("mode", "close"))
        elif kind == "drive_fault":
            self.drives.drive(int(kw["node_id"])).inject_fault(int(kw.get("error_code", 0x2310)))
        elif kind == "drive_heartbeat_loss":
            self.drives.drive(int(kw["node_id"])).inject_heartbeat_loss()
        elif kind in ("arm_protective_stop", "arm_emergency_stop"):
            if self.ur is None:
                raise SimStateError("no UR controller stand-in is running")
            reason = str(kw.get("reason", "injected"))
            if kind == "arm_protective_stop":
                self.ur.inject_protective_stop(reason)
            else:
                self.ur.inject_emergency_stop(reason)
        else:
            raise SimStateError("unknown fault %r, allowed: %s" % (kind, ", ".join(self.FAULTS)))
        log.warning("fault injected: %s %s", kind, kw or "")

    def clear_fault(self, kind: str, **kw: Any) -> None:
        """Undo what a fault changed where the device itself cannot: ``compressor_link_drop`` (link back now),
        ``drive_heartbeat_loss`` (``node_id``: the node reboots), ``arm_emergency_stop`` (button released).
        Latched device faults are cleared through the device protocol, as on the real robot (Modbus fault_reset
        coil, CiA 402 fault reset, dashboard unlock / power on / brake release)."""
        self._need_world()
        if kind == "compressor_link_drop":
            self.modbus.restore_link()
        elif kind == "tool_changer_link_drop" and self.changer_server is not None:
            self.changer_server.restore_link()
        elif kind == "drive_heartbeat_loss":
            self.drives.drive(int(kw["node_id"])).restore()
        elif kind == "arm_emergency_stop":
            if self.ur is None:
                raise SimStateError("no UR controller stand-in is running")
            self.ur.release_emergency_stop()
        else:
            raise SimStateError("fault %r is cleared through the device protocol or cannot be cleared here; "
                                "clearable here: compressor_link_drop, tool_changer_link_drop, drive_heartbeat_loss, "
                                "arm_emergency_stop"
                                % kind)

    # -- results -----------------------------------------------------------------------------------------------
    def outcome(self, manual: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """Outcome numbers (see :meth:`OutcomeRecorder.summary`) plus ``collisions``; ``manual``: the parts planned
        for the hand (``{"areas": [{work, area, along, height}], "joints": [{joint, along}]}``, see
        :meth:`OutcomeRecorder.manual_plan`; a ValueError when it does not fit the site)."""
        w = self._need_world()
        with w._lock:
            out = w.outcome.summary(manual)
            out["collisions"] = w.collisions
        return out

    def save_outcome(self, folder: str, manual: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """Write ``outcome.json`` and one PNG per wall into ``folder`` (the planned manual parts ``manual`` drawn,
        see :meth:`outcome`); returns the numbers and file names."""
        w = self._need_world()
        out = self.outcome(manual)
        os.makedirs(folder, exist_ok=True)
        with w._lock:
            out["pictures"] = [os.path.basename(p) for p in w.outcome.save_pictures(folder, manual=manual)]
            out["collision_log"] = list(w.collision_log)
        with open(os.path.join(folder, "outcome.json"), "w") as fh:
            json.dump(out, fh, indent=2, sort_keys=True)
        return out
