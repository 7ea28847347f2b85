"""Follows one job (a sequence of processes run by HICEM) from HICEM's state and prompt events.

ROS-free: the job node feeds it the fields of ``/hicem/state`` and ``/hicem/prompts`` messages as dicts. It
turns them into one-line progress messages ("[2/3 spraying] SPRAY_AREA, area 2 of 4"), per-process records
for the report, the count of operator interventions (answered prompts, by kind), and the parts of areas and
joints HICEM left for manual work (named in a spray, sand or taping task's detail when it is reported), which
:meth:`JobTracker.manual_plan` hands to the worksite's measurement.
"""

import time
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

from locem_bridge.hicem.nodes.area_work import AREA_WORK, parse_manual_joints, parse_manual_work

from .report import ProcessRecord

TERMINAL_PHASES = ("ended", "failed", "stopped")
LINE_ACTIONS = ("VALIDATE_TAPE_LINE", "TAPE_LINE", "MANUAL_TAPING")
AREA_ACTIONS = ("SPRAY_AREA", "SAND_AREA")


def with_manual_plan(call: Callable[..., Dict[str, Any]], name: str, manual: Mapping[str, Any],
                     **args: Any) -> Tuple[Dict[str, Any], str]:
    """``call(name, manual=manual, **args)`` (a worksite measurement: ``sim/outcome``, ``sim/save_outcome``); when
    the worksite refuses the plan (``call`` raises a RuntimeError naming ``manual``) ``call(name, **args)`` again,
    so the job keeps its measurement: (the result, the refusal or '')."""
    try:
        return call(name, manual=manual, **args), ""
    except RuntimeError as exc:
        if "manual" not in str(exc):
            raise
        return call(name, **args), str(exc)


@dataclass(frozen=True)
class JobStep:
    """One process of the job: a short name, the abstract process IRI and its options."""

    name: str
    iri: str
    options: Mapping[str, Any] = field(default_factory=dict)


class JobTracker:
    """State of a running job. ``totals`` gives ``joints`` and ``areas`` of the site, for "n of N" progress."""

    def __init__(self, steps: List[JobStep], totals: Mapping[str, int],
                 say: Callable[[str], None] = print, clock: Callable[[], float] = time.monotonic) -> None:
        self.steps = steps
        self.totals = dict(totals)
        self.say = say
        self.clock = clock
        self.records: List[ProcessRecord] = []
        self.interventions: Dict[str, int] = {}
        self.manual_areas: List[Dict[str, Any]] = []
        self.manual_joints: List[Dict[str, Any]] = []
        self.current: Optional[int] = None
        self._started = 0.0
        self._carried = 0.0
        self._tasks: Dict[str, List[str]] = {}
        self._last_task = ""
        self._done: Optional[Dict[str, Any]] = None

    # -- feeding ------------------------------------------------------------------------------------------
    def begin(self, index: int, carried_s: float = 0.0, resumed: bool = False) -> None:
        """The job node is about to start ``steps[index]`` (``resumed``: to follow it as HICEM goes on with it after
        a restart of the job, ``carried_s`` seconds already spent on it before)."""
        self.current = index
        self._started = self.clock()
        self._carried = max(0.0, float(carried_s))
        self._tasks = {}
        self._last_task = ""
        self._joint_index = 0
        self._last_line_action = ""
        self._area_index = 0
        self._last_action = ""
        self._all_tasks: set = set()
        self._done = None
        step = self.steps[index]
        self.say("%s %s %s" % (self._tag(), "resuming" if resumed else "starting", step.name))

    def on_state(self, state: Mapping[str, Any]) -> None:
        """A ``/hicem/state`` message (process, phase, action_type, task, skill, node, detail) as a dict."""
        if self.current is None or state.get("process") != self.steps[self.current].iri:
            return
        task = state.get("task", "")
        action = state.get("action_type", "")
        if task and task != self._last_task and state.get("phase") in ("running", "asking", "reporting"):
            self._last_task = task
            seen = self._tasks.setdefault(action, [])
            if task not in seen:
                seen.append(task)
                if action in LINE_ACTIONS:
                    # a joint starts with its validation, or with its taping when it is not validated
                    if action == "VALIDATE_TAPE_LINE" or self._last_line_action != "VALIDATE_TAPE_LINE":
                        self._joint_index += 1
                    self._last_line_action = action
                if action in AREA_ACTIONS:
                    # an area task after RECOVER is the failed area worked again, not a new one
                    if self._last_action != "RECOVER":
                        self._area_index += 1
            if task not in self._all_tasks:
                self._all_tasks.add(task)
                self._last_action = action
            n = (self._joint_index if action in LINE_ACTIONS else
                 self._area_index if action in AREA_ACTIONS else len(seen))
            skill = str(state.get("skill") or "")
            self.say("%s %s%s%s" % (self._tag(), action, " (skill %s)" % skill if skill and skill != action else "",
                                    self._count(action, n)))
        if state.get("phase") == "reporting" and action in AREA_ACTIONS:
            for part in parse_manual_work(str(state.get("detail", ""))):
                part = dict(part, work=AREA_WORK[action])
                if part not in self.manual_areas:
                    self.manual_areas.append(part)
        if state.get("phase") == "reporting" and action == "TAPE_LINE":
            for part in parse_manual_joints(str(state.get("detail", ""))):
                if part not in self.manual_joints:
                    self.manual_joints.append(part)
        if state.get("phase") in TERMINAL_PHASES and self._done is None:
            self._done = dict(state)

    def on_prompt(self, prompt: Mapping[str, Any]) -> None:
        """A ``/hicem/prompts`` event (id, event, kind, text, answer) as a dict."""
        if prompt.get("event") == "opened":
            self.say("%s operator: %s" % (self._tag(), prompt.get("text", "")))
        elif prompt.get("event") == "answered":
            kind = str(prompt.get("kind", "other"))
            self.interventions[kind] = self.interventions.get(kind, 0) + 1

    # -- reading ------------------------------------------------------------------------------------------
    @property
    def finished(self) -> Optional[Dict[str, Any]]:
        """The terminal state of the current process once it has ended, else None."""
        return self._done

    def end(self, status: Optional[str] = None, detail: str = "") -> ProcessRecord:
        """Close the current process (with its terminal state, or ``status`` when it never got one)."""
        assert self.current is not None
        step = self.steps[self.current]
        final = self._done or {}
        phase = status or final.get("phase", "failed")
        record = ProcessRecord(step.name, step.iri, "succeeded" if phase == "ended" else phase,
                               self.elapsed(), detail or final.get("detail", ""))
        self.records.append(record)
        self.say("%s %s %s in %.1f s%s" % (self._tag(), step.name, record.status, record.duration_s,
                                          (": " + record.detail) if record.detail and record.status != "succeeded"
                                          else ""))
        self.current = None
        return record

    def manual_plan(self) -> Dict[str, List[Dict[str, Any]]]:
        """The parts left for manual work so far, as the worksite's measurement takes them (``manual`` of
        ``sim/outcome``): ``{"areas": [{work, area, along, height}], "joints": [{joint, along}]}``."""
        return {"areas": [{"work": m["work"], "area": m["area"], "along": list(m["along"]),
                           "height": list(m["height"])} for m in list(self.manual_areas)],
                "joints": [{"joint": m["joint"], "along": list(m["along"])} for m in list(self.manual_joints)]}

    def elapsed(self) -> float:
        """Seconds spent on the current process (before a restart of the job included); 0 when none runs."""
        return 0.0 if self.current is None else self._carried + self.clock() - self._started

    @property
    def total_interventions(self) -> int:
        return sum(self.interventions.values())

    def _tag(self) -> str:
        if self.current is None:
            return "[job]"
        return "[%d/%d %s]" % (self.current + 1, len(self.steps), self.steps[self.current].name)

    def _count(self, action: str, n: int) -> str:
        if action in LINE_ACTIONS and self.totals.get("joints"):
            return ", joint %d of %d" % (n, self.totals["joints"])
        if action in AREA_ACTIONS and self.totals.get("areas"):
            return ", area %d of %d" % (n, self.totals["areas"])
        return ""
