"""The handles HICEM is given for the layers around it, and the contract shapes that cross them.

- :class:`LocemClient` / :class:`CommandHandle`: send one LOCEM command string without blocking, poll it (its
  reply, its latest progress feedback), cancel it. The ROS adapter implements it on the ``/locem/command_action`` action client; tests use in-process
  doubles. :class:`LocemReply` mirrors the service/action result (success, code, message, result JSON).
- :class:`PemkreClient`: start_process / next_action / set_task_status / report_world (docs/contracts.md);
  :func:`status_request_id`: the request id a client sends with a status report; a client raises
  :class:`PemkreUnavailableError` when PEMKRE is away (any other :class:`PemkreCallError` is a refusal).
- :func:`parse_next_action`: checks a PEMKRE next-action answer (the record
  :class:`locem_bridge.common.next_action.NextAction` with its one N-Triples codec) and decodes its parameters
  into the ``param_<name>`` values trees see.
"""
import abc
import hashlib
from typing import Any, Dict, Optional

from ..common.locem_codes import Code
from ..common.next_action import NextAction, NextActionError, local_name  # noqa: F401 (local_name: for nodes)
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

    def suspend(self, cause: str = "") -> None:
        """Suspend the command on its devices (LOCEM's ``SUSPEND id=N``: they come to rest where they are);
        :class:`LocemCallError` when LOCEM refuses (the command cannot be suspended, it has ended). A client that
        cannot suspend keeps this default."""
        raise LocemCallError("%r cannot be suspended through this LOCEM client" % self.command)

    def resume(self, cause: str = "") -> None:
        """Resume a suspended command from where its devices stopped (``RESUME id=N``); LocemCallError if refused."""
        raise LocemCallError("%r cannot be resumed through this LOCEM client" % self.command)

    def feedback(self) -> Optional[str]:
        """The text of the command's latest progress feedback (action feedback ``message``, e.g. SPRAY_AREA's
        ``raster 2.350 of 11.520 m``), None before the first; a client without feedback keeps this default."""
        return None


#: what a LOCEM client's reply message says (code ABORTED) when LOCEM went away while the command ran (it died):
#: the device did not stop by LOCEM's hand but by its own watchdog (e.g. the spray valve stays open for a while)
LOCEM_LOST = "went away while running"


def locem_lost(code: str, message: str) -> bool:
    """True for the reply of a command whose LOCEM went away while it ran (see :data:`LOCEM_LOST`)."""
    return code == "ABORTED" and LOCEM_LOST in (message or "")


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
    def next_action(self) -> NextAction:
        """Answer of docs/contracts.md: status action|ended|failed (+ action_type, task, parameters, and the
        matched skill and skill_kind when PEMKRE has a resource model); a :class:`NextAction` or its plain-object
        form (:meth:`NextAction.as_answer`)."""

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


def parse_next_action(answer: Any) -> NextAction:
    """Check a next-action answer (a :class:`NextAction` or its plain-object form, docs/contracts.md) and decode
    its parameters; raises :class:`PemkreCallError` naming the problem.

    An action type without a tree is *not* rejected here: the controller reports it to PEMKRE as a failure.
    """
    try:
        return NextAction.from_answer(answer)
    except NextActionError as exc:
        raise PemkreCallError(str(exc)) from None


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
