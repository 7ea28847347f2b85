"""The pieces of HICEM's skill control that are not the controller itself: the clock a suspended tree sees, and
which skill methods HICEM offers for its action in each state.

- :class:`PausableClock`: what a running tree's nodes read as ``NodeContext.clock``; it stands still while the
  action is suspended, so ``Timeout``, ``Sleep``, command and prompt deadlines do not run out meanwhile (the time
  suspended is not counted, as for LOCEM's pausable ``WAIT``).
- :func:`operator_methods`: the methods ``/hicem/{suspend,resume,halt,reset}`` and the operator page's Pause,
  Resume, Abort and Reset buttons accept in a skill state: those of OPC UA Part 10 ``ProgramStateMachineType``
  (:func:`locem_bridge.common.program_state.allowed_methods`) without ``Start`` (HICEM starts an action itself
  when PEMKRE names it) and without anything in ``Ready`` (no action is running then: nothing to suspend or halt).

ROS-free; :mod:`locem_bridge.hicem.controller` uses both, the ROS operator page :func:`operator_methods`.
"""
import threading
import time
from typing import Callable, List, Optional

from ..common.program_state import Method, ProgramState, allowed_methods


class PausableClock:
    """A monotonic clock (seconds) that stands still between :meth:`freeze` and :meth:`unfreeze`; thread-safe.

    Reads ``base()`` minus every time spent frozen: after a 10 s suspension a node that started a 5 s timeout
    1 s before it still has 4 s left.
    """

    def __init__(self, base: Callable[[], float] = time.monotonic) -> None:
        self._base = base
        self._offset = 0.0                      # time spent frozen so far
        self._frozen_at: Optional[float] = None  # base() when frozen, None while running
        self._lock = threading.Lock()

    def __call__(self) -> float:
        with self._lock:
            if self._frozen_at is not None:
                return self._frozen_at - self._offset
            return self._base() - self._offset

    @property
    def frozen(self) -> bool:
        return self._frozen_at is not None

    @property
    def frozen_s(self) -> float:
        """Time spent frozen so far (s), the current stretch included."""
        with self._lock:
            now = self._base() - self._frozen_at if self._frozen_at is not None else 0.0
            return self._offset + now

    def freeze(self) -> None:
        """Stop the clock (idempotent)."""
        with self._lock:
            if self._frozen_at is None:
                self._frozen_at = self._base()

    def unfreeze(self) -> None:
        """Let the clock run on from where it stood (idempotent)."""
        with self._lock:
            if self._frozen_at is not None:
                self._offset += self._base() - self._frozen_at
                self._frozen_at = None


def operator_methods(state: Optional[ProgramState]) -> List[Method]:
    """The skill methods HICEM accepts for its action in ``state`` (None: no action ran yet): Running -> Suspend,
    Halt; Suspended -> Resume, Halt; Halted -> Reset; Ready and None -> none."""
    if state is None or state == ProgramState.READY:
        return []
    return [m for m in allowed_methods(state) if m != Method.START]
