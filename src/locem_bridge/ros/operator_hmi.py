"""Operator HMI node: the web HMI (:mod:`locem_bridge.hmi`) and/or the automatic operator, over ROS.

:class:`RosHmiBackend` implements :class:`locem_bridge.hmi.backend.HmiBackend` on HICEM's and PEMKRE's ROS
interfaces (names relative to the node's namespace unless absolute):

- ``<hicem>/state`` (``HicemState``, latched) -> snapshot, and the open prompts (its ``prompts`` JSON field);
  every message also feeds the planned manual work its task reports name (the page's Manual work panel,
  ``/api/manual``; :class:`locem_bridge.hmi.manual_work.ManualWorkLog`);
- ``<hicem>/start_process`` (``HicemStartProcess``, with ``~process_options`` as JSON), ``<hicem>/stop``
  (``HicemStop``), ``<hicem>/operator_reply`` (``HicemOperatorReply``), and the page's Pause, Resume, Abort and
  Reset buttons: ``<hicem>/suspend``, ``<hicem>/resume``, ``<hicem>/halt``, ``<hicem>/reset`` (``SkillControl``);
  a ``success: false`` answer becomes a refusal shown to the operator (HTTP 409), an unreachable service a 503;
- ``<hicem>/skill_state`` (``SkillTransition``, latched) -> the running action's skill state, the cause of its
  last transition and the methods it allows (:func:`locem_bridge.hicem.skill_control.operator_methods`; Reset
  while an action it halted is not reset);
- ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``) -> health, with HICEM's own liveness and its
  ``waiting_for_health`` phase (read by :class:`locem_bridge.hmi.health.DiagnosticsHealth`);
- ``<pemkre>/query`` (``locem_bridge/PemkreQuery``, SPARQL results JSON) -> KPIs (``kpi_by_process``,
  ``kpi_by_task_type`` for the running specific process) and progress (``feature_status``: joints while the
  running process tapes, areas while it sprays or sands; see ``WorkFollower``). When PEMKRE is not up the page
  says so and the rest keeps working.
- ``<pemkre>/match`` (``locem_bridge/PemkreMatchProcess``) -> the page's skill matching of a process (the chosen
  skill per task and the rejected candidates with reasons); PEMKRE's refusal (no resource model) is shown as such.
- wall pictures: every ``<wall_id>.png`` in ``~pictures_dir``, and, when the simulated worksite runs, its
  pictures refreshed every ``~sim_picture_period`` s through ``<sim>/save_outcome`` into a private folder
  (:class:`locem_bridge.hmi.pictures.SimPictures`);
- the simulated operator's hands (:mod:`locem_bridge.hmi.sim_hands`): before an answer is sent, the simulator
  operations it implies (``<sim>/remove_tool`` + ``<sim>/mount_tool`` for a mounted tool, ``<sim>/manual_taping``
  for a joint taped by hand) run through ``locem_bridge/JsonCall``; if one fails the answer is not sent and the
  operator sees why. ``~sim_hands``: ``auto`` (default: when ``<sim>/mount_tool`` exists), ``true``, ``false``.

Parameters: ``~mode`` (``auto``: the automatic operator answers the prompts and the page is served to watch the
job, a port that cannot be bound is logged and the automatic operator carries on; ``web``: the page only, the
person answers; ``both``: the page and the automatic operator, a port that cannot be bound is fatal), ``~host``
(default 127.0.0.1), ``~port`` (default 8088), ``~hicem_ns`` (``hicem``), ``~pemkre_ns`` (``pemkre``),
``~processes`` (list of ``{iri, name, description}``; default: every ``proc:AbstractProcess`` of
``~ontologies``, default the package's ``ontologies/*.ttl``), ``~process_options`` (dict, e.g.
``{validateLines: true}``), ``~pictures_dir``, ``~auto_operator`` (dict, see :mod:`locem_bridge.hmi.auto_operator`,
merged over its defaults), ``~reject_lines`` (joint ids the automatic operator answers ``invalid``: a list or a
comma-separated string), ``~call_timeout`` (s, default 5), ``~sim_ns`` (``sim``), ``~sim_hands``,
``~sim_picture_period`` (s, default 5; 0 = never ask the simulator for pictures).
Lifecycle: start -> serve until ROS shutdown -> the server and the automatic operator are stopped.
"""
import glob
import json
import logging
import os
import sys
import threading
import time
from typing import Any, Callable, Dict, List, Optional

import rospy
import rosservice
from diagnostic_msgs.msg import DiagnosticArray

from locem_bridge.hmi import (DEFAULT_CONFIG, AutoOperator, AutoOperatorConfig, BackendRefused, BackendUnavailable,
                              DiagnosticsHealth, HmiError, HmiServer, SimPictures, snapshot_from_hicem,
                              wall_pictures_in)
from locem_bridge.common.program_state import ProgramState
from locem_bridge.hicem.skill_control import operator_methods
from locem_bridge.hmi.backend import SKILL_METHODS
from locem_bridge.hmi.hicem_view import WorkFollower
from locem_bridge.hmi.manual_work import ManualWorkLog
from locem_bridge.hmi.pemkre_view import KPI_QUERIES, processes_from_ontologies, rows_from_result, work_progress
from locem_bridge.hmi.sim_hands import HandsError, hand_actions
from locem_bridge.msg import HicemState, SkillTransition
from locem_bridge.srv import (HicemOperatorReply, HicemStartProcess, HicemStop, JsonCall, PemkreMatchProcess,
                              PemkreQuery, SkillControl)
from locem_bridge.ros.calls import timed
from locem_bridge.ros.params import as_list, package_share, param
from locem_bridge.ros.startup import config_guard

STATE_FIELDS = ("process", "specific_process", "phase", "action_type", "task", "skill", "tree", "node", "path",
                "detail")
MODES = ("web", "auto", "both")


def _timed_call(fn: Callable[[], Any], timeout: float, what: str) -> Any:
    """A blocking ROS call; BackendUnavailable (the page shows 503) if it fails or does not answer in time."""
    return timed(fn, timeout, what, BackendUnavailable)


class RosHmiBackend:
    """HmiBackend over ROS (see the module docstring). Create after ``rospy.init_node``; :meth:`close` ends the
    subscriptions."""

    def __init__(self, hicem_ns: str = "hicem", pemkre_ns: str = "pemkre",
                 processes: Optional[List[Dict[str, Any]]] = None, process_options: Optional[Dict[str, Any]] = None,
                 pictures_dir: str = "", call_timeout: float = 5.0, stop_timeout: float = 12.0,
                 progress_period_s: float = 1.0, sim_ns: str = "sim", sim_hands: str = "auto",
                 sim_picture_period_s: float = 5.0) -> None:
        self.hicem = rospy.resolve_name(hicem_ns).rstrip("/")
        self.pemkre = rospy.resolve_name(pemkre_ns).rstrip("/")
        self.processes = [dict(p) for p in (processes or [])]
        self.process_options = dict(process_options or {})
        self.pictures_dir = pictures_dir
        self.call_timeout = float(call_timeout)
        self.stop_timeout = float(stop_timeout)
        self.progress_period_s = float(progress_period_s)
        self._lock = threading.Lock()
        self._state: Optional[Dict[str, Any]] = None
        self._prompts: List[Dict[str, Any]] = []
        self._diag = DiagnosticsHealth()
        self._alive_checked = 0.0
        self._alive = False
        self._progress: Optional[Dict[str, Any]] = None
        self._progress_at = 0.0
        self._follower = WorkFollower()             # which work the running process does (fed every state)
        self._manual = ManualWorkLog()              # the planned manual work task reports named (every state)
        self._query = rospy.ServiceProxy(self.pemkre + "/query", PemkreQuery)
        self._match = rospy.ServiceProxy(self.pemkre + "/match", PemkreMatchProcess)
        self.sim = rospy.resolve_name(sim_ns).rstrip("/")
        if str(sim_hands).lower() not in ("auto", "true", "false"):
            raise HmiError("~sim_hands must be auto, true or false, got %r" % (sim_hands,))
        self.sim_hands = str(sim_hands).lower()
        self._sim_pictures = SimPictures(sim_picture_period_s,
                                         draw=lambda folder: self.sim_call("save_outcome", {"folder": folder}),
                                         can_draw=lambda: self._service_exists(self.sim + "/save_outcome"))
        self._joints: Optional[List[str]] = None
        self._start = rospy.ServiceProxy(self.hicem + "/start_process", HicemStartProcess)
        self._stop = rospy.ServiceProxy(self.hicem + "/stop", HicemStop)
        self._reply = rospy.ServiceProxy(self.hicem + "/operator_reply", HicemOperatorReply)
        self._skill_calls = {m: rospy.ServiceProxy("%s/%s" % (self.hicem, m.lower()), SkillControl)
                             for m in SKILL_METHODS}
        self._skill: Dict[str, Any] = {"skill_state": "", "allowed": [], "skill_detail": ""}
        self._halted = ""                           # the instance HICEM halted last, until it is reset
        self._subs = [rospy.Subscriber(self.hicem + "/state", HicemState, self._on_state, queue_size=20),
                      rospy.Subscriber(self.hicem + "/skill_state", SkillTransition, self._on_skill, queue_size=50),
                      rospy.Subscriber("/diagnostics", DiagnosticArray, self._on_diagnostics, queue_size=20)]

    def close(self) -> None:
        for s in self._subs:
            s.unregister()
        self._subs = []
        self._sim_pictures.close()

    # -- subscriptions --------------------------------------------------------------------------------------
    def _on_state(self, msg: Any) -> None:
        state = {f: str(getattr(msg, f, "")) for f in STATE_FIELDS}
        try:
            prompts = json.loads(msg.prompts) if msg.prompts.strip() else []
            if not isinstance(prompts, list):
                raise ValueError("not a list")
        except ValueError as err:
            rospy.logwarn_throttle(10, "operator_hmi: %s/state prompts field is not a JSON list: %s" % (self.hicem,
                                                                                                     err))
            prompts = []
        with self._lock:
            self._state = state
            self._prompts = [p for p in prompts if isinstance(p, dict)]
            self._follower.update(state)
        self._manual.update(state)

    def _on_skill(self, msg: Any) -> None:
        try:
            state = ProgramState(msg.to_state)
        except ValueError:
            rospy.logwarn_throttle(10, "operator_hmi: %s/skill_state names the state %r" % (self.hicem, msg.to_state))
            return
        with self._lock:
            if state == ProgramState.HALTED:
                self._halted = msg.instance
            elif msg.instance == self._halted:
                self._halted = ""
            allowed = operator_methods(state) if state in (ProgramState.RUNNING, ProgramState.SUSPENDED) else (
                operator_methods(ProgramState.HALTED) if self._halted else [])
            self._skill = {"skill_state": state.value, "allowed": [m.value for m in allowed],
                           "skill_detail": msg.cause}

    def _on_diagnostics(self, msg: Any) -> None:
        for st in msg.status:
            self._diag.note(st.name, st.level, st.message)

    # -- health ---------------------------------------------------------------------------------------------
    def _hicem_alive(self) -> bool:
        now = time.monotonic()
        if now - self._alive_checked > 2.0:
            self._alive_checked = now
            try:
                self._alive = rosservice.get_service_uri(self.hicem + "/stop") is not None
            except Exception:  # noqa: BLE001 - master unreachable: not alive
                self._alive = False
        return self._alive

    def _health(self, state: Optional[Dict[str, Any]]) -> Dict[str, str]:
        return self._diag.summary(self.hicem, self._hicem_alive(), state)

    # -- PEMKRE queries -------------------------------------------------------------------------------------
    def query(self, name: str, bindings: Optional[Dict[str, str]] = None) -> List[Dict[str, Any]]:
        """Rows of PEMKRE's named query; ``bindings`` maps variables to N-Triples terms (``<iri>``, ``"text"``).
        BackendUnavailable when PEMKRE cannot be reached, BackendRefused when it refuses."""
        names = sorted(bindings or {})
        values = [(bindings or {})[n] for n in names]
        resp = _timed_call(lambda: self._query(name, names, values), self.call_timeout,
                           "%s/query %s" % (self.pemkre, name))
        if not resp.success:
            raise BackendRefused("PEMKRE query %s refused (%s): %s" % (name, resp.code, resp.message))
        try:
            return rows_from_result(resp.results)
        except ValueError as err:
            raise BackendUnavailable("PEMKRE query %s: %s" % (name, err))

    # -- the simulated worksite -----------------------------------------------------------------------------
    def _service_exists(self, name: str) -> bool:
        try:
            return rosservice.get_service_uri(name) is not None
        except Exception:  # noqa: BLE001 - no master: no service
            return False

    def sim_call(self, operation: str, args: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
        """One ``<sim>/<operation>`` JsonCall; BackendRefused with the simulator's message if it refuses."""
        service = "%s/%s" % (self.sim, operation)
        proxy = rospy.ServiceProxy(service, JsonCall)
        resp = _timed_call(lambda: proxy(json.dumps(args or {})), self.call_timeout, service)
        if not resp.success:
            raise BackendRefused("simulated worksite: %s" % resp.message)
        try:
            result = json.loads(resp.result or "{}")
        except ValueError:
            result = {}
        return result if isinstance(result, dict) else {}

    def _hands_enabled(self) -> bool:
        if self.sim_hands == "auto":
            return self._service_exists(self.sim + "/mount_tool")
        return self.sim_hands == "true"

    def _site_joints(self) -> List[str]:
        if self._joints is None:
            joints = self.sim_call("outcome").get("joints", {})
            self._joints = sorted(joints) if isinstance(joints, (dict, list)) else []
        return self._joints

    def _do_hands(self, prompt: Dict[str, Any], answer: str) -> None:
        if not self._hands_enabled():
            return
        try:
            needs_joints = prompt.get("kind") in ("manual_taping", "finish_interrupted") and answer == "done"
            actions = hand_actions(prompt, answer, self._site_joints() if needs_joints else ())
        except HandsError as err:
            raise BackendRefused("the simulated operator cannot do this: %s" % err)
        for operation, args in actions:
            self.sim_call(operation, args)
            rospy.loginfo("operator_hmi: simulated operator did %s %s", operation, json.dumps(args))

    # -- HmiBackend -----------------------------------------------------------------------------------------
    def list_processes(self) -> List[Dict[str, Any]]:
        return [dict(p) for p in self.processes]

    def start_process(self, iri: str) -> Any:
        opts = json.dumps(self.process_options) if self.process_options else ""
        resp = _timed_call(lambda: self._start(process=iri, options=opts), self.call_timeout,
                           self.hicem + "/start_process")
        if not resp.success:
            raise BackendRefused(resp.message or "HICEM did not start %s" % iri)
        return {"message": resp.message}

    def stop(self) -> None:
        _timed_call(lambda: self._stop(reason="STOP pressed on the operator HMI"), self.stop_timeout,
                    self.hicem + "/stop")

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            state = dict(self._state) if self._state is not None else None
            work = self._follower.work
        now = time.monotonic()
        if work is None:
            self._progress = None
        elif (self._progress is None or self._progress.get("work") != work
              or now - self._progress_at >= self.progress_period_s):
            self._progress_at = now
            try:
                progress = work_progress(self.query("feature_status"), work)
                self._progress = dict(progress, work=work) if progress else None
            except HmiError:
                pass                                # progress is optional; KPIs report PEMKRE's absence
        with self._lock:
            skill = dict(self._skill)
        return snapshot_from_hicem(dict(state or {}, **skill), progress=self._progress, health=self._health(state))

    def skill_method(self, method: str, cause: str = "") -> Dict[str, Any]:
        """Suspend / Resume / Halt / Reset through ``<hicem>/<method>``; BackendRefused with HICEM's refusal."""
        proxy = self._skill_calls.get(method)
        if proxy is None:
            raise BackendRefused("unknown skill method %r; methods: %s" % (method, ", ".join(SKILL_METHODS)))
        service = "%s/%s" % (self.hicem, method.lower())
        resp = _timed_call(lambda: proxy(cause=cause), self.call_timeout, service)
        allowed = [m for m in resp.allowed.split(",") if m]
        if not resp.success:
            raise BackendRefused(resp.message or "HICEM refused %s" % method)
        with self._lock:
            self._skill = dict(self._skill, skill_state=resp.state, allowed=allowed)
        return {"state": resp.state, "allowed": allowed, "message": resp.message}

    def prompts(self) -> List[Dict[str, Any]]:
        with self._lock:
            return [dict(p) for p in self._prompts]

    def reply(self, prompt_id: str, answer: str) -> None:
        with self._lock:
            prompt = next((dict(p) for p in self._prompts if p.get("id") == prompt_id), None)
        if prompt is None:
            raise BackendRefused("prompt %r is not open" % prompt_id)
        self._do_hands(prompt, answer)
        resp = _timed_call(lambda: self._reply(prompt_id=prompt_id, answer=answer), self.call_timeout,
                           self.hicem + "/operator_reply")
        if not resp.success:
            raise BackendRefused(resp.message or "HICEM refused the answer")

    def manual_work(self) -> List[Dict[str, Any]]:
        """The planned manual work HICEM's task reports named so far (parts of areas and joints left for a person)."""
        return self._manual.items()

    def match_process(self, iri: str) -> Any:
        """PEMKRE's skill matching of the abstract process ``iri`` (JSON text, read by the page's ``match_view``)."""
        resp = _timed_call(lambda: self._match(process=iri), self.call_timeout, self.pemkre + "/match")
        if not resp.success:
            raise BackendRefused("PEMKRE match refused (%s): %s" % (resp.code, resp.message))
        return resp.match

    def kpis(self) -> Dict[str, List[Dict[str, Any]]]:
        with self._lock:
            specific = (self._state or {}).get("specific_process", "")
        if not specific:
            return {}
        return {table: self.query(name, {"process": "<%s>" % specific}) for table, name in KPI_QUERIES}

    def wall_pictures(self) -> Dict[str, Any]:
        with self._lock:
            phase = (self._state or {}).get("phase", "")
        pictures: Dict[str, Any] = dict(self._sim_pictures.pictures(phase))
        pictures.update(wall_pictures_in(self.pictures_dir))
        return pictures


def auto_config_from_params(raw: Any, reject_lines: List[str]) -> AutoOperatorConfig:
    """``~auto_operator`` merged over the defaults, plus ``~reject_lines`` as validate_line ``invalid`` answers."""
    cfg = json.loads(json.dumps(raw or {}))
    if not isinstance(cfg, dict):
        raise HmiError("~auto_operator must be a mapping, got %r" % (raw,))
    if reject_lines:
        kinds = cfg.setdefault("kinds", {})
        rule = dict(kinds.get("validate_line") or DEFAULT_CONFIG["kinds"]["validate_line"])
        per = dict(rule.get("per_feature") or {})
        per["invalid"] = sorted(set(as_list(per.get("invalid"))) | set(reject_lines))
        rule["per_feature"] = per
        kinds["validate_line"] = rule
    return AutoOperatorConfig.from_dict(cfg, base=DEFAULT_CONFIG)


class _RosLogHandler(logging.Handler):
    """Forwards the ROS-free HMI's Python log records (locem_bridge.hmi.*) to rosout."""

    def emit(self, record: logging.LogRecord) -> None:
        text = "operator_hmi: %s" % self.format(record)
        if record.levelno >= logging.ERROR:
            rospy.logerr(text)
        elif record.levelno >= logging.WARNING:
            rospy.logwarn(text)
        else:
            rospy.loginfo(text)


class OperatorHmiNode:
    def __init__(self) -> None:
        hmi_log = logging.getLogger("locem_bridge.hmi")
        if not any(isinstance(h, _RosLogHandler) for h in hmi_log.handlers):
            hmi_log.addHandler(_RosLogHandler())
            hmi_log.setLevel(logging.INFO)
            hmi_log.propagate = False
        mode = param("mode", "web")
        if mode not in MODES:
            raise HmiError("~mode must be one of %s, got %r" % (", ".join(MODES), mode))
        port = param("port", 8088)
        if not 0 <= port <= 65535:
            raise HmiError("~port must be in [0, 65535], got %d" % port)
        processes = param("processes", None)
        if not processes:
            files = as_list(param("ontologies", None)) or sorted(glob.glob(os.path.join(package_share(),
                                                                                            "ontologies", "*.ttl")))
            processes = processes_from_ontologies(files)
        options = param("process_options", {})
        if isinstance(options, str):
            options = json.loads(options) if options.strip() else {}
        self.backend = RosHmiBackend(param("hicem_ns", "hicem"), param("pemkre_ns", "pemkre"), processes, options,
                                     param("pictures_dir", ""), param("call_timeout", 5.0),
                                     sim_ns=param("sim_ns", "sim"), sim_hands=param("sim_hands", "auto"),
                                     sim_picture_period_s=param("sim_picture_period", 5.0))
        self.server: Optional[HmiServer] = None
        self.auto: Optional[AutoOperator] = None
        if mode in ("auto", "both"):
            self.auto = AutoOperator(self.backend, auto_config_from_params(param("auto_operator", {}),
                                                                           as_list(param("reject_lines", None))))
            self.auto.start()
        try:
            self.server = HmiServer(self.backend, param("host", "127.0.0.1"), port).start()
            rospy.loginfo("operator_hmi: serving the operator page on %s", self.server.url)
        except HmiError as err:
            if mode != "auto":
                raise
            rospy.logerr("operator_hmi: %s; the automatic operator answers without a page", err)
        if self.server is not None:
            if self.auto is not None:
                hub = self.server.hub
                self.auto.add_listener(lambda r: hub.note("automatic operator answered %s: %s (%s)" % (
                    r["kind"], r["answer"], r["reason"])))
        rospy.loginfo("operator_hmi: mode %s, %d processes offered, HICEM at %s", mode, len(processes),
                      self.backend.hicem)

    def shutdown(self) -> None:
        if self.auto is not None:
            self.auto.stop()
        if self.server is not None:
            self.server.close()
        self.backend.close()


@config_guard("operator_hmi")
def main() -> None:
    rospy.init_node("operator_hmi")
    try:
        node = OperatorHmiNode()
    except (HmiError, ValueError) as err:
        rospy.logfatal("operator_hmi: %s", err)
        sys.exit(2)
    rospy.on_shutdown(node.shutdown)
    rospy.spin()


if __name__ == "__main__":
    main()
