"""One running command: its state machine, its handle for callers, and the context its handler sees.

Lifecycle of an :class:`Execution` (every transition emits a :class:`CommandEvent`)::

    running ──► succeeded | failed | canceled
       │ ▲
       ▼ │  suspend / resume (pausable commands only)
     paused

The same life as a skill instance (:mod:`locem_bridge.common.program_state`, OPC UA ``ProgramStateMachineType``):
admitted = Start (Ready -> Running), ``suspend`` / ``resume`` = Suspend / Resume, a success = Running -> Ready,
``halt`` (and ``cancel``) = Halt, a failure = Running -> Halted without a call, ``reset`` = Halted -> Ready. The
event of each such change carries its :class:`~locem_bridge.common.program_state.Transition`; a method the state
does not allow is refused with :class:`InvalidArgument` naming the state and what it allows, and changes nothing.

Suspending a device command: its handler either blocks in ``check()`` while suspended (``WAIT``), or, inside
:meth:`CommandContext.unwinding`, gets :class:`SuspendRequest` from ``check()`` / ``sleep()`` so that its device
calls stop their motion on the way out; it then brings its devices to their suspended state, waits in
:meth:`CommandContext.wait_resumed` and continues from where they stopped (:mod:`locem_bridge.bridges.suspension`).
Callbacks registered with ``on_pause`` run at once in the suspending caller's thread (a valve closes first).

``cancel`` and the deadline both ask the handler to stop through its :class:`CommandContext`: the context's
``check()`` / ``sleep()`` raise, and callbacks registered with ``on_cancel`` (a device stop) run at once. A
handler that ignores the request still gets its caller an answer: ``grace`` seconds after the deadline the
execution is answered ``TIMEOUT`` and marked *stuck*; its resources stay occupied until the handler returns,
because the device it drives is in an unknown state.
"""

import _thread
import logging
import threading
import time
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Dict, List, Optional

from ..common.locem_codes import Code
from ..common.program_state import Method, ProgramState, Transition, TransitionRefused, transition_between
from .errors import Aborted, CommandTimeout, InvalidArgument, LocemError, SuspendRequest
from .registry import BoundCommand, Interface
from .response import Response

_log = logging.getLogger(__name__)
_RLock = getattr(_thread, "RLock", threading.RLock)  # what threading.RLock() returns, without its Python wrapper


class ExecState(str, Enum):
    REJECTED = "rejected"
    RUNNING = "running"
    PAUSED = "paused"
    SUCCEEDED = "succeeded"
    FAILED = "failed"
    CANCELED = "canceled"

    @property
    def terminal(self) -> bool:
        return self in (ExecState.REJECTED, ExecState.SUCCEEDED, ExecState.FAILED, ExecState.CANCELED)

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class CommandEvent:
    """A state change of one command, as published on ``/locem/status``."""

    id: int
    command: str
    name: str
    interface: str
    state: ExecState
    progress: float = 0.0
    code: str = ""
    message: str = ""
    result: Dict[str, Any] = field(default_factory=dict)
    stamp: float = field(default_factory=time.time)
    transition: Optional[Transition] = None    # the skill state transition this event is, if any



Listener = Callable[[CommandEvent], None]


class CommandContext:
    """What a handler gets as its first argument: cancellation, deadline, pause and progress.

    Handlers must call :meth:`check` (or :meth:`sleep`) at least every few tens of milliseconds while they
    wait for a device, and register a device stop with :meth:`on_cancel` so a cancel acts immediately.
    """

    def __init__(self, execution: "Execution") -> None:
        self._execution = execution

    @property
    def id(self) -> int:
        return self._execution.id

    @property
    def values(self) -> Dict[str, Any]:
        return dict(self._execution.bound.values)

    @property
    def follows_progress(self) -> bool:
        """True when someone listens to this command's progress (an action client); else :meth:`report` is moot."""
        return bool(self._execution._feedback_listeners)

    @property
    def cancelled(self) -> bool:
        return self._execution._cancel_error is not None

    def remaining(self) -> float:
        """Seconds left before the deadline (pauses do not count)."""
        return self._execution._deadline - time.monotonic()

    def check(self) -> None:
        """Block while paused (raise :class:`SuspendRequest` instead inside :meth:`unwinding`); raise
        :class:`Aborted` or :class:`CommandTimeout` once asked to stop."""
        execution = self._execution
        while True:
            error = execution._cancel_error
            if error is not None:
                raise error
            if not execution._paused:
                return
            if execution._unwinding:
                raise SuspendRequest("%s %d suspended" % (execution.bound.name, execution.id))
            execution._wake.wait()  # set by resume and by every stop request; the loop re-reads the state
            execution._wake.clear()

    @property
    def suspended(self) -> bool:
        """True while the command is suspended (and not asked to stop)."""
        execution = self._execution
        return execution._paused and execution._cancel_error is None

    def unwinding(self) -> "_Unwinding":
        """``with ctx.unwinding():`` -- while suspended, ``check()`` / ``sleep()`` raise :class:`SuspendRequest`
        instead of blocking, so the device calls under way stop and return to the handler."""
        return _Unwinding(self._execution)

    def ignoring_suspension(self) -> "SuspendedWaiter":
        """A waiter for the device moves that bring a suspended command's devices to their suspended state (the
        sander lifting off the wall): it does not block while suspended, it raises once asked to stop."""
        return SuspendedWaiter(self._execution)

    def wait_resumed(self) -> None:
        """Block while suspended; return on resume, raise once asked to stop (halt, cancel, STOP, deadline)."""
        execution = self._execution
        depth = execution._unwinding
        execution._unwinding = 0
        try:
            self.check()
        finally:
            execution._unwinding = depth

    def sleep(self, seconds: float) -> None:
        """Wait ``seconds`` of un-paused time, returning early only by raising when asked to stop."""
        remaining = float(seconds)
        execution = self._execution
        while True:
            self.check()
            if remaining <= 0.0:
                return
            start = time.monotonic()
            execution._wake.wait(remaining)
            execution._wake.clear()
            end = execution._pause_started if execution._paused else time.monotonic()
            remaining -= max(0.0, end - start)

    def report(self, progress: float, text: str = "") -> None:
        """Progress in 0..1 plus a short state text, forwarded to action feedback listeners."""
        self._execution._feedback(min(max(float(progress), 0.0), 1.0), text)

    def on_cancel(self, callback: Callable[[], None]) -> None:
        """Run ``callback`` (once) as soon as a cancel, ``STOP`` or the deadline asks this command to stop."""
        self._execution._add_cancel_callback(callback)

    def on_pause(self, pause: Callable[[], None], resume: Callable[[], None]) -> None:
        """Device actions to run when the command is paused and resumed (e.g. halt and continue a motion)."""
        self._execution._pause_callbacks.append((pause, resume))


class SuspendedWaiter:
    """See :meth:`CommandContext.ignoring_suspension`."""

    def __init__(self, execution: "Execution") -> None:
        self._execution = execution

    def check(self) -> None:
        error = self._execution._cancel_error
        if error is not None:
            raise error

    def sleep(self, seconds: float) -> None:
        self.check()
        end = time.monotonic() + max(0.0, float(seconds))
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return
            self._execution._wake.wait(left)
            self._execution._wake.clear()
            self.check()

    def on_cancel(self, callback: Callable[[], None]) -> None:
        self._execution._add_cancel_callback(callback)

    def report(self, progress: float, text: str = "") -> None:
        pass


class _Unwinding:
    def __init__(self, execution: "Execution") -> None:
        self._execution = execution

    def __enter__(self) -> None:
        self._execution._unwinding += 1

    def __exit__(self, *exc: Any) -> None:
        self._execution._unwinding -= 1


class Execution:
    """A caller's handle on one submitted command. Thread-safe."""

    # the state a command starts in; an instance gets its own value on its first change (a quick query never
    # changes most of them, and is answered sooner for not setting them one by one)
    state = ExecState.RUNNING
    progress = 0.0
    feedback_text = ""
    response: Optional[Response] = None
    stuck = False
    _paused = False
    _pause_started = 0.0
    _cancel_error: Optional[LocemError] = None
    _wake_event: Optional[threading.Event] = None  # made on first use: quick queries never sleep
    _answered = False
    _done_event: Optional[threading.Event] = None  # made by the first wait() that has to block
    _handler_returned = False  # set by the dispatcher once the handler has returned (or never started)
    _unwinding = 0             # > 0: check() raises SuspendRequest while paused (CommandContext.unwinding)
    program = ProgramState.RUNNING   # the skill state: Start was taken at admission
    _halt_cause: Optional[str] = None  # set by halt()/cancel(): the end is the Halt method's, with this cause

    def __init__(self, exec_id: int, bound: BoundCommand, interface: Interface, grace: float) -> None:
        self.id = exec_id
        self.bound = bound
        self.interface = interface
        self.started = time.monotonic()
        self._grace = grace
        self._deadline = self.started + bound.timeout
        self._cancel_callbacks: List[Callable[[], None]] = []
        self._pause_callbacks: List[Any] = []
        self._listeners: List[Listener] = []
        self._feedback_listeners: List[Listener] = []
        self._lock = _RLock()

    @property
    def _wake(self) -> threading.Event:
        """Set by pause, resume and every stop request; what a sleeping handler waits on."""
        event = self._wake_event
        if event is None:
            with self._lock:
                if self._wake_event is None:
                    self._wake_event = threading.Event()
                event = self._wake_event
        return event

    # -- read side --------------------------------------------------------------------------------------
    @property
    def text(self) -> str:
        return self.bound.text

    @property
    def done(self) -> bool:
        return self._answered

    @property
    def deadline(self) -> float:
        return self._deadline

    @property
    def paused(self) -> bool:
        return self._paused

    def wait(self, timeout: Optional[float] = None) -> Optional[Response]:
        """The response once answered (``None`` if ``timeout`` passed first)."""
        if not self._answered:
            with self._lock:
                if not self._answered and self._done_event is None:
                    self._done_event = threading.Event()
                event = self._done_event
            if event is not None:
                event.wait(timeout)
        return self.response

    def add_listener(self, listener: Listener, feedback: bool = True) -> None:
        """Per-command events: state changes, and progress feedback too unless ``feedback`` is false."""
        self._listeners.append(listener)
        if feedback:
            self._feedback_listeners.append(listener)

    def summary(self) -> Dict[str, Any]:
        return {"id": self.id, "command": self.text, "state": self.state.value, "interface": self.interface.value,
                "progress": round(self.progress, 4), "elapsed_s": round(time.monotonic() - self.started, 3),
                "resources": sorted(self.bound.claims), "stuck": self.stuck,
                "skill_state": self.program.value}

    # -- control side -----------------------------------------------------------------------------------
    def cancel(self, reason: str = "canceled by the caller") -> bool:
        """Ask the command to stop (the skill's Halt); returns False when it had already ended."""
        with self._lock:
            if self._halt_cause is None and not self.done and self._cancel_error is None:
                self._halt_cause = reason
        return self._request_stop(Aborted("%s: %s" % (self.bound.name, reason)))

    def _what(self) -> str:
        return "command %d (%s)" % (self.id, self.bound.name)

    def _refuse(self, method: Method) -> InvalidArgument:
        if self.done and self.program is not ProgramState.HALTED:
            return InvalidArgument("%s is not allowed: %s has ended (%s, skill state %s); a command runs once, send "
                                   "it again for a new instance" % (method.value, self._what(), self.state.value,
                                                                    self.program.value), argument="id")
        return InvalidArgument(str(TransitionRefused(self._what(), self.program, method)), argument="id")

    def suspend(self, cause: str = "") -> None:
        """Suspend (Running -> Suspended): the devices come to rest where they are; :meth:`resume` goes on."""
        with self._lock:
            if self.program is not ProgramState.RUNNING or self._cancel_error is not None:
                raise self._refuse(Method.SUSPEND)
            if not self.bound.spec.pausable:
                raise InvalidArgument("Suspend is not allowed: %s cannot be suspended (only pausable commands "
                                      "can; HELP %s); halt it instead" % (self._what(), self.bound.name),
                                      argument="id")
            self._paused = True
            self._pause_started = time.monotonic()
            self.state = ExecState.PAUSED
            self.program = ProgramState.SUSPENDED
            callbacks = [p for p, _ in self._pause_callbacks]
        _run_all(callbacks, "pause")   # device stops first (a valve closes), then the handler is woken
        self._wake.set()
        self._emit(self._event(self._transition(ProgramState.RUNNING, ProgramState.SUSPENDED, Method.SUSPEND,
                                                cause or "suspended")))

    def pause(self) -> None:
        """:meth:`suspend` (the procedure interface's older name)."""
        self.suspend("pause requested")

    def resume(self, cause: str = "") -> None:
        """Resume (Suspended -> Running): the handler continues from where its devices stopped."""
        with self._lock:
            if self.program is not ProgramState.SUSPENDED or self._cancel_error is not None:
                raise self._refuse(Method.RESUME)
            self._paused = False
            self._deadline += time.monotonic() - self._pause_started
            self.state = ExecState.RUNNING
            self.program = ProgramState.RUNNING
            callbacks = [r for _, r in self._pause_callbacks]
        _run_all(callbacks, "resume")
        self._wake.set()
        self._emit(self._event(self._transition(ProgramState.SUSPENDED, ProgramState.RUNNING, Method.RESUME,
                                                cause or "resumed")))

    def halt(self, cause: str = "") -> None:
        """Halt (Running or Suspended -> Halted): the command ends ``ABORTED`` with ``halted: <cause>``, its
        devices stopped safe (as a cancel)."""
        with self._lock:
            if self.program not in (ProgramState.RUNNING, ProgramState.SUSPENDED) or self._cancel_error is not None:
                raise self._refuse(Method.HALT)
            self._halt_cause = cause or "halt requested"
        self._request_stop(Aborted("%s: halted: %s" % (self.bound.name, self._halt_cause)))

    def reset(self, cause: str = "") -> None:
        """Reset (Halted -> Ready): a halted or failed command's skill instance is ready again."""
        with self._lock:
            if self.program is not ProgramState.HALTED:
                raise self._refuse(Method.RESET)
            self.program = ProgramState.READY
        self._emit(self._event(self._transition(ProgramState.HALTED, ProgramState.READY, Method.RESET,
                                                cause or "reset")))

    def _transition(self, source: ProgramState, target: ProgramState, method: Optional[Method],
                    cause: str) -> Transition:
        t = transition_between(source, target)
        return Transition(str(self.id), self.bound.name, t.number, t.name, source, target,
                          method.value if method is not None else "", cause)

    def start_event(self) -> CommandEvent:
        """The first event of an admitted command: Start (Ready -> Running). Inline commands (STOP, the skill
        methods themselves) are not skill instances: their events carry no transition."""
        if self.bound.spec.inline:
            return self._event()
        return self._event(self._transition(ProgramState.READY, ProgramState.RUNNING, Method.START,
                                            "%s interface" % self.interface.value))

    # -- used by the dispatcher and the context ----------------------------------------------------------
    def _request_stop(self, error: LocemError) -> bool:
        with self._lock:
            if self.done or self._cancel_error is not None:
                return False
            self._cancel_error = error
            callbacks = list(self._cancel_callbacks)
            self._paused = False
        self._wake.set()
        _run_all(callbacks, "cancel")
        return True

    def _expire(self) -> None:
        self._request_stop(CommandTimeout("%s did not finish within %.3g s; it was told to stop"
                                          % (self.bound.name, self.bound.timeout)))

    def _add_cancel_callback(self, callback: Callable[[], None]) -> None:
        with self._lock:
            already = self._cancel_error is not None
            if not already:
                self._cancel_callbacks.append(callback)
        if already:
            _run_all([callback], "cancel")

    def _feedback(self, progress: float, text: str) -> None:
        self.progress = progress
        self.feedback_text = text
        event = self._event()
        for listener in list(self._feedback_listeners):
            _call(listener, event)

    def _finish(self, response: Response, stuck: bool = False) -> bool:
        """Record the answer once; returns False when the execution had already been answered."""
        with self._lock:
            if self.done:
                return False
            self.response = response
            self.stuck = stuck
            source = self.program
            if response.success:
                self.state, self.progress = ExecState.SUCCEEDED, 1.0
                target, method, cause = ProgramState.READY, None, "completed"
            else:
                self.state = ExecState.CANCELED if response.code in (Code.ABORTED,) else ExecState.FAILED
                target = ProgramState.HALTED
                method = Method.HALT if self._halt_cause is not None else None
                cause = "%s: %s" % (response.code.value, response.message)
            self.program = target
            self._answered = True
            if self._done_event is not None:
                self._done_event.set()
        if self._listeners:  # a read-only query nobody follows has no one to tell
            self._emit(self._event(self._transition(source, target, method, cause)
                                   if source in (ProgramState.RUNNING, ProgramState.SUSPENDED)
                                   and not self.bound.spec.inline else None))
        return True

    def _event(self, transition: Optional[Transition] = None) -> CommandEvent:
        response = self.response
        return CommandEvent(
            id=self.id, command=self.text, name=self.bound.name, interface=self.interface.value, state=self.state,
            progress=self.progress, code=response.code.value if response else "",
            message=response.message if response else self.feedback_text,
            result=dict(response.result) if response else {}, transition=transition,
        )

    def _emit(self, event: CommandEvent) -> None:
        for listener in list(self._listeners):
            _call(listener, event)


def _run_all(callbacks: List[Callable[[], None]], what: str) -> None:
    for callback in callbacks:
        try:
            callback()
        except Exception:  # a failing device stop must not keep the others from running
            _log.exception("%s callback failed", what)


def _call(listener: Listener, event: CommandEvent) -> None:
    try:
        listener(event)
    except Exception:
        _log.exception("command event listener failed")
