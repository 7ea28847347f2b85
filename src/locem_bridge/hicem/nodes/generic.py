"""The HICEM node library: generic nodes and plasterboard use-case nodes.

Generic: CheckHealth, CheckDevicesUp (devices back after a failure, from LOCEM's STATUS), WaitForDevices (STATUS
until they are, bounded), CheckSafetyStop (a latched safety stop in STATUS), SendLocemCommand,
ReadDataStore, WriteDataStore, WaitForOperator, Log, CheckEqual, SelectEntry, IngestScan, MarkFeature.
Use case: TagIdNameToObjectId (PEMKRE symbol → stored object id), GetTapingPosition (approach pose for a joint
line), GetTapePath (line endpoints and wall normal), GetAreaRaster (base stations and raster rectangles for an
area).

No node holds a number of its own: distances, speeds, offsets and timeouts arrive through ports, fed from the
blackboard (``{@cfg....}`` = the robot/site parameters the controller loads, ``param_*`` = PEMKRE parameters) or
from the data store. Command templates (``SendLocemCommand.command``, ``WaitForOperator.text``, ``Log.message``)
fill ``{key}`` / ``{key.field}`` from the blackboard; numbers are written in plain decimal, lists as
space-separated numbers, and a substituted text containing whitespace is refused (it would smuggle extra
command arguments).
"""
import math
import re
from typing import Any, Dict, List, Optional, Sequence, Tuple

from py_trees.common import Status

from ..errors import HicemError, LocemError, PortError
from ..interfaces import check_reply, local_name
from ..node_base import ConditionLeaf, Leaf
from ..ports import TEMPLATE_FIELD, ANY, FLOAT, FLOAT_LIST, INT, JSON, STRING, STRING_LIST, input_port, output_port

_FIELD = TEMPLATE_FIELD


def lookup(blackboard: Any, path: str) -> Any:
    """Blackboard value for ``path`` (``a.b`` = field ``b`` of entry ``a`` if ``a.b`` is not an entry)."""
    try:
        return blackboard.get(path)
    except KeyError:
        raise HicemError("blackboard key '%s' is not set (or has no such field)" % path)


def format_number(v: float) -> str:
    s = ("%.6f" % v).rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def format_value(v: Any, key: str) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        if not math.isfinite(v):
            raise HicemError("'%s' is %r, not a finite number" % (key, v))
        return str(v) if isinstance(v, int) else format_number(v)
    if isinstance(v, (list, tuple)):
        return " ".join(format_value(x, key) for x in v)
    if isinstance(v, str):
        if not v or any(c.isspace() for c in v):
            raise HicemError("'%s' = %r is empty or contains whitespace; a command argument must be one word"
                             % (key, v))
        return v
    raise HicemError("'%s' is a %s, which cannot be written into a command" % (key, type(v).__name__))


def render(template: str, blackboard: Any, words: bool = True) -> str:
    """Fill ``{key}`` fields. ``words=False`` (operator texts, log lines) allows whitespace in values."""
    def sub(m: "re.Match[str]") -> str:
        v = lookup(blackboard, m.group(1))
        if not words and isinstance(v, str):
            return v
        return format_value(v, m.group(1))
    return _FIELD.sub(sub, template)


def _norm_angle(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


# ------------------------------------------------------------------------------------------------- generic --
class CheckHealth(ConditionLeaf):
    DESCRIPTION = ("SUCCESS while the modules (default: all crucial ones) are healthy in the HEM; FAILURE "
                   "with the reason otherwise. Put it first in a ReactiveSequence to guard a running action.")
    PORTS = (input_port("modules", STRING_LIST, "", "", "modules to check; empty = every crucial module"),)

    def on_tick(self) -> Status:
        hem = self.ctx.require("health", self.name)
        faults = hem.faults(self.get("modules") or None)
        if faults:
            return self.fail("unhealthy: " + "; ".join(r for _m, r in faults))
        return Status.SUCCESS


def devices_not_ready(status: Any, devices: Sequence[str], links_only: bool = False) -> List[str]:
    """Why the devices of a LOCEM STATUS result are not ready: one text per device that is not (empty when all
    are). A device is ready when its ``health`` entry has link 'up' and, unless ``links_only``, device 'ok' and
    no 'fault'. ``devices`` empty: every backend STATUS reports."""
    health = status.get("health") if isinstance(status, dict) else None
    if not isinstance(health, dict):
        return ["the STATUS result has no 'health' object (got %s)" % (
            sorted(status) if isinstance(status, dict) else type(status).__name__)]
    wanted = list(devices or sorted(health))
    if not wanted:
        return ["STATUS reports no device at all"]
    down = []
    for name in wanted:
        h = health.get(name)
        if not isinstance(h, dict):
            down.append("%s: not in STATUS (it reports %s)" % (name, ", ".join(sorted(health)) or "nothing"))
            continue
        why = []
        if h.get("link") != "up":
            why.append("link %s" % h.get("link", "unknown"))
        if not links_only and h.get("device", "ok") != "ok":
            why.append("device %s" % h.get("device"))
        if not links_only and h.get("fault"):
            why.append("fault %s" % h.get("fault"))
        if why:
            err = h.get("last_error") or ""
            down.append("%s: %s%s" % (name, ", ".join(why), " (%s)" % err if err else ""))
    return down


class CheckDevicesUp(ConditionLeaf):
    DESCRIPTION = ("SUCCESS when every listed device in a LOCEM STATUS result reports its link up and no fault "
                   "(its 'health' entry: link 'up', device 'ok', no 'fault'); FAILURE naming each device that "
                   "is not, with its last error. Used after a failed action to wait until the devices are back.")
    PORTS = (input_port("status", JSON, None, "", "the result of LOCEM's STATUS command (SendLocemCommand result)"),
             input_port("devices", STRING_LIST, "", "", "backends to check, e.g. 'compressor;arm'; empty = every "
                        "backend STATUS reports"))

    def on_tick(self) -> Status:
        down = devices_not_ready(self.get("status"), self.get("devices"))
        if down:
            return self.fail(down[0] if down[0].startswith(("the STATUS", "STATUS reports")) else
                             "devices not ready: " + "; ".join(down))
        return Status.SUCCESS


class WaitForDevices(Leaf):
    DESCRIPTION = ("Reads LOCEM's STATUS every poll seconds until LOCEM answers and every listed device is ready "
                   "(check=links: its link is up; check=ready: link up, device 'ok', no fault), then writes the "
                   "STATUS result and succeeds. Waits between reads on HICEM's own clock, so a LOCEM that does "
                   "not answer yet (restarting, NOT_READY while it makes its devices safe) is waited for too; a "
                   "STATUS without an answer within poll seconds is cancelled and read again. FAILURE after "
                   "timeout seconds, naming what was still not ready.")
    PORTS = (
        input_port("timeout", FLOAT, None, "s", "give up after this long"),
        input_port("poll", FLOAT, None, "s", "time between two STATUS reads (and the longest wait for one answer)"),
        input_port("check", STRING, "ready", "", "links: every link up (device faults and safety stops are left "
                   "to the tree); ready: link up, device ok, no fault", choices=("links", "ready")),
        input_port("devices", STRING_LIST, "", "", "backends to check, e.g. 'compressor;arm'; empty = every "
                   "backend STATUS reports"),
        output_port("status", JSON, None, "", "the STATUS result that showed the devices ready"),
    )

    def on_start(self) -> Optional[Status]:
        self._locem = self.ctx.require("locem", self.name)
        self._timeout, self._poll = self.get("timeout"), self.get("poll")
        if self._timeout < 0 or self._poll <= 0:
            raise PortError("%s: timeout must be >= 0 s and poll > 0 s, got %g and %g" % (
                self.name, self._timeout, self._poll))
        self._t0 = self.ctx.clock()
        self._handle: Any = None
        self._next = self._t0
        self._sent_at = self._t0
        self._why = "no STATUS read yet"
        self.reads = 0
        return None

    def _send(self, now: float) -> None:
        self._sent_at, self._next = now, now + self._poll
        self.reads += 1
        try:
            self._handle = self._locem.send("STATUS")
        except LocemError as exc:
            self._handle = None
            self._why = "LOCEM does not answer (%s)" % exc
            return
        self.ctx.track(self._handle)

    def _drop_handle(self) -> None:
        h, self._handle = self._handle, None
        if h is not None:
            if not h.done():
                h.cancel()
            self.ctx.untrack(h)

    def on_tick(self) -> Status:
        now = self.ctx.clock()
        h = self._handle
        if h is not None and h.done():
            self._drop_handle()
            reply = h.reply()
            if reply is None or not reply.success:
                self._why = ("LOCEM answers %s to STATUS: %s" % (reply.code, reply.message) if reply is not None
                             else "STATUS ended without a reply")
            else:
                down = devices_not_ready(reply.result, self.get("devices"), self.get("check") == "links")
                if not down:
                    self.set("status", reply.result)
                    return Status.SUCCESS
                self._why = "devices not ready: " + "; ".join(down)
        elif h is not None and now - self._sent_at > self._poll:
            self._drop_handle()
            self._why = "LOCEM did not answer STATUS within %.3g s" % self._poll
        if now - self._t0 > self._timeout:
            self._drop_handle()
            return self.fail("after %.3g s (%d STATUS reads): %s" % (self._timeout, self.reads, self._why))
        if self._handle is None and now >= self._next:
            self._send(now)
            return self.on_tick() if self._handle is not None and self._handle.done() else Status.RUNNING
        self.feedback_message = "waiting for devices: %s" % self._why
        return Status.RUNNING

    def on_halt(self) -> None:
        self._drop_handle()


class CheckSafetyStop(ConditionLeaf):
    DESCRIPTION = ("SUCCESS when a device reports a latched safety stop in a LOCEM STATUS result (its 'health' "
                   "device state starts with 'safety', e.g. the arm's 'safety stop: protective stop (safety mode "
                   "3)'), writing the stop; FAILURE when it reports none. A latched stop refuses every motion "
                   "until it is cleared (RESET_ARM, after an operator has checked the cause).")
    PORTS = (
        input_port("status", JSON, None, "", "the result of LOCEM's STATUS command"),
        input_port("device", STRING, None, "", "backend to look at, e.g. arm"),
        output_port("stop", STRING, None, "", "the latched stop, e.g. 'protective stop (safety mode 3)'"),
    )

    def on_tick(self) -> Status:
        status = self.get("status")
        health = status.get("health") if isinstance(status, dict) else None
        h = health.get(self.get("device")) if isinstance(health, dict) else None
        if not isinstance(h, dict):
            return self.fail("STATUS has no health entry for '%s'" % self.get("device"))
        state = str(h.get("device", ""))
        if not state.lower().startswith("safety"):
            return self.fail("%s reports no safety stop (device %s)" % (self.get("device"), state or "unknown"))
        stop = state.split(":", 1)[1].strip() if ":" in state else state
        self.set("stop", stop or state)
        return Status.SUCCESS


class SendLocemCommand(Leaf):
    DESCRIPTION = ("Sends one LOCEM command (template filled from the blackboard) through the action interface "
                   "and waits for its reply without blocking the tree; cancels it when halted. FAILURE on any "
                   "code other than OK, on an unexpected code, or when no reply came within timeout.")
    PORTS = (
        input_port("command", STRING, None, "", "command template, e.g. 'GOTO {approach_pose}'"),
        input_port("timeout", FLOAT, "{@cfg.locem.command_timeout_s}", "s", "give up (and cancel) after this"),
        output_port("result", JSON, None, "", "the reply's result object"),
        output_port("code", STRING, None, "", "the reply's code (also on failure)"),
        output_port("message", STRING, None, "", "the reply's message (also on failure)"),
    )

    def on_start(self) -> Optional[Status]:
        locem = self.ctx.require("locem", self.name)
        self._cmd = render(self.get("command"), self.ports.blackboard)
        self._limit = self.get("timeout")
        self._t0 = self.ctx.clock()
        try:
            self._handle = locem.send(self._cmd)
        except LocemError as exc:
            self._handle = None
            self.set("code", exc.code or "NOT_SENT")
            self.set("message", str(exc))
            return self.fail("cannot send %r: %s" % (self._cmd, exc))
        self.ctx.track(self._handle)
        self.ctx.commands_sent.append(self._cmd)
        self.feedback_message = "sent %s" % self._cmd
        return None

    def on_tick(self) -> Status:
        h = self._handle
        if not h.done():
            if self.ctx.clock() - self._t0 > self._limit:
                h.cancel()
                self.ctx.untrack(h)
                return self.fail("no reply to %r within %.3f s; cancelled" % (self._cmd, self._limit))
            return Status.RUNNING
        self.ctx.untrack(h)
        try:
            reply = check_reply(h.reply(), self._cmd)
        except LocemError as exc:
            return self.fail(str(exc))
        self.set("code", reply.code)
        self.set("message", reply.message)
        if not reply.success:
            return self.fail("LOCEM %s for %r: %s" % (reply.code, self._cmd, reply.message))
        self.set("result", reply.result)
        return Status.SUCCESS

    def on_halt(self) -> None:
        h = getattr(self, "_handle", None)
        if h is not None:
            h.cancel()
            self.ctx.untrack(h)


class ReadDataStore(Leaf):
    DESCRIPTION = "Copies collection/key (optionally one field of it) from the data store to value; FAILURE if absent."
    PORTS = (
        input_port("collection", STRING, None, "", "data store collection"),
        input_port("key", STRING, None, "", "entry key"),
        input_port("field", STRING, "", "", "dotted field inside the value; empty = whole value"),
        output_port("value", ANY, None, "", "the value read"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        coll, key = self.get("collection"), self.get("key")
        e = store.get(coll, key)
        if e is None:
            return self.fail("data store has no entry %s/%s" % (coll, key))
        v = e.value
        for f in [f for f in self.get("field").split(".") if f]:
            if not isinstance(v, dict) or f not in v:
                return self.fail("entry %s/%s has no field '%s'" % (coll, key, f))
            v = v[f]
        self.set("value", v)
        return Status.SUCCESS


class WriteDataStore(Leaf):
    DESCRIPTION = "Writes value to collection/key in the data store (HDICT if the collection is persistent)."
    PORTS = (
        input_port("collection", STRING, None, "", "data store collection"),
        input_port("key", STRING, None, "", "entry key"),
        input_port("value", ANY, None, "", "value to store (JSON-compatible)"),
    )

    def on_tick(self) -> Status:
        store = self.ctx.require("store", self.name)
        store.put(self.get("collection"), self.get("key"), self.get("value"), source="tree")
        return Status.SUCCESS


class WaitForOperator(Leaf):
    DESCRIPTION = ("Opens an operator prompt (text template filled from the blackboard) and stays RUNNING until "
                   "it is answered; writes the answer. An answer listed in 'refuse' (the operator says it cannot "
                   "be done) ends it in FAILURE with that answer and the prompt as the reason. Halting it "
                   "withdraws the prompt.")
    PORTS = (
        input_port("kind", STRING, None, "", "prompt kind shown to the HMI, e.g. mount_tool, validate_line"),
        input_port("text", STRING, None, "", "question template, e.g. 'Mount the {param_tool}'"),
        input_port("choices", STRING_LIST, None, "", "allowed answers, e.g. 'valid;invalid'"),
        input_port("timeout", FLOAT, "-1", "s", "FAILURE if unanswered this long; -1 = wait forever"),
        input_port("refuse", STRING_LIST, "", "", "answers (among choices) that fail the node, e.g. cannot_clear"),
        output_port("answer", STRING, None, "", "the operator's answer"),
    )

    @classmethod
    def validate_literals(cls, literals: "dict") -> Optional[str]:
        refuse, choices = literals.get("refuse"), literals.get("choices")
        if refuse and choices is not None:
            unknown = [a for a in refuse if a not in choices]
            if unknown:
                return "refuse lists %s, which %s not among the choices %s" % (
                    ", ".join(unknown), "is" if len(unknown) == 1 else "are", ";".join(choices))
        return None

    def on_start(self) -> Optional[Status]:
        desk = self.ctx.require("operator", self.name)
        text = render(self.get("text"), self.ports.blackboard, words=False)
        self._prompt = desk.open(self.get("kind"), text, self.get("choices"), {"node": self.name})
        self._t0 = self.ctx.clock()
        self.feedback_message = "waiting for operator: %s" % text
        return None

    def on_tick(self) -> Status:
        p = self._prompt
        if p.state == "answered":
            self.set("answer", p.answer)
            if p.answer in (self.get("refuse") or ()):
                return self.fail("operator answered %s to: %s" % (p.answer, p.text))
            return Status.SUCCESS
        if p.state == "cancelled":
            return self.fail("prompt %s was withdrawn" % p.id)
        limit = self.get("timeout")
        if limit >= 0 and self.ctx.clock() - self._t0 > limit:
            self.ctx.operator.cancel(p.id)
            return self.fail("operator did not answer within %.1f s" % limit)
        return Status.RUNNING

    def on_halt(self) -> None:
        p = getattr(self, "_prompt", None)
        if p is not None:
            self.ctx.operator.cancel(p.id)


class Log(Leaf):
    DESCRIPTION = "Writes a log line (template filled from the blackboard)."
    PORTS = (
        input_port("message", STRING, None, "", "text template"),
        input_port("level", STRING, "info", "", "log level", choices=("debug", "info", "warning", "error")),
    )

    def on_tick(self) -> Status:
        getattr(self.ctx.log, self.get("level"))("%s", render(self.get("message"), self.ports.blackboard, False))
        return Status.SUCCESS


class CheckEqual(ConditionLeaf):
    DESCRIPTION = "SUCCESS if a and b are equal (compared as text), FAILURE otherwise."
    PORTS = (input_port("a", STRING, None, "", "first value"), input_port("b", STRING, None, "", "second value"))

    def on_tick(self) -> Status:
        return Status.SUCCESS if self.get("a") == self.get("b") else Status.FAILURE


class SelectEntry(Leaf):
    DESCRIPTION = ("Looks key up in a table (a JSON object, e.g. {@cfg.site.locations}) and writes the entry to "
                   "value. If key points to a blackboard entry that is not set, fallback_key is used; a key "
                   "that is not in the table fails naming the keys that are.")
    PORTS = (
        input_port("table", JSON, None, "", "object to look in"),
        input_port("key", STRING, None, "", "entry name, e.g. {param_location}"),
        input_port("fallback_key", STRING, "", "", "used when key's blackboard entry is unset; empty = fail"),
        output_port("value", ANY, None, "", "the entry"),
    )

    def on_tick(self) -> Status:
        table = self.get("table")
        if not isinstance(table, dict):
            return self.fail("table is a %s, not an object" % type(table).__name__)
        ref = self.ports.key("key")
        if ref is not None and not self.ports.blackboard.has(ref) and self.get("fallback_key"):
            key = self.get("fallback_key")
        else:
            key = self.get("key")
        if key not in table:
            return self.fail("no entry '%s'; the table has: %s" % (key, ", ".join(sorted(table)) or "nothing"))
        self.set("value", table[key])
        return Status.SUCCESS


class IngestScan(Leaf):
    DESCRIPTION = ("Stores a SCAN result (walls, joints, areas) through the HDH and forwards new features to "
                   "PEMKRE; FAILURE naming the bad field if the result breaks the contract.")
    PORTS = (
        input_port("scan", JSON, None, "", "the SCAN command's result object"),
        output_port("new_features", INT, None, "", "number of new or changed features"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        res = hdh.ingest_scan(self.get("scan"))
        self.set("new_features", len(res.new) + len(res.changed))
        return Status.SUCCESS


class MarkFeature(Leaf):
    DESCRIPTION = "Records a processing status (taped, manual, sprayed, sanded ...) for a stored feature."
    PORTS = (input_port("feature_id", STRING, None, "", "feature id"),
             input_port("status", STRING, None, "", "new status word"))

    def on_tick(self) -> Status:
        self.ctx.require("data_handler", self.name).mark_feature(self.get("feature_id"), self.get("status"))
        return Status.SUCCESS


# ------------------------------------------------------------------------------------------------ use case --
class TagIdNameToObjectId(Leaf):
    DESCRIPTION = ("Maps a PEMKRE symbol (IRI or local name) to the id of an object stored in HICEM and checks "
                   "it exists with the expected kind (joint, area, wall: features from the scan; tool: the "
                   "configured tools).")
    PORTS = (
        input_port("symbol", STRING, None, "", "PEMKRE parameter, e.g. {param_line}"),
        input_port("kind", STRING, None, "", "expected object kind", choices=("joint", "area", "wall", "tool")),
        input_port("tools", STRING_LIST, "{@cfg.tools}", "", "tool names known to this robot"),
        output_port("object_id", STRING, None, "", "stored object id"),
    )

    def on_tick(self) -> Status:
        sym = local_name(self.get("symbol").strip())
        kind = self.get("kind")
        if kind == "tool":
            tools = self.get("tools")
            if sym not in tools:
                return self.fail("unknown tool '%s'; this robot has: %s" % (sym, ", ".join(tools)))
        else:
            self.ctx.require("data_handler", self.name).feature(sym, kind)
        self.set("object_id", sym)
        return Status.SUCCESS


def _wall_frame(hdh: Any, wall_id: str) -> Tuple[List[float], List[float]]:
    """(unit tangent p0→p1 in xy, inward normal (3D)) of a stored wall."""
    w = hdh.feature(wall_id, "wall")
    dx, dy = w["p1"][0] - w["p0"][0], w["p1"][1] - w["p0"][1]
    n = math.hypot(dx, dy)
    if n < 1e-9:
        raise HicemError("wall '%s' has zero length" % wall_id)
    return [dx / n, dy / n], list(w["normal"])


def _facing(normal: List[float], yaw_offset: float) -> float:
    """Base heading that faces the wall (base x axis against the inward normal) plus an offset."""
    return _norm_angle(math.atan2(-normal[1], -normal[0]) + yaw_offset)


def _joint_ends(j: Dict[str, Any], max_tilt: float) -> Tuple[List[float], List[float]]:
    """Start and end of a stored joint as the robot tapes it. Plasterboard joints are plumb (vertical joints) or
    level (horizontal ones): a vertical joint measured within ``max_tilt`` rad of plumb is taped plumb through
    the mean horizontal position of its two ends, a horizontal one within ``max_tilt`` of level at their mean
    height. The scanner's independent errors on the two ends then neither tilt the tape path nor add up at one
    end (the mean halves their variance); a joint tilted more than ``max_tilt`` is taped as measured, and
    ``max_tilt`` 0 keeps every measured line."""
    start, end = [float(v) for v in j["start"]], [float(v) for v in j["end"]]
    if max_tilt < 0.0:
        raise PortError("max_tilt must be >= 0 rad, got %g" % max_tilt)
    if max_tilt == 0.0:
        return start, end
    horizontal = math.hypot(end[0] - start[0], end[1] - start[1])
    rise = abs(end[2] - start[2])
    if j.get("kind") == "vertical" and math.atan2(horizontal, rise) <= max_tilt:
        mx, my = (start[0] + end[0]) / 2.0, (start[1] + end[1]) / 2.0
        return [mx, my, start[2]], [mx, my, end[2]]
    if j.get("kind") == "horizontal" and math.atan2(rise, horizontal) <= max_tilt:
        mz = (start[2] + end[2]) / 2.0
        return [start[0], start[1], mz], [end[0], end[1], mz]
    return start, end


class GetTapingPosition(Leaf):
    DESCRIPTION = ("Approach pose [x, y, theta] (map frame) of the base for taping a joint line: in front of the "
                   "line's foot (vertical) or middle (horizontal) as straightened within max_tilt, standoff from "
                   "the wall along its normal, "
                   "shifted along the wall by lateral_offset, facing the wall plus yaw_offset.")
    PORTS = (
        input_port("line_id", STRING, None, "", "stored joint id"),
        input_port("standoff", FLOAT, "{@cfg.taping.base_standoff}", "m", "base centre distance from the wall"),
        input_port("lateral_offset", FLOAT, "{@cfg.taping.lateral_offset}", "m", "shift along the wall"),
        input_port("yaw_offset", FLOAT, "{@cfg.taping.yaw_offset}", "rad", "added to the wall-facing heading"),
        input_port("max_tilt", FLOAT, "{@cfg.taping.plumb_tolerance}", "rad",
                   "a vertical joint within this angle of plumb (a horizontal one of level) is taped plumb (level) "
                   "through the mean of its ends; 0: as measured"),
        output_port("approach_pose", FLOAT_LIST, None, "m, m, rad", "x y theta for GOTO"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        t, nrm = _wall_frame(hdh, j["wall"])
        start, end = _joint_ends(j, self.get("max_tilt"))
        if j["kind"] == "vertical":
            fx, fy = start[0], start[1]
        else:
            fx, fy = (start[0] + end[0]) / 2.0, (start[1] + end[1]) / 2.0
        nxy = math.hypot(nrm[0], nrm[1])
        if nxy < 1e-9:
            return self.fail("wall '%s' normal has no horizontal part" % j["wall"])
        nx, ny = nrm[0] / nxy, nrm[1] / nxy
        d, lat = self.get("standoff"), self.get("lateral_offset")
        pose = [fx + nx * d + t[0] * lat, fy + ny * d + t[1] * lat, _facing([nx, ny], self.get("yaw_offset"))]
        self.set("approach_pose", pose)
        return Status.SUCCESS


class GetTapePath(Leaf):
    DESCRIPTION = ("Tape path of a joint line in the map frame: start and end points (straightened to plumb or "
                   "level within max_tilt) moved off the wall by surface_offset along the wall normal, the normal "
                   "itself and the length.")
    PORTS = (
        input_port("line_id", STRING, None, "", "stored joint id"),
        input_port("surface_offset", FLOAT, "{@cfg.taping.surface_offset}", "m", "tool point off the wall"),
        input_port("max_tilt", FLOAT, "{@cfg.taping.plumb_tolerance}", "rad",
                   "a vertical joint within this angle of plumb (a horizontal one of level) is taped plumb (level) "
                   "through the mean of its ends; 0: as measured"),
        output_port("path_start", FLOAT_LIST, None, "m", "x y z"),
        output_port("path_end", FLOAT_LIST, None, "m", "x y z"),
        output_port("normal", FLOAT_LIST, None, "", "inward wall normal nx ny nz"),
        output_port("length", FLOAT, None, "m", "path length"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        _t, n = _wall_frame(hdh, j["wall"])
        off = self.get("surface_offset")
        start, end = _joint_ends(j, self.get("max_tilt"))
        s = [start[i] + n[i] * off for i in range(3)]
        e = [end[i] + n[i] * off for i in range(3)]
        self.set("path_start", s)
        self.set("path_end", e)
        self.set("normal", n)
        self.set("length", math.dist(s, e))
        return Status.SUCCESS


class GetTapeSegments(Leaf):
    DESCRIPTION = ("Splits a joint line into pieces taped one after the other, each from its own base pose, for "
                   "arms that cannot reach a whole joint from one pose. A vertical joint is clipped to the "
                   "reachable height band [z_min, z_max] and taped outwards from its middle (middle to top, "
                   "middle to bottom: the approach to mid height is the one free of the wall); a horizontal joint "
                   "is cut into pieces no longer than segment_length, each approached in front of its middle. "
                   "Each piece: approach [x, y, theta] at standoff from the wall facing it (plus yaw_offset, "
                   "shifted along the wall by lateral_offset), start and end points (moved off the wall by "
                   "surface_offset) and the inward normal. The clipped length is reported as skipped.")
    PORTS = (
        input_port("line_id", STRING, None, "", "stored joint id"),
        input_port("segment_length", FLOAT, "{@cfg.taping.segment_length}", "m",
                   "longest piece taped from one base pose"),
        input_port("z_range", FLOAT_LIST, "{@cfg.taping.z_range}", "m",
                   "z_min;z_max, the height band the arm reaches with the tool facing the wall"),
        input_port("standoff", FLOAT, "{@cfg.taping.base_standoff}", "m", "base centre distance from the wall"),
        input_port("lateral_offset", FLOAT, "{@cfg.taping.lateral_offset}", "m", "shift along the wall"),
        input_port("yaw_offset", FLOAT, "{@cfg.taping.yaw_offset}", "rad", "added to the wall-facing heading"),
        input_port("surface_offset", FLOAT, "{@cfg.taping.surface_offset}", "m", "tool point off the wall"),
        input_port("max_tilt", FLOAT, "{@cfg.taping.plumb_tolerance}", "rad",
                   "a vertical joint within this angle of plumb (a horizontal one of level) is taped plumb (level) "
                   "through the mean of its ends; 0: as measured"),
        output_port("segments", JSON, None, "", "list of {approach, start, end, normal, length}"),
        output_port("count", INT, None, "", "number of pieces"),
        output_port("skipped", FLOAT, None, "m", "joint length outside the reachable band (not taped)"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        j = hdh.feature(self.get("line_id"), "joint")
        t, nrm = _wall_frame(hdh, j["wall"])
        seg_len = self.get("segment_length")
        if seg_len <= 0:
            raise PortError("%s: segment_length must be > 0 m, got %g" % (self.name, seg_len))
        band = list(self.get("z_range"))
        if len(band) != 2 or band[0] >= band[1]:
            raise PortError("%s: z_range must be two heights z_min < z_max, got %s" % (self.name, band))
        nxy = math.hypot(nrm[0], nrm[1])
        if nxy < 1e-9:
            return self.fail("wall '%s' normal has no horizontal part" % j["wall"])
        nx, ny = nrm[0] / nxy, nrm[1] / nxy
        d, lat, off = self.get("standoff"), self.get("lateral_offset"), self.get("surface_offset")
        heading = _facing([nx, ny], self.get("yaw_offset"))
        start, end = _joint_ends(j, self.get("max_tilt"))
        total = math.dist(start, end)
        pieces = []  # (a, b, foot) in map, before the surface offset
        if j["kind"] == "vertical":
            lo, hi = sorted((start, end), key=lambda p: p[2])
            z0, z1 = max(lo[2], band[0]), min(hi[2], band[1])
            if z1 - z0 < 1e-3:
                return self.fail("joint '%s' (z %.2f..%.2f m) lies outside the reachable band %.2f..%.2f m"
                                 % (j["id"], lo[2], hi[2], band[0], band[1]))

            def at(z: float) -> List[float]:
                f = (z - lo[2]) / (hi[2] - lo[2])
                return [lo[k] + (hi[k] - lo[k]) * f for k in range(3)]

            mid = (z0 + z1) / 2.0
            for a, b in ((mid, z1), (mid, z0)):
                n = max(1, int(math.ceil(abs(b - a) / seg_len - 1e-9)))
                for i in range(n):
                    za, zb = a + (b - a) * i / n, a + (b - a) * (i + 1) / n
                    pieces.append((at(za), at(zb), lo))
        else:
            n = max(1, int(math.ceil(total / seg_len - 1e-9)))
            for i in range(n):
                a = [start[k] + (end[k] - start[k]) * i / n for k in range(3)]
                b = [start[k] + (end[k] - start[k]) * (i + 1) / n for k in range(3)]
                pieces.append((a, b, [(a[k] + b[k]) / 2.0 for k in range(3)]))
        segments = []
        for a, b, foot in pieces:
            approach = [foot[0] + nx * d + t[0] * lat, foot[1] + ny * d + t[1] * lat, heading]
            segments.append({"approach": approach, "start": [a[k] + nrm[k] * off for k in range(3)],
                             "end": [b[k] + nrm[k] * off for k in range(3)], "normal": list(nrm),
                             "length": math.dist(a, b)})
        self.set("segments", segments)
        self.set("count", len(segments))
        self.set("skipped", max(0.0, total - sum(s["length"] for s in segments)))
        return Status.SUCCESS


class GetAreaRaster(Leaf):
    DESCRIPTION = ("Splits a wall area into sections no wider than section_width; for each: a base approach pose "
                   "facing the section's middle at base_standoff, and the raster rectangle (origin, u, width, "
                   "height, wall normal) in the map frame.")
    PORTS = (
        input_port("area_id", STRING, None, "", "stored area id"),
        input_port("section_width", FLOAT, None, "m", "widest strip covered from one base pose"),
        input_port("base_standoff", FLOAT, None, "m", "base centre distance from the wall"),
        input_port("yaw_offset", FLOAT, None, "rad", "added to the wall-facing heading"),
        input_port("edge_extension", FLOAT, "0.0", "m", "the first and last section reach this far beyond the "
                   "area's ends (spray run-in at the outer edges; sections meet exactly in between)"),
        output_port("sections", JSON, None, "", "list of {approach, origin, u, width, height, normal}"),
        output_port("count", INT, None, "", "number of sections"),
    )

    def on_tick(self) -> Status:
        hdh = self.ctx.require("data_handler", self.name)
        a = hdh.feature(self.get("area_id"), "area")
        _t, n = _wall_frame(hdh, a["wall"])
        sw, bs = self.get("section_width"), self.get("base_standoff")
        if sw <= 0:
            raise PortError("%s: section_width must be > 0 m, got %g" % (self.name, sw))
        count = max(1, int(math.ceil(a["width"] / sw - 1e-9)))
        w = a["width"] / count
        nxy = math.hypot(n[0], n[1]) or 1.0
        heading = _facing([n[0] / nxy, n[1] / nxy], self.get("yaw_offset"))
        ext = self.get("edge_extension")
        if ext < 0:
            raise PortError("%s: edge_extension must be >= 0 m, got %g" % (self.name, ext))
        sections = []
        for i in range(count):
            o = [a["origin"][k] + a["u"][k] * w * i for k in range(3)]
            mx, my = o[0] + a["u"][0] * w / 2.0, o[1] + a["u"][1] * w / 2.0
            s0 = -ext if i == 0 else 0.0                   # along u, relative to the section's own start
            s1 = w + ext if i == count - 1 else w
            o = [o[k] + a["u"][k] * s0 for k in range(3)]
            sections.append({"approach": [mx + n[0] / nxy * bs, my + n[1] / nxy * bs, heading], "origin": o,
                             "u": list(a["u"]), "width": s1 - s0, "height": a["height"], "normal": n, "index": i})
        self.set("sections", sections)
        self.set("count", count)
        return Status.SUCCESS


class PlanTransit(Leaf):
    DESCRIPTION = ("Base waypoints from the current pose to goal [x, y, theta] (map). A turn larger than max_turn "
                   "is not made next to a wall, where the corners of the turning base would sweep into it: the "
                   "base first drives to the transit point keeping its heading, turns there, then drives to the "
                   "goal. Otherwise the goal alone.")
    PORTS = (
        input_port("here", ANY, None, "m, m, rad", "current pose: [x, y, theta] or GET_POSE's result"),
        input_port("goal", FLOAT_LIST, None, "m, m, rad", "x y theta to reach"),
        input_port("transit", FLOAT_LIST, "{@cfg.site.locations.home}", "m", "x y (theta ignored) with room "
                   "to turn"),
        input_port("max_turn", FLOAT, "{@cfg.site.max_turn_near_walls}", "rad", "largest turn made on the way"),
        output_port("waypoints", JSON, None, "", "list of [x, y, theta] poses for GOTO, in order"),
    )

    def on_tick(self) -> Status:
        here = self.get("here")
        if isinstance(here, dict):
            here = here.get("pose")
        goal, transit = list(self.get("goal")), list(self.get("transit"))
        if not isinstance(here, (list, tuple)) or len(here) != 3 or len(goal) != 3 or len(transit) < 2:
            raise PortError("%s: here and goal must be [x, y, theta] and transit [x, y, ...], got %r, %r, %r"
                            % (self.name, here, goal, transit))
        turn = abs(_norm_angle(float(goal[2]) - float(here[2])))
        if turn <= self.get("max_turn"):
            waypoints = [goal]
        else:
            waypoints = [[transit[0], transit[1], float(here[2])], [transit[0], transit[1], float(goal[2])], goal]
        kept = [waypoints[0]]
        for w in waypoints[1:]:       # a goal at the transit point itself is not driven to twice
            if max(abs(float(a) - float(b)) for a, b in zip(w, kept[-1])) > 1e-6:
                kept.append(w)
        self.set("waypoints", kept)
        return Status.SUCCESS


LIBRARY = (CheckHealth, CheckDevicesUp, WaitForDevices, CheckSafetyStop, SendLocemCommand, ReadDataStore,
           WriteDataStore, WaitForOperator, Log, CheckEqual, SelectEntry, IngestScan, MarkFeature, TagIdNameToObjectId, GetTapingPosition, GetTapePath, GetTapeSegments,
           GetAreaRaster, PlanTransit)
