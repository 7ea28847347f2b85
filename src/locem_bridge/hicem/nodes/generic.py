"""Generic HICEM nodes (the paper's HHLC executes them): the ones any use case's trees need.

Health and devices: CheckHealth (the HEM's view), CheckDevicesUp (devices back after a failure, from LOCEM's
STATUS), WaitForDevices (STATUS until they are, bounded), CheckSafetyStop (a latched safety stop in STATUS).
LOCEM: SendLocemCommand, ComposeSkillCommand (a basic skill's command from the task parameters). Data store
(HDM/HDICT through the HDH): ReadDataStore, WriteDataStore, IngestScan, MarkFeature. Operator and flow: WaitForOperator, Log, CheckEqual, SelectEntry.

No node holds a number of its own: distances, speeds, offsets and timeouts arrive through ports, fed from the
blackboard (``{@cfg....}`` = the HICEM parameters the controller loads, ``param_*`` = PEMKRE parameters) or
from the data store. Command templates (``SendLocemCommand.command``, ``WaitForOperator.text``, ``Log.message``)
fill ``{key}`` / ``{key.field}`` from the blackboard (:func:`render`); numbers are written in plain decimal, lists
as space-separated numbers, and a substituted text containing whitespace is refused (it would smuggle extra
command arguments).
"""
import math
import re
from typing import Any, List, Optional, Sequence

from py_trees.common import Status

from ...common.health import problems as device_problems
from ..errors import HicemError, LocemCallError, PortError
from ..interfaces import check_reply
from ..node_base import ConditionLeaf, Leaf
from ..ports import TEMPLATE_FIELD, ANY, FLOAT, INT, JSON, STRING, STRING_LIST, input_port, output_port

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
    are). A device is ready when its ``health`` entry grades OK (:mod:`locem_bridge.common.health`: link 'up',
    device 'ok', no 'fault'), or with ``links_only`` when its link is up. ``devices`` empty: every backend STATUS
    reports."""
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
        why = device_problems(h, links_only)
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
                   "STATUS without an answer within poll seconds is cancelled and read again; an answered one is "
                   "a heartbeat of the HEM's module 'locem' (as the ROS adapter's own STATUS poll). FAILURE after "
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
        except LocemCallError as exc:
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
                if self.ctx.health is not None:      # LOCEM answered: a sign of life, as the ROS adapter's own STATUS
                    self.ctx.health.heartbeat("locem")     # poll counts it (the guarded commands after it see it)
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
        output_port("feedback", STRING, None, "", "the running command's latest progress feedback text (e.g. "
                    "SPRAY_AREA's 'raster 2.350 of 11.520 m'), updated on every tick and on the last; empty "
                    "before the first"),
    )

    def on_start(self) -> Optional[Status]:
        locem = self.ctx.require("locem", self.name)
        self.set("feedback", "")
        self._cmd = render(self.get("command"), self.ports.blackboard)
        self._limit = self.get("timeout")
        self._t0 = self.ctx.clock()
        try:
            self._handle = locem.send(self._cmd)
        except LocemCallError as exc:
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
        self.set("feedback", h.feedback() or "")
        if not h.done():
            if self.ctx.clock() - self._t0 > self._limit:
                h.cancel()
                self.ctx.untrack(h)
                return self.fail("no reply to %r within %.3f s; cancelled" % (self._cmd, self._limit))
            return Status.RUNNING
        self.ctx.untrack(h)
        try:
            reply = check_reply(h.reply(), self._cmd)
        except LocemCallError as exc:
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


_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
_PARAM_PREFIX = "param_"


def compose_skill_command(skill: str, params: "dict") -> str:
    """``NAME name=value ...``: the LOCEM command of a basic skill (``skill``: the command name) with the task's
    parameters as keyword arguments, sorted by name (LOCEM binds keywords to any declared argument).

    Values: IRIs arrive as their local names (the next-action codec), numbers in plain decimal, booleans
    ``true``/``false``; a value that is empty, contains whitespace, a quote or a template brace, a list, or a
    name that is not an identifier is refused (:class:`HicemError` naming it): one parameter is one command word.
    """
    if not isinstance(skill, str) or not _WORD.match(skill):
        raise HicemError("basic skill name %r is not a LOCEM command name ([A-Za-z][A-Za-z0-9_]*); the next "
                         "action must name the command in 'skill'" % (skill,))
    words = [skill.upper()]
    for name in sorted(params):
        value = params[name]
        if not _WORD.match(name):
            raise HicemError("parameter name %r of %s is not an identifier ([A-Za-z][A-Za-z0-9_]*)" % (name, skill))
        if isinstance(value, (list, tuple, dict)) or value is None:
            raise HicemError("parameter '%s' of %s is a %s; a command argument must be one word"
                             % (name, skill, type(value).__name__))
        text = format_value(value, name)
        bad = [c for c in text if c in "\"'{}"]
        if bad:
            raise HicemError("parameter '%s' of %s = %r contains %r; a command argument must be one word without "
                             "quotes or braces" % (name, skill, text, bad[0]))
        words.append("%s=%s" % (name, text))
    return " ".join(words)


class ComposeSkillCommand(Leaf):
    DESCRIPTION = ("Composes the LOCEM command of a basic skill: the command name (the next action's skill) "
                   "followed by every task parameter (blackboard param_<name> entries) as name=value, sorted by "
                   "name; IRIs as their local names. FAILURE naming the value that cannot be one command word "
                   "(empty, whitespace, quotes, braces, a list) or a skill that is not a command name.")
    PORTS = (
        input_port("skill", STRING, "{skill}", "", "LOCEM command name of the basic skill"),
        input_port("omit", STRING_LIST, "", "", "parameter names not sent (e.g. ones only PEMKRE uses)"),
        output_port("command", STRING, None, "", "the composed command, e.g. 'LIFT z=1.2'"),
    )

    def on_tick(self) -> Status:
        omit = set(self.get("omit") or ())
        params = {k[len(_PARAM_PREFIX):]: v for k, v in self.ports.blackboard.root.items()
                  if k.startswith(_PARAM_PREFIX) and k[len(_PARAM_PREFIX):] not in omit}
        self.set("command", compose_skill_command(self.get("skill"), params))
        return Status.SUCCESS


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


LIBRARY = (CheckHealth, CheckDevicesUp, WaitForDevices, CheckSafetyStop, SendLocemCommand, ComposeSkillCommand,
           ReadDataStore, WriteDataStore, WaitForOperator, Log, CheckEqual, SelectEntry, IngestScan, MarkFeature)
