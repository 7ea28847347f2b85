"""Control and decorator nodes with BehaviorTree.CPP 4 semantics, built on py_trees.

py_trees' own composites differ from BT.CPP in details integrators rely on (py_trees' memory Sequence does
not reset on failure, its Parallel has policies instead of thresholds, its Retry/Repeat take one attempt per
tick), so the executive implements the BT.CPP rules here on py_trees' ``Composite``/``Decorator`` classes:

- ``Sequence``: children in order, resumes at the RUNNING child; a FAILURE halts all children and restarts
  from the first child next time. ``SequenceWithMemory``: like Sequence but keeps its place after a failure.
- ``Fallback``: children in order until one succeeds; resumes at the RUNNING child.
- ``ReactiveSequence`` / ``ReactiveFallback``: re-tick from the first child on every tick; when a child
  returns RUNNING every other running child is halted (so a failing guard halts the running action).
- ``Parallel`` (``success_count``, ``failure_count``; negative values count from the number of children, -1 =
  all): ticks every child that has not finished; SUCCESS when ``success_count`` children succeeded, FAILURE when
  ``failure_count`` failed or success became impossible; running children are halted when it finishes.
- ``Inverter``, ``ForceSuccess``, ``ForceFailure``: RUNNING passes through.
- ``RetryUntilSuccessful`` (``num_attempts``, -1 = forever) and ``Repeat`` (``num_cycles``, -1 = forever):
  re-tick the child within the same tick after a completed attempt (BT.CPP), except in the unbounded case
  where they return RUNNING between attempts so that a halt can always get in.
- ``Timeout`` (``msec``): FAILURE and the child halted once ``msec`` elapsed since the first tick (checked at
  every tick against the context clock).
- ``SubTree``: transparent wrapper around the subtree's root; its blackboard scope is set up by the loader.
- ``LoopList`` (HICEM addition, listed in the catalogue): for each element of ``queue`` writes it to
  ``value`` and runs the child; RUNNING between elements, FAILURE on a child failure, ``if_empty`` at the end.
- Leaves ``AlwaysSuccess``, ``AlwaysFailure``, ``SetBlackboard`` (``value`` → ``output_key``), ``Sleep``.

Halting (``stop(INVALID)``) always reaches every RUNNING descendant, whose ``terminate`` cancels its work.
"""
from typing import List, Optional

import py_trees
from py_trees.common import Status

from .node_base import Leaf, NodeContext, Ported
from .ports import ANY, INT, STRING, PortBinding, input_port, inout_port, output_port

_DONE = (Status.SUCCESS, Status.FAILURE)


def _halt(node: py_trees.behaviour.Behaviour) -> None:
    if node.status != Status.INVALID:
        node.stop(Status.INVALID)


class _Control(Ported, py_trees.composites.Composite):
    KIND = "Control"
    MIN_CHILDREN = 1
    MAX_CHILDREN = None

    def __init__(self, name: str, children: List[py_trees.behaviour.Behaviour], ports: PortBinding,
                 ctx: NodeContext) -> None:
        py_trees.composites.Composite.__init__(self, name, children)
        self.ports = ports
        self.ctx = ctx
        self._idx = 0

    def _halt_children(self, start: int = 0, except_index: Optional[int] = None) -> None:
        for i in range(start, len(self.children)):
            if i != except_index:
                _halt(self.children[i])

    def _finish(self, status: Status) -> None:
        self._halt_children()
        self._idx = 0
        self.stop(status)

    def stop(self, new_status: Status = Status.INVALID) -> None:
        if new_status == Status.INVALID:
            self._idx = 0
        py_trees.composites.Composite.stop(self, new_status)


class _InOrder(_Control):
    """Ticks children in order, resuming at the RUNNING child. The first child that ends with ``_STOP_ON`` ends
    the node with that status; when every child ends otherwise, the node ends with the other status.
    ``_RESET_ON_STOP`` false: after such a stop the next tick resumes at the child that stopped it."""

    _STOP_ON = Status.FAILURE
    _RESET_ON_STOP = True

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            if self._RESET_ON_STOP:
                self._idx = 0
            self.initialise()
        n = len(self.children)
        while self._idx < n:
            child = self.children[self._idx]
            self.current_child = child
            for node in child.tick():
                yield node
            s = child.status
            if s == Status.RUNNING:
                self.status = Status.RUNNING
                yield self
                return
            if s == self._STOP_ON:
                if self._RESET_ON_STOP:
                    self._finish(s)
                else:
                    self._halt_children(self._idx)
                    self.stop(s)
                yield self
                return
            self._idx += 1
        self._finish(Status.SUCCESS if self._STOP_ON == Status.FAILURE else Status.FAILURE)
        yield self

    def stop(self, new_status: Status = Status.INVALID) -> None:
        if new_status == Status.INVALID and not self._RESET_ON_STOP:
            py_trees.composites.Composite.stop(self, new_status)  # keeps its place, as BT.CPP does
            return
        _Control.stop(self, new_status)


class Sequence(_InOrder):
    DESCRIPTION = "Ticks children in order; resumes at the RUNNING child; a failure restarts it from the first."
    _STOP_ON = Status.FAILURE


class SequenceWithMemory(Sequence):
    DESCRIPTION = "Like Sequence, but after a failure the next tick resumes at the failed child."
    _RESET_ON_STOP = False


class Fallback(_InOrder):
    DESCRIPTION = "Ticks children in order until one succeeds; resumes at the RUNNING child."
    _STOP_ON = Status.SUCCESS


class _Reactive(_Control):
    _STOP_ON = Status.FAILURE  # the status that ends the node early

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            self.initialise()
        for i, child in enumerate(self.children):
            self.current_child = child
            for node in child.tick():
                yield node
            s = child.status
            if s == Status.RUNNING:
                self._halt_children(0, except_index=i)
                self.status = Status.RUNNING
                yield self
                return
            if s == self._STOP_ON:
                self._finish(s)
                yield self
                return
        self._finish(Status.SUCCESS if self._STOP_ON == Status.FAILURE else Status.FAILURE)
        yield self


class ReactiveSequence(_Reactive):
    DESCRIPTION = "Re-ticks all children from the first on every tick; a failing child halts the running one."
    _STOP_ON = Status.FAILURE


class ReactiveFallback(_Reactive):
    DESCRIPTION = "Re-ticks all children from the first on every tick until one succeeds."
    _STOP_ON = Status.SUCCESS


class Parallel(_Control):
    DESCRIPTION = ("Ticks all unfinished children every tick. SUCCESS when success_count children succeeded, "
                   "FAILURE when failure_count failed (negative counts: n+1+count, -1 = all).")
    MIN_CHILDREN = 1
    PORTS = (
        input_port("success_count", INT, "-1", "", "children that must succeed (-1 = all)"),
        input_port("failure_count", INT, "1", "", "children whose failure fails the node (-1 = all)"),
    )

    @classmethod
    def required_counts(cls, n: int, success: int, failure: int):
        s = success if success >= 0 else max(n + success + 1, 0)
        f = failure if failure >= 0 else max(n + failure + 1, 0)
        return s, f

    def tick(self):  # type: ignore[override]
        n = len(self.children)
        if self.status != Status.RUNNING:
            self.initialise()
        s_req, f_req = self.required_counts(n, self.ports.get("success_count"), self.ports.get("failure_count"))
        if s_req > n or f_req > n or s_req == 0 or f_req == 0:
            self.ctx.report_failure(self.name, "Parallel with %d children cannot use success_count=%s/"
                                    "failure_count=%s" % (n, s_req, f_req))
            self._finish(Status.FAILURE)
            yield self
            return
        for child in self.children:
            if child.status in _DONE:
                continue
            self.current_child = child
            for node in child.tick():
                yield node
        succ = sum(1 for c in self.children if c.status == Status.SUCCESS)
        fail = sum(1 for c in self.children if c.status == Status.FAILURE)
        if succ >= s_req:
            self._finish(Status.SUCCESS)
        elif fail >= f_req or (n - fail) < s_req:
            self._finish(Status.FAILURE)
        else:
            self.status = Status.RUNNING
        yield self


class _Decorator(Ported, py_trees.decorators.Decorator):
    KIND = "Decorator"
    MIN_CHILDREN = 1
    MAX_CHILDREN = 1

    def __init__(self, name: str, children: List[py_trees.behaviour.Behaviour], ports: PortBinding,
                 ctx: NodeContext) -> None:
        py_trees.decorators.Decorator.__init__(self, name, children[0])
        self.ports = ports
        self.ctx = ctx

    def update(self) -> Status:
        """Mirror the child (decorators that override tick() never call this)."""
        return self.decorated.status


class Inverter(_Decorator):
    DESCRIPTION = "SUCCESS becomes FAILURE and vice versa; RUNNING passes through."

    def update(self) -> Status:
        s = self.decorated.status
        if s == Status.SUCCESS:
            return Status.FAILURE
        if s == Status.FAILURE:
            return Status.SUCCESS
        return s


class ForceSuccess(_Decorator):
    DESCRIPTION = "Returns SUCCESS when the child finishes, whatever its result; RUNNING passes through."

    def update(self) -> Status:
        return Status.RUNNING if self.decorated.status == Status.RUNNING else Status.SUCCESS


class ForceFailure(_Decorator):
    DESCRIPTION = "Returns FAILURE when the child finishes, whatever its result; RUNNING passes through."

    def update(self) -> Status:
        return Status.RUNNING if self.decorated.status == Status.RUNNING else Status.FAILURE


class SubTree(_Decorator):
    DESCRIPTION = "Runs another BehaviorTree with its own blackboard scope (ports remap keys)."

    def update(self) -> Status:
        return self.decorated.status


class _LoopingDecorator(_Decorator):
    """Shared tick of RetryUntilSuccessful and Repeat (BT.CPP: loop inside the tick while bounded)."""
    _COUNT_PORT = ""
    _COUNTS_ON = Status.SUCCESS  # child status that counts one round and loops
    _ENDS_ON = Status.FAILURE    # child status that ends the node with that status

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            self._count = 0
            self.initialise()
        limit = self.ports.get(self._COUNT_PORT)
        while True:
            for node in self.decorated.tick():
                yield node
            s = self.decorated.status
            if s == Status.RUNNING:
                self.status = Status.RUNNING
                yield self
                return
            if s == self._ENDS_ON:
                self.stop(s)
                yield self
                return
            self._count += 1
            _halt(self.decorated)
            if limit >= 0 and self._count >= limit:
                self.stop(self._COUNTS_ON)
                yield self
                return
            if limit < 0:
                self.status = Status.RUNNING
                yield self
                return


def _count_ok(port: str):
    def check(cls, literals):  # type: ignore[no-untyped-def]
        v = literals.get(port)
        if v is not None and v != -1 and v < 1:
            return "port '%s' must be -1 (forever) or at least 1, got %d" % (port, v)
        return None
    return classmethod(check)


def _non_negative(port: str):
    def check(cls, literals):  # type: ignore[no-untyped-def]
        v = literals.get(port)
        if v is not None and v < 0:
            return "port '%s' must be >= 0 ms, got %d" % (port, v)
        return None
    return classmethod(check)


class RetryUntilSuccessful(_LoopingDecorator):
    DESCRIPTION = "Re-runs a failing child up to num_attempts times (-1 = forever); SUCCESS on its first success."
    PORTS = (input_port("num_attempts", INT, None, "", "attempts before giving up (-1 = forever)"),)
    _COUNT_PORT = "num_attempts"
    validate_literals = _count_ok("num_attempts")
    _COUNTS_ON = Status.FAILURE
    _ENDS_ON = Status.SUCCESS


class Repeat(_LoopingDecorator):
    DESCRIPTION = "Runs the child num_cycles times (-1 = forever) while it succeeds; FAILURE on its first failure."
    PORTS = (input_port("num_cycles", INT, None, "", "successful runs wanted (-1 = forever)"),)
    _COUNT_PORT = "num_cycles"
    validate_literals = _count_ok("num_cycles")
    _COUNTS_ON = Status.SUCCESS
    _ENDS_ON = Status.FAILURE


class Timeout(_Decorator):
    DESCRIPTION = "Halts the child and returns FAILURE once msec milliseconds passed since its first tick."
    PORTS = (input_port("msec", INT, None, "ms", "time limit for the child"),)
    validate_literals = _non_negative("msec")

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            self._t0 = self.ctx.clock()
            self.initialise()
        limit_s = self.ports.get("msec") / 1000.0
        if self.ctx.clock() - self._t0 >= limit_s:
            _halt(self.decorated)
            self.ctx.report_failure(self.name, "timed out after %d ms" % self.ports.get("msec"))
            self.stop(Status.FAILURE)
            yield self
            return
        for node in self.decorated.tick():
            yield node
        s = self.decorated.status
        if s == Status.RUNNING:
            self.status = Status.RUNNING
        else:
            self.stop(s)
        yield self


class LoopList(_Decorator):
    NODE_ID = "LoopList"
    DESCRIPTION = ("For each element of queue: writes it to value and runs the child (RUNNING between "
                   "elements); FAILURE on a child failure; if_empty when the queue is exhausted.")
    PORTS = (
        input_port("queue", ANY, None, "", "list of elements (e.g. raster sections)"),
        output_port("value", ANY, None, "", "the current element"),
        input_port("if_empty", STRING, "SUCCESS", "", "result when no element is left",
                   choices=("SUCCESS", "FAILURE")),
    )

    def tick(self):  # type: ignore[override]
        if self.status != Status.RUNNING:
            q = self.ports.get("queue")
            if not isinstance(q, (list, tuple)):
                self.ctx.report_failure(self.name, "queue is a %s, not a list" % type(q).__name__)
                self.stop(Status.FAILURE)
                yield self
                return
            self._queue = list(q)
            self._pos = 0
            self.initialise()
        if self.decorated.status != Status.RUNNING:
            if self._pos >= len(self._queue):
                self.stop(Status.SUCCESS if self.ports.get("if_empty") == "SUCCESS" else Status.FAILURE)
                yield self
                return
            self.ports.set("value", self._queue[self._pos])
            self._pos += 1
        for node in self.decorated.tick():
            yield node
        s = self.decorated.status
        if s == Status.FAILURE:
            self.stop(Status.FAILURE)
        else:
            if s == Status.SUCCESS:
                _halt(self.decorated)
            self.status = Status.RUNNING
        yield self


class AlwaysSuccess(Leaf):
    DESCRIPTION = "Returns SUCCESS."

    def on_tick(self) -> Status:
        return Status.SUCCESS


class AlwaysFailure(Leaf):
    DESCRIPTION = "Returns FAILURE."

    def on_tick(self) -> Status:
        return Status.FAILURE


class SetBlackboard(Leaf):
    DESCRIPTION = "Writes value into the blackboard entry named by output_key."
    PORTS = (
        input_port("value", ANY, None, "", "value to write ({key} copies another entry)"),
        inout_port("output_key", STRING, None, "", "entry to write: a key name or {key}"),
    )

    def on_tick(self) -> Status:
        key = self.ports.key("output_key") or self.get("output_key")
        self.ports.blackboard.set(key, self.get("value"))
        return Status.SUCCESS


class Sleep(Leaf):
    DESCRIPTION = "RUNNING for msec milliseconds, then SUCCESS."
    PORTS = (input_port("msec", INT, None, "ms", "duration"),)
    validate_literals = _non_negative("msec")

    def on_start(self) -> Optional[Status]:
        self._t_end = self.ctx.clock() + self.get("msec") / 1000.0
        return None

    def on_tick(self) -> Status:
        return Status.SUCCESS if self.ctx.clock() >= self._t_end else Status.RUNNING


BUILTIN_NODES = (Sequence, SequenceWithMemory, Fallback, ReactiveSequence, ReactiveFallback, Parallel,
                 Inverter, ForceSuccess, ForceFailure, RetryUntilSuccessful, Repeat, Timeout, SubTree,
                 AlwaysSuccess, AlwaysFailure, SetBlackboard, Sleep)
"""Nodes BT.CPP itself provides (Groot2 knows them; they are not listed in the HICEM catalogue)."""

EXTRA_CONTROL_NODES = (LoopList,)
"""Control/decorator nodes HICEM adds; listed in the catalogue."""
