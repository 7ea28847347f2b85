"""Suspend and resume inside a device command: the device semantics of the skill methods Suspend and Resume.

A command whose declaration is ``pausable`` runs its device work through :class:`Resumable`:

1. **Suspend** (``SUSPEND id=N``, a procedure's ``suspend``, HICEM suspending its action): the command's
   ``stop`` runs at once in the caller's thread, process outputs first (the spray valve closes, the taping tool
   and the sander switch off), then the motions decelerate (the arm ``stopL`` / ``stopJ`` along its path, the base
   brakes to zero velocity at its drives' deceleration, the lift halts). It is not a protective stop: the arm stays
   in normal mode. The device call under way in the handler's thread returns by :class:`SuspendRequest`.
2. ``on_suspended`` brings the devices to their suspended state (e.g. the sander lifts off the wall) and
   ``settle`` waits until they are at rest. The compressor keeps its pressure.
3. The handler waits (:meth:`~locem_bridge.locem.execution.CommandContext.wait_resumed`); pause time does not
   count against the command's deadline. A Halt, cancel or STOP while suspended ends it as usual.
4. **Resume**: ``attempt`` runs again. Every attempt goes on from where the devices are: a move to a target
   re-issued from the stop point follows the rest of the same straight or joint-space line; a step list
   (:class:`Steps`) restarts at the step that was interrupted; a raster restarts at the point its tool switched
   off (``skip=``), with its own run-up, so there is no gap and no second coat.

Scripts and benchmarks that run handlers with a plain waiter (no suspension) just run ``attempt`` once.
"""
import logging
import time
from typing import Any, Callable, List, Optional, TypeVar

from ..locem.errors import SuspendRequest

log = logging.getLogger(__name__)
T = TypeVar("T")

#: how long ``settle`` may wait for the devices to come to rest after a suspension (s, wall time)
SETTLE_TIMEOUT_S = 3.0


class Resumable:
    """Runs one command's device work so that it can be suspended and resumed (module doc).

    ``stop``: the immediate device stop (outputs off first, then motions), run in the suspending caller's
    thread; ``on_suspended(waiter)``: device moves into the suspended state (a waiter that is not blocked by the
    suspension); ``settle(waiter)``: wait until the devices are at rest."""

    def __init__(self, ctx: Any, stop: Callable[[], None],
                 on_suspended: Optional[Callable[[Any], None]] = None,
                 settle: Optional[Callable[[Any], None]] = None) -> None:
        self.ctx = ctx
        self._stop = stop
        self._on_suspended = on_suspended
        self._settle = settle
        self.suspensions = 0
        self.supported = all(hasattr(ctx, a) for a in ("unwinding", "wait_resumed", "on_pause", "suspended"))
        if self.supported:
            ctx.on_pause(self._stop_now, _nothing)

    def _stop_now(self) -> None:
        try:
            self._stop()
        except Exception:
            log.exception("device stop on suspend failed")

    def run(self, attempt: Callable[[], T]) -> T:
        if not self.supported:
            return attempt()
        ctx = self.ctx
        while True:
            try:
                with ctx.unwinding():
                    return attempt()
            except BaseException as exc:
                if not ctx.suspended:           # a real end: halt, cancel, STOP, a fault
                    if isinstance(exc, SuspendRequest):   # resumed and halted in one breath: end as asked
                        ctx.check()
                    raise
                log.info("%s: suspended (%s)", getattr(ctx, "id", "?"), type(exc).__name__)
            self.suspensions += 1
            quiet = ctx.ignoring_suspension()
            if self._settle is not None:
                self._settle(quiet)
            if self._on_suspended is not None:
                self._on_suspended(quiet)
            ctx.wait_resumed()


class Steps:
    """A command's device work as a list of steps, each re-runnable from wherever the devices stopped (a move
    to a target, a switch). :meth:`run` is the ``attempt`` of :class:`Resumable`: after a suspension it goes on
    with the step that was interrupted. ``current`` names it (e.g. for a tool that must be on again)."""

    def __init__(self, steps: List[Callable[[], Any]]) -> None:
        self._steps = steps
        self.index = 0
        self.result: Any = None

    def run(self) -> Any:
        while self.index < len(self._steps):
            self.result = self._steps[self.index]()
            self.index += 1
        return self.result


def _nothing() -> None:
    pass


def wait_until(waiter: Any, condition: Callable[[], bool], timeout: float = SETTLE_TIMEOUT_S,
               period: float = 0.01) -> bool:
    """Poll ``condition`` through ``waiter`` until it holds (True) or ``timeout`` s pass (False)."""
    end = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > end:
            return False
        waiter.sleep(period)
    return True


# -- per device: the immediate stop and "at rest" ------------------------------------------------------------
REST_JOINT_SPEED = 1e-3      # rad/s: an arm is at rest below this on every joint
REST_BASE_SPEED = 1e-3       # m/s and rad/s: a base is at rest below this
REST_LIFT_STEP = 2e-4        # m: a lift is at rest when its height changes less than this in REST_LIFT_DT
REST_LIFT_DT = 0.03          # s


def arm_at_rest(arm: Any) -> bool:
    qd = arm.cached_state().get("qd") or [0.0]
    return max(abs(float(v)) for v in qd) < REST_JOINT_SPEED


def arm_settle(arm: Any) -> Callable[[Any], None]:
    return lambda waiter: wait_until(waiter, lambda: arm_at_rest(arm))


def base_settle(base: Any) -> Callable[[Any], None]:
    return lambda waiter: wait_until(waiter, lambda: max(abs(float(v)) for v in base.twist()) < REST_BASE_SPEED)


def lift_settle(lift: Any) -> Callable[[Any], None]:
    def settle(waiter: Any) -> None:
        last = [lift.height()]

        def still() -> bool:
            h = lift.height()
            moved, last[0] = abs(h - last[0]), h
            return moved < REST_LIFT_STEP
        wait_until(waiter, still, period=REST_LIFT_DT)
    return settle
