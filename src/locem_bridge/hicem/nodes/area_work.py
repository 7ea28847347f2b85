"""Section progress of area work (spraying, sanding): which sections of an area are finished.

An area is worked section by section, one base pose each (``GetAreaRaster``). When the task fails part-way
(a compressor link drop, a protective stop) PEMKRE retries it, and after a HICEM restart the task is resumed;
both run the same tree again. Without a record the finished sections would be worked a second time (a second
coat of compound on them). The record lives in the data store collection ``progress`` (persistent in the
shipped parameters, so it survives a restart), one entry per (work, area): ``{"done": [section indices]}``.

Use in a tree: ``PendingSections`` after ``GetAreaRaster`` gives the sections still to do, ``RecordSectionDone``
after each section's command succeeded, ``ForgetSectionsDone`` once the whole area is marked done (the next
job on the same area starts from the first section).

Part of a section: a section cut while it runs (LOCEM killed mid-spray, a link lost) would be worked again from
its start, a second coat on its first part. ``RecordSectionProgress`` (a decorator around the section's command)
keeps the command's progress feedback -- the raster's worked length done, ``raster <m> of <m> m``
(:mod:`locem_bridge.common.raster_progress`) -- in the same entry as it arrives, ``{"done": [...], "partial":
{"<index>": metres}}`` (after LOCEM died mid-command: the point the spray reached for sure before the
compressor's watchdog closed the valve, which the feedback gives too); ``SectionResume`` gives the retried
section's ``skip`` (SPRAY_AREA ``skip=``) from it, so
the work goes on at the point reached; ``RecordSectionDone`` drops the section's partial record.

A power loss stops every process at once: the last feedback recorded lags the spray by its way to the store
(tens of milliseconds of lane, more on a busy machine), while the arm stops where the spray stopped (the valve
closes with the compressor). So ``RecordSectionProgress`` also keeps the furthest point the last feedback allows
(``"bound"``: where the spray gets should LOCEM stop now), ``NoteToolAtCut`` (RECOVER, before anything moves the
arm) notes the tool's point in the map frame for each cut section (``"tool_at"``), and ``SectionResume`` goes on
where that point stands on the section's raster (:func:`locem_bridge.common.raster_progress.raster_point`), never
behind the recorded point nor beyond the bound.

Manual work: a section LOCEM refuses because the arm cannot reach it from its base pose (``LeaveSectionManual``
after the section's command failed: the answer's code and a phrase of its message, ``area_work.unreachable_*``
in the HICEM parameters) is recorded in the same entry, ``{"done": [...], "manual": [{index, along, height,
reason}]}``, counted as handled, and the area goes on; ``AreaDetail`` then writes the task detail, e.g.
``sanded; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, height 0..2.5 m)``, which PEMKRE logs and
the run report lists (:func:`parse_manual_work`). Unreachable parts are manual work, not a failed process.
"""
import re
from typing import Any, Dict, List, Optional, Tuple

from py_trees.common import Status

from locem_bridge.common.raster_progress import parse_progress_text, raster_point
from locem_bridge.hicem.controls import _Decorator
from locem_bridge.hicem.interfaces import locem_lost

from ..errors import PortError
from ..node_base import ConditionLeaf, Leaf
from ..ports import FLOAT, INT, JSON, STRING, STRING_LIST, input_port, output_port
from .plasterboard import AREA_ID

PROGRESS = "progress"
# the port every node of an area's record takes besides AREA_ID, declared once
WORK = input_port("work", STRING, None, "", "what is done to the area (spray, sand)")


def progress_key(work: str, area_id: str) -> str:
    return "%s/%s" % (work, area_id)


def _done(store: Any, work: str, area_id: str) -> List[int]:
    entry = store.get(PROGRESS, progress_key(work, area_id))
    return [int(i) for i in (entry.value.get("done", []) if entry is not None else [])]


def _record(store: Any, work: str, area_id: str) -> Dict[str, Any]:
    entry = store.get(PROGRESS, progress_key(work, area_id))
    value = dict(entry.value) if entry is not None else {}
    value.setdefault("done", [])
    return value


#: a cut section's entries in its area's record, each ``{"<index>": value}``: the raster length recorded done, the
#: furthest point the last feedback allows, the tool's point where the cut left the arm
SECTION_ENTRIES = ("partial", "bound", "tool_at")


def _drop_section(record: Dict[str, Any], index: int, entries: Any = SECTION_ENTRIES) -> None:
    for name in entries:
        kept = dict(record.get(name, {}))
        if kept.pop(str(index), None) is not None:
            if kept:
                record[name] = kept
            else:
                del record[name]


def _put_manual(store: Any, work: str, area_id: str, keep: Any, new: List[Dict[str, Any]]) -> None:
    """Replace the manual parts of (work, area_id) whose index ``keep(index)`` refuses by ``new``, in one
    transaction."""
    with store.transaction():
        record = _record(store, work, area_id)
        record["manual"] = [m for m in record.get("manual", []) if keep(int(m["index"]))] + new
        store.put(PROGRESS, progress_key(work, area_id), record, source="tree")


#: action type -> the area work its task details name manual parts of (the job report, the operator page)
AREA_WORK = {"SPRAY_AREA": "spray", "SAND_AREA": "sand"}


def _num(v: float) -> str:
    s = ("%.2f" % v).rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def span_text(pair: Any) -> str:
    """``a..b m`` of an extent ``[a, b]`` (m, to the centimetre, as the manual-work texts write it)."""
    return "%s..%s m" % (_num(float(pair[0])), _num(float(pair[1])))


_MANUAL = re.compile(r"manual work on (\S+): (.*)$")
_SECTION = re.compile(r"section (\d+) \(along (-?[0-9.]+)\.\.(-?[0-9.]+) m, height (-?[0-9.]+)\.\.(-?[0-9.]+) m\)")


def manual_work_text(area_id: str, manual: List[Dict[str, Any]]) -> str:
    """``manual work on <area>: section 3 (along 1.2..1.8 m, height 0..2.5 m), section 4 (...)``; sections are
    numbered from 1, along = distance along the area from its origin, height = above the floor (m)."""
    return "manual work on %s: %s" % (area_id, ", ".join(
        "section %d (along %s, height %s)" % (int(m["index"]) + 1, span_text(m["along"]), span_text(m["height"]))
        for m in sorted(manual, key=lambda m: int(m["index"]))))


def parse_manual_work(detail: str) -> List[Dict[str, Any]]:
    """The manual work a task detail lists (see :func:`manual_work_text`): ``[{area, section, along, height}]``
    with section numbered from 1; empty when the detail lists none."""
    m = _MANUAL.search(detail or "")
    if not m:
        return []
    return [{"area": m.group(1), "section": int(s.group(1)), "along": [float(s.group(2)), float(s.group(3))],
             "height": [float(s.group(4)), float(s.group(5))]} for s in _SECTION.finditer(m.group(2))]


_JOINT_PART = re.compile(r"part (\d+) \(along (-?[0-9.]+)\.\.(-?[0-9.]+) m(?:; ([^)]*))?\)")


def manual_joint_text(joint_id: str, parts: List[Dict[str, Any]]) -> str:
    """``manual work on <joint>: part 1 (along 0..0.42 m; near a corner), part 2 (...)``: the stretches of a joint
    left for taping by hand, along = distance from the joint's start (m); a reason's parentheses are dropped."""
    return "manual work on %s: %s" % (joint_id, ", ".join(
        "part %d (along %s%s)" % (k + 1, span_text(m["along"]),
                                        ("; " + re.sub(r"[()]", "", str(m["reason"]))) if m.get("reason") else "")
        for k, m in enumerate(sorted(parts, key=lambda m: float(m["along"][0])))))


def parse_manual_joints(detail: str) -> List[Dict[str, Any]]:
    """The manual parts of a joint a task detail lists (see :func:`manual_joint_text`): ``[{joint, part, along,
    reason}]`` with part numbered from 1; empty when the detail lists none."""
    m = _MANUAL.search(detail or "")
    if not m:
        return []
    return [{"joint": m.group(1), "part": int(p.group(1)), "along": [float(p.group(2)), float(p.group(3))],
             "reason": p.group(4) or ""} for p in _JOINT_PART.finditer(m.group(2))]


def _check_work(node: Leaf) -> str:
    work = node.get("work")
    if not work or "/" in work:
        raise PortError("%s: work must be a non-empty name without '/' (e.g. spray, sand), got %r" % (node.name, work))
    return work


class PendingSections(Leaf):
    DESCRIPTION = ("The sections of an area still to be worked: those of `sections` whose index is not recorded "
                   "done for (work, area_id) in the data store collection 'progress' (RecordSectionDone). A task "
                   "retried after a failure or resumed after a HICEM restart goes on where it stopped instead of "
                   "working finished sections again.")
    PORTS = (
        input_port("sections", JSON, None, "", "list of sections, each with its 'index' (GetAreaRaster)"),
        AREA_ID,
        input_port("work", STRING, None, "", "what is done to the area (spray, sand): one record per work"),
        output_port("pending", JSON, None, "", "the sections not done yet, in their order"),
        output_port("done_count", INT, None, "", "number of sections already done"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        work = _check_work(self)
        sections = self.get("sections")
        if not isinstance(sections, list) or not all(isinstance(s, dict) and "index" in s for s in sections):
            raise PortError("%s: sections must be a list of objects with an 'index' (GetAreaRaster's output)"
                            % self.name)
        done = set(_done(store, work, self.get("area_id")))
        pending = [s for s in sections if int(s["index"]) not in done]
        self.set("pending", pending)
        self.set("done_count", len(sections) - len(pending))
        return Status.SUCCESS


class RecordSectionDone(Leaf):
    DESCRIPTION = "Records section `index` of (work, area_id) as done in the data store collection 'progress'."
    PORTS = (
        AREA_ID, WORK,
        input_port("index", INT, None, "", "the finished section's index"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        work, area = _check_work(self), self.get("area_id")
        with store.transaction():
            record = _record(store, work, area)
            if self.get("index") not in record["done"]:
                record["done"] = sorted(record["done"] + [self.get("index")])
            _drop_section(record, int(self.get("index")))
            store.put(PROGRESS, progress_key(work, area), record, source="tree")
        return Status.SUCCESS


class RecordSectionProgress(_Decorator):
    DESCRIPTION = ("Runs its child (the section's command, e.g. the GuardedCommand subtree of SPRAY_AREA) and after "
                   "each of its ticks, the last one included, records the command's progress feedback -- the "
                   "raster's worked length done, 'raster <m> of <m> m' -- for section `index` of (work, area_id) in "
                   "the data store collection 'progress' when it went further than recorded, so a section cut "
                   "while it runs is resumed at that point (SectionResume). When the command failed because LOCEM "
                   "went away (it died: the spray valve closes only by the compressor's watchdog), the point the "
                   "last feedback gave for that case ('(<m> m if LOCEM stops now)') is recorded instead. While the "
                   "command runs that point is also kept as the section's bound (how far the spray may have got "
                   "should everything stop now, e.g. a power loss, with no last feedback recorded); once the "
                   "command has ended, with any reply, the bound is the recorded point. Other feedback texts are "
                   "ignored; the result is the child's.")
    PORTS = (
        AREA_ID, WORK,
        input_port("index", INT, None, "", "the running section's index"),
        input_port("feedback", STRING, "{feedback}", "", "the command's latest feedback text (SendLocemCommand's "
                   "feedback port; GuardedCommand writes it to {feedback})"),
        input_port("code", STRING, "{code}", "", "the command's reply code (GuardedCommand's code)"),
        input_port("message", STRING, "{message}", "", "the command's reply message (GuardedCommand's message)"),
    )

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            self._recorded: Optional[Tuple[float, float]] = None
            self._if_stopped = 0.0
            self.initialise()
        for node in self.decorated.tick():
            yield node
        s = self.decorated.status
        self._record(lost=s == Status.FAILURE and self._lost(), ended=s != Status.RUNNING)
        if s == Status.RUNNING:
            self.status = Status.RUNNING
        else:
            self.stop(s)
        yield self

    def terminate(self, new_status: Status) -> None:
        if new_status == Status.INVALID and self.status == Status.RUNNING:
            # halted while the command ran (a health fault, a cancel, a shutdown): HICEM saw it end, LOCEM closes
            # the valve and stops the arm, so the point recorded stands and no bound stays open
            self._record(lost=False, ended=True)
        super().terminate(new_status)

    def _port(self, name: str) -> Optional[str]:
        try:
            return self.ports.get(name)
        except PortError:                 # nothing sent yet (the guard failed first): no such entry
            return None

    def _lost(self) -> bool:
        return locem_lost(self._port("code") or "", self._port("message") or "")

    def _record(self, lost: bool, ended: bool) -> None:
        parsed = parse_progress_text(self._port("feedback") or "")
        if parsed is not None:
            self._if_stopped = max(self._if_stopped, parsed[2])
        done_m = parsed[0] if parsed is not None else 0.0
        if lost:                          # the valve stayed open until the compressor's watchdog closed it
            done_m = max(done_m, self._if_stopped)
        bound = done_m if ended else max(done_m, self._if_stopped)
        if self._recorded is not None and done_m <= self._recorded[0] + 1e-6 and abs(bound - self._recorded[1]) <= 1e-6:
            return
        if self._recorded is None and bound <= 0.0:
            return
        store = self.ctx.require("store", self.name)
        work, area, index = _check_work(self), self.ports.get("area_id"), int(self.ports.get("index"))
        key = str(index)
        with store.transaction():
            record = _record(store, work, area)
            before = float(record.get("partial", {}).get(key, 0.0)), record.get("bound", {}).get(key)
            done_m = max(done_m, before[0])
            after = round(done_m, 4), (round(bound, 4) if bound > done_m + 1e-6 else None)
            if (done_m > 0.0 or after[1] is not None) and after != (round(before[0], 4), before[1]):
                _drop_section(record, index, ("bound", "tool_at"))   # a note of an earlier cut is old now
                record["partial"] = dict(record.get("partial", {}), **{key: after[0]})
                if after[1] is not None:            # open: how far the spray may have got should all stop now
                    record["bound"] = dict(record.get("bound", {}), **{key: after[1]})
                store.put(PROGRESS, progress_key(work, area), record, source="tree")
        self._recorded = (done_m, bound)
        if lost:
            self.ctx.log.info("%s of %s, section %d cut by LOCEM going away: sprayed to %.3f m of its raster",
                              work, area, index + 1, done_m)

    def get(self, port: str) -> Any:          # _check_work reads the work port through this
        return self.ports.get(port)


def _open_cuts(record: Dict[str, Any]) -> List[str]:
    """The sections of an area's record cut with no end seen (a bound beyond the recorded point) and no note yet."""
    partial, bounds, notes = record.get("partial", {}), record.get("bound", {}), record.get("tool_at", {})
    return [k for k in partial if float(bounds.get(k, 0.0)) > float(partial[k]) + 1e-6 and k not in notes]


class CheckCutOpen(ConditionLeaf):
    DESCRIPTION = ("SUCCESS when an area section was cut while its command ran with no end seen (e.g. a power loss: "
                   "its 'progress' record has a bound beyond the recorded point) and where the tool stood is not "
                   "noted yet (NoteToolAtCut); FAILURE otherwise. RECOVER reads the tool's point only then.")
    PORTS = ()

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        cut = ["%s section %d" % (e.key, int(k) + 1) for e in store.entries(PROGRESS) for k in _open_cuts(e.value)]
        if not cut:
            return self.fail("no section cut with no end seen")
        self.feedback_message = "cut with no end seen: " + ", ".join(cut)
        return Status.SUCCESS


class NoteToolAtCut(Leaf):
    DESCRIPTION = ("Notes where the tool stands now (`point`, the map frame: LOCEM GET_TOOL_POINT's result) for the "
                   "area section whose command was cut with no end seen (its 'progress' record still has a bound "
                   "beyond the recorded point: the process stopped while the command ran, e.g. a power loss; of "
                   "several, the record written last) and that has no note yet; nothing when no tool is mounted. "
                   "Run it before anything moves the arm (RECOVER): the arm stopped where the work stopped, "
                   "which the last feedback recorded lags; SectionResume goes on from there. SUCCESS (also with "
                   "nothing to note).")
    PORTS = (
        input_port("point", JSON, None, "", "GET_TOOL_POINT's result: {point: [x, y, z], axis, tool}"),
        output_port("noted", INT, None, "", "how many cut sections got the note"),
    )

    def on_tick(self) -> Status:
        result = self.get("point")
        point = result.get("point") if isinstance(result, dict) else None
        if not isinstance(point, list) or len(point) != 3:
            raise PortError("%s: point must be GET_TOOL_POINT's result {point: [x, y, z], ...}, got %r"
                            % (self.name, result))
        store = self.ctx.require("store", self.name)
        noted = 0
        if not result.get("tool"):
            self.ctx.log.info("%s: no tool on the arm: nothing noted", self.name)
            self.set("noted", 0)
            return Status.SUCCESS
        with store.transaction():
            cut = [e for e in store.entries(PROGRESS) if _open_cuts(e.value)]
            if cut:
                entry = max(cut, key=lambda e: e.stamp)        # the one running last: one command at a time
                record = dict(entry.value)
                notes = dict(record.get("tool_at", {}))
                for k in _open_cuts(record):
                    notes[k] = [round(float(v), 5) for v in point]
                    self.ctx.log.info("%s, section %d cut while it ran (recorded %.3f m, at most %.3f m): the tool "
                                      "stands at %s", entry.key, int(k) + 1, float(record["partial"][k]),
                                      float(record["bound"][k]), " ".join("%.3f" % float(v) for v in point))
                    noted += 1
                record["tool_at"] = notes
                store.put(PROGRESS, entry.key, record, source="tree")
        self.set("noted", noted)
        self.feedback_message = "%d cut section(s) noted" % noted
        return Status.SUCCESS


class SectionResume(Leaf):
    DESCRIPTION = ("Where a section's work goes on: `skip` = the raster length recorded done for section `index` of "
                   "(work, area_id) by RecordSectionProgress (0 when none), less `back_off`, for the command's "
                   "skip= argument (SPRAY_AREA). The recorded point lags the spray (the arm's measured TCP while "
                   "the valve was open; after LOCEM died, the least the spray reached before the compressor's "
                   "watchdog closed the valve), so no back-off is needed to avoid a gap (default 0); a positive "
                   "one buys a longer overlap. When the section was cut with no end seen and NoteToolAtCut noted "
                   "where the tool stood, and that point is on the section's raster (`section` with `run_in` and "
                   "`standoff`, the command's), the work goes on there instead (less `back_off`: on a real robot "
                   "the arm may brake a few centimetres past the point where the spray stopped): never behind the "
                   "recorded point, never beyond the bound the last feedback allowed.")
    PORTS = (
        AREA_ID, WORK,
        input_port("index", INT, None, "", "the section's index"),
        input_port("back_off", FLOAT, "0", "m", "raster length worked again before the recorded point (or the noted "
                   "tool point)"),
        input_port("section", JSON, "null", "", "the section (GetAreaRaster: origin, u, width, height, normal, "
                   "spacing) for a noted tool point; null: the recorded point only"),
        input_port("run_in", FLOAT, "0", "m", "the command's run_in= (lane length worked beyond each end)"),
        input_port("standoff", FLOAT, "0", "m", "the command's standoff= (TCP distance from the wall)"),
        output_port("skip", FLOAT, None, "m", "raster length to leave out: 0 for a section not begun"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        back_off = self.get("back_off")
        if back_off < 0:
            raise PortError("%s: back_off must be >= 0 m, got %g" % (self.name, back_off))
        work, area, index = _check_work(self), self.get("area_id"), int(self.get("index"))
        record = _record(store, work, area)
        done_m = float(record.get("partial", {}).get(str(index), 0.0))
        skip = max(0.0, done_m - back_off) if done_m > 0 else 0.0
        at = self._tool_point(record, index, done_m)
        at = max(0.0, at - back_off) if at is not None else None
        if at is not None and at > skip:
            self.ctx.log.info("%s of %s, section %d: the tool stood at %.3f m of its raster when it was cut "
                              "(%.3f m recorded)", work, area, index + 1, at, done_m)
            skip = at
        self.set("skip", round(skip, 4))
        if skip > 0:
            self.feedback_message = "section %d goes on after %.3f m" % (index + 1, skip)
            self.ctx.log.info("%s of %s, section %d: goes on after %.3f m of its raster (cut there before)",
                              work, area, index + 1, skip)
        return Status.SUCCESS

    def _tool_point(self, record: Dict[str, Any], index: int, done_m: float) -> Optional[float]:
        """The raster length at the noted tool point, within [recorded, bound]; None without a usable note."""
        point = record.get("tool_at", {}).get(str(index))
        bound = float(record.get("bound", {}).get(str(index), done_m))
        section = self.get("section")
        if point is None or bound <= done_m + 1e-6 or not section:
            return None
        if not isinstance(section, dict) or not all(k in section for k in ("origin", "u", "width", "height",
                                                                             "normal", "spacing")):
            raise PortError("%s: section must be GetAreaRaster's section (origin, u, width, height, normal, "
                            "spacing), got %r" % (self.name, section))
        at = raster_point(point, section["origin"], section["u"], float(section["width"]), float(section["height"]),
                          section["normal"], float(section["spacing"]), self.get("run_in"), self.get("standoff"))
        if at is None:
            self.ctx.log.info("%s: the tool noted at the cut (%s) is not on section %d's raster: going on after "
                              "the recorded point", self.name, point, index + 1)
            return None
        return min(max(at, done_m), bound)


class LeaveSectionManual(Leaf):
    DESCRIPTION = ("After a section's command failed: when LOCEM refused it because the arm cannot reach it (the "
                   "answer's code is one of `codes` and its message contains one of `phrases`), records the "
                   "section as manual work with its extent in the data store collection 'progress' and succeeds, "
                   "so the area goes on with its next section and the process does not fail for it. Any other "
                   "failure: FAILURE, keeping the command's failure as the action's reason.")
    PORTS = (
        AREA_ID, WORK,
        input_port("section", JSON, None, "", "the section (GetAreaRaster): index, origin, width, height"),
        input_port("code", STRING, None, "", "the failed command's code (GuardedCommand's code)"),
        input_port("message", STRING, "", "", "the failed command's message"),
        input_port("codes", STRING_LIST, "{@cfg.area_work.unreachable_codes}", "",
                   "codes that can mean 'out of reach', e.g. INVALID_ARGUMENT"),
        input_port("phrases", STRING_LIST, "{@cfg.area_work.unreachable_phrases}", "",
                   "a phrase of the message that says so, e.g. 'not reachable'"),
    )

    def on_tick(self) -> Status:
        code, message = self.get("code"), self.get("message") or ""
        if code not in self.get("codes") or not any(p.lower() in message.lower() for p in self.get("phrases")):
            last = self.ctx.last_failure()
            if last is not None:        # keep the command's failure as the reason the action reports
                self.ctx.report_failure(*last)
            return Status.FAILURE
        store = self.ctx.require("store", self.name)
        hdh = self.ctx.require("data_handler", self.name)
        work, area_id, sec = _check_work(self), self.get("area_id"), self.get("section")
        try:
            area = hdh.feature(area_id, "area")
            along0 = sum((float(sec["origin"][k]) - float(area["origin"][k])) * float(area["u"][k]) for k in range(3))
            along = [along0, along0 + float(sec["width"])]
            height = [float(sec["origin"][2]), float(sec["origin"][2]) + float(sec["height"])]
            index = int(sec["index"])
        except (KeyError, TypeError, ValueError, IndexError) as exc:
            raise PortError("%s: section must be a GetAreaRaster section of area %s (%s)" % (self.name, area_id, exc))
        along = [max(0.0, along[0]), min(float(area["width"]), along[1])]
        _put_manual(store, work, area_id, lambda i: i != index,
                    [{"index": index, "along": along, "height": height, "reason": "%s: %s" % (code, message)}])
        self.ctx.log.warning("%s of %s, section %d left for manual work: %s", work, area_id, index + 1, message)
        self.feedback_message = "section %d left for manual work" % (index + 1)
        return Status.SUCCESS


class LeavePlannedManual(Leaf):
    DESCRIPTION = ("Records the parts of an area the plan leaves to the hand (GetAreaRaster's manual: out of "
                   "reach, near a corner, above the tool's band) as manual work in the data store collection "
                   "'progress', numbered after the area's sections, before any section is worked: the task "
                   "detail and the run report list them with their extent and reason.")
    PORTS = (
        AREA_ID, WORK,
        input_port("manual", JSON, None, "", "[{along: [a, b], height: [c, d], reason}] (GetAreaRaster manual)"),
        input_port("first_index", INT, None, "", "the number of sections (the first manual part's index)"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        work, area_id, first = _check_work(self), self.get("area_id"), self.get("first_index")
        parts = self.get("manual") or []
        if not isinstance(parts, list):
            raise PortError("%s: manual must be a list of {along, height, reason}, got %r" % (self.name, parts))
        if not parts:
            return Status.SUCCESS
        _put_manual(store, work, area_id, lambda i: i < first,
                    [{"index": first + k, "along": [float(x) for x in m["along"]],
                      "height": [float(x) for x in m["height"]], "reason": "planned: %s" % m.get("reason", "")}
                     for k, m in enumerate(parts)])
        self.feedback_message = "%d part(s) left for manual work by the plan" % len(parts)
        return Status.SUCCESS


class AreaDetail(Leaf):
    DESCRIPTION = ("The task detail of an area task: `done` alone, or followed by the sections left for manual work "
                   "('sanded; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, height 0..2.5 m)'), "
                   "read from the data store collection 'progress' before ForgetSectionsDone drops the record.")
    PORTS = (
        AREA_ID, WORK,
        input_port("done", STRING, None, "", "the word for a finished area, e.g. sanded"),
        output_port("detail", STRING, None, "", "the task detail"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        work, area_id = _check_work(self), self.get("area_id")
        manual = _record(store, work, area_id).get("manual", [])
        self.set("detail", self.get("done") + ("; " + manual_work_text(area_id, manual) if manual else ""))
        return Status.SUCCESS


class ForgetSectionsDone(Leaf):
    DESCRIPTION = ("Removes the section record of (work, area_id) once the whole area is done, so the next job "
                   "on it starts from its first section.")
    PORTS = (
        AREA_ID, WORK,
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        store.delete(PROGRESS, progress_key(_check_work(self), self.get("area_id")))
        return Status.SUCCESS


LIBRARY = (PendingSections, RecordSectionDone, ForgetSectionsDone, LeaveSectionManual, LeavePlannedManual, AreaDetail,
           RecordSectionProgress, SectionResume, CheckCutOpen, NoteToolAtCut)
