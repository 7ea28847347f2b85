"""Shared helpers of the job rostest suites (``test/ros/job_*.test``).

Each suite includes the REAL ``launch/plasterboard.launch`` (sim worksite, LOCEM with its bridges, PEMKRE,
HICEM, operator_hmi, the job node) and adds one test node. The .test file gives the test node the launch's
settings as private parameters (``results_dir``, ``hmi_port``, ``host``, ``modbus_port``, ...). The job node is
``required`` in the launch: when it exits after writing the report, roslaunch shuts everything down, so a test
node reads what it needs from the ROS graph while the job runs and the rest from ``report.json`` (it waits for
the file; the job writes the run folder under a temporary name and renames it, so a reader never sees half a
report).

Addresses: plasterboard.launch does not expose the stand-ins' addresses, so each .test sets, after the include,
the sim node's ``~host``, ``~modbus_port``, ``~can_channel``, ``~can_port`` and LOCEM's ``~robot_overrides``
(roslaunch keeps the last value given to a parameter): suites never meet each other or a main job on the
default 127.0.0.1 addresses. Results and state (PEMKRE store, HDICT) go under ``$ROS_HOME`` (a fresh folder per
run under test_rostest_suites.py), in a folder named with ``$(anon ...)``.

What is here:

- :func:`setting` - one private parameter of the test node, with a clear error when the .test lacks it;
- :class:`HicemTimeline` - every ``/hicem/state`` and ``/hicem/prompts`` message with its arrival time;
- :class:`SimCalls` - the simulator's ``/sim/*`` JsonCall services (outcome, faults);
- :class:`HmiClient` - the operator page's JSON API over HTTP, with the headers a browser on that page sends;
- :class:`MotionProbe` - device ground truth: arm joint speeds and tool outputs straight from the UR controller
  stand-in over RTDE (the real ur_rtde receive client), base pose from ``/sim/ground_truth/base_pose``, the
  spray valve from the compressor stand-in over Modbus TCP (the real pymodbus client);
- :func:`node_pid`, :func:`pemkre_rows`, :func:`feature_status` - the ROS graph and PEMKRE's world state;
- :func:`wait_for_report`, :func:`outcome_goal_failures`, :func:`kpi_count` - the run report.

Sim time: the worksite's clock runs ``time_scale`` sim seconds per wall second from its start (linear, see
``locem_bridge.sim.clock``), so a wall interval times ``time_scale`` is the sim interval.
"""
import inspect
import json
import math
import os
import signal
import threading
import time
import urllib.error
import urllib.request
from typing import Any, Callable, Dict, List, Optional, Tuple

import rospy
from geometry_msgs.msg import Pose2D

from locem_bridge.msg import HicemPrompt, HicemState, Status as LocemStatus
from locem_bridge.srv import JsonCall

ONT = "https://locem-bridge.example.org/ont/plasterboard#"
TAPING = ONT + "TapingProcess"
SPRAYING = ONT + "SprayingProcess"
SANDING = ONT + "SandingProcess"
TERMINAL = ("ended", "failed", "stopped")


class SuiteSetupError(AssertionError):
    """The .test file or the stack under test is not what the suite needs (named in the message)."""


_INTERRUPTED = threading.Event()


def init_test_node(name: str) -> None:
    """``rospy.init_node`` for a job suite's test node, keeping SIGINT from killing it mid-assertion.

    The job node is ``required`` in plasterboard.launch: when it exits (right after writing report.json)
    roslaunch sends SIGINT to every process, this test node included, and rostest then reads the test node's
    results file. The test node records the SIGINT (see :func:`launch_shutting_down`) and finishes its
    assertions and results file instead; roslaunch waits up to 15 s for it before escalating to SIGTERM.
    """
    rospy.init_node(name, anonymous=True)
    signal.signal(signal.SIGINT, lambda _sig, _frame: _INTERRUPTED.set())


def launch_shutting_down() -> bool:
    """True once roslaunch has asked this node to exit (the job ended or died)."""
    return _INTERRUPTED.is_set()


def setting(name: str, default: Any = None) -> Any:
    """Private parameter ``~name`` of the test node (set by ``<param>`` inside the ``<test>`` tag)."""
    value = rospy.get_param("~" + name, default)
    if value is None:
        raise SuiteSetupError("the .test file must give the test node the parameter '%s'" % name)
    return value


def wait_until(predicate: Callable[[], Any], timeout: float, period: float = 0.05) -> Any:
    """Poll ``predicate`` until it returns a true value or ``timeout`` wall seconds pass; returns its value."""
    end = time.monotonic() + timeout
    while time.monotonic() < end and not rospy.is_shutdown() and not _INTERRUPTED.is_set():
        value = predicate()
        if value:
            return value
        time.sleep(period)
    return predicate()


# ---------------------------------------------------------------------------------------------------- HICEM
class LocemResults:
    """Results of the LOCEM commands that succeeded, from /locem/status (name -> list of result objects, each
    with the command string as received under ``_command``)."""

    def __init__(self, ns: str = "/locem") -> None:
        self._lock = threading.Lock()
        self._results: Dict[str, List[Dict[str, Any]]] = {}
        self._sub = rospy.Subscriber(ns + "/status", LocemStatus, self._on_status, queue_size=500)

    def _on_status(self, m: Any) -> None:
        if m.state != "succeeded":
            return
        try:
            result = json.loads(m.result or "{}")
        except ValueError:
            result = {"unparsed": m.result}
        if isinstance(result, dict):
            result.setdefault("_command", m.command)
        with self._lock:
            self._results.setdefault(m.name, []).append(result)

    def of(self, name: str) -> List[Dict[str, Any]]:
        with self._lock:
            return list(self._results.get(name, []))


class HicemTimeline:
    """Records ``/hicem/state`` (latched) and ``/hicem/prompts`` with monotonic arrival times."""

    def __init__(self, ns: str = "/hicem") -> None:
        self._lock = threading.Lock()
        self.states: List[Tuple[float, Dict[str, str]]] = []
        self.prompts: List[Tuple[float, Dict[str, str]]] = []
        self._subs = [rospy.Subscriber(ns + "/state", HicemState, self._on_state, queue_size=200),
                      rospy.Subscriber(ns + "/prompts", HicemPrompt, self._on_prompt, queue_size=200)]

    def _on_state(self, m: Any) -> None:
        state = {f: getattr(m, f) for f in ("process", "specific_process", "phase", "action_type", "task",
                                            "tree", "node", "detail")}
        with self._lock:
            self.states.append((time.monotonic(), state))

    def _on_prompt(self, m: Any) -> None:
        with self._lock:
            self.prompts.append((time.monotonic(), {"id": m.id, "event": m.event, "kind": m.kind, "text": m.text,
                                                    "answer": m.answer}))

    def close(self) -> None:
        for s in self._subs:
            s.unregister()

    def snapshot(self) -> List[Dict[str, str]]:
        with self._lock:
            return [s for _t, s in self.states]

    def timed(self) -> List[Tuple[float, Dict[str, str]]]:
        with self._lock:
            return list(self.states)

    def latest(self) -> Dict[str, str]:
        with self._lock:
            return dict(self.states[-1][1]) if self.states else {}

    def wait_for(self, predicate: Callable[[Dict[str, str]], bool], timeout: float) -> Optional[Dict[str, str]]:
        """The first recorded state (past or future) for which ``predicate`` holds, or None after ``timeout``."""
        def find() -> Optional[Dict[str, str]]:
            for s in self.snapshot():
                if predicate(s):
                    return s
            return None
        return wait_until(find, timeout)

    def actions(self, process: str) -> List[Tuple[str, str]]:
        """(action type, task) of every task HICEM started for ``process``, in order, each once."""
        seen: List[Tuple[str, str]] = []
        for s in self.snapshot():
            if s["process"] == process and s["task"] and s["action_type"]:
                key = (s["action_type"], s["task"])
                if key not in seen:
                    seen.append(key)
        return seen

    def answered(self) -> List[Dict[str, str]]:
        with self._lock:
            return [p for _t, p in self.prompts if p["event"] == "answered"]

    def asked(self) -> Dict[str, int]:
        """Prompts opened so far, counted by kind."""
        counts: Dict[str, int] = {}
        with self._lock:
            for _t, p in self.prompts:
                if p["event"] == "opened":
                    counts[p["kind"]] = counts.get(p["kind"], 0) + 1
        return counts


# ------------------------------------------------------------------------------------------------ simulator
class SimCalls:
    """The simulated worksite's ``<ns>/sim/*`` services (``locem_bridge/JsonCall``, JSON arguments)."""

    def __init__(self, ns: str = "/sim", timeout: float = 60.0) -> None:
        self.ns = ns.rstrip("/")
        rospy.wait_for_service(self.ns + "/outcome", timeout=timeout)

    def call(self, operation: str, **args: Any) -> Dict[str, Any]:
        reply = rospy.ServiceProxy("%s/%s" % (self.ns, operation), JsonCall)(json.dumps(args))
        if not reply.success:
            raise AssertionError("%s/%s %s refused: %s" % (self.ns, operation, args, reply.message))
        return json.loads(reply.result or "{}")

    def outcome(self) -> Dict[str, Any]:
        return self.call("outcome")

    def inject_fault(self, kind: str, **kw: Any) -> Dict[str, Any]:
        return self.call("inject_fault", kind=kind, **kw)

    def clear_fault(self, kind: str, **kw: Any) -> Dict[str, Any]:
        return self.call("clear_fault", kind=kind, **kw)

    def time_scale(self) -> float:
        return float(rospy.get_param(self.ns + "/time_scale"))


# --------------------------------------------------------------------------------------------- operator HMI
class HmiClient:
    """The operator page's JSON API (see ``locem_bridge.hmi``), spoken as the page's own script does: same-origin
    requests with ``Content-Type: application/json``."""

    def __init__(self, port: int, host: str = "127.0.0.1", timeout: float = 15.0) -> None:
        self.base = "http://%s:%d" % (host, int(port))
        self.timeout = timeout

    def _open(self, request: urllib.request.Request) -> Tuple[int, Any]:
        try:
            with urllib.request.urlopen(request, timeout=self.timeout) as answer:
                body = answer.read()
                status = answer.status
        except urllib.error.HTTPError as error:
            body, status = error.read(), error.code
        kind = "json"
        try:
            value = json.loads(body.decode("utf-8")) if body else {}
        except ValueError:
            kind, value = "text", body
        return status, value if kind == "json" else {"raw": value}

    def get(self, path: str) -> Tuple[int, Any]:
        return self._open(urllib.request.Request(self.base + path, headers={"Accept": "application/json"}))

    def post(self, path: str, body: Optional[Dict[str, Any]] = None) -> Tuple[int, Any]:
        data = json.dumps(body or {}).encode("utf-8")
        request = urllib.request.Request(self.base + path, data=data, method="POST", headers={
            "Content-Type": "application/json", "Accept": "application/json", "Origin": self.base,
            "Referer": self.base + "/"})
        return self._open(request)

    def state(self) -> Dict[str, Any]:
        status, value = self.get("/api/state")
        if status != 200:
            raise AssertionError("GET /api/state answered %d: %s" % (status, value))
        return value

    def wait_up(self, timeout: float = 60.0) -> Dict[str, Any]:
        def up() -> Optional[Dict[str, Any]]:
            try:
                return self.state()
            except (OSError, AssertionError):
                return None
        value = wait_until(up, timeout, period=0.2)
        if not value:
            raise SuiteSetupError("the operator page %s did not answer within %.0f s (operator:=web|both and "
                                  "hmi_port?)" % (self.base, timeout))
        return value

    def stop(self) -> Tuple[int, Any]:
        return self.post("/api/stop", {})


# ------------------------------------------------------------------------------------ device ground truth
class MotionProbe:
    """Samples the devices' own state, not LOCEM's view of it.

    - arm: ``actual_qd`` (rad/s of sim time) and ``actual_digital_output_bits`` from the UR controller stand-in
      through ur_rtde's ``RTDEReceiveInterface`` (a second RTDE client next to LOCEM's), polled at ~250 Hz;
    - base: the wheel drives' actual velocity (0x606C) from their cyclic TPDOs on the base's CAN bus (the real
      canopen client as a listener beside LOCEM's master: it sends nothing; every ``tpdo_period_ms``, 20 ms),
      when ``can=True`` and the .test gives the sim's ``~can_channel``/``~can_port``; otherwise
      ``/sim/ground_truth/base_pose`` (20 Hz wall), speed from consecutive poses. The drives' own velocity is
      the sharper of the two: a pose 50 ms apart that moved less than 2 mm says "still" up to a period late, plus
      the sim node's and the topic's delays on a busy machine;
    - compressor: the spray valve (discrete input 1) over Modbus TCP with pymodbus, read on demand.

    ``host``/``modbus_port`` are the stand-ins' addresses (the .test file gives them). Every sample is
    ``(monotonic wall time, value)``; call :meth:`close` at the end (it ends the RTDE client, the CAN listener
    and the thread).
    """

    ARM_STILL = 1e-3     # rad/s: a joint faster than this is moving
    BASE_STILL = 2e-3    # m between two ground-truth poses (50 ms wall apart): the base is moving
    WHEEL_STILL = 0.02   # rad/s at a wheel shaft (2.5 mm/s at the rim of a 0.127 m wheel): that wheel is moving

    def __init__(self, host: str, modbus_port: int, sim_ns: str = "/sim", period: float = 0.004,
                 can: bool = False) -> None:
        import rtde_receive
        self.host = host
        self.modbus_port = int(modbus_port)
        self._rtde = rtde_receive.RTDEReceiveInterface(host, 250.0, ["actual_qd", "actual_digital_output_bits"])
        self._lock = threading.Lock()
        self.arm: List[Tuple[float, float]] = []          # (t, max |qd|)
        self.outputs: List[Tuple[float, int]] = []        # (t, digital output bits)
        self.base: List[Tuple[float, Tuple[float, float, float]]] = []
        #: (t, node id, |actual velocity| rad/s) of every wheel TPDO received (``can=True``)
        self.wheels: List[Tuple[float, int, float]] = []
        self._period = period
        self._stop = threading.Event()
        self._sub = rospy.Subscriber(sim_ns.rstrip("/") + "/ground_truth/base_pose", Pose2D, self._on_pose,
                                     queue_size=50)
        self._network: Any = None
        self._wheel_ids: List[int] = []
        self._wheel_latest: Dict[int, float] = {}
        #: (t, any wheel faster than WHEEL_STILL) at every wheel TPDO once every wheel was heard (``can=True``)
        self.base_moving: List[Tuple[float, bool]] = []
        self._thread = threading.Thread(target=self._poll, name="motion-probe", daemon=True)
        try:
            if can:
                self._listen_to_wheels(sim_ns)
            self._thread.start()
        except BaseException:
            self.close()
            raise

    def _on_pose(self, m: Any) -> None:
        with self._lock:
            self.base.append((time.monotonic(), (m.x, m.y, m.theta)))

    def _listen_to_wheels(self, sim_ns: str) -> None:
        """Join the base's CAN bus (the sim's ``~can_channel``/``~can_port``, the robot file LOCEM runs with) as a
        listener of every wheel drive's TPDOs: their mapping is the drives' object dictionary (the robot's EDS),
        read from the file, not over SDO, so nothing is sent on the bus."""
        import canopen
        import yaml
        channel = rospy.get_param(sim_ns.rstrip("/") + "/can_channel", None)
        port = rospy.get_param(sim_ns.rstrip("/") + "/can_port", None)
        robot_file = rospy.get_param("/locem/robot_config", None)
        if channel is None or port is None or not robot_file:
            raise SuiteSetupError("MotionProbe(can=True) needs %s/can_channel, %s/can_port and /locem/robot_config "
                                  "(the .test sets them)" % (sim_ns, sim_ns))
        with open(robot_file, encoding="utf-8") as handle:
            base = yaml.safe_load(handle)["robot"]["base"]
        drives = base["drives"]
        eds = os.path.join(os.path.dirname(robot_file), base["eds"])
        scale = float(drives["velocity_units_per_rad_s"])
        self._network = canopen.Network()
        self._network.connect(interface=drives["can"]["interface"], channel=channel, port=int(port),
                              receive_own_messages=False)
        self._wheel_ids = [int(wheel["node_id"]) for wheel in drives["wheels"]]
        for node_id in self._wheel_ids:
            node = canopen.RemoteNode(node_id, eds)
            self._network.add_node(node)
            node.tpdo.read(from_od=True)
            for pdo in node.tpdo.map.values():
                if any(v.index == 0x606C for v in pdo.map):
                    pdo.add_callback(self._wheel_callback(node_id, scale))
        if not wait_until(lambda: len(self._wheel_latest) == len(self._wheel_ids), timeout=3.0, period=0.02):
            raise SuiteSetupError("MotionProbe: heard no velocity TPDO of wheel drive(s) %s on %s %s:%s within 3 s "
                                  "(heard: %s)" % (sorted(set(self._wheel_ids) - set(self._wheel_latest)),
                                                   drives["can"]["interface"], channel, port,
                                                   sorted(self._wheel_latest) or "none"))

    def _wheel_callback(self, node_id: int, scale: float) -> Callable[[Any], None]:
        def on_tpdo(pdo: Any) -> None:
            velocity = abs(next(v.raw for v in pdo.map if v.index == 0x606C)) / scale
            now = time.monotonic()
            with self._lock:
                self.wheels.append((now, node_id, velocity))
                self._wheel_latest[node_id] = velocity
                if len(self._wheel_latest) == len(self._wheel_ids):
                    self.base_moving.append((now, any(v > self.WHEEL_STILL for v in self._wheel_latest.values())))
        return on_tpdo

    def _poll(self) -> None:
        while not self._stop.is_set():
            try:
                qd = self._rtde.getActualQd()
                bits = int(self._rtde.getActualDigitalOutputBits())
            except RuntimeError:
                time.sleep(0.05)
                continue
            now = time.monotonic()
            with self._lock:
                self.arm.append((now, max(abs(v) for v in qd) if qd else 0.0))
                self.outputs.append((now, bits))
            time.sleep(self._period)

    def close(self) -> None:
        self._stop.set()
        if self._thread.ident is not None:                 # started
            self._thread.join(2.0)
        self._sub.unregister()
        try:
            self._rtde.disconnect()
        except RuntimeError:
            pass
        if self._network is not None:
            try:
                self._network.disconnect()
            except Exception as exc:  # noqa: BLE001 - a listener error re-raised at disconnect: closing anyway
                rospy.logwarn("MotionProbe: CAN listener: %s", exc)
            self._network = None

    # -- reading -------------------------------------------------------------------------------------------
    def _base_speeds(self) -> List[Tuple[float, float]]:
        """(t, distance moved since the previous ground-truth pose) for every pose after the first."""
        with self._lock:
            poses = list(self.base)
        out = []
        for (t0, p0), (t1, p1) in zip(poses, poses[1:]):
            out.append((t1, math.hypot(p1[0] - p0[0], p1[1] - p0[1]) + 0.5 * abs(
                (p1[2] - p0[2] + math.pi) % (2 * math.pi) - math.pi)))
        return out

    def _base_samples(self) -> List[Tuple[float, bool]]:
        """(t, moving) of the base: with the wheel listener, at every wheel TPDO whether any wheel's latest
        velocity is above WHEEL_STILL (from the first time every wheel was heard); otherwise at every ground-truth
        pose whether it moved more than BASE_STILL since the one before."""
        if self._network is None:
            return [(t, d > self.BASE_STILL) for t, d in self._base_speeds()]
        with self._lock:
            return list(self.base_moving)

    def moving(self, window: float = 0.15) -> Dict[str, bool]:
        """Which of arm / base moved in the last ``window`` wall seconds."""
        now = time.monotonic()
        with self._lock:
            arm = [v for t, v in self.arm if now - t <= window]
        base = [m for t, m in self._base_samples() if now - t <= max(window, 0.12)]
        return {"arm": any(v > self.ARM_STILL for v in arm), "base": any(base)}

    def wheel_speed(self, window: float = 0.1) -> float:
        """The fastest wheel's velocity (rad/s) heard in the last ``window`` wall seconds (``can=True``)."""
        now = time.monotonic()
        with self._lock:
            recent = []
            for t, _n, v in reversed(self.wheels):       # newest first: stop at the window's start
                if now - t > window:
                    break
                recent.append(v)
        return max(recent, default=0.0)

    def still_since(self, device: str, after: float, until: Optional[float] = None) -> Optional[float]:
        """Wall time of the first sample of ``device`` (``arm`` or ``base``) in [after, until] from which on
        every sample in that window shows it still (a conservative stop time: it stopped at or before then);
        None if it still moved at the window's last sample or there is no sample."""
        until = time.monotonic() if until is None else until
        if device == "arm":
            with self._lock:
                samples = [(t, v > self.ARM_STILL) for t, v in self.arm if after <= t <= until]
        else:
            samples = [(t, moving) for t, moving in self._base_samples() if after <= t <= until]
        if not samples or samples[-1][1]:
            return None
        first_still: Optional[float] = None
        for t, moving in samples:
            if moving:
                first_still = None
            elif first_still is None:
                first_still = t
        return first_still

    def samples_between(self, device: str, after: float, until: float) -> int:
        if device == "base":
            return sum(1 for t, _ in self._base_samples() if after <= t <= until)
        with self._lock:
            return sum(1 for t, _ in self.arm if after <= t <= until)

    def tool_outputs(self) -> int:
        with self._lock:
            return self.outputs[-1][1] if self.outputs else -1

    def spray_valve_open(self) -> bool:
        from pymodbus.client import ModbusTcpClient
        client = ModbusTcpClient(self.host, port=self.modbus_port, timeout=2)
        try:
            if not client.connect():
                raise AssertionError("no Modbus connection to the compressor stand-in %s:%d" % (
                    self.host, self.modbus_port))
            read = client.read_discrete_inputs
            unit = "device_id" if "device_id" in inspect.signature(read).parameters else "slave"
            answer = read(1, count=1, **{unit: 1})
            if answer.isError():
                raise AssertionError("compressor stand-in refused reading valve_open: %s" % answer)
            return bool(answer.bits[0])
        finally:
            client.close()


# ----------------------------------------------------------------------------------------- ROS graph helpers
def node_pid(node: str, caller: str = "/job_suite_test") -> int:
    """The OS process id of a running ROS node (its XML-RPC ``getPid``)."""
    import xmlrpc.client
    import rosgraph
    uri = rosgraph.Master(caller).lookupNode(node)
    code, message, pid = xmlrpc.client.ServerProxy(uri).getPid(caller)
    if code != 1:
        raise AssertionError("%s getPid failed: %s" % (node, message))
    return int(pid)


def try_node_pid(node: str) -> Optional[int]:
    try:
        return node_pid(node)
    except Exception:  # noqa: BLE001 - not registered / not answering: no pid
        return None


def pemkre_rows(name: str, **bindings: str) -> List[Dict[str, str]]:
    """Rows of PEMKRE's named query (``/pemkre/query``); bindings are N-Triples terms (``'"text"'``, ``'<iri>'``)."""
    from locem_bridge.srv import PemkreQuery
    names = sorted(bindings)
    reply = rospy.ServiceProxy("/pemkre/query", PemkreQuery)(name, names, [bindings[n] for n in names])
    if not reply.success:
        raise AssertionError("PEMKRE query %s refused: %s" % (name, reply.message))
    results = json.loads(reply.results)
    return [{k: v.get("value") for k, v in b.items()} for b in results.get("results", {}).get("bindings", [])]


def feature_status(feature_id: str) -> Dict[str, str]:
    """PEMKRE's processing states of one scanned feature by id (property local name -> state local name)."""
    rows = pemkre_rows("feature_by_id", id='"%s"' % feature_id)
    if not rows:
        raise AssertionError("PEMKRE knows no feature %r" % feature_id)
    states = pemkre_rows("feature_status", feature="<%s>" % rows[0]["feature"])
    return {r["property"].split("#")[-1]: r["state"].split("#")[-1] for r in states}


# ------------------------------------------------------------------------------------------------ the report
def wait_for_report(results_dir: str, timeout: float) -> Dict[str, Any]:
    """``results_dir/latest/report.json`` once the job has written it (AssertionError after ``timeout``)."""
    path = os.path.join(results_dir, "latest", "report.json")

    def read() -> Optional[Dict[str, Any]]:
        if not os.path.exists(path):
            return None
        with open(path, encoding="utf-8") as handle:
            return json.load(handle)
    end = time.monotonic() + timeout
    grace = None
    while time.monotonic() < end:
        report = read()
        if report is not None:
            return report
        if _INTERRUPTED.is_set():             # the launch is ending: the report is there now or never
            grace = grace or time.monotonic() + 1.0
            if time.monotonic() > grace:
                break
        time.sleep(0.02)
    report = read()
    if report is None:
        raise AssertionError("no %s within %.0f s%s" % (path, timeout, " (the launch shut down without it: did "
                                                         "the job node die?)" if _INTERRUPTED.is_set() else ""))
    return report


def process_record(report: Dict[str, Any], name: str) -> Dict[str, Any]:
    for p in report["processes"]:
        if p["name"] == name:
            return p
    raise AssertionError("report lists no process %r: %s" % (name, [p["name"] for p in report["processes"]]))


def kpi_actions(report: Dict[str, Any], process: str) -> Dict[str, Dict[str, str]]:
    """The report's KPI rows (PEMKRE's ``kpi_by_task_type``) of the specific process run for the abstract
    ``process`` IRI, by action type."""
    prefix = "/log/%s_" % process.split("#")[-1]
    return {row["actionType"]: row for row in report.get("kpis", []) if prefix in row.get("process", "")}


def kpi_interventions(report: Dict[str, Any]) -> int:
    """Operator interventions PEMKRE counted (sum of the report's KPI column), a cross-check of the job's own."""
    return sum(int(r.get("operatorInterventions", 0)) for r in report.get("kpis", []))


def kpi_count(report: Dict[str, Any], action_type: str, column: str = "count") -> int:
    return sum(int(r.get(column, 0)) for r in report.get("kpis", []) if r.get("actionType") == action_type)


def outcome_goal_failures(report: Dict[str, Any], asked: Dict[str, int], manual: Tuple[str, ...] = ()) -> List[str]:
    """Every outcome goal of issue 7 the report misses (empty list = all met).

    ``asked``: prompts the operator was asked during the run by kind (:meth:`HicemTimeline.asked`), for the goal
    operator_interventions = tool changes + validations asked (+ joints the operator taped by hand, when some
    were rejected). ``manual``: joints the operator rejected (they must be manual, not taped by the robot)."""
    o = report["outcome"]
    failures = []
    for p in report["processes"]:
        if p["status"] != "succeeded":
            failures.append("process %s %s: %s" % (p["name"], p["status"], p.get("detail", "")))
    for jid, j in sorted(o["joints"].items()):
        if jid in manual:
            if not j.get("manual"):
                failures.append("%s was rejected but is not manual: %s" % (jid, j))
        elif not j.get("taped") or float(j.get("coverage", 0.0)) < 0.99:
            failures.append("%s: taped %s, coverage %.3f < 0.99" % (jid, j.get("taped"),
                                                                    float(j.get("coverage", 0.0))))
    if o["joints_total"] < 1:
        failures.append("no joints on the site")
    if o["spray_coverage"] < 0.98:
        failures.append("spray_coverage %.3f < 0.98" % o["spray_coverage"])
    if o["spray_thickness_cv"] > 0.15:
        failures.append("spray thickness CV %.3f > 0.15" % o["spray_thickness_cv"])
    if o["sand_coverage"] < 0.98:
        failures.append("sand_coverage %.3f < 0.98" % o["sand_coverage"])
    if o["collisions"] != 0:
        failures.append("%d collisions" % o["collisions"])
    expected = asked.get("mount_tool", 0) + asked.get("validate_line", 0) + asked.get("manual_taping", 0)
    if o["operator_interventions"] != expected:
        failures.append("operator_interventions %d != tool changes %d + validations %d + manual tapings %d asked"
                        % (o["operator_interventions"], asked.get("mount_tool", 0), asked.get("validate_line", 0),
                           asked.get("manual_taping", 0)))
    if kpi_interventions(report) != o["operator_interventions"]:
        failures.append("PEMKRE's KPI table counts %d operator interventions, the job %d" % (
            kpi_interventions(report), o["operator_interventions"]))
    return failures
