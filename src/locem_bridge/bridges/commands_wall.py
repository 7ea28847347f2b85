"""The plasterboard commands, composed from the atomic device operations ("multiple atomic actions using a single
ROS action call"): SCAN, MOUNT_TOOL, APPLY_TAPE_START, APPLY_TAPE, SPRAY_AREA, SAND_AREA, HOME.

Every number comes from HICEM (line endpoints, area rectangle, wall normal, offsets, speeds) in the ``map``
frame; LOCEM never knows feature ids. Geometry: the map point is expressed in the UR ``base`` frame through the
base odometry pose and ``robot.arm.mount`` (on a robot with a lift, at the lift's height now: wall commands
take the map points as they are, whatever the lift height; HICEM lifts first); the TCP faces the wall (tool z axis against the inward wall
normal, tool x axis horizontal). Approaches to a wall are straight moves when the tool already faces the way
the target does (from the ``wall_ready`` pose HICEM drives in), otherwise a joint move to the controller's IK
solution first; the work itself is straight moves (MOVE_L semantics, 1 mm accuracy). HOME from a wall pose
passes ``robot.arm.home_via`` first.

Process outputs are switched from ``robot.tools.<tool>.switch``: a UR standard digital output (taping tool,
sander) or the compressor's spray valve. Whatever ends a command (success, error, cancel, STOP, deadline), the
process output is switched off before the command answers; a compressor link lost mid SPRAY_AREA ends the
command with ``HARDWARE_ERROR`` within one second (when the link returns the compressor backend brings the device
to its safe state: valve closed, motor off). SPRAY_AREA therefore switches the motor on itself every time
(valve closed, motor on, set-point, wait for pressure), so a SPRAY_AREA after such a failure (HICEM's RECOVER,
then the area again) needs no COMPRESSOR_ON first.
"""

import logging
import math
import threading
import time
from functools import lru_cache
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

import numpy as np

from locem_bridge.common.raster_progress import lane_heights, progress_text
from locem_bridge.locem.errors import NotReady
from locem_bridge.locem.registry import Arg, CommandSpec

from .commands_compressor import wait_for_pressure
from .errors import BadRequest, BridgeError
from locem_bridge.common.geometry import angle_between, invert, matrix_to_pose, pose_to_matrix
from .geometry import arm_base_in_footprint, planar, tool_frame_facing
from .interfaces import Arm, Base, Compressor, Lift, Scanner, Waiter
from .suspension import Resumable, Steps, arm_settle

log = logging.getLogger(__name__)

CATEGORY = "wall"
EXT = 100.0
APPROACH_SPEED = 0.25          # m/s, free moves near the wall
CONTACT_SPEED = 0.05           # m/s, the last centimetres to the wall
STRAIGHT_APPROACH_ANGLE = 0.6  # rad, tool re-orientation up to which a wall approach is one straight move
LANE_ACCEL = 4.0               # m/s^2, raster lanes (short run-up: 3 cm at 0.5 m/s)
RUNUP_MARGIN = 0.01            # m, constant-speed travel before the tool switches on
PATH_BLEND = 0.03              # m, blend radius of the turns between raster lanes (one blended path)
LEAD_IN = 0.3                  # m, a raster path's lead-in beside its first lane (see WallCommands._raster_path)
SKIP_RESOLUTION = 0.001        # m, a lane with less than this left after SPRAY_AREA skip= is not worked again
LIFT_OFF = 0.03                # m, how far a suspended sander lifts off the wall
LOCALISED_WAIT_S = 1.0         # s, the longest a wall command waits for the base's first fix after its stop


def _point(prefix: str, doc: str, suffix: str = "") -> tuple:
    return tuple(Arg.number("%s%s%s" % (prefix, c, suffix), "m", -EXT, EXT, "%s %s (map)" % (doc, c)) for c in "xyz")


def _normal() -> tuple:
    return tuple(Arg.number("n%s" % c, "", -1.0, 1.0, "inward wall normal %s (map; normalised by LOCEM)" % c)
                 for c in "xyz")


def _line_len(v: Mapping[str, Any]) -> float:
    return math.sqrt((v["x1"] - v["x0"]) ** 2 + (v["y1"] - v["y0"]) ** 2 + (v["z1"] - v["z0"]) ** 2)


def _raster_len(v: Mapping[str, Any]) -> float:
    length, extent = ((v["height"], v["width"]) if v.get("lanes") == "vertical" else (v["width"], v["height"]))
    lanes = math.ceil(extent / v["spacing"]) + 1
    return lanes * (length + 2.0 * v.get("run_in", 0.0) + v["spacing"] + 0.6)


_LINE_ARGS = _point("", "line start", "0") + _point("", "line end", "1")
_WORK_RESULT = (("length_m", "length worked"), ("duration_s", "seconds"))

SCAN = CommandSpec(
    "SCAN", "Detect the wall joints and areas visible from the current base pose (docs/contracts.md shape).",
    resources=frozenset({"scanner"}), category=CATEGORY, timeout=10.0,
    result=(("stamp", "time of the scan"), ("walls", "walls seen"), ("joints", "joint lines: start, end, kind"),
            ("areas", "wall areas: origin, u, width, height"),
            ("obstacles", "walls not worked (concrete): id, p0, p1, height; absent when none")),
    capability="sk:cap_DetectWallFeatures")


def mount_tool_spec(tools: Tuple[str, ...]) -> CommandSpec:
    """MOUNT_TOOL of a robot whose tools (``robot.tools`` of its file) are ``tools``."""
    return CommandSpec(
        "MOUNT_TOOL", "Make the operator-mounted tool active: TCP offset and payload from the robot configuration.",
        args=(Arg.choice("tool", tools, "the tool the operator mounted"),), resources=frozenset({"arm", "tool"}),
        category=CATEGORY, timeout=5.0, result=(("tool", "active tool"), ("tcp", "TCP offset"), ("mass", "kg")),
        capability="sk:cap_MountToolByOperator")


APPLY_TAPE_START = CommandSpec(
    "APPLY_TAPE_START", "Bring the taping tool in front of a line's start for the operator to judge (tool off).",
    args=_LINE_ARGS + _normal() + (Arg.number("approach", "m", 0.0, 0.5, "distance in front of the wall", default=0.05,
                              keyword_only=True),),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=60.0, result=(("tcp_pose", "arm base frame"),),
    pausable=True,
    capability="plb:cap_ShowTapeLineStart")
APPLY_TAPE = CommandSpec(
    "APPLY_TAPE", "Tape a joint line: approach its start, taping tool on, follow the line, tool off, retract.",
    args=APPLY_TAPE_START.args[:9] + (
        Arg.number("speed", "m/s", 0.01, 0.5, "speed along the line", default=0.1, keyword_only=True),
        Arg.number("offset", "m", -0.01, 0.05, "TCP distance from the wall surface while taping", default=0.0,
                   keyword_only=True),
        Arg.number("approach", "m", 0.01, 0.5, "approach / retract distance", default=0.05, keyword_only=True)),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=120.0, result=_WORK_RESULT, pausable=True,
    deadline=lambda v: _line_len(v) / v["speed"] + 60.0, capability="plb:cap_ApplyTapeStroke")
_AREA_ARGS = _point("o", "area origin") + (
    Arg.number("ux", "", -1.0, 1.0, "along-wall unit vector x"), Arg.number("uy", "", -1.0, 1.0, "along-wall unit vector y"),
    Arg.number("uz", "", -1.0, 1.0, "along-wall unit vector z"),
    Arg.number("width", "m", 0.01, 10.0, "extent along u"), Arg.number("height", "m", 0.01, 5.0, "extent upwards"))
SPRAY_AREA = CommandSpec(
    "SPRAY_AREA", "Spray an area in horizontal raster lanes: compressor on, pressure reached, valve open only on "
    "the lanes, closed at the end and on any error.",
    args=_AREA_ARGS + _normal() + (
        Arg.number("spacing", "m", 0.02, 1.0, "distance between lanes", default=0.2, keyword_only=True),
        Arg.number("standoff", "m", 0.05, 1.0, "nozzle to wall", default=0.3, keyword_only=True),
        Arg.number("speed", "m/s", 0.01, 1.0, "speed along a lane", default=0.4, keyword_only=True),
        Arg.number("pressure", "bar", 0.5, 10.0, "spray pressure", default=2.5, keyword_only=True),
        Arg.number("run_in", "m", 0.0, 0.5, "lane length sprayed beyond each end of the area (0 when a "
                   "neighbouring section continues the lanes: their spray footprints then add up evenly)",
                   default=0.1, keyword_only=True),
        Arg.number("skip", "m", 0.0, 1000.0, "worked length of the raster left out from its start (lanes with "
                   "their run-in end to end, turns not counted; at most lanes x (width + 2 run_in)): the command "
                   "goes on where an interrupted one stopped, the point its feedback reported as 'raster <m> of "
                   "<m> m'", default=0.0, keyword_only=True)),
    resources=frozenset({"arm", "tool", "compressor"}), category=CATEGORY, timeout=600.0, pausable=True,
    result=_WORK_RESULT
    + (("lanes", "lanes sprayed (a lane begun part way counts)"), ("skipped_m", "raster length left out (skip)")),
    deadline=lambda v: _raster_len(v) / v["speed"] * 2.0 + 90.0, capability="plb:cap_SprayRaster")
SAND_AREA = CommandSpec(
    "SAND_AREA", "Sand an area in raster lanes in contact with the wall, sander on only on the lanes: horizontal "
    "lanes stacked upwards, or (lanes=vertical) vertical lanes stacked along u, e.g. one pass (width 0) up the side "
    "of a door frame, where horizontal lanes cannot run on and a round pad leaves bare scallops between them.",
    args=_AREA_ARGS[:6] + (
        Arg.number("width", "m", 0.0, 10.0, "extent along u (at least 0.01 m; 0 with lanes=vertical: one lane up "
                   "the origin's side)"),
        Arg.number("height", "m", 0.01, 5.0, "extent upwards")) + _normal() + (
        Arg.number("spacing", "m", 0.02, 1.0, "distance between lanes", default=0.1, keyword_only=True),
        Arg.number("speed", "m/s", 0.01, 0.5, "speed along a lane", default=0.15, keyword_only=True),
        Arg.number("force", "N", 0.0, 100.0, "contact force set-point along the tool axis (contact=force)",
                   default=20.0, keyword_only=True),
        Arg.choice("contact", ("position", "force"), "position: lanes on the wall surface; force: force mode holds "
                   "the set-point along the tool axis while the lanes run (needs a controller with force control; "
                   "the UR stand-in needs contact surfaces)", default="position", keyword_only=True),
        Arg.choice("lanes", ("horizontal", "vertical"), "direction of the lanes: horizontal (along u, stacked "
                   "upwards over height) or vertical (upwards, stacked along u over width)", default="horizontal",
                   keyword_only=True)),
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=600.0, pausable=True, result=_WORK_RESULT
    + (("lanes", "lanes sanded"),), deadline=lambda v: _raster_len(v) / v["speed"] * 2.0 + 90.0,
    capability="plb:cap_SandRaster")
WALL_READY = CommandSpec(
    "WALL_READY", "Arm to the named pose 'wall_ready' (tool facing forward, links close to the base) to drive along "
    "walls: from a wall pose first a straight retract to the pose's TCP point, then the joint move.",
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=60.0, result=(("q", "joint positions"),),
    pausable=True, capability="sk:cap_ArmToWallReady")
HOME = CommandSpec(
    "HOME", "Process outputs off, arm to its home pose.", resources=frozenset({"arm", "tool"}), category=CATEGORY,
    timeout=60.0, result=(("q", "joint positions"),), pausable=True, capability="sk:cap_ArmHome")
GET_TOOL_POINT = CommandSpec(
    "GET_TOOL_POINT", "Read where the active tool works now, in the map frame: its TCP point and axis (base odometry, "
    "the arm's mount and lift applied; the tool's TCP offset set on the controller first, nothing moves). After a "
    "power loss the arm stands where the work stopped: HICEM reads it back before anything moves the arm.",
    resources=frozenset({"arm", "tool"}), category=CATEGORY, timeout=3.0,
    result=(("point", "[x, y, z] TCP point in map, m"), ("axis", "[x, y, z] tool axis in map (into the wall at work)"),
            ("tool", "the active tool ('' none)")))



@lru_cache(maxsize=16)
def wall_specs(tools: Tuple[str, ...]) -> Tuple[CommandSpec, ...]:
    """The wall commands of a robot with these tools (MOUNT_TOOL's choices)."""
    return (SCAN, mount_tool_spec(tuple(tools)), APPLY_TAPE_START, APPLY_TAPE, SPRAY_AREA, SAND_AREA, WALL_READY,
            HOME, GET_TOOL_POINT)


def specs_for(robot: Mapping[str, Any]) -> Tuple[CommandSpec, ...]:
    """The wall commands of the robot section ``robot`` (a loaded robot file's ``robot``); a robot with a
    ``tool_changer`` has no MOUNT_TOOL (CHANGE_TOOL, bridges/commands_changer.py)."""
    return tuple(s for s in wall_specs(tuple(robot.get("tools", {})))
                 if not ("tool_changer" in robot and s.name == "MOUNT_TOOL"))


class HookedWaiter:
    """A :class:`~.interfaces.Waiter` that passes everything on to ``ctx`` and runs :meth:`_after_wait` (a
    subclass's hook) after every sleep and check, i.e. at every wait of a device operation's loop."""

    def __init__(self, ctx: Waiter) -> None:
        self._ctx = ctx

    def _after_wait(self) -> None:
        pass

    def sleep(self, seconds: float) -> None:
        self._ctx.sleep(seconds)
        self._after_wait()

    def check(self) -> None:
        self._ctx.check()
        self._after_wait()

    def on_cancel(self, callback: Callable[[], None]) -> None:
        self._ctx.on_cancel(callback)

    def report(self, progress: float, text: str = "") -> None:
        self._ctx.report(progress, text)


class GuardedWaiter(HookedWaiter):
    """A waiter that also runs ``guard()`` (e.g. the compressor link check) whenever it sleeps or checks."""

    def __init__(self, ctx: Waiter, guard: Callable[[], None]) -> None:
        super().__init__(ctx)
        self._guard = guard

    def _after_wait(self) -> None:
        self._guard()


class LaneSwitch(HookedWaiter):
    """A waiter for one raster lane: on every wait of the arm's motion loop it reads the arm's latest TCP and
    switches the tool's process output on while the TCP is between ``f_on`` and ``f_off`` of the lane ``a -> b``
    (fractions of the straight line, arm base frame), off outside. The arm thus accelerates and brakes with the
    tool off and passes the worked stretch at constant speed: no extra compound or sanding where a lane starts
    or ends.

    Dead time: the TCP sample is already ``age`` old when it is read (the arm's state poll), and the output
    changes only some time into the switch request (a Modbus write to the compressor, an RTDE output). Without
    compensation the tool would switch ``speed x dead time`` too late at both ends of the stretch (a few mm at
    0.5 m/s on hardware; centimetres in a time-scaled simulation, where the arm moves faster in wall time). The
    decision is therefore taken on the TCP predicted ``age + LATENCY_SHARE x switch duration`` ahead along its
    measured velocity (both in wall time; the switch duration is a running average of the requests' own
    durations), at most ``MAX_LEAD_S``. Age and velocity go by when each sample was taken (the state's
    ``sample_time`` and ``sample_tick``, from the controller's clock), not by when the poll's answer arrived: on a busy machine that
    varies by tens of milliseconds from poll to poll, and a velocity from it by several times.

    Step: the decision is only taken at the loop's waits, one step apart, so the output changes up to one step of
    travel after the TCP crossed a stretch's end (6 cm at 0.5 m/s and time scale 10 with the loop's 10 ms; 3 mm on
    hardware). The step is measured (``update_s``: it follows a longer step at once and a shorter one slowly, so a
    loaded machine's irregular waits are not underestimated) and its travel (``step_m``, at most MAX_STEP_M) is
    what ``lead_steps`` and ``margin_steps`` count in: the prediction looks ``lead_steps`` steps of travel further
    and the stretch is widened by ``margin_steps`` of them at both ends. 0 and 0: the first wait past each end
    (on average half a step late at both: what sanding uses); 0.5 and 0: the wait nearest each end (unbiased);
    0.5 and 0.5: the last wait before the start and the first past the end (the whole stretch worked for sure, on
    average half a step more at each end: what spraying uses, so two sections that meet leave no bare strip
    between them whatever the time scale, with no run-in past their common end). Both count the same capped
    travel, so a cap never moves the switching off ahead of the end. One predicted point is judged against one
    interval for switching on and off alike, so the output never chatters.

    The first switch request of a lane has no running average to go by: :meth:`prime` measures one (a request
    to switch off, which the output already is) before the motion starts."""

    #: share of a switch request's duration after which the output has changed (request out, answer back)
    LATENCY_SHARE = 0.5
    #: longest prediction (s of wall time); a stalled state poll is not extrapolated further
    MAX_LEAD_S = 0.1
    #: m, the longest step of travel lead_steps and margin_steps count in (a stalled loop does not switch on far
    #: ahead of a stretch)
    MAX_STEP_M = 0.08

    def __init__(self, ctx: Waiter, arm: Arm, switch: Callable[[bool], None], a: Sequence[float], b: Sequence[float],
                 f_on: float, f_off: float, clock: Callable[[], float] = time.time,
                 lead_steps: float = 0.0, margin_steps: float = 0.0) -> None:
        """``clock``: wall time in s, the clock of the arm state's ``stamp``; ``lead_steps``, ``margin_steps``:
        see the class docstring."""
        super().__init__(ctx)
        self._lead_steps, self._margin_steps = float(lead_steps), float(margin_steps)
        self._arm, self._raw_switch, self._clock = arm, switch, clock
        self._a = np.asarray(a[:3], dtype=float)
        self._ab = np.asarray(b[:3], dtype=float) - self._a
        self._len2 = max(float(self._ab.dot(self._ab)), 1e-12)
        self._f_on, self._f_off = f_on, f_off
        self.on = False
        self.switched_on_at: Optional[float] = None
        self._last: Optional[Tuple[float, np.ndarray]] = None     # (tick, TCP position) of the previous sample
        self._velocity = np.zeros(3)
        self.switch_s = 0.0                                        # running average of a switch request (s)
        self._before: List[Callable[[bool], None]] = []
        self.held = False                                          # suspended: never switches on again
        self._decision = threading.RLock()                         # one decision at a time, hold_off between
        self.update_s = 0.0                                        # running average between two decisions (s)
        self._last_update: Optional[float] = None

    def hold_off(self) -> Optional[np.ndarray]:
        """Suspension (from another thread): the switch stays off from now on (a decision under way ends first,
        so none switches on afterwards); returns the TCP predicted for the moment a switch request made now takes
        effect (where the tool stops working), None without a TCP."""
        with self._decision:
            self.held = True
            return self._predicted_tcp()

    def before_switch(self, callback: Callable[[bool], None]) -> None:
        """Run ``callback(on)`` right before every switch request (e.g. a progress report as the valve opens)."""
        self._before.append(callback)

    def _switch(self, on: bool) -> None:
        for callback in self._before:
            callback(on)
        self._timed_switch(on)

    def _timed_switch(self, on: bool) -> None:
        t0 = self._clock()
        self._raw_switch(on)
        took = max(0.0, self._clock() - t0)
        self.switch_s = took if self.switch_s == 0.0 else 0.7 * self.switch_s + 0.3 * took

    def prime(self) -> None:
        """Before the motion, with the output off: one request to switch it off, timed, so the first switching on
        is compensated for the request's duration too."""
        if not self.on:
            self._timed_switch(False)

    def _decision_tcp(self) -> Optional[np.ndarray]:
        """The TCP a decision taken now is judged on: :meth:`_predicted_tcp` ``lead_steps`` steps of travel further
        (see the class docstring); measures the step."""
        self._measure_step()
        p = self._predicted_tcp()
        speed = float(np.linalg.norm(self._velocity))
        if p is None or speed <= 1e-9:
            return p
        return p + self._velocity / speed * (self._lead_steps * self.step_m())

    def _measure_step(self) -> None:
        """One more decision: the wall time since the last one goes into ``update_s``."""
        now = self._clock()
        if self._last_update is not None:
            step = min(max(0.0, now - self._last_update), self.MAX_LEAD_S)
            self.update_s = step if step > self.update_s else 0.8 * self.update_s + 0.2 * step
        self._last_update = now

    def step_m(self) -> float:
        """The travel of one loop step (m) at the measured speed, at most MAX_STEP_M."""
        return min(self.MAX_STEP_M, float(np.linalg.norm(self._velocity)) * self.update_s)

    def _margin(self, length: float) -> float:
        """The widening of a stretch ``length`` m long at each end, as a fraction of it (``margin_steps``)."""
        return self._margin_steps * self.step_m() / max(length, 1e-9)

    def _sample(self) -> Optional[Tuple[np.ndarray, Optional[float], Optional[float]]]:
        """The arm's latest TCP position (arm base frame), when it was taken (wall time; None: unknown) and its
        tick: the time between two samples is the difference of their ticks (``sample_tick``: the controller's
        clock; velocities from ``sample_time`` differences took in each renewal of its mapping's offset, a few
        milliseconds whenever the quickest answer leaves its window: against 20 ms between two polls, a speed off
        by a tenth and more, which the switch's fast-rising speed keeps)."""
        state = self._arm.cached_state()
        tcp = state.get("tcp")
        if not tcp:
            return None
        stamp = state.get("sample_time", state.get("stamp"))
        tick = state.get("sample_tick", stamp)
        return (np.asarray(tcp[:3], dtype=float), (float(stamp) if stamp is not None else None),
                (float(tick) if tick is not None else None))

    def _predicted_tcp(self) -> Optional[np.ndarray]:
        """The TCP position (arm base frame) expected when a switch requested now takes effect."""
        sample = self._sample()
        if sample is None:
            return None
        p, stamp, tick = sample
        if stamp is None or tick is None:
            return p
        if self._last is None or tick > self._last[0]:        # a new sample
            if self._last is not None:
                self._velocity = (p - self._last[1]) / (tick - self._last[0])
            self._last = (tick, p)
        lead = min(self.MAX_LEAD_S, max(0.0, self._clock() - stamp) + self.LATENCY_SHARE * self.switch_s)
        return p + self._velocity * lead

    def _update(self) -> None:
        p = self._decision_tcp()
        if p is None:
            return
        f = float((p - self._a).dot(self._ab)) / self._len2
        m = self._margin(math.sqrt(self._len2))
        want = self._f_on - m <= f <= self._f_off + m and not self.held
        if want != self.on:
            self._switch(want)
            self.on = want
            if want and self.switched_on_at is None:
                self.switched_on_at = f

    def _after_wait(self) -> None:
        with self._decision:
            self._update()


#: per tool, LaneSwitch's (lead_steps, margin_steps): the spray gun works each lane's whole stretch for sure
#: (sections meet with no run-in: default site at time scale 1, thickness CV 0.087 with 2 cm run-ins, 0.039
#: without), and along a raster path it is switched by the path (RasterSwitch's path, cut waits); the sander
#: switches at the first wait past each end (a pad over a frame's edge sands the frame)
SWITCH_LEADS = {"spray_gun": (0.5, 0.5)}
NO_LEADS = (0.0, 0.0)


class RasterSwitch(LaneSwitch):
    """:class:`LaneSwitch` for a whole raster driven as one blended path: the tool is on while the (predicted)
    TCP is on the worked stretch of any lane.

    Given the ``path`` (its waypoints from its start, arm base frame), the decision goes along it: the TCP's
    position is its distance travelled along the path (projected onto the nearest segment, searched forward from
    the last one), its speed the TCP's speed between samples, and the prediction runs on along the path, so a TCP
    still in the turn into a lane is judged on where the turn takes it, not on a straight line through its current
    direction (which at a time scale of 10, a turn and its run-up passed in one or two waits, pointed off the lane
    and switched on late). Two speeds are kept, one that follows a rise at once and a fall slowly, one the other
    way round: switching on goes by the higher, at least the high speed measured on the stretches so far (the
    lane speed the arm regains right after a turn), switching off by the lower (a stalled controller's catch-up looks
    fast): an error then sprays a little more, never leaves a gap. A stretch switched off at its end is not
    switched on again. And the switching point is not left to the motion loop's next wait: a wait it falls into
    is cut there (:meth:`sleep`),
    so the output changes ``EARLY_S`` of travel before each stretch and after it (what a cut wait may oversleep),
    at any time scale; the loop step (``lead_steps``, ``margin_steps``) does not come into it.

    Without a path: the predicted TCP's fraction 0..1 of a stretch, within ``reach`` of its line, judged at the
    loop's waits as :class:`LaneSwitch` does."""

    #: s of wall time: the output goes on this long before the TCP reaches a stretch and off this long after it
    #: passed its end (a cut wait's oversleeping; 1.5 mm at 0.5 m/s, 1.5 cm at time scale 10)
    EARLY_S = 0.003
    #: s, the shortest cut wait
    MIN_WAIT_S = 0.0005
    #: m, a switching point this close counts as reached (a cut wait ends on it up to rounding)
    REACHED_M = 1e-6

    def __init__(self, ctx: Waiter, arm: Arm, switch: Callable[[bool], None],
                 stretches: Sequence[Sequence[Sequence[float]]], reach: float,
                 clock: Callable[[], float] = time.time, lead_steps: float = 0.0,
                 margin_steps: float = 0.0, path: Optional[Sequence[Sequence[float]]] = None) -> None:
        super().__init__(ctx, arm, switch, stretches[0][0], stretches[0][1], 0.0, 1.0, clock, lead_steps,
                         margin_steps)
        self._lines = [(np.asarray(a[:3], dtype=float), np.asarray(b[:3], dtype=float) - np.asarray(a[:3], dtype=float))
                       for a, b in stretches]
        self._reach = reach
        self._points: Optional[np.ndarray] = None
        if path is not None and len(path) >= 2:
            pts = np.asarray([q[:3] for q in path], dtype=float)
            lengths = np.linalg.norm(np.diff(pts, axis=0), axis=1)
            self._points = pts
            self._lengths = lengths
            self._cum = np.concatenate([[0.0], np.cumsum(lengths)])
            self._segment = 0                                        # the segment the TCP was last found on
            self._speeds = (0.0, 0.0)                                 # m/s of wall time: high, low
            self._cruise = 0.0                     # m/s of wall time: the speed with the tool on, as "high"
            self._current = 0                                         # the stretch the output is on for
            self._next = 0                                            # the first stretch not yet worked
            self._due: Optional[float] = None                         # wall time of the next switching point
            self._intervals = []
            for a, ab in self._lines:
                mid = a + 0.5 * ab
                j = int(np.argmin([self._distance(mid, k) for k in range(len(lengths))]))
                self._intervals.append(tuple(sorted((self._along(a, j), self._along(a + ab, j)))))

    def _project(self, p: np.ndarray, k: int) -> Tuple[float, float]:
        """(distance along the path, distance from it) of ``p`` projected onto path segment ``k``."""
        a, d = self._points[k], self._points[k + 1] - self._points[k]
        f = min(1.0, max(0.0, float((p - a).dot(d)) / max(float(d.dot(d)), 1e-12)))
        return float(self._cum[k] + f * self._lengths[k]), float(np.linalg.norm(p - a - d * f))

    def _distance(self, p: np.ndarray, k: int) -> float:
        return self._project(p, k)[1]

    def _along(self, p: np.ndarray, k: int) -> float:
        return self._project(p, k)[0]

    def _path_position(self) -> Optional[Tuple[float, float]]:
        """(distance along the path, sample time) of the latest TCP sample; updates the speed along the path."""
        sample = self._sample()
        if sample is None:
            return None
        p, stamp, tick = sample
        t = stamp if stamp is not None else self._clock()
        tick = t if tick is None else tick
        last = min(len(self._lengths), self._segment + 4)
        k = min(range(self._segment, last), key=lambda i: self._distance(p, i))
        self._segment = k
        s = self._along(p, k)
        if self._last is None or tick > self._last[0]:        # a new sample (its 3-D velocity: hold_off's too)
            if self._last is not None:
                self._velocity = (p - self._last[1]) / (tick - self._last[0])
                v = float(np.linalg.norm(self._velocity))
                hi, lo = self._speeds
                self._speeds = (v if v > hi else 0.8 * hi + 0.2 * v, v if v < lo or lo == 0.0 else 0.8 * lo + 0.2 * v)
                if self.on:                        # follows a rise at once, a fall slowly (a spike fades)
                    self._cruise = v if v > self._cruise else 0.9 * self._cruise + 0.1 * v
            self._last = (tick, p)
        return s, t

    def sleep(self, seconds: float) -> None:
        """Along a path: a wait that the next switching point falls into is cut there, so the output changes
        at that point, not up to one loop step later (5 cm at 0.5 m/s and time scale 10)."""
        end = self._clock() + seconds
        while self._points is not None:
            now, due = self._clock(), self._due
            if due is None or due >= end or now >= end:
                break
            self._ctx.sleep(max(due - now, self.MIN_WAIT_S))
            self._after_wait()
        left = end - self._clock()
        if left > 0.0:
            self._ctx.sleep(left)
        self._after_wait()

    def _update(self) -> None:
        if self._points is None:
            self._update_by_lines()
            return
        self._due = None
        where = self._path_position()
        if where is None:
            return
        s, t = where
        now = self._clock()
        # off: the low speed; on: the high one, at least the lanes' speed so far (after a turn the arm speeds up
        # again to it at once, while a speed measured in the turn was a fraction of it: the valve opened up to
        # 12 cm into the lane at a time scale of 10)
        speed = self._speeds[1] if self.on else max(self._speeds[0], self._cruise)
        lead = min(self.MAX_LEAD_S, max(0.0, now - t) + self.LATENCY_SHARE * self.switch_s)
        s_pred = s + speed * lead
        early = speed * self.EARLY_S               # on this much before each stretch, off this much after it
        if self.on:
            want = not self.held and s_pred < self._intervals[self._current][1] + early - self.REACHED_M
        else:
            hits = [i for i in range(self._next, len(self._intervals))
                    if self._intervals[i][0] - early - self.REACHED_M <= s_pred <= self._intervals[i][1]]
            want = not self.held and bool(hits)
            if want:
                self._current = hits[0]
        if want != self.on:
            self._switch(want)
            self.on = want
            if not want:
                self._next = self._current + 1      # a stretch switched off at its end is never switched on again
        # the next switching point, in wall time from now
        if speed > 1e-6 and not self.held:
            if self.on:
                ahead = self._intervals[self._current][1] + early - s_pred
            else:
                ahead = min((a - early - s_pred for a, _b in self._intervals[self._next:] if a - early > s_pred),
                            default=-1.0)
            if ahead > self.REACHED_M:
                self._due = now + ahead / speed

    def _update_by_lines(self) -> None:
        p = self._decision_tcp()
        if p is None:
            return
        want = False
        for a, ab in self._lines:
            f = float((p - a).dot(ab)) / max(float(ab.dot(ab)), 1e-12)
            m = self._margin(float(np.linalg.norm(ab)))
            if -m <= f <= 1.0 + m and float(np.linalg.norm(p - a - ab * f)) <= self._reach:
                want = not self.held
                break
        if want != self.on:
            self._switch(want)
            self.on = want


JUMP_M = 0.1


def path_gaps(points: Sequence[np.ndarray], ends: Sequence[Tuple[np.ndarray, np.ndarray]], speed: float,
              blend: float, spacing: float) -> List[float]:
    """For a serpentine run as one blended path (``points``: each lane's two ends, run-ups included, in order;
    ``ends``: each lane's worked stretch, start and end; lanes ``spacing`` apart, turns blended with ``blend``,
    lane ``speed`` at :data:`LANE_ACCEL`): the path from each stretch's end to the next one's start (run-out, turn,
    run-up) as the length the arm would cover at lane speed in the time it takes. The controller slows down on
    the turn's two arcs (to sqrt(LANE_ACCEL x radius); a 90 degree blend's arc radius is its blend radius) and on
    the straight between them, and brakes and speeds up at LANE_ACCEL: the unblended lengths plus that time lost,
    an upper bound, so the point :class:`RasterProgress` gives should LOCEM die stays behind the spray."""
    v_turn = min(speed, math.sqrt(LANE_ACCEL * blend))
    # two quarter arcs and the straight between them at v_turn, braking before and speeding up after at LANE_ACCEL
    lost = ((math.pi * blend + max(0.0, spacing - 2.0 * blend)) * (speed / v_turn - 1.0)
            + (speed - v_turn) ** 2 / LANE_ACCEL)
    return [float(np.linalg.norm(points[2 * i + 1] - ends[i][1])
                  + np.linalg.norm(points[2 * i + 2] - points[2 * i + 1])
                  + np.linalg.norm(ends[i + 1][0] - points[2 * i + 2])) + lost for i in range(len(ends) - 1)]


class RasterProgress(HookedWaiter):
    """A waiter around a raster's tool switch (:class:`LaneSwitch`, :class:`RasterSwitch`; every wait goes on to
    it) that reports the raster's progress: the worked length done (m, counted from the raster's start, a skipped
    part included; :mod:`locem_bridge.common.raster_progress`) from the arm's measured TCP while the tool is on, at
    most every ``PERIOD_S`` and whenever a stretch is finished (the tool switched off at its end). The arm's own
    motion progress ("waypoint 3 of 24") is replaced by it. The measured TCP lags the tool, so the reported length
    never runs ahead of the part actually worked.

    ``hold_s``: how long the spray goes on for sure should LOCEM die now (the compressor's watchdog keeps the valve
    open for its timeout less one poll; the arm's controller goes on along its path meanwhile). While the tool is
    on, each report adds the point the TCP reaches in that time at its measured speed: where a retry after LOCEM's
    death can go on without a gap. ``gaps_m``: for a raster that is one controller path, the path's length from
    each stretch's end to the next one's start, counted as the length the arm covers at lane speed in the time it
    takes (it slows down in the turn; counted long, so the point is never ahead); the point then goes on into the
    following stretches, as the arm and the open valve do. Without
    it (one move per stretch: the arm stops at the stretch's end) the point is at most the stretch's end.

    Speeds come from the controller's own clock (``sample_tick``, else ``sample_time``) when the arm gives it: the times the
    poll answers arrived at jitter on a busy machine, and the slowest of a few jittered speeds was a fraction of
    the true one (a retry then sprayed again what the arm had sprayed on its way after LOCEM died)."""

    #: s of wall time between two reports while the tool is on (20 Hz); sooner when the point the spray reaches
    #: should LOCEM die moved more than JUMP_M (the first speed measured on a stretch)
    PERIOD_S = 0.05
    #: s of TCP samples the speed is measured over (several arm polls at 50 Hz)
    TRACK_S = 0.1
    #: s added to that span: at least the error of a sample's stamp (one RTDE cycle: 2 ms at 500 Hz, 8 ms at 125 Hz)
    STAMP_SLACK_S = 0.01

    def __init__(self, switch: LaneSwitch, arm: Arm, stretches: Sequence[Sequence[Sequence[float]]],
                 starts_m: Sequence[float], total_m: float, reach: float, hold_s: float = 0.0,
                 clock: Callable[[], float] = time.monotonic, gaps_m: Optional[Sequence[float]] = None) -> None:
        """``stretches``: each worked stretch's start and end (arm base frame), ``starts_m`` where each begins in
        metres of the raster, ``total_m`` the raster's whole worked length; ``reach``: distance from a stretch's
        line within which the TCP counts as on it; ``gaps_m``: path length between stretch i's end and stretch
        i+1's start (one controller path), None when the arm stops at each stretch's end."""
        super().__init__(switch)
        self._switch, self._arm, self._clock = switch, arm, clock
        self._lines = [(np.asarray(a[:3], dtype=float), np.asarray(b[:3], dtype=float) - np.asarray(a[:3], dtype=float))
                       for a, b in stretches]
        self._starts = [float(v) for v in starts_m]
        self._total = float(total_m)
        self._reach = reach
        self._lane: Optional[int] = None                 # the stretch the tool was last on
        self._was_on = False
        self._last_report = -1e9
        self._reported = -1.0
        self._reported_ahead = 0.0
        self.done_m = self._starts[0] if self._starts else 0.0
        self._hold_s = max(0.0, hold_s)
        if gaps_m is not None and len(gaps_m) != max(0, len(self._lines) - 1):
            raise ValueError("RasterProgress: %d gaps for %d stretches (one between each two)"
                             % (len(gaps_m), len(self._lines)))
        self._gaps = [max(0.0, float(g)) for g in gaps_m] if gaps_m is not None else None
        self.if_stopped_m: Optional[float] = None         # None while the tool is off
        self._track: List[Tuple[float, np.ndarray]] = []  # (stamp, position) of the TCP samples of TRACK_S
        # report just before the switch opens the valve (its request on the way): a LOCEM killed right after the
        # valve opened has already told where the spray will get to
        switch.before_switch(self._before_switch)

    def _sample_tcp(self) -> Optional[np.ndarray]:
        """The measured TCP position; keeps the new samples of the last ``TRACK_S`` for the TCP's speed."""
        state = self._arm.cached_state()
        tcp = state.get("tcp")
        if not tcp:
            return None
        p = np.asarray(tcp[:3], dtype=float)
        taken = state.get("sample_tick", state.get("sample_time", state.get("stamp")))   # see LaneSwitch._sample
        stamp = float(taken) if taken is not None else self._clock()
        if not self._track or stamp > self._track[-1][0]:
            self._track = [(t, q) for t, q in self._track if t >= stamp - self.TRACK_S] + [(stamp, p)]
        return p

    def _speed(self) -> float:
        """The TCP's speed along its path (m/s): the path travelled over the samples of the last ``TRACK_S``
        divided by their time span and ``STAMP_SLACK_S``. One sample's stamp may be a control cycle off its
        position (the controller's clock and the pose are read one after the other); over a span of several
        samples that error is a small part, where the speed between two samples 20 ms apart was off by half and
        more, and the slack keeps it from making the speed too high. A run-up counts as its mean speed, below the
        speed reached: the point given should LOCEM die stays behind the spray."""
        if len(self._track) < 2 or self._track[-1][0] - self._track[0][0] <= 0.0:
            return 0.0
        path = sum(float(np.linalg.norm(b[1] - a[1])) for a, b in zip(self._track, self._track[1:]))
        return path / (self._track[-1][0] - self._track[0][0] + self.STAMP_SLACK_S)

    def _on_stretch(self, p: np.ndarray) -> Optional[Tuple[int, float]]:
        """(stretch index, fraction 0..1 along it) of the TCP ``p`` while the tool is on (before a stretch's start
        it counts as at the start: the tool switches on a little ahead of the measured TCP), or None."""
        for i, (a, ab) in enumerate(self._lines):
            f = float((p - a).dot(ab)) / max(float(ab.dot(ab)), 1e-12)
            if -0.5 <= f <= 1.05 and float(np.linalg.norm(p - a - ab * f)) <= self._reach:
                return i, f
        return None

    def _at(self, lane: int, f: float) -> None:
        """The measured TCP at fraction ``f`` (unclamped) of stretch ``lane`` with the tool on: done and the point
        the spray reaches should LOCEM die now."""
        self._lane = lane
        length = float(np.linalg.norm(self._lines[lane][1]))
        self._advance(self._starts[lane] + min(1.0, max(0.0, f)) * length)
        ahead = self._reach_if_stopped(lane, f * length)
        self.if_stopped_m = max(ahead, self.done_m, self.if_stopped_m or 0.0)

    def _reach_if_stopped(self, lane: int, along: float) -> float:
        """The raster point the TCP passes ``hold_s`` from now at its recent speed (:meth:`_speed`), from
        ``along`` m into stretch ``lane``: at most the stretch's end, or on a path (``gaps_m``) through the turns
        into the next stretches. The speed is the TCP's along its path, not along the stretch: right after a turn
        the last samples run partly across the lane, at the path's speed all the same."""
        length = float(np.linalg.norm(self._lines[lane][1]))
        speed = self._speed()
        travel = speed * self._hold_s if speed > 0.0 else 0.0       # hold_s may be inf (no watchdog)
        if along < 0.0:                   # before the stretch: the tool reaches its start first
            travel, along = max(0.0, travel + along), 0.0
        along = min(along, length)
        if self._gaps is None or travel <= length - along:
            return self._starts[lane] + min(along + travel, length)
        travel -= length - along
        for i in range(lane + 1, len(self._lines)):
            travel -= self._gaps[i - 1]
            if travel <= 0.0:
                return self._end_of(i - 1)
            stretch = float(np.linalg.norm(self._lines[i][1]))
            if travel <= stretch:
                return self._starts[i] + travel
            travel -= stretch
        return self._end_of(len(self._lines) - 1)

    def _before_switch(self, on: bool) -> None:
        p = self._sample_tcp()
        where = self._on_stretch(p) if on and p is not None else None
        if where is None:
            return
        self._at(*where)
        self._report(self._clock())

    def resume_point(self, p: Optional[np.ndarray], tool_on: bool) -> float:
        """Where a suspended raster goes on (m of the raster): the point ``p`` where the tool stopped working
        while it was on a stretch, else the worked length done."""
        where = self._on_stretch(p) if tool_on and p is not None else None
        if where is None:
            return self.done_m
        lane, f = where
        return max(self.done_m, self._starts[lane] + min(1.0, max(0.0, f)) * float(np.linalg.norm(self._lines[lane][1])))

    def _end_of(self, i: int) -> float:
        return self._starts[i] + float(np.linalg.norm(self._lines[i][1]))

    def _after_wait(self) -> None:
        on = bool(self._switch.on)
        finished = False
        p = self._sample_tcp()
        if on and p is not None:
            where = self._on_stretch(p)
            if where is not None:
                self._at(*where)
        elif self._was_on and self._lane is not None:
            self._advance(self._end_of(self._lane))      # switched off by position: the TCP passed the end
            self.if_stopped_m = None
            finished = True
        self._was_on = on
        now = self._clock()
        ahead = self.if_stopped_m or 0.0
        if (self.done_m > self._reported or ahead > self._reported_ahead) and (
                finished or now - self._last_report >= self.PERIOD_S or ahead - self._reported_ahead > JUMP_M):
            self._report(now)

    def _advance(self, done_m: float) -> None:
        self.done_m = max(self.done_m, min(done_m, self._total))

    def _report(self, now: float) -> None:
        self._last_report, self._reported, self._reported_ahead = now, self.done_m, self.if_stopped_m or 0.0
        super().report(self.done_m / self._total if self._total > 0 else 1.0,
                       progress_text(self.done_m, self._total, self.if_stopped_m))

    def finish(self) -> None:
        """After the motion ended normally: it ends beyond the last stretch, whose end is reported."""
        self._advance(self._end_of(len(self._lines) - 1))
        self.if_stopped_m = None
        if self.done_m > self._reported:
            self._report(self._clock())

    def report(self, progress: float, text: str = "") -> None:
        pass                # the arm's motion progress: the raster's own is reported instead


class WallCommands:
    """Composed plasterboard commands over an arm, a base (pose), a compressor and a scanner (any may be None:
    the commands that need a missing one answer NOT_READY)."""

    name = "wall"

    def __init__(self, robot_cfg: Mapping[str, Any], arm: Optional[Arm] = None, base: Optional[Base] = None,
                 compressor: Optional[Compressor] = None, scanner: Optional[Scanner] = None,
                 lift: Optional[Lift] = None) -> None:
        self.tools = dict(robot_cfg.get("tools", {}))
        mount = robot_cfg.get("arm", {}).get("mount", {})
        self._mount = arm_base_in_footprint(mount.get("xyz", [0.0, 0.0, 0.0]), mount.get("rpy", [0.0, 0.0, 0.0]))
        #: the lift carrying the arm (robot.lift): the arm's base frame is at its height, not at mount.xyz's z
        self.lift = lift
        self.arm, self.base, self.compressor, self.scanner = arm, base, compressor, scanner
        self.active_tool: Optional[str] = None
        #: called with the tool after every MOUNT_TOOL (the LOCEM node keeps it for a respawned LOCEM)
        self.tool_listener: Optional[Callable[[str], None]] = None
        arm_cfg = robot_cfg.get("arm", {})
        self.home_via: Optional[str] = arm_cfg.get("home_via") or None
        flange = arm_cfg.get("wall_ready_flange")
        self.ready_flange: Optional[List[float]] = [float(v) for v in flange] if flange else None
        #: a robot with an automatic tool changer: its tools carry changer plates, only the changer couples them
        #: (CHANGE_TOOL, bridges/commands_changer.py), so MOUNT_TOOL is not offered
        self.changer_fitted = "tool_changer" in robot_cfg

    def specs(self) -> Iterable[CommandSpec]:
        specs = wall_specs(tuple(self.tools))
        return tuple(s for s in specs if not (self.changer_fitted and s.name == "MOUNT_TOOL"))

    def handlers(self) -> Dict[str, Any]:
        out = {"SCAN": self.scan, "MOUNT_TOOL": self.mount_tool, "APPLY_TAPE_START": self.apply_tape_start,
                "APPLY_TAPE": self.apply_tape, "SPRAY_AREA": self.spray_area, "SAND_AREA": self.sand_area,
                "WALL_READY": self.wall_ready, "HOME": self.home, "GET_TOOL_POINT": self.get_tool_point}
        if self.changer_fitted:
            del out["MOUNT_TOOL"]
        return out

    def stop(self) -> None:
        self._outputs_off()

    def health(self) -> Dict[str, Any]:
        return {"link": "up", "device": "ok", "last_error": "", "active_tool": self.active_tool or ""}

    def restore_tool(self, tool: str) -> None:
        """What a previous LOCEM had mounted (it died; the tool is still on the arm): the active tool again, its
        TCP offset and payload set on the controller before the next motion. Raises BadRequest for a tool not in
        robot.tools."""
        if tool not in self.tools:
            raise BadRequest("tool %s is not in robot.tools (%s)" % (tool, ", ".join(sorted(self.tools))),
                             argument="tool")
        self.active_tool = tool

    # -- helpers -----------------------------------------------------------------------------------------
    def _need(self, what: str) -> Any:
        dev = getattr(self, what)
        if dev is None:
            raise NotReady("this robot has no %s backend configured" % what)
        return dev

    def _need_tool(self, tool: str) -> None:
        if self.active_tool != tool:
            raise NotReady("the %s is needed but the active tool is %s; %s"
                           % (tool, self.active_tool or "none", "send CHANGE_TOOL tool=%s" % tool
                              if self.changer_fitted else "mount it and send MOUNT_TOOL %s" % tool))
        self._apply_tool()

    def _apply_tool(self) -> None:
        """The active tool's TCP offset and payload on the controller. They live in the controller's running
        program: a restarted control script (ur_rtde uploads it again for every path move, and after a stop or
        a reconnect) starts with the installation's, so every wall command sets the active tool's again before
        it moves."""
        if self.active_tool is None:
            return
        cfg = self.tools[self.active_tool]
        arm = self._need("arm")
        arm.set_tcp([float(v) for v in cfg["tcp"]])
        arm.set_payload(float(cfg["mass"]), [float(v) for v in cfg["cog"]])

    @property
    def mount(self) -> np.ndarray:
        """base_footprint <- arm base_link now: ``robot.arm.mount``, raised to the lift's height on a lift."""
        if self.lift is None:
            return self._mount
        moved = self._mount.copy()
        moved[2, 3] = self.lift.height()
        return moved

    def _map_arm(self) -> np.ndarray:
        """``map <- arm base`` now: the base's odometry pose and the arm's mount (at the lift's height)."""
        x, y, th = self._need("base").pose()
        return planar(x, y, th).dot(self.mount)

    def _localised(self, ctx: Any) -> None:
        """Before a wall command computes its first target: the base's pose holds the localisation fix that
        follows its stop (:meth:`~locem_bridge.bridges.interfaces.Base.wait_localised`, at most
        LOCALISED_WAIT_S), so all its targets come from one settled pose."""
        late = self._need("base").wait_localised(ctx, LOCALISED_WAIT_S)
        if late:
            log.info("%s", late)

    def to_arm(self, point: Sequence[float], normal: Sequence[float]) -> List[float]:
        """TCP pose (arm base frame) at a map ``point`` facing the wall with inward ``normal``."""
        t_map_arm = self._map_arm()
        try:
            frame = tool_frame_facing(point, normal)
        except ValueError as error:
            raise BadRequest(str(error), argument="nx")
        return matrix_to_pose(invert(t_map_arm).dot(frame))

    def _switch(self, tool: str, on: bool) -> None:
        sw = self.tools.get(tool, {}).get("switch", {})
        if sw.get("source") == "ur_digital_out":
            self._need("arm").set_digital_output(int(sw["index"]), on)
        elif sw.get("source") == "compressor_valve":
            self._need("compressor").set_valve(on)

    def _outputs_off(self) -> None:
        for tool in self.tools:
            try:
                self._switch(tool, False)
            except (BridgeError, NotReady):
                pass

    def _approach(self, ctx: Any, pose: Sequence[float]) -> None:
        """Bring the TCP to ``pose``. When the tool already points the way ``pose`` does (within
        ``STRAIGHT_APPROACH_ANGLE``: the arm comes from ``wall_ready`` or from the previous wall pose) a straight
        move, which keeps the tool and links in front of the robot; otherwise a joint move to the controller's
        IK solution (large re-orientation), then an exact straight move."""
        arm = self._need("arm")
        if angle_between(arm.tcp_pose(), pose) <= STRAIGHT_APPROACH_ANGLE:
            arm.move_linear(ctx, pose, APPROACH_SPEED, 1.2)
            return
        q = arm.inverse_kinematics(pose)
        arm.move_joints(ctx, q, 1.0, 2.0)
        arm.move_linear(ctx, pose, APPROACH_SPEED, 1.2)

    def _retract(self, ctx: Any) -> None:
        """From a wall pose (tool pointing forward): one straight move to the TCP point of 'wall_ready' (its
        flange point ``robot.arm.wall_ready_flange`` plus the active tool's length), tool still facing forward,
        so the joint move to 'wall_ready' that may follow is short and away from the wall."""
        if self.ready_flange is None:
            return
        self._apply_tool()                       # the TCP the straight move below is computed for
        if not self._facing_forward():
            return
        length = float(self.tools.get(self.active_tool or "", {}).get("tcp", [0.0, 0.0, 0.0])[2])
        mount = self.mount                       # wall_ready_flange is given for the configured mount: it rides along
        point = [self.ready_flange[0] + length, self.ready_flange[1],
                 self.ready_flange[2] + float(mount[2, 3] - self._mount[2, 3])]
        pose = matrix_to_pose(invert(mount).dot(tool_frame_facing(point, [-1.0, 0.0, 0.0])))
        self._need("arm").move_linear(ctx, pose, APPROACH_SPEED, 1.2)

    # -- suspension (bridges/suspension.py) -----------------------------------------------------------------
    def _resumable(self, ctx: Any, tool: Optional[str], live: Optional[Dict[str, Any]] = None,
                   lift_off: bool = False) -> Resumable:
        """Suspend: the tool's process output off first (spray valve, taping tool, sander), then the arm
        decelerates along its path; a raster notes where its tool stopped working (``live['skip']``); with
        ``lift_off`` the tool then backs off the wall by LIFT_OFF along its axis. The compressor keeps its
        pressure. Resume: the interrupted step again from there (a raster from its skip point, run-up first)."""
        arm = self._need("arm")

        def stop() -> None:
            sw = live.get("switch") if live is not None else None
            p = sw.hold_off() if sw is not None else None
            on = bool(sw.on) if sw is not None else False
            if tool is not None:
                self._switch_off_safely(tool)
            if live is not None and live.get("progress") is not None:
                live["skip"] = max(live["skip"], live["progress"].resume_point(p, on))
            if live is not None and live.get("lane") is not None:
                live["at"] = arm.tcp_pose()
            arm.stop_motion("suspended")

        def off_the_wall(waiter: Any) -> None:
            pose = arm.tcp_pose()
            z = pose_to_matrix(pose)[:3, 2]                     # the tool axis, pointing at the wall
            lifted = [pose[0] - z[0] * LIFT_OFF, pose[1] - z[1] * LIFT_OFF, pose[2] - z[2] * LIFT_OFF] + list(pose[3:])
            arm.move_linear(waiter, lifted, CONTACT_SPEED, 1.0)

        return Resumable(ctx, stop, on_suspended=off_the_wall if lift_off else None, settle=arm_settle(arm))

    def _facing_forward(self) -> bool:
        """True when the tool axis points ahead of the base (the arm is working at or near a wall)."""
        arm = self._need("arm")
        rot = pose_to_matrix(arm.tcp_pose())[:3, :3]
        z_in_footprint = self.mount[:3, :3].dot(rot[:, 2])
        return float(z_in_footprint[0]) > 0.5

    @staticmethod
    def _unit(v: Sequence[float], name: str) -> np.ndarray:
        a = np.asarray(v, dtype=float)
        n = float(np.linalg.norm(a))
        if n < 1e-6:
            raise BadRequest("%s must not be the zero vector" % name, argument=name)
        return a / n

    # -- handlers ----------------------------------------------------------------------------------------
    def scan(self, ctx: Any) -> Dict[str, Any]:
        result = self._need("scanner").scan(self._need("base").pose())
        result["message"] = "%d walls, %d joints, %d areas" % (len(result.get("walls", [])),
                                                               len(result.get("joints", [])),
                                                               len(result.get("areas", [])))
        return result

    def mount_tool(self, ctx: Any, tool: str) -> Dict[str, Any]:
        if tool not in self.tools:
            raise BadRequest("tool %s is not in robot.tools (%s)" % (tool, ", ".join(sorted(self.tools))),
                             argument="tool")
        self._outputs_off()
        return self.activate_tool(tool)

    def activate_tool(self, tool: Optional[str]) -> Dict[str, Any]:
        """``tool`` is on the flange now (None: nothing is): its TCP offset and payload (none: the flange, 0 kg)
        on the controller, the active tool of the wall commands; MOUNT_TOOL and CHANGE_TOOL end with it."""
        arm = self._need("arm")
        cfg = self.tools[tool] if tool is not None else {"tcp": [0.0] * 6, "mass": 0.0, "cog": [0.0] * 3}
        arm.set_tcp([float(v) for v in cfg["tcp"]])
        arm.set_payload(float(cfg["mass"]), [float(v) for v in cfg["cog"]])
        self.active_tool = tool
        if self.tool_listener is not None:
            self.tool_listener(tool or "")           # "": nothing on the flange
        return {"tool": tool or "", "tcp": cfg["tcp"], "mass": cfg["mass"]}

    def get_tool_point(self, ctx: Any) -> Dict[str, Any]:
        self._apply_tool()              # a restarted controller holds the installation's TCP, not the tool's
        time.sleep(0.02)                # its measured TCP pose follows the new offset within a control cycle or two
        frame = self._map_arm().dot(pose_to_matrix(self._need("arm").tcp_pose()))
        point = [round(float(v), 5) for v in frame[:3, 3]]
        axis = [round(float(v), 5) for v in frame[:3, 2]]
        return {"point": point, "axis": axis, "tool": self.active_tool or "",
                "message": "%s at %.4f %.4f %.4f" % (self.active_tool or "flange", point[0], point[1], point[2])}

    def apply_tape_start(self, ctx: Any, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float,
                         nx: float, ny: float, nz: float, approach: float) -> Dict[str, Any]:
        self._need_tool("taping_tool")
        n = self._unit([nx, ny, nz], "normal")
        p0 = np.array([x0, y0, z0])
        self._localised(ctx)
        pose = self.to_arm(p0 + n * approach, n)
        self._resumable(ctx, None).run(lambda: self._approach(ctx, pose))
        return {"tcp_pose": pose}

    def apply_tape(self, ctx: Any, x0: float, y0: float, z0: float, x1: float, y1: float, z1: float, nx: float,
                   ny: float, nz: float, speed: float, offset: float, approach: float) -> Dict[str, Any]:
        self._need_tool("taping_tool")
        arm = self._need("arm")
        n = self._unit([nx, ny, nz], "normal")
        p0, p1 = np.array([x0, y0, z0]), np.array([x1, y1, z1])
        length = float(np.linalg.norm(p1 - p0))
        if length < 1e-3:
            raise BadRequest("APPLY_TAPE: the line is shorter than 1 mm", argument="x1")
        start = time.monotonic()
        self._localised(ctx)

        def tape() -> None:          # resumed: on again where the roller stopped, on along the rest of the line
            self._switch("taping_tool", True)
            ctx.report(0.1, "taping")
            arm.move_linear(ctx, self.to_arm(p1 + n * offset, n), speed, 1.0)

        steps = Steps([lambda: self._approach(ctx, self.to_arm(p0 + n * approach, n)),
                       lambda: arm.move_linear(ctx, self.to_arm(p0 + n * offset, n), CONTACT_SPEED, 1.0),
                       tape,
                       lambda: self._switch("taping_tool", False),
                       lambda: arm.move_linear(ctx, self.to_arm(p1 + n * approach, n), APPROACH_SPEED, 1.2),
                       lambda: self._retract(ctx)])
        resumable = self._resumable(ctx, "taping_tool")
        try:
            resumable.run(steps.run)
        finally:
            self._switch_off_safely("taping_tool")
        return {"length_m": length, "duration_s": round(time.monotonic() - start, 3),
                "suspensions": resumable.suspensions}

    def _switch_off_safely(self, tool: str) -> None:
        try:
            self._switch(tool, False)
        except (BridgeError, NotReady):
            pass

    @staticmethod
    def _raster_lanes(heights: Sequence[float], width: float, run_in: float,
                      skip: float) -> List[Tuple[int, float, float, float, float]]:
        """The lanes still to work after ``skip`` m of the raster's worked length (module
        :mod:`locem_bridge.common.raster_progress`): ``(k, height, w0, w1, start_m)`` with the worked stretch
        ``w0 -> w1`` along the area (lane k runs forward when k is even; the first lane left may start part way)
        and ``start_m`` its start in metres of the raster. Lanes with less than ``SKIP_RESOLUTION`` left are
        dropped."""
        lane_len = width + 2.0 * run_in
        out = []
        for k, t in enumerate(heights):
            forward = k % 2 == 0
            w0, w1 = (-run_in, width + run_in) if forward else (width + run_in, -run_in)
            begin = k * lane_len
            cut = min(max(skip - begin, 0.0), lane_len)
            if lane_len - cut < SKIP_RESOLUTION:
                continue
            w0 = w0 + cut if forward else w0 - cut
            out.append((k, t, w0, w1, begin + cut))
        return out

    def _raster(self, ctx: Any, tool: str, origin: Sequence[float], u: Sequence[float], width: float,
                height: float, normal: Sequence[float], spacing: float, speed: float, offset: float,
                run_in: float, skip: float = 0.0, hold_s: float = 0.0,
                live: Optional[Dict[str, Any]] = None, across: Optional[Sequence[float]] = None) -> Dict[str, Any]:
        """Lanes along ``u`` stacked along ``across`` (default: up; horizontal lanes from the area's bottom to its
        top), alternating direction. Each lane is one straight
        move that starts ``run-up`` before the worked stretch [-run_in, width + run_in] and ends as far after
        it (the distance the arm needs to reach ``speed`` at ``LANE_ACCEL``); the tool is on only over the
        worked stretch (:class:`LaneSwitch`). ``skip``: metres of the raster's worked length (the stretches end
        to end) left out from its start, so the first lane worked may start part way, with its own run-up.
        Progress (:class:`RasterProgress`): the worked length done, counted from the raster's start; ``hold_s``:
        how long the tool stays on should LOCEM die (see there). ``live``: the running lane's switch and progress
        are kept there for a suspension (:meth:`_resumable`)."""
        arm = self._need("arm")
        live = live if live is not None else {}
        n = self._unit(normal, "normal")
        uu = self._unit(u, "u")
        up = np.array([0.0, 0.0, 1.0]) if across is None else self._unit(across, "across")
        o = np.asarray(origin, dtype=float)
        heights = lane_heights(height, spacing)
        total_m = len(heights) * (width + 2.0 * run_in)
        lanes = self._raster_lanes(heights, width, run_in, skip)
        start = time.monotonic()
        if not lanes:
            ctx.report(1.0, progress_text(total_m, total_m))
            return {"length_m": 0.0, "lanes": 0, "skipped_m": round(min(skip, total_m), 4),
                    "duration_s": round(time.monotonic() - start, 3)}
        self._localised(ctx)
        runup = speed * speed / (2.0 * LANE_ACCEL) + RUNUP_MARGIN
        # one blended path when the arm has them: always for a tool switched along the path (a resume into the
        # last lane gets its lead-in too), else for two lanes or more
        if arm.supports(Arm.PATH) and len(heights) > 1 and (len(lanes) > 1 or tool in SWITCH_LEADS):
            out = self._raster_path(ctx, tool, o, uu, up, n, heights, lanes, total_m, speed, offset, hold_s, live)
        else:
            s1 = 0.0
            for i, (k, t, w0, w1, start_m) in enumerate(lanes):
                forward = k % 2 == 0
                s0, s1 = (w0 - runup, w1 + runup) if forward else (w0 + runup, w1 - runup)
                a = o + uu * s0 + up * t + n * offset
                b = o + uu * s1 + up * t + n * offset
                if i == 0:
                    self._approach(ctx, self.to_arm(a + n * 0.05, n))
                arm.move_linear(ctx, self.to_arm(a, n), APPROACH_SPEED, 1.2)
                pa, pb = self.to_arm(a, n), self.to_arm(b, n)
                span = abs(s1 - s0)
                lane = LaneSwitch(ctx, arm, lambda on: self._switch(tool, on), pa, pb,
                                  runup / span, 1.0 - runup / span, time.time, *SWITCH_LEADS.get(tool, NO_LEADS))
                lane.prime()
                stretch = (self.to_arm(o + uu * w0 + up * t + n * offset, n),
                           self.to_arm(o + uu * w1 + up * t + n * offset, n))
                progress = RasterProgress(lane, arm, [stretch], [start_m], total_m, reach=0.05, hold_s=hold_s)
                live.update(switch=lane, progress=progress)
                try:
                    arm.move_linear(progress, pb, speed, LANE_ACCEL)
                finally:
                    live.update(switch=None, progress=None)
                    self._switch_off_safely(tool)
                progress.finish()
                live["skip"] = max(live.get("skip", 0.0), progress.done_m)
            t_last = lanes[-1][1]
            last = o + uu * s1 + up * t_last + n * (offset + 0.05)
            arm.move_linear(ctx, self.to_arm(last, n), APPROACH_SPEED, 1.2)
            self._retract(ctx)
            out = {"lanes": len(lanes)}
        out.update({"length_m": round(sum(abs(w1 - w0) for _k, _t, w0, w1, _s in lanes), 4),
                    "skipped_m": round(lanes[0][4], 4), "duration_s": round(time.monotonic() - start, 3)})
        return out

    def _raster_path(self, ctx: Any, tool: str, o: np.ndarray, uu: np.ndarray, up: np.ndarray, n: np.ndarray,
                     heights: Sequence[float], lanes: Sequence[Tuple[int, float, float, float, float]],
                     total_m: float, speed: float, offset: float, hold_s: float = 0.0,
                     live: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """The serpentine as ONE blended controller path (MOVE_PATH semantics): each lane's ends, run-up
        included, are waypoints; the turns between lanes are rounded (blend within the run-up, so the worked
        stretches are straight and at speed); the tool is switched by position (:class:`RasterSwitch`).

        For the spray gun (switched along the path) the path starts with a lead-in: ``LEAD_IN`` m (at most the
        lane's length) against the first lane's direction, half a lane spacing beside it (towards the next lane;
        towards the previous one when it is the last), then a turn into the first lane like every other (also when
        a resume left the last lane alone). So the
        first lane too is entered at speed while LOCEM watches the arm: a path starts moving while its request is
        still being answered, which takes tens of milliseconds (centimetres of travel at a time scale of 10, more on
        a busy machine), and an arm starting from rest right before the stretch had often passed its start before
        the first decision. (The sander, in contact with the wall, has none: it would rub the wall with its motor
        off.)"""
        arm = self._need("arm")
        spacing = abs(heights[1] - heights[0])
        blend = min(PATH_BLEND, 0.45 * spacing)
        lead_blend = min(PATH_BLEND, 0.45 * spacing / 2.0)
        runup = speed * speed / (2.0 * LANE_ACCEL) + RUNUP_MARGIN + blend
        points, stretches, starts, ends = [], [], [], []
        for k, t, w0, w1, start_m in lanes:
            sign = 1.0 if k % 2 == 0 else -1.0
            a = o + uu * (w0 - sign * runup) + up * t + n * offset
            b = o + uu * (w1 + sign * runup) + up * t + n * offset
            points += [a, b]
            ends.append((o + uu * w0 + up * t + n * offset, o + uu * w1 + up * t + n * offset))
            stretches.append((self.to_arm(ends[-1][0], n), self.to_arm(ends[-1][1], n)))
            starts.append(start_m)
        gaps = path_gaps(points, ends, speed, blend, spacing)
        by_path = tool in SWITCH_LEADS                   # switched along the path (RasterSwitch), with a lead-in
        if by_path:
            k0, _t, w0, w1, _s = lanes[0]
            sign = 1.0 if k0 % 2 == 0 else -1.0
            beside = up * (spacing / 2.0) * (1.0 if k0 + 1 < len(heights) else -1.0)
            lead = min(LEAD_IN, abs(w1 - w0) + 2.0 * runup)
            points = [points[0] + beside + uu * sign * lead, points[0] + beside] + points
        self._approach(ctx, self.to_arm(points[0] + n * 0.05, n))
        arm.move_linear(ctx, self.to_arm(points[0], n), APPROACH_SPEED, 1.2)
        poses = [self.to_arm(p, n) for p in points[1:]]
        # every turn blended (the lead-in's two with the half spacing's radius), the path ends at rest
        blends = ([lead_blend, lead_blend] if by_path else []) + [blend] * (len(poses) - (3 if by_path else 1)) + [0.0]
        switch = RasterSwitch(ctx, arm, lambda on: self._switch(tool, on), stretches, 0.25 * spacing, time.time,
                              *SWITCH_LEADS.get(tool, NO_LEADS),
                              path=[self.to_arm(points[0], n)] + poses if by_path else None)
        switch.prime()
        progress = RasterProgress(switch, arm, stretches, starts, total_m, reach=0.25 * spacing, hold_s=hold_s,
                                  gaps_m=gaps)
        live = live if live is not None else {}
        live.update(switch=switch, progress=progress)
        try:
            arm.move_path(progress, poses, speed, LANE_ACCEL, blends)
        finally:
            live.update(switch=None, progress=None)
            self._switch_off_safely(tool)
        progress.finish()
        live["skip"] = max(live.get("skip", 0.0), progress.done_m)
        last = points[-1] + n * 0.05
        arm.move_linear(ctx, self.to_arm(last, n), APPROACH_SPEED, 1.2)
        self._retract(ctx)
        return {"lanes": len(lanes)}

    def spray_area(self, ctx: Any, ox: float, oy: float, oz: float, ux: float, uy: float, uz: float, width: float,
                   height: float, nx: float, ny: float, nz: float, spacing: float, standoff: float, speed: float,
                   pressure: float, run_in: float = 0.1, skip: float = 0.0) -> Dict[str, Any]:
        self._need_tool("spray_gun")
        comp = self._need("compressor")
        lo, hi = comp.pressure_range
        if not lo <= pressure <= hi:
            raise BadRequest("SPRAY_AREA: pressure %.2f bar is outside the working band %.2f..%.2f bar"
                             % (pressure, lo, hi), argument="pressure")
        heights = lane_heights(height, spacing)
        total_m = len(heights) * (width + 2.0 * run_in)
        if skip > total_m + SKIP_RESOLUTION:
            raise BadRequest("SPRAY_AREA: skip %.3f m is beyond the raster's worked length %.3f m (%d lanes of "
                             "width + 2 x run_in = %.3f m); allowed 0..%.3f m"
                             % (skip, total_m, len(heights), width + 2.0 * run_in, total_m), argument="skip")
        if not self._raster_lanes(heights, width, run_in, skip):
            ctx.report(1.0, progress_text(total_m, total_m))         # nothing left: no device is touched
            return {"length_m": 0.0, "lanes": 0, "skipped_m": round(min(skip, total_m), 4), "duration_s": 0.0}
        guarded = GuardedWaiter(ctx, comp.check_link)
        # should LOCEM die, the compressor's watchdog keeps the valve open for its timeout less one poll
        # (none: open until the arm stops, at the stretch's end or, on a path, the raster's end)
        hold_s = (max(0.0, comp.watchdog_timeout - 1.0 / comp.poll_rate) if comp.watchdog_timeout > 0
                  else float("inf"))
        live: Dict[str, Any] = {"skip": skip}

        def pressure_up() -> None:
            comp.check_link()
            comp.set_valve(False)
            comp.set_motor(True)
            comp.set_setpoint(pressure)
            wait_for_pressure(comp, guarded, pressure, 0.2, timeout=30.0)

        steps = Steps([pressure_up, lambda: self._raster(
            guarded, "spray_gun", [ox, oy, oz], [ux, uy, uz], width, height, [nx, ny, nz], spacing, speed, standoff,
            run_in=run_in, skip=live["skip"], hold_s=hold_s, live=live)])
        resumable = self._resumable(ctx, "spray_gun", live)
        try:
            out = resumable.run(steps.run)
        finally:
            self._switch_off_safely("spray_gun")
        return self._worked(out, total_m, skip, resumable.suspensions)

    @staticmethod
    def _worked(out: Dict[str, Any], total_m: float, skip: float, suspensions: int) -> Dict[str, Any]:
        """A raster's result over all its attempts: the length worked from ``skip`` on, and the suspensions."""
        if suspensions:
            out["length_m"] = round(max(0.0, total_m - skip), 4)
            out["skipped_m"] = round(min(skip, total_m), 4)
        out["suspensions"] = suspensions
        return out

    def sand_area(self, ctx: Any, ox: float, oy: float, oz: float, ux: float, uy: float, uz: float, width: float,
                  height: float, nx: float, ny: float, nz: float, spacing: float, speed: float,
                  force: float, contact: str = "position", lanes: str = "horizontal") -> Dict[str, Any]:
        """Raster lanes over the area. ``contact=force``: each lane starts ``standoff`` in front of the wall, force
        mode pushes along the tool axis until the contact force is within tolerance, the sander runs while the
        lane is followed under force control, then force mode ends and the tool lifts back to the standoff.
        ``lanes=vertical``: the lanes run upwards over ``height`` and are stacked along u over ``width``."""
        vertical = lanes == "vertical"
        if width < 0.01 and not vertical:
            raise BadRequest("SAND_AREA: width %.3f m: horizontal lanes need a width of at least 0.01 m; width 0 "
                             "is allowed with lanes=vertical (one lane up the origin's side)" % width,
                             argument="width")
        self._need_tool("sander")
        arm = self._need("arm")
        up_axis = [0.0, 0.0, 1.0]
        # the lanes' direction and the direction they are stacked in, with their extents
        along, across, length, extent = ((up_axis, [ux, uy, uz], height, width) if vertical
                                         else ([ux, uy, uz], up_axis, width, height))
        if contact != "force" or not arm.supports(Arm.FORCE):
            live: Dict[str, Any] = {"skip": 0.0}
            resumable = self._resumable(ctx, "sander", live, lift_off=True)
            try:
                out = resumable.run(lambda: self._raster(ctx, "sander", [ox, oy, oz], along, length, extent,
                                                         [nx, ny, nz], spacing, speed, 0.0, run_in=0.0,
                                                         skip=live["skip"], live=live, across=across))
            finally:
                self._switch_off_safely("sander")
            out = self._worked(out, len(lane_heights(extent, spacing)) * length, 0.0, resumable.suspensions)
            out["force_n"] = force
            out["contact"] = "position"
            return out
        if force <= 0:
            raise BadRequest("SAND_AREA: contact=force needs force > 0 N", argument="force")
        standoff, approach_speed, tolerance = 0.01, 0.02, max(1.0, 0.1 * force)     # m, m/s along the axis, N
        n = self._unit([nx, ny, nz], "normal")
        uu = self._unit(along, "u")
        up = self._unit(across, "u")
        o = np.array([ox, oy, oz], dtype=float)
        heights = lane_heights(extent, spacing)          # lanes of ``length`` along uu, at heights along up
        start = time.monotonic()
        total = 0.0
        samples: List[float] = []
        end_pose: Optional[List[float]] = None
        # a suspension in a lane: the lane goes on from the point where the sander stopped (live['at'], the TCP
        # then), approached again at the standoff with force mode, as a lane's start
        live: Dict[str, Any] = {"k": 0, "f": 0.0, "lane": None, "at": None}
        resumable = self._resumable(ctx, "sander", live, lift_off=True)
        self._localised(ctx)

        def work_lanes() -> None:
            nonlocal total, end_pose
            first = True
            for k in range(live["k"], len(heights)):
                t = heights[k]
                s0, s1 = (0.0, length) if k % 2 == 0 else (length, 0.0)
                s0 = s0 + (s1 - s0) * live["f"]
                a = o + uu * s0 + up * t + n * standoff
                b = o + uu * s1 + up * t + n * standoff
                if first:
                    self._approach(ctx, self.to_arm(a + n * 0.05, n))
                    first = False
                pa, pb = self.to_arm(a, n), self.to_arm(b, n)
                arm.move_linear(ctx, pa, APPROACH_SPEED, 1.2)
                arm.force_mode_start(pa, force, approach_speed)
                arm.wait_for_contact(ctx, tolerance, standoff + 0.01, timeout=standoff / approach_speed * 4 + 5.0)
                self._switch("sander", True)
                arm.record_force(True)
                live.update(lane=(pa, pb, s0, s1), at=None)
                try:
                    arm.move_linear(ctx, pb, speed, 1.2)
                except BaseException:
                    at, (qa, qb, _s0, _s1) = live["at"], live["lane"]
                    if at is not None:          # suspended: where along this lane the sander stopped
                        ab = np.asarray(qb[:3]) - np.asarray(qa[:3])
                        f = float((np.asarray(at[:3]) - np.asarray(qa[:3])).dot(ab)) / max(float(ab.dot(ab)), 1e-12)
                        live["f"] = live["f"] + (1.0 - live["f"]) * min(max(f, 0.0), 1.0)
                        live["k"] = k
                        total += abs(s1 - s0) * min(max(f, 0.0), 1.0)
                    raise
                finally:
                    live["lane"] = None
                arm.record_force(False)
                self._switch_off_safely("sander")
                stats = arm.force_mode_stop()
                if stats.get("samples"):
                    samples.extend([stats["min"], stats["max"]])
                    total += abs(s1 - s0)
                arm.move_linear(ctx, pb, APPROACH_SPEED, 1.2)      # lift back to the standoff
                end_pose = pb
                live.update(k=k + 1, f=0.0)
                ctx.report((k + 1) / len(heights), "lane %d of %d" % (k + 1, len(heights)))
        try:
            resumable.run(work_lanes)
        finally:
            self._switch_off_safely("sander")
            arm.force_mode_stop()
        if end_pose is not None:
            last = o + uu * (length if len(heights) % 2 else 0.0) + up * heights[-1] + n * 0.05
            arm.move_linear(ctx, self.to_arm(last, n), APPROACH_SPEED, 1.2)
        return {"length_m": round(total, 4), "lanes": len(heights), "duration_s": round(time.monotonic() - start, 3),
                "force_n": force, "contact": "force", "suspensions": resumable.suspensions,
                "force_min_n": round(min(samples), 2) if samples else None,
                "force_max_n": round(max(samples), 2) if samples else None}

    def wall_ready(self, ctx: Any) -> Dict[str, Any]:
        arm = self._need("arm")
        q = arm.named_pose("wall_ready")
        steps = Steps([lambda: self._retract(ctx), lambda: arm.move_joints(ctx, q, 1.0, 1.4)])
        return self._resumable(ctx, None).run(steps.run)

    def home(self, ctx: Any) -> Dict[str, Any]:
        self._outputs_off()
        arm = self._need("arm")
        q = arm.named_pose("home")
        steps = Steps([lambda: self.clear_of_wall(ctx), lambda: arm.move_joints(ctx, q, 1.0, 1.4)])
        return self._resumable(ctx, None).run(steps.run)

    def clear_of_wall(self, ctx: Any) -> None:
        """From a wall pose (tool pointing forward): the straight retract, then ``robot.arm.home_via``, so the
        joint move that follows (HOME, CHANGE_TOOL) starts away from the wall."""
        arm = self._need("arm")
        if self.home_via and self._facing_forward():
            self._retract(ctx)
            arm.move_joints(ctx, arm.named_pose(self.home_via), 1.0, 1.4)
