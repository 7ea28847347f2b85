"""The job's own record of a run, kept on disk while it runs: what a job cut short (a power loss, ``kill -9``,
Ctrl-C) needs to go on where it stopped and to be reported as one job (``tools/main.sh --resume``).

ROS-free. The job node keeps one :class:`JobJournal` per run (``<state_dir>/<run>_job.json``) and saves it when a
launch of the run begins, when a process begins and ends, and every :data:`SAVE_PERIOD_S` while a process runs
(operator answers and manual parts go with the next save). A save writes a new file, syncs it to the disk and renames it over the
old one, so the file is always one whole journal: the last saved, at most :data:`SAVE_PERIOD_S` old.

It holds the job's steps with their options (a resumed run refuses a job file whose steps differ), every launch of the run (start,
last seen alive, how it ended: empty while it runs or when it was cut off), the records of the processes that
ended, the process that was running and the time spent on it so far, the operator interventions by kind and the
parts HICEM left for manual work.

:func:`resume_point` decides where a resumed job goes on: after the processes the journal recorded as ended
(succeeded or failed: a stopped, timed-out, interrupted or never started process runs again, its time so far
carried over) and those PEMKRE's execution log shows ended since the run began (the journal may have missed an end
the power cut short).
"""

import json
import time
from dataclasses import asdict, dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

from ..common.files import write_whole
from .report import ProcessRecord
from .tracker import JobStep, JobTracker

FORMAT = 1
SAVE_PERIOD_S = 2.0            # a running process's journal is at most this old (wall seconds)
DONE = ("succeeded", "failed")  # a process recorded with one of these is not run again on resume ...
NOT_STARTED = "not started"     # ... unless its detail begins so: HICEM never ran it (the job node's word)


class JournalError(ValueError):
    """A journal that cannot be used: unreadable, not a journal, of another job; the message names the file."""


@dataclass
class Launch:
    """One launch of the run: wall-clock start and last sign of life (epoch seconds), how the job ended in it
    (a :data:`locem_bridge.job.report.ENDED_REASONS` key; empty while it runs or when it was cut off)."""

    started: float
    last_seen: float
    ended: str = ""

    def as_dict(self) -> Dict[str, Any]:
        return {"started": self.started, "last_seen": self.last_seen, "ended": self.ended,
                "wall_clock_s": round(max(0.0, self.last_seen - self.started), 3)}


@dataclass
class JobJournal:
    """The run's journal at ``path`` (see the module doc); ``clock`` gives epoch seconds."""

    path: str
    steps: List[Dict[str, Any]] = field(default_factory=list)
    launches: List[Launch] = field(default_factory=list)
    records: List[ProcessRecord] = field(default_factory=list)
    current: Optional[Dict[str, Any]] = None          # {"index": i, "spent_s": s} of the process running
    interventions: Dict[str, int] = field(default_factory=dict)
    manual_areas: List[Dict[str, Any]] = field(default_factory=list)
    manual_joints: List[Dict[str, Any]] = field(default_factory=list)
    clock: Callable[[], float] = field(default=time.time, repr=False)

    # -- reading ------------------------------------------------------------------------------------------
    @classmethod
    def load(cls, path: str, steps: Sequence[JobStep], clock: Callable[[], float] = time.time) -> "JobJournal":
        """The journal saved at ``path`` for a job of ``steps``; :class:`JournalError` names the file and what is
        wrong (missing, not JSON, not a journal, written for other steps)."""
        try:
            with open(path, encoding="utf-8") as handle:
                doc = json.load(handle)
        except FileNotFoundError:
            raise JournalError("%s: no job journal there (was the run started by this version, with this "
                               "state folder?)" % path)
        except (OSError, ValueError) as exc:
            raise JournalError("%s: cannot be read as a job journal: %s" % (path, exc))
        if not isinstance(doc, dict) or doc.get("format") != FORMAT:
            raise JournalError("%s: not a job journal of format %d (found %r)" % (
                path, FORMAT, doc.get("format") if isinstance(doc, dict) else type(doc).__name__))
        try:
            journal = cls(path=path, steps=[dict(s) for s in doc["steps"]],
                          launches=[Launch(float(x["started"]), float(x["last_seen"]), str(x.get("ended", "")))
                                    for x in doc["launches"]],
                          records=[ProcessRecord(str(r["name"]), str(r["iri"]), str(r["status"]),
                                                 float(r["duration_s"]), str(r.get("detail", "")))
                                   for r in doc["records"]],
                          current=dict(doc["current"]) if doc.get("current") else None,
                          interventions={str(k): int(v) for k, v in doc.get("interventions", {}).items()},
                          manual_areas=list(doc.get("manual_areas", [])),
                          manual_joints=list(doc.get("manual_joints", [])), clock=clock)
        except (KeyError, TypeError, ValueError) as exc:
            raise JournalError("%s: a job journal with a missing or bad entry (%s: %s)" % (
                path, type(exc).__name__, exc))
        wanted = _step_list(steps)
        if journal.steps != wanted:
            raise JournalError("%s: the run's job had the steps %s; the job file now has %s (resume with the job "
                               "file the run began with)" % (path, _names(journal.steps), _names(wanted)))
        return journal

    @classmethod
    def fresh(cls, path: str, steps: Sequence[JobStep], clock: Callable[[], float] = time.time) -> "JobJournal":
        return cls(path=path, steps=_step_list(steps), clock=clock)

    # -- writing ------------------------------------------------------------------------------------------
    def begin_launch(self) -> None:
        """A launch of the run begins (the job node started)."""
        now = self.clock()
        self.launches.append(Launch(now, now))
        self.save()

    def capture(self, tracker: JobTracker) -> None:
        """Take the job's state from ``tracker`` (records, running process and its time, interventions, manual
        parts) and save it."""
        self.records = list(tracker.records)
        self.current = (None if tracker.current is None else
                        {"index": tracker.current, "spent_s": round(tracker.elapsed(), 3)})
        self.interventions = dict(tracker.interventions)
        self.manual_areas = [dict(m) for m in tracker.manual_areas]
        self.manual_joints = [dict(m) for m in tracker.manual_joints]
        self.save()

    def end_launch(self, reason: str) -> None:
        """The job ended in this launch with ``reason`` (an ENDED_REASONS key)."""
        if self.launches:
            self.launches[-1].ended = reason
        self.save()

    def save(self) -> None:
        """Write the journal: a new file, synced, renamed over the old one (OSError when the disk refuses)."""
        if self.launches:
            self.launches[-1].last_seen = self.clock()
        doc = {"format": FORMAT, "steps": self.steps, "launches": [asdict(x) for x in self.launches],
               "records": [asdict(r) for r in self.records], "current": self.current,
               "interventions": self.interventions, "manual_areas": self.manual_areas,
               "manual_joints": self.manual_joints}
        write_whole(self.path, json.dumps(doc, indent=1, sort_keys=True))

    def restore(self, tracker: JobTracker, records: Sequence[ProcessRecord]) -> None:
        """Give ``tracker`` what the run did before this launch: ``records`` (from :func:`resume_point`), the
        interventions and the manual parts."""
        tracker.records = list(records)
        tracker.interventions = dict(self.interventions)
        tracker.manual_areas = [dict(m) for m in self.manual_areas]
        tracker.manual_joints = [dict(m) for m in self.manual_joints]

    def report_launches(self) -> List[Dict[str, Any]]:
        """The launches for the report (``report.json`` ``launches``), oldest first."""
        return [x.as_dict() for x in self.launches]

    def report_timing(self) -> Dict[str, float]:
        """The report's timing over the launches of a resumed run (none for one launch): ``wall_clock_total_s``
        (their wall clock added up) and ``down_s`` (between them)."""
        if len(self.launches) < 2:
            return {}
        spans = [max(0.0, x.last_seen - x.started) for x in self.launches]
        return {"wall_clock_total_s": sum(spans),
                "down_s": sum(max(0.0, b.started - a.started - span)
                              for a, b, span in zip(self.launches, self.launches[1:], spans))}


@dataclass(frozen=True)
class ResumePoint:
    """Where a resumed job goes on: the records of the processes that ended (``records``, in step order), the
    step to run next (``index``; ``len(steps)`` when none is left), the time already spent on it (``carried_s``)
    and one line per decision taken from PEMKRE's log rather than the journal (``notes``)."""

    records: List[ProcessRecord]
    index: int
    carried_s: float
    notes: List[str]


def resume_point(steps: Sequence[JobStep], journal: JobJournal, pemkre_processes: Sequence[Mapping[str, Any]],
                 since: Optional[float] = None) -> ResumePoint:
    """Where the job of ``steps`` goes on after the launches ``journal`` recorded.

    ``pemkre_processes``: PEMKRE's specific processes (rows of its ``kpi_by_process`` query: ``abstractProcess``,
    ``status`` running|ended|failed, ``startedAt``, ``endedAt`` as epoch seconds or ISO text, ``durationSeconds``);
    only those started at or after ``since`` (default: the run's first launch) count, so an earlier job's
    processes in the same store are not taken for this one's. They are handed to the steps in the order they
    started: each step takes the processes of its IRI that follow the previous step's (several when it was started
    again), so a job that runs one process twice does not take the first run for the second. A step is done when
    the journal recorded its end (succeeded or failed; not a start that failed), or -- when the journal has no
    record of it -- the last of its processes in PEMKRE's log ended or failed (the journal's save was cut short)."""
    if since is None:
        since = journal.launches[0].started if journal.launches else 0.0
    rows = sorted((r for r in pemkre_processes if _started(r, since) is not None),
                  key=lambda r: float(_started(r, since) or 0.0))
    at = 0                           # the next of PEMKRE's processes to hand out
    records: List[ProcessRecord] = []
    notes: List[str] = []
    carried = 0.0
    for index, step in enumerate(steps):
        mine: List[Mapping[str, Any]] = []
        while at < len(rows) and str(rows[at].get("abstractProcess")) == step.iri:
            mine.append(rows[at])
            at += 1
        if index < len(journal.records):
            record = journal.records[index]
            if record.status in DONE and not record.detail.startswith(NOT_STARTED):
                records.append(record)
                continue
            carried = record.duration_s    # stopped, timed out, interrupted, not started: it runs again
            break
        latest = mine[-1] if mine else None
        if latest is None or str(latest.get("status")) not in ("ended", "failed"):
            break
        status = "succeeded" if latest["status"] == "ended" else "failed"
        duration = _float(latest.get("durationSeconds"))
        if duration is None:
            start, end = _epoch(latest.get("startedAt")), _epoch(latest.get("endedAt"))
            duration = (end - start) if start is not None and end is not None else 0.0
        records.append(ProcessRecord(step.name, step.iri, status, float(duration),
                                     "its end was taken from PEMKRE's log (the job's journal missed it)"))
        notes.append("%s %s according to PEMKRE's log (not in the job's journal)" % (step.name, status))
    index = len(records)
    if journal.current and int(journal.current.get("index", -1)) == index:
        carried = float(journal.current.get("spent_s", 0.0))
    return ResumePoint(records, index, carried, notes)


def _started(row: Mapping[str, Any], since: float) -> Optional[float]:
    """When PEMKRE's process ``row`` started, None when before ``since`` (a second of slack: one machine's clocks)
    or unknown."""
    start = _epoch(row.get("startedAt"))
    return None if start is None or start + 1.0 < since else start


def _epoch(value: Any) -> Optional[float]:
    """Epoch seconds of a number or an ISO 8601 date-time text (PEMKRE's xsd:dateTime values)."""
    number = _float(value)
    if number is not None:
        return number
    if not isinstance(value, str) or not value:
        return None
    import datetime
    import re
    text = value.strip().replace("Z", "+00:00")
    # xsd:dateTime allows any number of fraction digits; fromisoformat before Python 3.11 takes 3 or 6
    text = re.sub(r"\.(\d+)", lambda m: "." + (m.group(1) + "000000")[:6], text, count=1)
    try:
        stamp = datetime.datetime.fromisoformat(text)
    except ValueError:
        return None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=datetime.timezone.utc)
    return stamp.timestamp()


def _float(value: Any) -> Optional[float]:
    try:
        return float(value)
    except (TypeError, ValueError):
        return None


def _step_list(steps: Sequence[JobStep]) -> List[Dict[str, Any]]:
    return [{"name": s.name, "iri": s.iri, "options": json.loads(json.dumps(dict(s.options), sort_keys=True))}
            for s in steps]


def _names(steps: Sequence[Mapping[str, Any]]) -> str:
    return ", ".join("%s (%s%s)" % (s["name"], s["iri"], ", options %s" % json.dumps(s["options"], sort_keys=True)
                                    if s.get("options") else "") for s in steps) or "none"
