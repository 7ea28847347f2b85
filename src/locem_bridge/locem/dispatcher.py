"""The dispatcher: validates, applies the resource policy, runs handlers against deadlines.

Policy, stated once:

* **Validation first.** A command is parsed and bound to its declaration before anything else; a rejected
  command never reaches a handler, and the rejection is published like any other event.
* **Events are state changes.** Every command's start, pause, resume and end is published to the listeners
  (``/locem/status``), except runs of read-only ``query`` commands (``HELP``, ``STATUS``), which change nothing.
* **One running command per resource.** Each command declares the resources it occupies (``base``, ``arm``,
  ``compressor``, ``tool``, ...). A command needing an occupied resource is answered ``BUSY`` at once; there is
  no hidden queue (the procedure interface is the queue).
* **A bounded number of running commands.** At most ``max_running`` (:data:`DEFAULT_MAX_RUNNING`) commands
  that run in their own thread may run at once, whatever their resources; one more is answered ``BUSY`` naming
  the limit. ``STOP`` and the inline queries (``HELP``, ``STATUS``) do not count and are never refused by it.
* **STOP pre-empts everything.** Preemptive commands are never ``BUSY``; ``STOP`` cancels every running
  command, runs every registered device stop hook, and waits (bounded) until the handlers have returned.
* **Every command has a deadline** (its declared or computed timeout, pauses excluded). At the deadline the
  handler is told to stop; ``grace`` seconds later the caller is answered ``TIMEOUT`` whether or not the handler
  has returned. A handler that has not returned keeps its resources (the device state is unknown) and is
  listed as stuck by ``STATUS``.

Handlers run in their own thread, except ``inline`` ones (quick queries such as ``HELP`` and ``STATUS``),
which run in the caller's thread. A waiting handler sleeps on its execution's event (see
:meth:`CommandContext.sleep`), so it costs nothing until a cancel, ``STOP``, pause or its time wakes it.
"""

import collections
import functools
import heapq
import itertools
import logging
import threading
import time
import traceback
from typing import Any, Callable, Dict, List, Optional, Tuple

from ..common.locem_codes import Code
from ..common.program_state import Method
from .errors import Aborted, Busy, CommandTimeout, InvalidArgument, LocemError
from .execution import CommandContext, CommandEvent, ExecState, Execution, Listener
from .grammar import parse
from .registry import BoundCommand, CommandRegistry, Interface
from .response import Response

_log = logging.getLogger(__name__)

HealthSource = Callable[[], Dict[str, Any]]

BIND_CACHE_SIZE = 256
"""Accepted command strings whose parse and binding are remembered (see :meth:`Dispatcher.bind`)."""
KEEP_RECENT = 256
"""Ended commands whose skill instance can still be reset (``RESET id=N``)."""
DEFAULT_MAX_RUNNING = 64
"""Commands that may run at once in their own thread (the ROS node's ``~max_running`` parameter)."""


class Dispatcher:
    """Thread-safe front door of the LOCEM core. Construct with a registry whose handlers are bound."""

    def __init__(self, registry: CommandRegistry, grace: float = 1.0, stop_timeout: float = 2.0,
                 max_running: int = DEFAULT_MAX_RUNNING) -> None:
        if int(max_running) < 1:
            raise ValueError("max_running must be at least 1, got %r" % (max_running,))
        self.registry = registry
        self.max_running = int(max_running)
        self.grace = grace
        self.stop_timeout = stop_timeout
        self.started = time.monotonic()
        self._ids = itertools.count(1)
        self._lock = threading.Lock()
        self._released = threading.Condition(self._lock)
        self._owners: Dict[str, Execution] = {}
        self._running: Dict[int, Execution] = {}
        self._threaded = 0  # running executions that hold a thread (not inline): bounded by max_running
        self._listeners: List[Listener] = []
        self._stop_hooks: List[Tuple[str, Callable[[], None]]] = []
        self._health: Dict[str, HealthSource] = {}
        self._watch: List[Tuple[float, int, Execution]] = []
        self._watch_cv = threading.Condition()
        self._bind_cached = functools.lru_cache(maxsize=BIND_CACHE_SIZE)(self._bind_uncached)
        self._recent: "collections.OrderedDict[int, Execution]" = collections.OrderedDict()
        self._closed = False
        self._watchdog = threading.Thread(target=self._watch_deadlines, name="locem-watchdog", daemon=True)
        self._watchdog.start()

    # -- wiring -------------------------------------------------------------------------------------------
    def add_listener(self, listener: Listener) -> None:
        """Called for every command event (rejections, state changes, results) of every interface."""
        self._listeners.append(listener)

    def add_stop_hook(self, name: str, hook: Callable[[], None]) -> None:
        """A device-wide stop run by ``STOP`` (e.g. zero base velocity, stop the arm, close the valve)."""
        self._stop_hooks.append((name, hook))

    def add_health_source(self, name: str, source: HealthSource) -> None:
        """A backend's health (link state, device state, last error), summarised by ``STATUS``."""
        self._health[name] = source

    # -- entry points -------------------------------------------------------------------------------------
    def bind(self, text: object, interface: Optional[Interface] = None) -> BoundCommand:
        """Parse and check ``text`` without running it; raises the typed :class:`LocemError`.

        Accepted strings are remembered (the last :data:`BIND_CACHE_SIZE`, per registry version): a client that
        sends the same command again (STATUS, a poll) skips the parse. Refused ones are checked every time.
        """
        if type(text) is not str:
            return self.registry.bind_arguments(parse(text), interface)
        return self._bind_cached(text, interface, self.registry.version)

    def _bind_uncached(self, text: str, interface: Optional[Interface], version: int) -> BoundCommand:
        return self.registry.bind_arguments(parse(text), interface)

    def submit(self, text: object, interface: Interface,
               listener: Optional[Listener] = None) -> Execution:
        """Start a command and return its handle; raises :class:`LocemError` when it is refused.

        ``listener`` receives this command's events (including progress feedback) from the first one on.
        """
        try:
            bound = self.bind(text, interface)
            handler = self.registry.require_handler(bound)
            execution = self._admit(bound, interface)
        except LocemError as error:
            self._emit(self._rejection(text, interface, error))
            raise
        if listener is not None:
            execution.add_listener(listener)
        if not bound.spec.query:
            execution.add_listener(self._emit, feedback=False)
            self._remember(execution)
            self._emit(execution.start_event())
        if bound.spec.inline:
            self._run(execution, handler)
            return execution
        try:
            threading.Thread(target=self._run, args=(execution, handler),
                             name="locem-%s-%d" % (bound.name.lower(), execution.id), daemon=True).start()
        except RuntimeError as error:  # "can't start new thread": answer it like any other end, never lose it
            execution._handler_returned = True
            self._release(execution)
            execution._finish(Response.from_error(Busy("%s could not start: %s; wait for running commands to "
                                                       "end or send STOP" % (bound.name, error))))
        return execution

    def execute(self, text: object, interface: Interface = Interface.SERVICE) -> Response:
        """Run a command to its end and return the response; never raises.

        A read-only inline query that occupies no resource (``HELP``, ``STATUS``, a device read) is answered
        right here: it changes nothing, publishes nothing, cannot be cancelled, so it needs no admission.
        """
        try:
            bound = self._bind_cached(text, interface, self.registry.version) if type(text) is str else \
                self.bind(text, interface)
        except LocemError as error:
            self._emit(self._rejection(text, interface, error))
            return Response.from_error(error)
        spec = bound.spec
        if spec.query and spec.inline and not (spec.claims(bound.values) if spec.claims else spec.resources):
            handler = self.registry.handler(spec.name)
            if handler is not None:  # else submit() answers NOT_READY and publishes it
                return self._call(Execution(next(self._ids), bound, interface, self.grace), handler)
        try:
            execution = self.submit(text, interface)
        except LocemError as error:  # already published by submit()
            return Response.from_error(error)
        response = execution.wait()
        assert response is not None  # wait() without timeout returns only once answered
        return response

    def stop_all(self, reason: str = "stopped by STOP") -> Dict[str, Any]:
        """Cancel every running command, run every device stop hook, wait for the handlers (bounded)."""
        with self._lock:
            victims = [e for e in self._running.values() if not e.bound.spec.preemptive]
        for execution in victims:
            execution.cancel(reason)
        hook_errors = []
        for name, hook in list(self._stop_hooks):
            try:
                hook()
            except Exception as error:  # every hook runs, whatever one of them does
                _log.exception("stop hook %s failed", name)
                hook_errors.append("%s: %s" % (name, error))
        deadline = time.monotonic() + self.stop_timeout
        with self._lock:
            while any(not e._handler_returned for e in victims):
                left = deadline - time.monotonic()
                if left <= 0:
                    break
                self._released.wait(left)
        still = [e.id for e in victims if not e._handler_returned]
        return {"stopped": [e.id for e in victims], "still_running": still, "hook_errors": hook_errors}

    def control(self, exec_id: int, method: Method, cause: str = "") -> Execution:
        """Suspend, resume, halt or reset the skill instance of command ``exec_id`` (a running one, or one of the
        last :data:`KEEP_RECENT` that changed state); :class:`InvalidArgument` names an unknown id or a method its
        state does not allow, and nothing changes."""
        with self._lock:
            execution = self._running.get(int(exec_id)) or self._recent.get(int(exec_id))
            known = sorted(set(self._running) | set(self._recent))
        if execution is None or execution.bound.spec.query:
            raise InvalidArgument("no command with id %s to %s (commands known now: %s)"
                                  % (exec_id, method.value.lower(), _span(known)), argument="id")
        if method is Method.SUSPEND:
            execution.suspend(cause)
        elif method is Method.RESUME:
            execution.resume(cause)
        elif method is Method.HALT:
            execution.halt(cause)
            execution.wait(self.stop_timeout + self.grace)       # answered once its devices are safe
        elif method is Method.RESET:
            execution.reset(cause)
        else:
            raise InvalidArgument("%s is not a method a caller may use on a running command; allowed: Suspend, "
                                  "Resume, Halt, Reset" % method.value, argument="method")
        return execution

    def running(self) -> List[Execution]:
        with self._lock:
            return sorted(self._running.values(), key=lambda e: e.id)

    def owner_of(self, resource: str) -> Optional[Execution]:
        with self._lock:
            return self._owners.get(resource)

    def wait_for_resources(self, resources: Any, timeout: float, capacity: bool = False) -> bool:
        """Block until none of ``resources`` is occupied (True) or ``timeout`` passes (False).

        With ``capacity`` also until one more command may run under ``max_running``.
        """
        deadline = time.monotonic() + timeout
        with self._lock:
            while any(r in self._owners for r in resources) or (capacity and self._threaded >= self.max_running):
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._released.wait(left)
            return True

    def wake_waiters(self) -> None:
        """Wake every :meth:`wait_for_resources` caller so it re-reads its own state (e.g. a canceled procedure)."""
        with self._lock:
            self._released.notify_all()

    def health(self) -> Dict[str, Any]:
        report = {}
        for name, source in sorted(self._health.items()):
            try:
                report[name] = source()
            except Exception as error:
                report[name] = {"link": "unknown", "last_error": "health query failed: %s" % error}
        return report

    def status(self, exclude: Optional[int] = None) -> Dict[str, Any]:
        """Running commands (but ``exclude``, e.g. the asking STATUS itself), occupied resources, health."""
        with self._lock:  # (an idle LOCEM, the common case, skips the comprehensions: STATUS is polled)
            owners = {r: e.id for r, e in self._owners.items()} if self._owners else {}
            running = [e.summary() for e in sorted(self._running.values(), key=lambda e: e.id)
                       if e.id != exclude] if self._running else []
        return {"uptime_s": round((time.monotonic() - self.started) * 1000.0) / 1000.0, "running": running,
                "resources": owners, "health": self.health() if self._health else {}}

    def close(self) -> None:
        """Stop everything and end the watchdog (for node shutdown and tests)."""
        self.stop_all("LOCEM is shutting down")
        with self._watch_cv:
            self._closed = True
            self._watch_cv.notify()
        self._watchdog.join(timeout=2.0)

    # -- internals ----------------------------------------------------------------------------------------
    def _admit(self, bound: BoundCommand, interface: Interface) -> Execution:
        claims = bound.claims
        with self._lock:
            if not bound.spec.preemptive:
                for resource in sorted(claims):
                    owner = self._owners.get(resource)
                    if owner is not None:
                        raise Busy("%s needs the %s, which is running '%s' (id %d)%s; wait for it, cancel it, "
                                   "or send STOP" % (bound.name, resource, owner.text, owner.id,
                                                     " and is stuck after a timeout" if owner.stuck else ""))
                if not bound.spec.inline and self._threaded >= self.max_running:
                    raise Busy("%s refused: LOCEM is already running %d commands, its limit (max_running = %d, "
                               "the node's ~max_running parameter); wait for one to end, cancel one, or send STOP"
                               % (bound.name, self._threaded, self.max_running))
            execution = Execution(next(self._ids), bound, interface, self.grace)
            if not bound.spec.inline:
                self._threaded += 1
            for resource in claims:
                self._owners[resource] = execution
            self._running[execution.id] = execution
        if not bound.spec.inline:
            with self._watch_cv:
                heapq.heappush(self._watch, (execution.deadline, execution.id, execution))
                self._watch_cv.notify()
        return execution

    def _run(self, execution: Execution, handler: Callable[..., Any]) -> None:
        try:
            response = self._call(execution, handler)
        finally:
            execution._handler_returned = True
        # resources first, answer second: whoever sees the answer (a service reply, the final status event, a
        # procedure queue) may send the next command on the same resource at once and must not get BUSY
        self._release(execution)
        execution._finish(response)

    def _call(self, execution: Execution, handler: Callable[..., Any]) -> Response:
        """Run the handler; every way it can end becomes a response (a bug in it too)."""
        try:
            result = handler(CommandContext(execution), **execution.bound.values)  # ** makes the handler's copy
            if result is not None and not isinstance(result, dict):
                raise TypeError("handler returned %s, expected a dict or None" % type(result).__name__)
            result = dict(result or {})  # the handler's dict stays its own
            message = result.pop("message", None)
            return Response(Code.OK, message if isinstance(message, str) else "%s done" % execution.bound.name,
                            result)
        except LocemError as error:
            pending = execution._cancel_error
            if pending is not None and isinstance(error, (Aborted, CommandTimeout)):
                return Response.from_error(pending)  # the reason it was asked to stop
            return Response.from_error(error)
        except Exception as error:  # a bug in a handler: report it, keep serving
            _log.error("handler of %s raised:\n%s", execution.bound.name, traceback.format_exc())
            return Response.from_error(LocemError("%s failed inside LOCEM: %s: %s"
                                                  % (execution.bound.name, type(error).__name__, error)))

    def _remember(self, execution: Execution) -> None:
        with self._lock:
            self._recent[execution.id] = execution
            while len(self._recent) > KEEP_RECENT:
                self._recent.popitem(last=False)

    def _release(self, execution: Execution) -> None:
        with self._lock:
            for resource, owner in list(self._owners.items()):
                if owner is execution:
                    del self._owners[resource]
            if self._running.pop(execution.id, None) is not None and not execution.bound.spec.inline:
                self._threaded -= 1
            self._released.notify_all()

    def _watch_deadlines(self) -> None:
        while True:
            with self._watch_cv:
                while not self._closed and not self._watch:
                    self._watch_cv.wait()
                if self._closed:
                    return
                due, _, execution = self._watch[0]
                now = time.monotonic()
                if due > now:
                    self._watch_cv.wait(due - now)
                    continue
                heapq.heappop(self._watch)
            self._on_due(execution)

    def _on_due(self, execution: Execution) -> None:
        if execution._handler_returned:
            return
        now = time.monotonic()
        if execution.paused:  # re-armed on resume through the moved deadline
            self._rearm(execution, now + 0.05)
            return
        if execution.deadline > now:  # moved by a pause
            self._rearm(execution, execution.deadline)
            return
        if execution._cancel_error is None:
            execution._expire()
        if not execution.done and now >= execution.deadline + self.grace:
            error = execution._cancel_error or CommandTimeout("%s timed out" % execution.bound.name)
            if not isinstance(error, CommandTimeout):
                error = CommandTimeout("%s did not stop within %.3g s of being told to (%s)"
                                       % (execution.bound.name, self.grace, error.message))
            _log.error("%s (id %d) did not return after its deadline; its resources stay occupied",
                       execution.bound.name, execution.id)
            execution._finish(Response.from_error(error), stuck=True)
            return
        self._rearm(execution, max(now, execution.deadline) + self.grace)

    def _rearm(self, execution: Execution, due: float) -> None:
        with self._watch_cv:
            heapq.heappush(self._watch, (due, execution.id, execution))
            self._watch_cv.notify()

    def _rejection(self, text: object, interface: Interface, error: LocemError) -> CommandEvent:
        shown = text if isinstance(text, str) else repr(text)
        name = shown.split(None, 1)[0].upper() if shown.strip() else ""
        return CommandEvent(id=next(self._ids), command=shown[:200], name=name[:64], interface=interface.value,
                            state=ExecState.REJECTED, code=error.code.value, message=error.message)

    def _emit(self, event: CommandEvent) -> None:
        for listener in list(self._listeners):
            try:
                listener(event)
            except Exception:
                _log.exception("dispatcher listener failed")



def _span(ids: List[int]) -> str:
    if not ids:
        return "none"
    return "%d to %d" % (ids[0], ids[-1]) if len(ids) > 1 else str(ids[0])
