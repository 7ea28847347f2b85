"""One running command: its state machine, its handle for callers, and the context its handler sees.

Lifecycle of an :class:`Execution` (every transition emits a :class:`CommandEvent`)::

    running ──► succeeded | failed | canceled
       │ ▲
       ▼ │  pause / resume (pausable commands only)
     paused

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
from .errors import Aborted, CommandTimeout, InvalidArgument, LocemError
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
        """Block while paused; raise :class:`Aborted` or :class:`CommandTimeout` once asked to stop."""
        execution = self._execution
        while True:
            error = execution._cancel_error
            if error is not None:
                raise error
            if not execution._paused:
                return
            execution._wake.wait()  # set by resume and by every stop request; the loop re-reads the state
            execution._wake.clear()

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
                "resources": sorted(self.bound.claims), "stuck": self.stuck}

    # -- control side -----------------------------------------------------------------------------------
    def cancel(self, reason: str = "canceled by the caller") -> bool:
        """Ask the command to stop; returns False when it had already ended."""
        return self._request_stop(Aborted("%s: %s" % (self.bound.name, reason)))

    def pause(self) -> None:
        with self._lock:
            if not self.bound.spec.pausable:
                raise InvalidArgument("%s cannot be paused; cancel it instead" % self.bound.name)
            if self.done or self._cancel_error is not None:
                raise InvalidArgument("command %d has already ended" % self.id)
            if self._paused:
                return
            self._paused = True
            self._pause_started = time.monotonic()
            self.state = ExecState.PAUSED
            callbacks = [p for p, _ in self._pause_callbacks]
        self._wake.set()
        _run_all(callbacks, "pause")
        self._emit(self._event())

    def resume(self) -> None:
        with self._lock:
            if not self._paused:
                raise InvalidArgument("command %d is not paused" % self.id)
            self._paused = False
            self._deadline += time.monotonic() - self._pause_started
            self.state = ExecState.RUNNING
            callbacks = [r for _, r in self._pause_callbacks]
        _run_all(callbacks, "resume")
        self._wake.set()
        self._emit(self._event())

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
            if response.success:
                self.state, self.progress = ExecState.SUCCEEDED, 1.0
            elif response.code in (Code.ABORTED,):
                self.state = ExecState.CANCELED
            else:
                self.state = ExecState.FAILED
            self._answered = True
            if self._done_event is not None:
                self._done_event.set()
        if self._listeners:  # a read-only query nobody follows has no one to tell
            self._emit(self._event())
        return True

    def _event(self) -> CommandEvent:
        response = self.response
        return CommandEvent(
            id=self.id, command=self.text, name=self.bound.name, interface=self.interface.value, state=self.state,
            progress=self.progress, code=response.code.value if response else "",
            message=response.message if response else self.feedback_text,
            result=dict(response.result) if response else {},
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
