"""The handles HICEM is given for the layers around it, and the contract shapes that cross them.

- :class:`LocemClient` / :class:`CommandHandle`: send one LOCEM command string without blocking, poll it (its
  reply, its latest progress feedback), cancel it. The ROS adapter implements it on the ``/locem/command_action`` action client; tests use in-process
  doubles. :class:`LocemReply` mirrors the service/action result (success, code, message, result JSON).
- :class:`PemkreClient`: start_process / next_action / set_task_status / report_world (docs/contracts.md);
  :func:`status_request_id`: the request id a client sends with a status report; a client raises
  :class:`PemkreUnavailableError` when PEMKRE is away (any other :class:`PemkreCallError` is a refusal).
- :func:`parse_next_action`: validates a PEMKRE next-action answer and decodes its N-Triples parameters into
  the ``param_<name>`` values trees see.
"""
import abc
import hashlib
import re
from typing import Any, Dict, List, Optional

from ..common.locem_codes import Code
from .errors import LocemCallError, PemkreCallError


class LocemReply:
    """Final answer to one LOCEM command."""
    __slots__ = ("success", "code", "message", "result")

    def __init__(self, success: bool, code: str, message: str = "", result: Optional[Dict[str, Any]] = None):
        self.success = bool(success)
        self.code = code
        self.message = message
        self.result = result if result is not None else {}

    def __repr__(self) -> str:
        return "LocemReply(%s, %s, %r)" % (self.success, self.code, self.message)


class CommandHandle(abc.ABC):
    """One command in flight. ``done()`` and ``reply()`` never block; ``cancel()`` is idempotent."""

    command: str = ""

    @abc.abstractmethod
    def done(self) -> bool: ...

    @abc.abstractmethod
    def reply(self) -> Optional[LocemReply]: ...

    @abc.abstractmethod
    def cancel(self) -> None: ...

    def feedback(self) -> Optional[str]:
        """The text of the command's latest progress feedback (action feedback ``message``, e.g. SPRAY_AREA's
        ``raster 2.350 of 11.520 m``), None before the first; a client without feedback keeps this default."""
        return None


class LocemClient(abc.ABC):
    """Sends command strings to LOCEM. ``send`` returns at once; raise :class:`LocemCallError` if it cannot."""

    @abc.abstractmethod
    def send(self, command: str) -> CommandHandle: ...


class PemkreClient(abc.ABC):
    """The semantic layer as HICEM sees it (``/pemkre/*`` services in ROS)."""

    @abc.abstractmethod
    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        """Start a specific process for the abstract process IRI (with the process's options, e.g.
        ``{"validateLines": True}``); returns the specific process IRI."""

    @abc.abstractmethod
    def next_action(self) -> Dict[str, Any]:
        """Answer of docs/contracts.md: status action|ended|failed (+ action_type, task, parameters)."""

    @abc.abstractmethod
    def set_task_status(self, task: str, status: str, detail: str = "") -> None: ...

    @abc.abstractmethod
    def report_world(self, update: Dict[str, Any]) -> None:
        """New or changed world features, in the SCAN result shape of docs/contracts.md."""


class PemkreUnavailableError(PemkreCallError):
    """PEMKRE did not answer within the client's deadline (not running, restarting): not the process's fault.
    The controller waits for PEMKRE and repeats the call instead of failing the process."""


def status_request_id(task: str, status: str) -> str:
    """Request id of HICEM's report ``status`` for ``task`` (docs/contracts.md): a task takes each status once, so
    every attempt of a report -- a retry across a PEMKRE restart, a re-report after HICEM's own restart -- carries
    the same id and PEMKRE applies it once."""
    return "hicem-%s-%s" % (status, hashlib.sha1(task.encode("utf-8")).hexdigest()[:24])


class NextAction:
    """A validated PEMKRE next-action answer."""

    def __init__(self, status: str, action_type: str = "", task: str = "",
                 parameters: Optional[Dict[str, Any]] = None, raw_parameters: str = "", detail: str = ""):
        self.status = status
        self.action_type = action_type
        self.task = task
        self.parameters = parameters or {}
        self.raw_parameters = raw_parameters
        self.detail = detail

    def blackboard_entries(self) -> Dict[str, Any]:
        return {"param_%s" % k: v for k, v in self.parameters.items()}


_IRI = r"<([^<>\"{}|^`\\\s]*)>"
_LIT = r"\"((?:[^\"\\]|\\.)*)\"(?:\^\^<([^<>\s]*)>|@([A-Za-z]+(?:-[A-Za-z0-9]+)*))?"
_TRIPLE = re.compile(r"^\s*" + _IRI + r"\s+" + _IRI + r"\s+(?:" + _IRI + "|" + _LIT + r")\s*\.\s*$")
_XSD = "http://www.w3.org/2001/XMLSchema#"
_ESC = {"t": "\t", "b": "\b", "n": "\n", "r": "\r", "f": "\f", '"': '"', "'": "'", "\\": "\\"}


def local_name(iri: str) -> str:
    """Part after the last '#' or '/' (docs/contracts.md)."""
    return re.split(r"[#/]", iri)[-1]


def _unescape(s: str) -> str:
    out, i = [], 0
    while i < len(s):
        c = s[i]
        if c == "\\" and i + 1 < len(s):
            n = s[i + 1]
            if n in _ESC:
                out.append(_ESC[n])
                i += 2
                continue
            if n in "uU":
                width = 4 if n == "u" else 8
                out.append(chr(int(s[i + 2:i + 2 + width], 16)))
                i += 2 + width
                continue
        out.append(c)
        i += 1
    return "".join(out)


def _literal_value(text: str, dtype: Optional[str]) -> Any:
    if dtype in (_XSD + "integer", _XSD + "int", _XSD + "long", _XSD + "nonNegativeInteger"):
        return int(text)
    if dtype in (_XSD + "decimal", _XSD + "double", _XSD + "float"):
        return float(text)
    if dtype == _XSD + "boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError("bad xsd:boolean %r" % text)
        return text in ("true", "1")
    return text


def parse_parameters(task: str, ntriples: str) -> Dict[str, Any]:
    """Decode the N-Triples parameter document: predicate local name → object local name / literal value."""
    params: Dict[str, Any] = {}
    for n, line in enumerate(ntriples.splitlines(), 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        m = _TRIPLE.match(line)
        if not m:
            raise PemkreCallError("parameters line %d is not an N-Triples triple: %r" % (n, line[:120]))
        subj, pred, obj_iri, lit, dtype, _lang = m.groups()
        if subj != task:
            raise PemkreCallError("parameters line %d: subject <%s> is not the task <%s>" % (n, subj, task))
        name = local_name(pred)
        if obj_iri is not None:
            value: Any = local_name(obj_iri)
        else:
            try:
                value = _literal_value(_unescape(lit), dtype)
            except ValueError as exc:
                raise PemkreCallError("parameters line %d: literal %r: %s" % (n, lit, exc))
        params[name] = value
    return params


def parse_next_action(answer: Dict[str, Any], known_types: Optional[List[str]] = None) -> NextAction:
    """Validate a next-action answer (docs/contracts.md); raises :class:`PemkreCallError` naming the problem.

    An action type without a tree is *not* rejected here: the controller reports it to PEMKRE as a failure.
    """
    if not isinstance(answer, dict):
        raise PemkreCallError("next_action answer must be an object, got %s" % type(answer).__name__)
    status = answer.get("status")
    if status in ("ended", "failed"):
        return NextAction(status, detail=str(answer.get("detail", answer.get("message", ""))))
    if status != "action":
        raise PemkreCallError("next_action status %r is not one of: action, ended, failed" % (status,))
    at = answer.get("action_type")
    task = answer.get("task")
    if not isinstance(at, str) or not at:
        raise PemkreCallError("next_action: 'action_type' missing or not a string")
    if not isinstance(task, str) or not task:
        raise PemkreCallError("next_action: 'task' (the task instance IRI) missing or not a string")
    nt = answer.get("parameters", "")
    if not isinstance(nt, str):
        raise PemkreCallError("next_action: 'parameters' must be an N-Triples string")
    return NextAction("action", at, task, parse_parameters(task, nt), nt)


def check_reply(reply: Any, command: str) -> LocemReply:
    """Accept only replies HICEM understands; raise :class:`LocemCallError` otherwise."""
    if not isinstance(reply, LocemReply):
        raise LocemCallError("LOCEM reply to %r is a %s, not a LocemReply" % (command, type(reply).__name__))
    known = [c.value for c in Code]
    if reply.code not in known:
        raise LocemCallError("LOCEM answered %r with the unexpected code %r (known: %s): %s" % (
            command, reply.code, ", ".join(known), reply.message), reply.code)
    if reply.success != (reply.code == "OK"):
        raise LocemCallError("LOCEM reply to %r is inconsistent: success=%s with code %s" % (
            command, reply.success, reply.code), reply.code)
    if not isinstance(reply.result, dict):
        raise LocemCallError("LOCEM reply to %r: result must be a JSON object" % command, reply.code)
    return reply
