"""The procedure queue: low-bandwidth, queued execution of commands (Robotnik-style procedure manager).

States of a procedure, published on change only::

    queued ──► running ◄──► paused
       │          │            │
       └──────────┴────────────┴──► finished  (outcome: the command's code, message and result)

* ``add`` validates the command at once (an invalid one is refused and never queued) and appends it.
* Procedures run one at a time, in the order they were added. A procedure whose resources are held by a
  command from another interface, or that would exceed the dispatcher's ``max_running``, waits, still
  ``queued``, until they are free.
* ``pause`` / ``resume`` apply to the running procedure, when its command is pausable.
* The skill methods act on the skill instance of a procedure's command (OPC UA Part 10, see
  :mod:`locem_bridge.locem.execution`): ``suspend`` (the same as ``pause``, with a cause), ``resume``, ``halt``
  (the command ends ``ABORTED`` ``halted``, its devices safe; answered once it has ended) and ``reset`` (a halted or
  failed one's skill instance back to Ready; the procedure stays finished). A method the skill state does not
  allow is refused with :class:`InvalidArgument` naming the state and the methods it allows; a queued procedure
  has no command yet (``cancel`` removes it).
* ``cancel`` removes a queued procedure or cancels the running one; either way it ends ``finished`` with
  code ``ABORTED``.
* ``STOP`` (a dispatcher stop hook) cancels the running procedure and every queued one: nothing queued before a
  STOP starts after it.
"""

import collections
import logging
import threading
import time
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Deque, Dict, List, Optional

from ..common.locem_codes import Code
from ..common.program_state import Method, ProgramState
from .dispatcher import Dispatcher
from .errors import Aborted, Busy, InvalidArgument, LocemError
from .execution import CommandEvent, ExecState, Execution
from .registry import BoundCommand, Interface
from .response import Response

_log = logging.getLogger(__name__)

MAX_QUEUED = 100
"""Procedures that may wait in the queue at once; ``add`` answers BUSY beyond it."""
KEEP_FINISHED = 256
"""Finished procedures kept for ``query_state``."""


class ProcedureState(str, Enum):
    QUEUED = "queued"
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"

    def __str__(self) -> str:
        return self.value


@dataclass
class Procedure:
    id: int
    command: str
    bound: BoundCommand
    state: ProcedureState = ProcedureState.QUEUED
    response: Optional[Response] = None
    execution: Optional[Execution] = None
    added: float = field(default_factory=time.time)

    def snapshot(self) -> "ProcedureSnapshot":
        response = self.response
        execution = self.execution
        return ProcedureSnapshot(self.id, self.command, self.state,
                                 response.code.value if response else "",
                                 response.message if response else "",
                                 dict(response.result) if response else {},
                                 execution.progress if execution else 0.0,
                                 execution.id if execution else 0,
                                 execution.program if execution else ProgramState.READY)


@dataclass(frozen=True)
class ProcedureSnapshot:
    """What ``query_state`` answers and what is published on each change."""

    id: int
    command: str
    state: ProcedureState
    code: str = ""
    message: str = ""
    result: Dict[str, Any] = field(default_factory=dict)
    progress: float = 0.0
    command_id: int = 0                                # the id of its LOCEM command once started, else 0
    skill_state: ProgramState = ProgramState.READY     # its command's skill state (Ready while queued)


StateListener = Callable[[ProcedureSnapshot], None]


class ProcedureManager:
    """Owns the queue and one worker thread. ``close()`` ends the worker."""

    def __init__(self, dispatcher: Dispatcher, poll: float = 1.0) -> None:
        self._dispatcher = dispatcher
        self._poll = poll
        self._lock = threading.Condition()
        self._queue: Deque[Procedure] = collections.deque()
        self._all: "collections.OrderedDict[int, Procedure]" = collections.OrderedDict()
        self._current: Optional[Procedure] = None
        self._next_id = 1
        self._listeners: List[StateListener] = []
        self._closed = False
        dispatcher.add_stop_hook("procedures", lambda: self.cancel_all("stopped by STOP"))
        self._worker = threading.Thread(target=self._work, name="locem-procedures", daemon=True)
        self._worker.start()

    def add_listener(self, listener: StateListener) -> None:
        self._listeners.append(listener)

    # -- the five operations ------------------------------------------------------------------------------
    def add(self, command: str) -> ProcedureSnapshot:
        bound = self._dispatcher.bind(command, Interface.PROCEDURE)
        self._dispatcher.registry.require_handler(bound)
        with self._lock:
            if len(self._queue) >= MAX_QUEUED:
                raise Busy("the procedure queue is full (%d waiting); cancel some or wait" % MAX_QUEUED)
            procedure = Procedure(self._next_id, command, bound)
            self._next_id += 1
            self._queue.append(procedure)
            self._all[procedure.id] = procedure
            self._trim()
            snapshot = procedure.snapshot()
            self._publish(snapshot)
            self._lock.notify_all()
        return snapshot

    def query_state(self, procedure_id: int) -> ProcedureSnapshot:
        with self._lock:
            return self._get(procedure_id).snapshot()

    def cancel(self, procedure_id: int) -> ProcedureSnapshot:
        with self._lock:
            procedure = self._get(procedure_id)
            if procedure.state is ProcedureState.FINISHED:
                raise InvalidArgument("procedure %d has already finished (%s)"
                                      % (procedure_id, procedure.response.code.value if procedure.response else "?"))
            if procedure.state is ProcedureState.QUEUED:
                self._queue.remove(procedure)
                self._finish(procedure, Response.from_error(Aborted("procedure %d canceled before it started"
                                                                    % procedure_id)))
                snapshot = procedure.snapshot()
            else:
                snapshot = None
        if snapshot is not None:
            self._dispatcher.wake_waiters()  # the worker may be waiting for this one's resources
            return snapshot
        with self._lock:
            execution = procedure.execution
        if execution is not None:
            execution.cancel("procedure %d canceled" % procedure_id)
            self._wait_finished(procedure, execution)
        return self.query_state(procedure_id)

    def pause(self, procedure_id: int) -> ProcedureSnapshot:
        execution = self._running_execution(procedure_id, "paused")
        execution.suspend("pause requested")
        return self.query_state(procedure_id)

    def resume(self, procedure_id: int, cause: str = "") -> ProcedureSnapshot:
        """Resume the paused (suspended) procedure; refused (naming the skill state) when it is not paused."""
        return self._skill_method(procedure_id, Method.RESUME, cause or "resume requested")

    def suspend(self, procedure_id: int, cause: str = "") -> ProcedureSnapshot:
        """Suspend the running procedure's command (``pause`` with a cause): it ends up ``paused``."""
        return self._skill_method(procedure_id, Method.SUSPEND, cause or "suspend requested")

    def halt(self, procedure_id: int, cause: str = "") -> ProcedureSnapshot:
        """Halt a running or paused procedure's command; answered once it has ended (``finished``, ABORTED)."""
        return self._skill_method(procedure_id, Method.HALT, cause or "halt requested")

    def reset(self, procedure_id: int, cause: str = "") -> ProcedureSnapshot:
        """Reset a finished procedure's halted (or failed) command to Ready; the procedure stays ``finished``."""
        return self._skill_method(procedure_id, Method.RESET, cause or "reset requested")

    def _skill_method(self, procedure_id: int, method: Method, cause: str) -> ProcedureSnapshot:
        with self._lock:
            procedure = self._get(procedure_id)
            execution = procedure.execution
            state = procedure.state
        if execution is None:  # queued (or finished before it could start): no skill instance yet
            raise InvalidArgument("procedure %d is %s, its command has not started (skill Ready): %s is not allowed "
                                  "on it%s" % (procedure_id, state.value, method.value,
                                               "; cancel removes it from the queue"
                                               if state is ProcedureState.QUEUED else ""), argument="id")
        try:
            if method is Method.SUSPEND:
                execution.suspend(cause)
            elif method is Method.RESUME:
                execution.resume(cause)
            elif method is Method.HALT:
                execution.halt(cause)
                self._wait_finished(procedure, execution)  # as cancel: answered once its devices are safe
            else:
                execution.reset(cause)
        except InvalidArgument as error:
            state = self.query_state(procedure_id).state
            not_paused = ", not paused" if method is Method.RESUME else ""
            raise InvalidArgument("procedure %d is %s%s: %s" % (procedure_id, state.value, not_paused, error.message),
                                  argument="id") from None
        return self.query_state(procedure_id)

    def _wait_finished(self, procedure: Procedure, execution: Execution) -> None:
        """Wait (bounded) for the command's end and for the procedure to be marked finished (its listener runs
        just after the command's answer)."""
        timeout = self._dispatcher.stop_timeout + self._dispatcher.grace
        deadline = time.monotonic() + timeout
        execution.wait(timeout)
        with self._lock:
            while procedure.state is not ProcedureState.FINISHED and execution.done:
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._lock.wait(min(left, 0.05))

    def cancel_all(self, reason: str) -> None:
        with self._lock:
            queued = list(self._queue)
            self._queue.clear()
            for procedure in queued:
                self._finish(procedure, Response.from_error(Aborted("procedure %d: %s" % (procedure.id, reason))))
            running = self._current.execution if self._current else None
        if running is not None:
            running.cancel(reason)
        self._dispatcher.wake_waiters()

    def list(self) -> List[ProcedureSnapshot]:
        with self._lock:
            return [p.snapshot() for p in self._all.values()]

    def close(self) -> None:
        self.cancel_all("LOCEM is shutting down")
        with self._lock:
            self._closed = True
            self._lock.notify_all()
        self._worker.join(timeout=2.0)

    # -- internals ----------------------------------------------------------------------------------------
    def _get(self, procedure_id: int) -> Procedure:
        procedure = self._all.get(int(procedure_id))
        if procedure is None:
            known = list(self._all)
            span = "known ids: %d to %d" % (known[0], known[-1]) if known else "no procedures yet"
            raise InvalidArgument("no procedure with id %s (%s)" % (procedure_id, span), argument="id")
        return procedure

    def _running_execution(self, procedure_id: int, verb: str) -> Execution:
        with self._lock:
            procedure = self._get(procedure_id)
            if procedure.state is not ProcedureState.RUNNING or procedure.execution is None:
                raise InvalidArgument("procedure %d is %s; only the running procedure can be %s"
                                      % (procedure_id, procedure.state.value, verb))
            return procedure.execution

    def _work(self) -> None:
        while True:
            with self._lock:
                while not self._closed and not self._queue:
                    self._lock.wait()
                if self._closed:
                    return
                procedure = self._queue[0]
            # sleeps until a command ends (the dispatcher's condition) or a cancel here nudges it; poll is a backstop
            if not self._dispatcher.wait_for_resources(procedure.bound.claims, self._poll,
                                                       capacity=not procedure.bound.spec.inline):
                continue  # still queued; a cancel may remove it meanwhile
            with self._lock:
                if not self._queue or self._queue[0] is not procedure:
                    continue  # canceled while we waited
                try:
                    execution = self._dispatcher.submit(procedure.command, Interface.PROCEDURE,
                                                        listener=lambda e, p=procedure: self._on_event(p, e))
                except Busy:
                    continue  # another interface took the resource first: stay queued, try again
                except LocemError as error:  # e.g. the backend went away since add(): finish with its code
                    self._queue.popleft()
                    self._finish(procedure, Response.from_error(error))
                    continue
                self._queue.popleft()
                procedure.execution = execution
                self._current = procedure
                if procedure.state is ProcedureState.QUEUED:  # a quick command may have finished already
                    procedure.state = ProcedureState.RUNNING
                    self._publish(procedure.snapshot())
            execution.wait()
            with self._lock:
                self._current = None

    def _on_event(self, procedure: Procedure, event: CommandEvent) -> None:
        state = {ExecState.RUNNING: ProcedureState.RUNNING, ExecState.PAUSED: ProcedureState.PAUSED}.get(event.state)
        with self._lock:
            if event.state.terminal:
                execution = procedure.execution
                response = execution.response if execution is not None and execution.response is not None else \
                    Response(Code(event.code), event.message, dict(event.result))
                self._finish(procedure, response)
            elif state is not None and state is not procedure.state and procedure.state is not ProcedureState.QUEUED:
                procedure.state = state
                self._publish(procedure.snapshot())
            # anything else is progress feedback: not a state change, not published

    def _finish(self, procedure: Procedure, response: Response) -> None:
        if procedure.state is ProcedureState.FINISHED:
            return
        procedure.state = ProcedureState.FINISHED
        procedure.response = response
        self._publish(procedure.snapshot())
        self._lock.notify_all()  # a cancel / halt waiting for this end (the worker re-checks its queue)

    def _trim(self) -> None:
        finished = [pid for pid, p in self._all.items() if p.state is ProcedureState.FINISHED]
        for pid in finished[: max(0, len(finished) - KEEP_FINISHED)]:
            del self._all[pid]

    def _publish(self, snapshot: ProcedureSnapshot) -> None:
        """Called with the lock held, so listeners see the transitions in order; they must be quick."""
        for listener in list(self._listeners):
            try:
                listener(snapshot)
            except Exception:
                _log.exception("procedure listener failed")
