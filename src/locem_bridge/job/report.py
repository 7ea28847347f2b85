"""The run report of a job: ``results/<run>/report.json``, ``report.md`` and the wall pictures.

``report.json`` keeps at least these keys:

* ``processes``: list of ``{name, iri, status, duration_s}`` in the order they ran;
* ``outcome.joints_total``, ``outcome.joints_taped``, ``outcome.tape_coverage``, ``outcome.spray_coverage``,
  ``outcome.sand_coverage`` (fractions 0..1), ``outcome.operator_interventions``, ``outcome.collisions``.

``tape_coverage`` is the mean covered fraction over the joints the robot was to tape (joints the operator sent to
manual taping are reported as ``joints_manual`` and excluded); ``spray_coverage`` and ``sand_coverage`` are the
covered fractions of all wall area. ``outcome.areas_manual`` lists the parts of areas HICEM left for manual work
(a section the arm could not reach: ``{work, area, section, along, height}``, metres along the area and above the
floor); the processes still succeed. ``results/latest`` is a relative symlink to the newest run.

The robot is judged on the parts it was to work: ``outcome.joints_planned_manual`` lists the parts of joints HICEM
left for taping by hand (``{joint, part, along, reason}``, metres from the joint's start), and the worksite measured
the job knowing both lists (each joint's ``manual_m`` and ``coverage_reachable``, each wall's ``*_reachable`` and
``*_manual_m2``). ``outcome.reachable`` holds ``tape_coverage_min`` and ``tape_coverage`` (lowest and mean
``coverage_reachable`` over the robot's joints: not sent to manual taping and with a part outside the planned manual
parts; None when each of them is wholly manual), ``spray_coverage``, ``sand_coverage`` (over the work area outside the planned
manual parts) and ``spray_thickness_cv`` (the largest of the walls' on those cells); without planned manual parts
they equal ``tape_coverage``, ``spray_coverage``, ``sand_coverage`` and ``spray_thickness_cv``.
``outcome.manual_touched`` (``tape_m``, ``spray_m2``, ``sand_m2``) is work the worksite found deep inside the
planned manual parts, where the robot cannot reach: it should be 0.

``launches`` lists the launches of the run (one unless it was resumed with ``tools/main.sh --resume``): ``started``,
``last_seen`` (ISO local time), ``wall_clock_s`` and ``ended`` (the job's end reason in that launch, or ``cut off``
when it has none: a power loss or kill); the processes, outcome, interventions and KPIs cover them all, and
``timing`` then adds ``wall_clock_total_s`` and ``down_s`` (between the launches).

``ended`` says how the job ended: ``{"reason", "early", "detail", "not_run", "unread"}`` where ``reason`` is one
of :data:`ENDED_REASONS`, ``early`` is true when the job did not run to its end (a reason of
:data:`EARLY_REASONS`, or steps that never ran), ``not_run`` names those steps and
``unread`` lists what the job node could not read for the report (the simulation's final measurement, the KPI
table, ...: a report written while the launch shuts down uses what it collected before). An empty ``outcome``
(the simulation never answered) is reported as not measured (``outcome.measured`` false), not refused.
"""

import datetime
import json
import os
import shutil
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional

ENDED_REASONS = {
    "completed": "every process ran and succeeded",
    "process_failed": "a process of the job failed",
    "operator_stop": "the operator pressed STOP",
    "process_timeout": "a process did not end within the job's process timeout",
    "shutdown": "the launch shut down (SIGINT/SIGTERM) before the job was done",
    "hicem_unreachable": "HICEM could not be reached",
    "pemkre_unreachable": "PEMKRE could not be reached",
    "worksite_unreachable": "the worksite (its measurement and scan services) could not be reached",
}
EARLY_REASONS = ("operator_stop", "process_timeout", "shutdown", "hicem_unreachable", "pemkre_unreachable",
                 "worksite_unreachable")
REQUIRED_OUTCOME_KEYS = ("joints_total", "joints_taped", "tape_coverage", "spray_coverage", "sand_coverage",
                         "operator_interventions", "collisions")


class ReportError(ValueError):
    """The data handed to the report writer is incomplete or inconsistent."""


@dataclass
class ProcessRecord:
    name: str
    iri: str
    status: str
    duration_s: float
    detail: str = ""


@dataclass
class RunRecord:
    """Everything a finished (or aborted) job knows; ``outcome`` is the worksite's measurement summary."""

    processes: List[ProcessRecord]
    outcome: Dict[str, Any]
    operator_interventions: int
    collisions: int
    settings: Dict[str, Any] = field(default_factory=dict)
    kpis: List[Dict[str, Any]] = field(default_factory=list)
    timing: Dict[str, float] = field(default_factory=dict)
    pictures: List[str] = field(default_factory=list)
    started: Optional[datetime.datetime] = None
    manual_areas: List[Dict[str, Any]] = field(default_factory=list)
    ended: Optional["JobEnd"] = None
    manual_joints: List[Dict[str, Any]] = field(default_factory=list)
    launches: List[Dict[str, Any]] = field(default_factory=list)


@dataclass
class JobEnd:
    """How and why the job ended: ``reason`` from :data:`ENDED_REASONS`, what ``detail`` the job node knows,
    the steps that never ran and what could not be read for the report."""

    reason: str
    detail: str = ""
    not_run: List[str] = field(default_factory=list)
    unread: List[str] = field(default_factory=list)

    def as_dict(self) -> Dict[str, Any]:
        if self.reason not in ENDED_REASONS:
            raise ReportError("ended.reason %r is not one of %s" % (self.reason, ", ".join(ENDED_REASONS)))
        return {"reason": self.reason, "early": bool(self.not_run) or self.reason in EARLY_REASONS,
                "what": ENDED_REASONS[self.reason], "detail": self.detail, "not_run": list(self.not_run), "unread": list(self.unread)}


def run_name(now: Optional[datetime.datetime] = None) -> str:
    now = now or datetime.datetime.now()
    return now.strftime("%Y%m%d-%H%M%S")


def build_report(record: RunRecord, run: str) -> Dict[str, Any]:
    """The ``report.json`` document (pure function; raises :class:`ReportError` for unusable input)."""
    measured = bool(record.outcome)
    joints = record.outcome.get("joints") if measured else {}
    if not isinstance(joints, dict):
        raise ReportError("outcome.joints must map joint id -> {coverage, taped, manual}")
    robot_joints = {jid: j for jid, j in joints.items() if not j.get("manual")}
    tape_coverage = (sum(float(j["coverage"]) for j in robot_joints.values()) / len(robot_joints)
                     if robot_joints else 0.0)
    walls = record.outcome.get("walls", {})
    cvs = [float(w["thickness_cv"]) for w in walls.values() if "thickness_cv" in w]
    # on the parts the robot was to work (a joint wholly manual is no robot joint here)
    reach_cov = [float(j.get("coverage_reachable", j["coverage"])) for j in robot_joints.values()
                 if j.get("coverage_reachable", j["coverage"]) is not None]
    reach_cvs = [float(w.get("thickness_cv_reachable", w.get("thickness_cv"))) for w in walls.values()
                 if w.get("thickness_cv_reachable", w.get("thickness_cv")) is not None]
    sim_reach = record.outcome.get("reachable") or {}

    def fraction(key: str) -> Optional[float]:
        value = sim_reach.get(key, record.outcome.get(key, 0.0))
        return None if value is None else round(float(value), 6)
    no_joint = None if robot_joints else 0.0     # robot joints, each wholly manual: nothing measured on them
    touched = record.outcome.get("manual_touched") or {}
    outcome = {
        "joints_total": len(joints),
        "joints_taped": sum(1 for j in robot_joints.values() if j.get("taped")),
        "joints_manual": len(joints) - len(robot_joints),
        "tape_coverage": round(tape_coverage, 6),
        "spray_coverage": round(float(record.outcome.get("spray_coverage", 0.0)), 6),
        "spray_thickness_cv": round(max(cvs), 6) if cvs else 0.0,
        "sand_coverage": round(float(record.outcome.get("sand_coverage", 0.0)), 6),
        "operator_interventions": int(record.operator_interventions),
        "collisions": int(record.collisions),
        "areas_manual": [dict(m) for m in record.manual_areas],
        "joints_planned_manual": [dict(m) for m in record.manual_joints],
        "reachable": {"tape_coverage_min": round(min(reach_cov), 6) if reach_cov else no_joint,
                      "tape_coverage": round(sum(reach_cov) / len(reach_cov), 6) if reach_cov else no_joint,
                      "spray_coverage": fraction("spray_coverage"), "sand_coverage": fraction("sand_coverage"),
                      "spray_thickness_cv": round(max(reach_cvs), 6) if reach_cvs else 0.0},
        "manual_touched": {k: round(float(touched.get(k) or 0.0), 6) for k in ("tape_m", "spray_m2", "sand_m2")},
        "joints": joints,
        "walls": walls,
        "spray_seams": [dict(x) for x in record.outcome.get("spray_seams", [])] if measured else [],
        "measured": measured,
    }
    for key in ("tape_coverage", "spray_coverage", "sand_coverage"):
        if not 0.0 <= outcome[key] <= 1.0:
            raise ReportError("outcome.%s = %r is not a fraction in 0..1" % (key, outcome[key]))
        value = outcome["reachable"][key]
        if value is not None and not 0.0 <= value <= 1.0:
            raise ReportError("outcome.reachable.%s = %r is not a fraction in 0..1" % (key, value))
    started = record.started.isoformat(timespec="seconds") if record.started else None
    return {
        "run": run,
        "started": started,
        "settings": record.settings,
        "processes": [{"name": p.name, "iri": p.iri, "status": p.status, "duration_s": round(p.duration_s, 3),
                       "detail": p.detail} for p in record.processes],
        "outcome": outcome,
        "kpis": record.kpis,
        "timing": {k: round(v, 3) for k, v in record.timing.items()},
        "pictures": [os.path.basename(p) for p in record.pictures],
        "ended": (record.ended or JobEnd("completed")).as_dict(),
        "launches": [_launch(x) for x in record.launches],
    }


def _launch(launch: Dict[str, Any]) -> Dict[str, Any]:
    """A launch of the run as the report shows it: ISO start and last sign of life, wall seconds, how it ended."""
    def iso(t: Any) -> Optional[str]:
        return None if t is None else datetime.datetime.fromtimestamp(float(t)).isoformat(timespec="seconds")
    return {"started": iso(launch.get("started")), "last_seen": iso(launch.get("last_seen")),
            "wall_clock_s": round(float(launch.get("wall_clock_s", 0.0)), 3),
            "ended": launch.get("ended") or "cut off (no end recorded: a power loss, kill or crash)"}


def render_markdown(report: Dict[str, Any]) -> str:
    o = report["outcome"]
    lines = ["# Run %s" % report["run"], ""]
    ended = report.get("ended") or {}
    if ended:
        lines += ["**Ended: %s**%s -- %s%s" % (ended["reason"], " (early)" if ended.get("early") else "",
                                              ended.get("what", ""),
                                              (": " + ended["detail"]) if ended.get("detail") else ""), ""]
        if ended.get("not_run"):
            lines += ["Not run: " + ", ".join(ended["not_run"]), ""]
        for item in ended.get("unread") or []:
            lines += ["Could not be read: " + item, ""]
    if report.get("settings"):
        lines += ["Settings: " + ", ".join("%s=%s" % kv for kv in sorted(report["settings"].items())), ""]
    lines += ["## Processes", "", "| process | status | duration |", "| --- | --- | --- |"]
    lines += ["| %s | %s | %.1f s |" % (p["name"], p["status"], p["duration_s"]) for p in report["processes"]]
    lines += ["", "## Outcome", "", "| measure | value |", "| --- | --- |",
              "| joints taped by the robot | %d of %d (%d manual) |" % (o["joints_taped"], o["joints_total"] -
                                                                      o["joints_manual"], o["joints_manual"]),
              "| tape coverage | %.1f %% |" % (100 * o["tape_coverage"]),
              "| spray coverage | %.1f %% (thickness CV %.3f) |" % (100 * o["spray_coverage"], o["spray_thickness_cv"]),
              "| sand coverage | %.1f %% |" % (100 * o["sand_coverage"])]
    reach = o.get("reachable")
    if reach:
        lines += ["| tape coverage of the reachable parts | %s (lowest joint %s) |" % (
                      _percent(reach["tape_coverage"]), _percent(reach["tape_coverage_min"])),
                  "| spray coverage of the reachable parts | %s (thickness CV %.3f) |" % (
                      _percent(reach["spray_coverage"]), reach["spray_thickness_cv"]),
                  "| sand coverage of the reachable parts | %s |" % _percent(reach["sand_coverage"])]
    lines += ["| area sections left for manual work | %s |" % (
                  "; ".join("%s %s section %d (along %g..%g m, height %g..%g m)" % (
                      m["work"], m["area"], m["section"], m["along"][0], m["along"][1], m["height"][0],
                      m["height"][1]) for m in o.get("areas_manual", [])) or "none"),
              "| joint parts left for manual work | %s |" % (
                  "; ".join("%s part %d (along %g..%g m%s)" % (
                      m["joint"], m["part"], m["along"][0], m["along"][1],
                      ("; " + m["reason"]) if m.get("reason") else "")
                      for m in o.get("joints_planned_manual", [])) or "none")]
    touched = o.get("manual_touched")
    if touched:
        lines += ["| work done inside the planned manual parts | tape %.2f m, spray %.3f m2, sand %.3f m2 |" % (
            touched["tape_m"], touched["spray_m2"], touched["sand_m2"])]
    lines += ["| operator interventions | %d |" % o["operator_interventions"],
              "| collisions | %d |" % o["collisions"]]
    if not o.get("measured", True):
        lines += ["", "The worksite's outcome could not be measured: the numbers above are not measurements."]
    if len(report.get("launches") or []) > 1:
        lines += ["", "## Launches", "", "The run was resumed: one report over its %d launches." % len(
            report["launches"]), "", "| launch | started | last seen | wall clock | ended |",
            "| --- | --- | --- | --- | --- |"]
        lines += ["| %d | %s | %s | %.0f s | %s |" % (n, x["started"], x["last_seen"], x["wall_clock_s"], x["ended"])
                  for n, x in enumerate(report["launches"], 1)]
    if report.get("timing"):
        lines += ["", "## Time", "", "| part | seconds |", "| --- | --- |"]
        lines += ["| %s | %.2f |" % kv for kv in report["timing"].items()]
    if report.get("kpis"):
        keys = list(report["kpis"][0])
        lines += ["", "## KPIs", "", "| " + " | ".join(keys) + " |", "|" + " --- |" * len(keys)]
        lines += ["| " + " | ".join(str(row.get(k, "")) for k in keys) + " |" for row in report["kpis"]]
    if report.get("pictures"):
        lines += ["", "## Walls", ""] + ["![%s](%s)" % (p[:-4], p) for p in report["pictures"]]
    return "\n".join(lines) + "\n"


def _percent(value: Optional[float]) -> str:
    """A fraction as a percentage, or ``n/a`` (None: nothing the robot was to work)."""
    return "n/a" if value is None else "%.1f %%" % (100 * value)


def write_report(record: RunRecord, results_dir: str, run: Optional[str] = None) -> str:
    """Write the run folder and point ``results/latest`` at it; returns the folder path.

    The folder is written under a temporary name and renamed into place, so a reader never sees half a report.
    """
    run = run or run_name(record.started)
    report = build_report(record, run)
    os.makedirs(results_dir, exist_ok=True)
    final = os.path.join(results_dir, run)
    staging = final + ".partial"
    shutil.rmtree(staging, ignore_errors=True)
    os.makedirs(staging)
    for picture in record.pictures:
        shutil.copy2(picture, os.path.join(staging, os.path.basename(picture)))
    with open(os.path.join(staging, "report.json"), "w", encoding="utf-8") as handle:
        json.dump(report, handle, indent=2, sort_keys=True)
    with open(os.path.join(staging, "report.md"), "w", encoding="utf-8") as handle:
        handle.write(render_markdown(report))
    if os.path.exists(final):
        shutil.rmtree(final)
    os.rename(staging, final)
    latest = os.path.join(results_dir, "latest")
    tmp_link = latest + ".tmp"
    if os.path.lexists(tmp_link):
        os.remove(tmp_link)
    os.symlink(run, tmp_link)
    os.replace(tmp_link, latest)
    return final
