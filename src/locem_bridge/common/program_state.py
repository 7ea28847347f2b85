"""The state machine of one running skill instance: OPC UA Part 10 ``ProgramStateMachineType``.

States and transitions (the numbers are the transition numbers of ``ontologies/skill.ttl``, where the same
machine is declared for PEMKRE; a test keeps the two equal)::

               Start (2)                Suspend (5)
      Ready ─────────────► Running ─────────────────► Suspended
        ▲  ▲◄───────────── │  ▲ ◄───────────────────── │  │
        │  │ completes (4) │  │       Resume (6)       │  │ ends while suspended (8)
        │  └───────────────┼──┼────────────────────────┼──┘
        │                  ▼  │                        │
        │ Reset (1)     Halted ◄───────────────────────┘ Halt (7)
        └──────────────  ▲  ▲   Halt or a failure (3)
                         └──┴── Halt (9, from Ready)

* The methods a caller may use: ``Start``, ``Suspend``, ``Resume``, ``Halt``, ``Reset``. A method the current state
  does not allow is refused with :class:`TransitionRefused`, which names the state and the methods it allows,
  and changes nothing.
* The program takes transitions 3 (a failure), 4 and 8 by itself (:meth:`ProgramStateMachine.complete`,
  :meth:`ProgramStateMachine.fail`).
* Every transition reaches the listeners as a :class:`Transition` with its cause (who asked, or why).

ROS-free; used by LOCEM (one machine per command: a basic skill) and HICEM (one per action: a composite skill).
"""
import threading
import time
from dataclasses import dataclass, field
from enum import Enum
from typing import Callable, Dict, List, Optional, Tuple


class ProgramState(str, Enum):
    READY = "Ready"
    RUNNING = "Running"
    SUSPENDED = "Suspended"
    HALTED = "Halted"

    def __str__(self) -> str:
        return self.value


class Method(str, Enum):
    START = "Start"
    SUSPEND = "Suspend"
    RESUME = "Resume"
    HALT = "Halt"
    RESET = "Reset"

    def __str__(self) -> str:
        return self.value

    @classmethod
    def parse(cls, text: str) -> "Method":
        """``suspend``, ``Suspend`` or ``SUSPEND``; ValueError naming the allowed methods otherwise."""
        for m in cls:
            if str(text).strip().lower() == m.value.lower():
                return m
        raise ValueError("unknown skill method %r; allowed: %s" % (text, ", ".join(m.value for m in cls)))


@dataclass(frozen=True)
class TransitionType:
    number: int
    name: str
    source: ProgramState
    target: ProgramState
    method: Optional[Method]        # None: taken by the program itself


_R, _U, _S, _H = ProgramState.READY, ProgramState.RUNNING, ProgramState.SUSPENDED, ProgramState.HALTED
TRANSITIONS: Tuple[TransitionType, ...] = (
    TransitionType(1, "HaltedToReady", _H, _R, Method.RESET),
    TransitionType(2, "ReadyToRunning", _R, _U, Method.START),
    TransitionType(3, "RunningToHalted", _U, _H, Method.HALT),
    TransitionType(4, "RunningToReady", _U, _R, None),
    TransitionType(5, "RunningToSuspended", _U, _S, Method.SUSPEND),
    TransitionType(6, "SuspendedToRunning", _S, _U, Method.RESUME),
    TransitionType(7, "SuspendedToHalted", _S, _H, Method.HALT),
    TransitionType(8, "SuspendedToReady", _S, _R, None),
    TransitionType(9, "ReadyToHalted", _R, _H, Method.HALT),
)
"""Every transition of ProgramStateMachineType; 3 is also taken without a call when the skill fails."""

_BY_METHOD: Dict[Tuple[ProgramState, Method], TransitionType] = {
    (t.source, t.method): t for t in TRANSITIONS if t.method is not None}
_BY_STATES: Dict[Tuple[ProgramState, ProgramState], TransitionType] = {(t.source, t.target): t for t in TRANSITIONS}


def transition_between(source: ProgramState, target: ProgramState) -> TransitionType:
    """The transition from ``source`` to ``target`` (KeyError when the machine has none)."""
    return _BY_STATES[(source, target)]


def allowed_methods(state: ProgramState) -> List[Method]:
    """The methods a caller may use in ``state``, in the order of :class:`Method`."""
    return [m for m in Method if (state, m) in _BY_METHOD]


class TransitionRefused(Exception):
    """A method the state does not allow; nothing changed."""

    def __init__(self, what: str, state: ProgramState, method: Method) -> None:
        allowed = allowed_methods(state)
        super().__init__("%s is not allowed: %s is %s (allowed in %s: %s)"
                         % (method.value, what, state.value, state.value,
                            ", ".join(m.value for m in allowed) or "none"))
        self.state = state
        self.method = method
        self.allowed = allowed


@dataclass(frozen=True)
class Transition:
    """One transition of one skill instance, as published (``/locem/skill_state``, ``/hicem/skill_state``)."""

    instance: str                   # the instance: a LOCEM command id, a HICEM task
    skill: str                      # the skill: a command name, a composite skill / action type
    number: int                     # the transition number (1..9)
    name: str                       # e.g. RunningToSuspended
    source: ProgramState
    target: ProgramState
    method: str                     # the method that caused it, '' when the program took it by itself
    cause: str                      # who asked or what happened
    stamp: float = field(default_factory=time.time)



TransitionListener = Callable[[Transition], None]


class ProgramStateMachine:
    """The state of one skill instance; thread-safe. Listeners are called outside the lock, in order."""

    def __init__(self, instance: str, skill: str, state: ProgramState = ProgramState.READY,
                 listener: Optional[TransitionListener] = None) -> None:
        self.instance = instance
        self.skill = skill
        self._state = state
        self._lock = threading.Lock()
        self._listeners: List[TransitionListener] = [listener] if listener is not None else []

    @property
    def state(self) -> ProgramState:
        return self._state

    def allowed(self) -> List[Method]:
        return allowed_methods(self._state)

    def add_listener(self, listener: TransitionListener) -> None:
        self._listeners.append(listener)

    def describe(self) -> str:
        return "%s %s" % (self.skill, self.instance) if self.skill else str(self.instance)

    def check(self, method: Method) -> TransitionType:
        """The transition ``method`` would take now; :class:`TransitionRefused` if none (nothing changes)."""
        t = _BY_METHOD.get((self._state, method))
        if t is None:
            raise TransitionRefused(self.describe(), self._state, method)
        return t

    def call(self, method: Method, cause: str = "") -> Transition:
        """Take the transition of ``method``; :class:`TransitionRefused` (nothing changes) if not allowed."""
        with self._lock:
            t = _BY_METHOD.get((self._state, method))
            if t is None:
                raise TransitionRefused(self.describe(), self._state, method)
            self._state = t.target
        return self._tell(t, method.value, cause)

    def complete(self, cause: str = "completed") -> Optional[Transition]:
        """The skill ended well (Running/Suspended -> Ready); None when it was not running."""
        return self._internal(ProgramState.READY, cause)

    def fail(self, cause: str) -> Optional[Transition]:
        """The skill failed (-> Halted, transition 3 or 7 without a call); None when it was not running."""
        return self._internal(ProgramState.HALTED, cause)

    def _internal(self, target: ProgramState, cause: str) -> Optional[Transition]:
        with self._lock:
            if self._state not in (ProgramState.RUNNING, ProgramState.SUSPENDED):
                return None
            t = transition_between(self._state, target)
            self._state = target
        return self._tell(t, "", cause)

    def _tell(self, t: TransitionType, method: str, cause: str) -> Transition:
        tr = Transition(str(self.instance), self.skill, t.number, t.name, t.source, t.target, method, cause)
        for listener in list(self._listeners):
            try:
                listener(tr)
            except Exception:  # a broken observer must not change the skill's course
                import logging
                logging.getLogger(__name__).exception("transition listener failed")
        return tr
