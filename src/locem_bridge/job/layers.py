"""Split the wall-clock time of a job between the layers of the stack, from what the stack published.

ROS-free. The job benchmark records, while ``plasterboard.launch`` runs, plain time-stamped tuples into a
:class:`JobRecording` (``time.time()`` seconds):

- ``hicem_states``: ``(stamp, {"process", "phase", "action_type", "task"[, "skill"]})`` from ``/hicem/state``;
- ``prompts``: ``(stamp, prompt_id, event)`` from ``/hicem/prompts`` (``opened`` | ``answered`` | ``cancelled``);
- ``locem_events``: ``(stamp, command_id, name, interface, state)`` from ``/locem/status``;
- ``arm_samples`` / ``base_samples``: ``(stamp, moving)`` from ``joint_states`` and the simulator's ground truth
  base pose (the devices actually moving);
- ``pemkre_calls``: records of :mod:`locem_bridge.job.call_log` (exact PEMKRE call times measured inside
  HICEM) when HICEM was started with the hook, else empty.

:func:`analyse` turns a recording into the numbers the benchmark prints and stores. Every instant of a process
(HICEM's process start to its end phase) goes to exactly one layer, in this priority order:

``device``          an arm joint or the base was moving;
``locem_handling``  a LOCEM command was running (between its first and its final ``/locem/status`` event) but
                    no device moved: command parsing, bridge round trips, ramps, settling, checks;
``pemkre``          a PEMKRE call: exact with the call log; without it, HICEM's ``starting``/``asking``/
                    ``reporting`` phases (PEMKRE calls plus the HDICT writes around them);
``operator``        an operator prompt was open;
``health_wait``     HICEM waited for a crucial module to come back (``waiting_for_health``);
``hicem``           the rest: ticking trees, the data store, and the gaps between a LOCEM reply and the next
                    tick or between actions.

The LOCEM ``STATUS`` and ``HELP`` service calls (HICEM's heartbeat polls) and health events are not commands
of the job and are left out.
"""

from dataclasses import dataclass, field
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple

from .timeline import (Interval, activity_intervals, intersect, merge, phase_spans, spans_from_events,
                       split_window, subtract, total)

LAYERS = ("device", "locem_handling", "pemkre", "operator", "health_wait", "hicem")
TERMINAL = ("ended", "failed", "stopped")
PEMKRE_PHASES = ("starting", "asking", "reporting")
LOCEM_TERMINAL = ("rejected", "succeeded", "failed", "canceled")
NOT_JOB_COMMANDS = ("STATUS", "HELP", "HEALTH")


@dataclass
class JobRecording:
    """What the benchmark saw of one run (see the module doc for each field)."""

    steps: List[Tuple[str, str]]                      # (name, process IRI) in job order
    start: float                                      # launch started
    end: float                                        # launch ended (or the benchmark gave up)
    hicem_states: List[Tuple[float, Dict[str, str]]] = field(default_factory=list)
    prompts: List[Tuple[float, str, str]] = field(default_factory=list)
    locem_events: List[Tuple[float, int, str, str, str]] = field(default_factory=list)
    arm_samples: List[Tuple[float, bool]] = field(default_factory=list)
    base_samples: List[Tuple[float, bool]] = field(default_factory=list)
    pemkre_calls: List[Mapping[str, Any]] = field(default_factory=list)
    sample_gap: float = 0.25                          # longest sample period counted as motion (s)


def process_windows(rec: JobRecording) -> List[Dict[str, Any]]:
    """One entry per job step HICEM started: ``{name, iri, start, end, status}`` (status = HICEM's end phase,
    or ``unfinished`` when the recording ended first)."""
    spans = phase_spans(rec.hicem_states, rec.end, keys=("process", "phase"))
    out = []
    for name, iri in rec.steps:
        start = end = None
        status = "unfinished"
        for span in spans:
            if span["process"] != iri:
                continue
            if start is None:
                if span["phase"] in TERMINAL or span["phase"] == "idle":
                    continue  # a latched end state of an earlier run of the same process
                start = span["start"]
            if span["phase"] in TERMINAL:
                end, status = span["start"], span["phase"]
                break
        if start is not None:
            out.append({"name": name, "iri": iri, "start": start, "end": end if end is not None else rec.end,
                        "status": status})
    return out


def locem_commands(rec: JobRecording) -> Dict[int, Dict[str, Any]]:
    """``{id: {name, interface, start, end, final}}`` of the job's LOCEM commands."""
    events, info = [], {}
    for stamp, cid, name, interface, state in rec.locem_events:
        if name.upper() in NOT_JOB_COMMANDS or interface == "health":
            continue
        events.append((stamp, cid, "end" if state in LOCEM_TERMINAL else "event"))
        entry = info.setdefault(cid, {"name": name, "interface": interface, "final": ""})
        if state in LOCEM_TERMINAL and not entry["final"]:
            entry["final"] = state
    for cid, (t0, t1) in spans_from_events(events, rec.end).items():
        info[cid].update(start=t0, end=t1)
    return info


def layer_intervals(rec: JobRecording) -> Dict[str, List[Interval]]:
    """The raw (overlapping) intervals of each layer, before the priority split."""
    device = merge(activity_intervals(rec.arm_samples, rec.sample_gap)
                   + activity_intervals(rec.base_samples, rec.sample_gap))
    locem = merge((c["start"], c["end"]) for c in locem_commands(rec).values())
    states = phase_spans(rec.hicem_states, rec.end, keys=("process", "phase"))
    if rec.pemkre_calls:
        pemkre = merge((float(c["t0"]), float(c["t1"])) for c in rec.pemkre_calls)
    else:
        pemkre = merge((s["start"], s["end"]) for s in states if s["phase"] in PEMKRE_PHASES)
    prompt_events = [(t, pid, "end" if ev in ("answered", "cancelled") else "event") for t, pid, ev in rec.prompts]
    operator = merge(spans_from_events(prompt_events, rec.end).values())
    health = merge((s["start"], s["end"]) for s in states if s["phase"] == "waiting_for_health")
    return {"device": device, "locem_commands": locem, "pemkre": pemkre, "operator": operator,
            "health_wait": health, "arm": activity_intervals(rec.arm_samples, rec.sample_gap),
            "base": activity_intervals(rec.base_samples, rec.sample_gap)}


def split(window: Interval, raw: Mapping[str, List[Interval]]) -> Dict[str, float]:
    """Seconds of ``window`` per layer (:data:`LAYERS`), adding up to the window."""
    return split_window(window, [("device", raw["device"]), ("locem_handling", raw["locem_commands"]),
                                 ("pemkre", raw["pemkre"]), ("operator", raw["operator"]),
                                 ("health_wait", raw["health_wait"])], rest="hicem")


def analyse(rec: JobRecording) -> Dict[str, Any]:
    """Every number of the job benchmark's time split (seconds), as a JSON-ready dict."""
    procs = process_windows(rec)
    raw = layer_intervals(rec)
    out: Dict[str, Any] = {"launch_s": rec.end - rec.start, "pemkre_source":
                           "call_log" if rec.pemkre_calls else "hicem_phases", "processes": []}
    windows = [(p["start"], p["end"]) for p in procs]
    for p in procs:
        row = dict(p)
        row["wall_s"] = p["end"] - p["start"]
        row["layers"] = split((p["start"], p["end"]), raw)
        out["processes"].append(row)
    if procs:
        job = (procs[0]["start"], procs[-1]["end"])
        out["startup_s"] = job[0] - rec.start
        out["job_s"] = job[1] - job[0]
        out["teardown_s"] = rec.end - job[1]
        layers = {name: sum(p["layers"][name] for p in out["processes"]) for name in LAYERS}
        layers["between_processes"] = out["job_s"] - sum(p["wall_s"] for p in out["processes"])
        out["layers"] = layers
        in_procs = merge(windows)
        out["locem_commands_s"] = total(intersect(raw["locem_commands"], in_procs))
        out["device_s"] = total(intersect(raw["device"], in_procs))
        out["arm_moving_s"] = total(intersect(raw["arm"], in_procs))
        out["base_moving_s"] = total(intersect(raw["base"], in_procs))
        out["device_outside_commands_s"] = total(subtract(intersect(raw["device"], in_procs),
                                                          raw["locem_commands"]))
        out["pemkre_calls_s"] = total(intersect(raw["pemkre"], in_procs))
    else:
        out.update(startup_s=rec.end - rec.start, job_s=0.0, teardown_s=0.0,
                   layers={name: 0.0 for name in LAYERS}, locem_commands_s=0.0, device_s=0.0, arm_moving_s=0.0,
                   base_moving_s=0.0,
                   device_outside_commands_s=0.0, pemkre_calls_s=0.0)
        out["layers"]["between_processes"] = 0.0
    out["commands"] = command_table(rec, raw["device"])
    out["actions"] = action_table(rec, raw["device"])
    out["pemkre_call_table"] = call_table(rec.pemkre_calls)
    return out


def command_table(rec: JobRecording, device: Sequence[Interval]) -> Dict[str, Dict[str, float]]:
    """Per LOCEM command name: ``count``, ``total_s`` (merged), ``device_s`` (devices moving meanwhile),
    ``failed`` (commands not ending ``succeeded``)."""
    by_name: Dict[str, Dict[str, Any]] = {}
    for c in locem_commands(rec).values():
        e = by_name.setdefault(c["name"], {"count": 0, "spans": [], "failed": 0})
        e["count"] += 1
        e["spans"].append((c["start"], c["end"]))
        e["failed"] += 0 if c["final"] == "succeeded" else 1
    return {name: {"count": e["count"], "total_s": total(e["spans"]),
                   "device_s": total(intersect(e["spans"], device)), "failed": e["failed"]}
            for name, e in sorted(by_name.items())}


def action_table(rec: JobRecording, device: Sequence[Interval]) -> Dict[str, Dict[str, float]]:
    """Per HICEM high-level action type: ``count`` (tasks), ``wall_s`` (from the action's first state to the
    next action or process end), ``device_s``, ``skills`` (the skills PEMKRE matched its tasks to, as HICEM's
    state named them; empty without matching)."""
    spans = phase_spans(rec.hicem_states, rec.end, keys=("process", "action_type", "task"))
    by_type: Dict[str, Dict[str, Any]] = {}
    for s in spans:
        if not s["action_type"] or not s["task"]:
            continue
        e = by_type.setdefault(s["action_type"], {"tasks": set(), "spans": []})
        e["tasks"].add(s["task"])
        e["spans"].append((s["start"], s["end"]))
    skills: Dict[str, set] = {}
    for _stamp, state in rec.hicem_states:
        if state.get("action_type") and state.get("skill"):
            skills.setdefault(state["action_type"], set()).add(state["skill"])
    return {name: {"count": len(e["tasks"]), "wall_s": total(e["spans"]),
                   "device_s": total(intersect(e["spans"], device)), "skills": sorted(skills.get(name, ()))}
            for name, e in sorted(by_type.items())}


def call_table(calls: Sequence[Mapping[str, Any]]) -> Dict[str, Dict[str, float]]:
    """Per recorded call name: ``count``, ``total_s``, ``max_s``, ``failed``."""
    out: Dict[str, Dict[str, float]] = {}
    for c in calls:
        d = float(c["t1"]) - float(c["t0"])
        e = out.setdefault(str(c["call"]), {"count": 0, "total_s": 0.0, "max_s": 0.0, "failed": 0})
        e["count"] += 1
        e["total_s"] += d
        e["max_s"] = max(e["max_s"], d)
        e["failed"] += 0 if c.get("ok", True) else 1
    return out


def window_of(rec: JobRecording) -> Optional[Interval]:
    """The job window (first process start to last process end), or None when no process started."""
    procs = process_windows(rec)
    return (procs[0]["start"], procs[-1]["end"]) if procs else None


__all__ = ["JobRecording", "LAYERS", "analyse", "process_windows", "locem_commands", "layer_intervals", "split",
           "command_table", "action_table", "call_table", "window_of"]
