"""Section progress of area work (spraying, sanding): which sections of an area are finished.

An area is worked section by section, one base pose each (``GetAreaRaster``). When the task fails part-way
(a compressor link drop, a protective stop) PEMKRE retries it, and after a HICEM restart the task is resumed;
both run the same tree again. Without a record the finished sections would be worked a second time (a second
coat of compound on them). The record lives in the data store collection ``progress`` (persistent in the
shipped parameters, so it survives a restart), one entry per (work, area): ``{"done": [section indices]}``.

Use in a tree: ``PendingSections`` after ``GetAreaRaster`` gives the sections still to do, ``RecordSectionDone``
after each section's command succeeded, ``ForgetSectionsDone`` once the whole area is marked done (the next
job on the same area starts from the first section).
"""
from typing import Any, List

from py_trees.common import Status

from .errors import PortError
from .node_base import Leaf
from .ports import INT, JSON, STRING, input_port, output_port

PROGRESS = "progress"


def progress_key(work: str, area_id: str) -> str:
    return "%s/%s" % (work, area_id)


def _done(store: Any, work: str, area_id: str) -> List[int]:
    entry = store.get(PROGRESS, progress_key(work, area_id))
    return [int(i) for i in (entry.value.get("done", []) if entry is not None else [])]


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
        input_port("area_id", STRING, None, "", "stored area id"),
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
        input_port("area_id", STRING, None, "", "stored area id"),
        input_port("work", STRING, None, "", "what is done to the area (spray, sand)"),
        input_port("index", INT, None, "", "the finished section's index"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        work, area = _check_work(self), self.get("area_id")
        with store.transaction():
            done = _done(store, work, area)
            if self.get("index") not in done:
                done.append(self.get("index"))
            store.put(PROGRESS, progress_key(work, area), {"done": sorted(done)}, source="tree")
        return Status.SUCCESS


class ForgetSectionsDone(Leaf):
    DESCRIPTION = ("Removes the section record of (work, area_id) once the whole area is done, so the next job "
                   "on it starts from its first section.")
    PORTS = (
        input_port("area_id", STRING, None, "", "stored area id"),
        input_port("work", STRING, None, "", "what is done to the area (spray, sand)"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        store.delete(PROGRESS, progress_key(_check_work(self), self.get("area_id")))
        return Status.SUCCESS


LIBRARY = (PendingSections, RecordSectionDone, ForgetSectionsDone)
