"""TEST DOUBLES for the layers around HICEM (not product code).

- :class:`LocemDouble`: an in-process stand-in for LOCEM's action interface. It checks command names and
  numeric arguments like the LOCEM grammar will (unknown name → INVALID_COMMAND, non-number → INVALID_ARGUMENT),
  lets each command take a configurable time, answers SCAN with a site, supports cancel, suspend and resume
  (a suspended command's time stands still; names in ``non_suspendable`` refuse, as LOCEM's commands that are not
  pausable), injected failures, odd codes and a progress feedback text per command name, and logs every command
  and SUSPEND/RESUME/CANCEL (optionally to a file, fsync'ed, for the crash tests).
- :class:`PemkreDouble`: a tiny process engine following docs/contracts.md for the taping process (SCAN →
  GET_TOOL → per joint VALIDATE_TAPE_LINE → TAPE_LINE or MANUAL_TAPING → GO_HOME → ended). It refuses status
  updates for tasks that are not running, like the real PEMKRE must, and can persist its state to a JSON file
  so it survives the HICEM process being killed. What follows a failed task is a constructor choice,
  ``after_failure``: ``"continue"`` (the default, kept for the benchmark and the other suites that use this
  double) goes on with the next pending task, which the real taping process does NOT do; ``"fail_process"``
  behaves like the real PEMKRE taping process (no failure transition: the next ``next_action`` answers
  ``failed`` with ``task <iri> (TYPE) failed: <detail>``). A test whose expectation depends on what happens
  after a failed task passes ``after_failure`` explicitly, or uses the real engine (test_with_pemkre_engine.py).
  ``skills`` (action type -> (skill, skill_kind)) makes its answers name the matched skill, as PEMKRE with a
  resource model does.
"""
import json
import os
import threading
import time
from typing import Any, Callable, Dict, List, Optional

from locem_bridge.hicem.errors import LocemCallError, PemkreCallError
from locem_bridge.hicem.interfaces import CommandHandle, LocemClient, LocemReply, PemkreClient

SITE = {
    "stamp": 1.0,
    "walls": [{"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.8, 3.0], "height": 2.5, "thickness": 0.0125,
               "normal": [0.0, -1.0, 0.0]},
              {"id": "wall_2", "p0": [4.8, 3.0], "p1": [4.8, 0.0], "height": 2.5, "thickness": 0.0125,
               "normal": [-1.0, 0.0, 0.0]}],
    "joints": [{"id": "wall_1_joint_1", "wall": "wall_1", "kind": "vertical", "start": [1.2, 3.0, 0.0],
                "end": [1.2, 3.0, 2.5], "width": 0.05},
               {"id": "wall_1_joint_2", "wall": "wall_1", "kind": "vertical", "start": [2.4, 3.0, 0.0],
                "end": [2.4, 3.0, 2.5], "width": 0.05},
               {"id": "wall_2_joint_1", "wall": "wall_2", "kind": "horizontal", "start": [4.8, 2.5, 1.2],
                "end": [4.8, 0.5, 1.2], "width": 0.05}],
    "areas": [{"id": "wall_1_area_1", "wall": "wall_1", "origin": [0.0, 3.0, 0.0], "u": [1.0, 0.0, 0.0],
               "width": 4.8, "height": 2.5}],
}

# keyword arguments that take a word (LOCEM's Arg.choice), with the words allowed
CHOICES = {"contact": ("position", "force"), "lanes": ("horizontal", "vertical")}
# name -> number of positional numeric args (None = any count of numbers, key=value allowed)
GRAMMAR = {"SCAN": 0, "HOME": 0, "GET_POSE": 0, "GET_TOOL_POINT": 0, "STOP": 0, "WAIT": 1, "STATUS": 0, "GOTO": 3, "LIFT": 0, "MOUNT_TOOL": "word", "CHANGE_TOOL": "word", "MOVE_HOME": "word", "WALL_READY": 0, "RESET_ARM": 0,
           "APPLY_TAPE_START": 9, "APPLY_TAPE": 9, "SPRAY_AREA": 11, "SAND_AREA": 11}


class _Handle(CommandHandle):
    def __init__(self, owner: "LocemDouble", command: str, reply: LocemReply, duration: float) -> None:
        self.owner = owner
        self.command = command
        self._reply = reply
        self.t_done = time.monotonic() + duration
        self.cancelled = False
        self.cancel_time: Optional[float] = None
        self.remaining: Optional[float] = None     # time left when suspended, None while not suspended

    def done(self) -> bool:
        return self.cancelled or time.monotonic() >= self.t_done

    def reply(self) -> Optional[LocemReply]:
        if self.cancelled:
            return LocemReply(False, "ABORTED", "cancelled")
        return self._reply if self.done() else None

    def feedback(self) -> Optional[str]:
        """The progress feedback the double gives for this command's name (``LocemDouble.feedback``), if any."""
        name = self.command.split()[0].upper() if self.command.split() else ""
        return self.owner.feedback.get(name)

    def cancel(self) -> None:
        if not self.cancelled and not (time.monotonic() >= self.t_done):
            self.cancelled = True
            self.cancel_time = time.monotonic()
            self.owner.log("CANCEL " + self.command)

    # suspension, as LOCEM's SUSPEND/RESUME id=N: a pausable command stops its clock while suspended
    def suspend(self, cause: str = "") -> None:
        name = self.command.split()[0].upper() if self.command.split() else ""
        if name in self.owner.non_suspendable:
            raise LocemCallError("Suspend is not allowed: %s cannot be suspended (not pausable)" % name,
                                 "INVALID_ARGUMENT")
        if self.done() or self.remaining is not None:
            raise LocemCallError("Suspend is not allowed: %s is not running" % name, "INVALID_ARGUMENT")
        self.remaining = self.t_done - time.monotonic()
        self.t_done = float("inf")
        self.owner.log("SUSPEND %s cause=%s" % (self.command, cause))

    def resume(self, cause: str = "") -> None:
        if self.remaining is None or self.cancelled:
            raise LocemCallError("Resume is not allowed: %r is not suspended" % self.command, "INVALID_ARGUMENT")
        self.t_done = time.monotonic() + self.remaining
        self.remaining = None
        self.owner.log("RESUME %s cause=%s" % (self.command, cause))


class LocemDouble(LocemClient):
    """TEST DOUBLE of LOCEM (see module doc)."""

    def __init__(self, durations: Optional[Dict[str, float]] = None, site: Optional[Dict[str, Any]] = None,
                 log_path: Optional[str] = None) -> None:
        self.durations = durations or {}
        self.site = site if site is not None else SITE
        self.sent: List[str] = []
        self.handles: List[_Handle] = []
        self.fail_next: Dict[str, LocemReply] = {}
        # name -> the progress feedback text its commands report (e.g. SPRAY_AREA: 'raster 2.345 of 6.480 m')
        self.feedback: Dict[str, str] = {}
        self.pose = [1.4, 1.4, 0.7854]     # the default site's start (config/sites/default.yaml)
        self.tool_point = [0.0, 0.0, 0.0]  # GET_TOOL_POINT's point (map frame)
        # STATUS 'health' (LOCEM's per-backend records); health_script: answers given first, one per STATUS
        self.health: Dict[str, Dict[str, Any]] = {n: {"link": "up", "device": "ok", "last_error": ""}
                                                  for n in ("arm", "base", "compressor", "wall")}
        self.health_script: List[Dict[str, Dict[str, Any]]] = []
        self.log_path = log_path
        # commands that refuse SUSPEND (not pausable in LOCEM: tool changes, STATUS, ...)
        self.non_suspendable = {"MOUNT_TOOL", "CHANGE_TOOL", "STATUS", "STOP", "SCAN", "GET_POSE"}
        self._lock = threading.Lock()

    def log(self, line: str) -> None:
        with self._lock:
            self.sent.append(line)
            if self.log_path:
                with open(self.log_path, "a") as f:
                    f.write(line + "\n")
                    f.flush()
                    os.fsync(f.fileno())

    def _validate(self, command: str) -> Optional[LocemReply]:
        words = command.split()
        if not words:
            return LocemReply(False, "INVALID_COMMAND", "empty command")
        name = words[0].upper()
        if name not in GRAMMAR:
            return LocemReply(False, "INVALID_COMMAND", "unknown command %s" % name)
        pos = [w for w in words[1:] if "=" not in w]
        spec = GRAMMAR[name]
        if spec == "word":
            named = len(pos) + len([w for w in words[1:] if "=" in w])    # LOCEM binds an argument by keyword too
            return None if named == 1 else LocemReply(False, "INVALID_ARGUMENT", "%s takes one name" % name)
        if len(pos) != spec:
            return LocemReply(False, "INVALID_ARGUMENT", "%s takes %s arguments, got %d" % (name, spec, len(pos)))
        for key, value in [w.split("=", 1) for w in words[1:] if "=" in w]:
            if key in CHOICES and value not in CHOICES[key]:
                return LocemReply(False, "INVALID_ARGUMENT", "%s must be one of %s, got %r" % (
                    key, "|".join(CHOICES[key]), value))
        for w in pos + [w.split("=", 1)[1] for w in words[1:] if "=" in w and w.split("=", 1)[0] not in CHOICES]:
            try:
                float(w)
            except ValueError:
                return LocemReply(False, "INVALID_ARGUMENT", "%r is not a number" % w)
        return None

    def send(self, command: str) -> _Handle:
        self.log(command)
        name = command.split()[0].upper() if command.split() else ""
        bad = self._validate(command)
        if bad is not None:
            reply, dur = bad, 0.0
        elif name in self.fail_next:
            reply, dur = self.fail_next.pop(name), self.durations.get(name, 0.0)
        else:
            result = json.loads(json.dumps(self.site)) if name == "SCAN" else {}
            if name == "GOTO":          # the double's base is where it was last sent
                self.pose = [float(w) for w in command.split()[1:4]]
            elif name == "GET_POSE":
                result = {"pose": list(self.pose), "twist": [0.0, 0.0, 0.0]}
            elif name == "GET_TOOL_POINT":
                result = {"point": list(self.tool_point), "axis": [1.0, 0.0, 0.0], "tool": "spray_gun"}
            elif name == "STATUS":
                health = self.health_script.pop(0) if self.health_script else self.health
                result = {"running": [], "resources": {}, "health": json.loads(json.dumps(health)), "uptime_s": 1.0}
            reply, dur = LocemReply(True, "OK", "", result), self.durations.get(name, 0.0)
        h = _Handle(self, command, reply, dur)
        self.handles.append(h)
        return h

    def running(self) -> List[_Handle]:
        return [h for h in self.handles if not h.done()]


def nt(task: str, params: Dict[str, Any]) -> str:
    lines = []
    for k, v in params.items():
        if isinstance(v, str):
            lines.append("<%s> <http://example.org/proc#%s> <http://example.org/world#%s> ." % (task, k, v))
        elif isinstance(v, bool):
            lines.append('<%s> <http://example.org/proc#%s> "%s"^^<http://www.w3.org/2001/XMLSchema#boolean> .'
                         % (task, k, "true" if v else "false"))
        else:
            lines.append('<%s> <http://example.org/proc#%s> "%s"^^<http://www.w3.org/2001/XMLSchema#double> .'
                         % (task, k, v))
    return "\n".join(lines)


class PemkreDouble(PemkreClient):
    """TEST DOUBLE of PEMKRE for the taping process (see module doc)."""

    PROCESS = "http://example.org/proc#TapingProcess"

    AFTER_FAILURE = ("continue", "fail_process")

    def __init__(self, state_path: Optional[str] = None, validate_lines: bool = True,
                 extra_actions: Optional[List[str]] = None, after_failure: str = "continue",
                 skills: Optional[Dict[str, Any]] = None) -> None:
        if after_failure not in self.AFTER_FAILURE:
            raise ValueError("after_failure must be one of %s, got %r" % (", ".join(self.AFTER_FAILURE), after_failure))
        self.after_failure = after_failure
        self.skills = dict(skills or {})
        self.state_path = state_path
        self.validate_lines = validate_lines
        self.extra_actions = extra_actions or []
        self.calls: List[tuple] = []
        self.s: Dict[str, Any] = {"started": False, "joints": [], "current": None, "statuses": [], "seq": 0,
                                  "done": [], "pending": []}
        if state_path and os.path.exists(state_path):
            with open(state_path) as f:
                self.s = json.load(f)

    def _save(self) -> None:
        if self.state_path:
            tmp = self.state_path + ".tmp"
            with open(tmp, "w") as f:
                json.dump(self.s, f)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, self.state_path)

    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        self.calls.append(("start_process", process_iri, options))
        if options and "validateLines" in options:
            self.validate_lines = bool(options["validateLines"])
        if process_iri != self.PROCESS:
            raise PemkreCallError("unknown process IRI %r" % process_iri)
        self.s.update(started=True, failed=None, pending=[["SCAN", {}]] + [[a, {}] for a in self.extra_actions]
                      + [["GET_TOOL", {"tool": "taping_tool"}]])
        self._save()
        return "http://example.org/run#p1"

    def report_world(self, update: Dict[str, Any]) -> None:
        self.calls.append(("report_world", update))
        for j in update.get("joints", []):
            if j["id"] not in self.s["joints"]:
                self.s["joints"].append(j["id"])
                self.s["pending"].append(["VALIDATE_TAPE_LINE" if self.validate_lines else "TAPE_LINE",
                                          {"line": j["id"]}])
        self._save()

    def next_action(self) -> Dict[str, Any]:
        self.calls.append(("next_action",))
        if not self.s["started"]:
            return {"status": "failed", "detail": "no process"}
        if self.s.get("failed"):
            return {"status": "failed", "detail": self.s["failed"]}
        cur = self.s["current"]
        if cur is not None and cur["status"] in ("offered", "in_progress"):
            return self._answer(cur["type"], cur["task"], cur["params"])
        if not self.s["pending"]:
            if self.s.get("home_done"):
                return {"status": "ended"}
            self.s["pending"].append(["GO_HOME", {}])
        at, params = self.s["pending"].pop(0)
        self.s["seq"] += 1
        task = "http://example.org/run#task_%d" % self.s["seq"]
        self.s["current"] = {"type": at, "task": task, "params": params, "status": "offered"}
        self._save()
        return self._answer(at, task, params)

    def _answer(self, at: str, task: str, params: Dict[str, Any]) -> Dict[str, Any]:
        skill, kind = self.skills.get(at, ("", ""))
        return {"status": "action", "action_type": at, "task": task, "parameters": nt(task, params),
                "skill": skill, "skill_kind": kind}

    def set_task_status(self, task: str, status: str, detail: str = "") -> None:
        self.calls.append(("set_task_status", task, status, detail))
        cur = self.s["current"]
        if cur is None or cur["task"] != task:
            raise PemkreCallError("task %s is not the current task" % task)
        if status == "in_progress":
            if cur["status"] != "offered":
                raise PemkreCallError("task %s is already %s" % (task, cur["status"]))
            cur["status"] = "in_progress"
        elif status in ("succeeded", "failed"):
            if cur["status"] != "in_progress":
                raise PemkreCallError("task %s is not running (it is %s)" % (task, cur["status"]))
            cur["status"] = status
            self.s["statuses"].append([cur["type"], task, status, detail, cur["params"]])
            if status == "failed" and self.after_failure == "fail_process":
                self.s["failed"] = "task <%s> (%s) failed: %s" % (task, cur["type"], detail)
            if status == "succeeded" and cur["type"] == "VALIDATE_TAPE_LINE":
                nxt = "TAPE_LINE" if detail == "valid" else "MANUAL_TAPING"
                self.s["pending"].insert(0, [nxt, cur["params"]])
            if cur["type"] == "GO_HOME":
                self.s["home_done"] = True
            self.s["current"] = None
        else:
            raise PemkreCallError("status %r not allowed" % status)
        self._save()

    def executed(self, action_type: Optional[str] = None) -> List[list]:
        return [s for s in self.s["statuses"] if action_type is None or s[0] == action_type]


class AutoOperator:
    """TEST helper: answers prompts from a table (per kind, optionally per line id in the prompt text)."""

    def __init__(self, controller: Any, answers: Dict[str, str], reject: Optional[List[str]] = None,
                 delay_s: float = 0.0) -> None:
        self.controller = controller
        self.answers = answers
        self.reject = reject or []
        self.delay_s = delay_s
        self.asked: List[str] = []

    def __call__(self, event: str, prompt: Any) -> None:
        if event != "opened":
            return
        self.asked.append(prompt.kind)
        ans = self.answers[prompt.kind]
        if prompt.kind == "validate_line" and any(r in prompt.text for r in self.reject):
            ans = "invalid"
        threading.Timer(self.delay_s, self._answer, args=(prompt.id, ans)).start()

    def _answer(self, pid: str, ans: str) -> None:
        try:
            self.controller.operator_reply(pid, ans)
        except Exception:
            pass  # the prompt may have been withdrawn meanwhile


class Heartbeats:
    """TEST helper: feeds 'locem' heartbeats to the HEM from a thread until stopped."""

    def __init__(self, health: Any, module: str = "locem", period_s: float = 0.02,
                 alive: Optional[Callable[[], bool]] = None) -> None:
        self.health = health
        self.module = module
        self.period_s = period_s
        self.alive = alive or (lambda: True)       # no heartbeat while it says False (the module is dead)
        self._stop = threading.Event()
        self.last = time.monotonic()
        self._t = threading.Thread(target=self._run, daemon=True)
        self._t.start()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            if not self.alive():
                continue
            self.health.heartbeat(self.module)
            self.last = time.monotonic()

    def stop(self) -> None:
        self._stop.set()
        self._t.join(2.0)


def run_with_heartbeats(ex: Any, process: str, options: Optional[Dict[str, Any]] = None) -> str:
    """TEST helper: ``ex.controller.run_process`` with LOCEM's heartbeats fed to the HEM meanwhile; closes the
    executive afterwards (its controller's state stays readable). Returns the final phase."""
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        return ex.controller.run_process(process, options)
    finally:
        beats.stop()
        ex.close()
