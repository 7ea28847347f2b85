"""HHLC (the paper's HICEM High Level Controller): the high-level controller loop of HICEM (ROS-free core;
``ros/hicem_node`` adapts it).

Lifecycle of one process (:meth:`HighLevelController.start_process`, worker thread, or :meth:`run_process`,
blocking): PEMKRE ``start_process`` → loop { ``next_action`` → pick the tree (:func:`tree_for`: the matched
composite skill's tree, :data:`BASIC_SKILL_TREE` for a basic skill, else the tree whose BehaviorTree ID is the
action type) → HDICT record ``phase=running`` → ``set_task_status(in_progress)`` → tick the tree every ``hhlc.tick_period_s`` until SUCCESS/FAILURE → ``phase=finished`` (outcome stored) →
``set_task_status(succeeded|failed, detail)`` → ``phase=reported`` } until PEMKRE answers ``ended``/``failed``.

- The tree gets a fresh blackboard: ``cfg.*`` (HICEM parameters), ``robot.*`` (robot facts), ``param_<name>``
  (PEMKRE parameters), ``task``, ``action_type``, ``skill`` and ``skill_kind`` (the matched skill; empty when
  PEMKRE names none). ``task_detail`` written by the tree becomes the status detail; on failure the detail is the
  reason recorded by the failing node.
- :meth:`stop`: the running tree is halted (its LOCEM commands are cancelled, its prompts withdrawn), the
  safe commands (``locem.safe_commands``) are sent, the task is reported failed ``stopped: <reason>``, the
  process state becomes ``stopped``. A crucial-module fault from the HEM halts the tree the same way at once
  (reported failed with the fault), then the loop waits for health to return before asking PEMKRE again.
- An action type without a tree, a malformed PEMKRE answer or an exception from PEMKRE ends the process as
  ``failed`` with the reason (PEMKRE told when possible); nothing is left running. PEMKRE being away
  (:class:`PemkreUnavailableError`: restarting, not running) is not the process's failure: the call is repeated
  (phase ``waiting_for_pemkre``) until PEMKRE answers, a stop arrives or ``pemkre_wait_s`` has passed.
- :meth:`resume`: after a crash the HDICT says which process and action were interrupted. A finished but
  unreported outcome is reported; a running action is halted on the devices (safe commands) and then handled
  by ``hhlc.resume_policy``: ``rerun`` its tree, ``fail`` it ("interrupted ..."), or run a recovery tree (e.g.
  RESUME_TAPE_LINE: the operator finishes the joint by hand). Completed tasks are never run again (a task
  already reported is re-reported from the HDICT, not executed).
- :meth:`state` / state listeners: process, action type, task, skill, tree, running node, phase, and the
  action's skill state (``skill_state``, ``allowed``: the skill methods accepted now, ``skill_detail``: the cause
  of the last transition).

Skill state (issue 18; OPC UA Part 10 ``ProgramStateMachineType``, :mod:`locem_bridge.common.program_state`): the
running action is a composite skill instance with one state machine (instance = the task IRI, skill = the matched
skill or else the action type). Start when its tree starts; the tree's SUCCESS takes Running -> Ready, its failure
(and a stop, a health fault) Running -> Halted. Transitions go to :meth:`add_transition_listener` listeners (the
ROS node's ``/hicem/skill_state``). The methods, from any thread (:meth:`suspend_action`, :meth:`resume_action`,
:meth:`halt_action`, :meth:`reset_action`, or :meth:`skill_method`), return the new state or raise
:class:`SkillMethodRefused` (nothing changed) with the state machine's text, or saying that no action runs:

- Suspend: the worker stops ticking the tree (tree and blackboard stay as they are), every outstanding LOCEM
  command is suspended on its devices (``CommandHandle.suspend``), the clock the tree's nodes see stands still
  (:class:`PausableClock`: Timeout, Sleep, command and prompt deadlines do not run out) and the HDICT's
  ``hhlc/action`` record gets ``phase: suspended``, ``suspended_at`` (wall-clock s) and ``suspend_cause``. A
  command LOCEM cannot suspend (not pausable, e.g. a tool change under way) runs to its end: the action stays
  Running with phase ``suspending`` (only Halt accepted; nothing new is sent, the tree is not ticked) and becomes
  Suspended when that command ends, the transition's cause saying so. Nothing is lost: the command's reply is
  read by its node after Resume.
- Resume: the suspended commands continue (a command LOCEM will not resume is cancelled: its node fails the
  action), the clock runs on, the HDICT record is ``running`` again and the tree is ticked from where it stood.
- Halt: the tree is halted like for a stop (its commands cancelled), the task is reported failed
  ``halted: <cause>`` and the process goes on with PEMKRE's next action as after any failure.
- Reset: the last Halted action instance back to Ready (bookkeeping: the next action has an instance of its
  own).
- A HICEM crash while suspended: :meth:`resume` finds ``phase: suspended`` and comes back Suspended (one
  RunningToSuspended transition whose cause says it was restored after a restart), with no device command sent.
  Resume then settles the action as after any restart (safe commands, then ``hhlc.resume_policy``); Halt sends
  the safe commands and reports the task failed ``halted: <cause>``; a stop reports it failed ``stopped: ...``.

Threads: one worker runs the loop and ticks trees; stop/abort/operator replies come from other threads and
only set flags or touch the thread-safe OperatorDesk. The skill methods take the controller's skill lock, which
the worker holds around each tick, so they never meet a tick half done.
"""
import functools
import logging
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple, Union

from py_trees.common import Status

from ..common.next_action import ACTION, BASIC, COMPOSITE
from ..common.program_state import Method, ProgramState, ProgramStateMachine, Transition, TransitionRefused
from ..common.task_status import FAILED, IN_PROGRESS, SUCCEEDED
from .blackboard import Blackboard
from .config import HicemParams
from .datastore import DataManager
from .errors import ControllerError, HicemError, LocemCallError, PemkreCallError, SkillMethodRefused
from .interfaces import CommandHandle, LocemReply, NextAction, PemkreUnavailableError, check_reply, parse_next_action
from .node_base import NodeContext
from .operator import OperatorDesk
from .skill_control import PausableClock, operator_methods
from .xml_loader import BuiltTree, TreeLibrary

LOG = logging.getLogger("locem_bridge.hicem.controller")
HHLC = "hhlc"
TASKS = "tasks"
BASIC_SKILL_TREE = "BASIC_SKILL"
"""The shipped generic tree (trees/BASIC_SKILL.xml) that runs a basic skill: one LOCEM command."""


def tree_for(na: NextAction) -> str:
    """The tree that realizes a next action: the composite skill's tree, the generic basic-skill tree, or (no
    skill named: an older PEMKRE, no resource model) the tree of the action type."""
    if na.skill_kind == COMPOSITE:
        return na.skill
    if na.skill_kind == BASIC:
        return BASIC_SKILL_TREE
    return na.action_type


def _what(na: NextAction) -> str:
    """How a missing tree is named: the skill when PEMKRE matched one, else the action type."""
    if na.skill_kind:
        return "%s skill '%s' (action type %s)" % (na.skill_kind, na.skill, na.action_type)
    return "action type '%s'" % na.action_type


class ActionStats:
    """Timing of one high-level action: wall time and the parts spent in PEMKRE calls and idle waits."""

    def __init__(self, action_type: str) -> None:
        self.action_type = action_type
        self.wall_s = 0.0
        self.pemkre_s = 0.0
        self.wait_s = 0.0
        self.locem_s = 0.0
        self.ticks = 0

    @property
    def overhead_s(self) -> float:
        """HICEM's own time: everything except PEMKRE calls, LOCEM calls and waiting between ticks."""
        return self.wall_s - self.pemkre_s - self.wait_s - self.locem_s


class _TimedLocem:
    """Wraps the LOCEM client to account time spent inside it (send/poll) for the overhead figure."""

    def __init__(self, inner: Any, stats_ref: Callable[[], Optional[ActionStats]]) -> None:
        self.inner = inner
        self._stats = stats_ref

    def send(self, command: str) -> Any:
        t = time.perf_counter()
        try:
            return _TimedHandle(self.inner.send(command), self._stats)
        finally:
            s = self._stats()
            if s is not None:
                s.locem_s += time.perf_counter() - t


class _TimedHandle(CommandHandle):
    """A LOCEM command handle that adds the time spent in its calls to the running action's statistics."""

    def __init__(self, inner: CommandHandle, stats_ref: Callable[[], Optional[ActionStats]]) -> None:
        self.inner = inner
        self.command = inner.command
        self._stats = stats_ref

    def _timed(self, fn: Callable[[], Any]) -> Any:
        t = time.perf_counter()
        try:
            return fn()
        finally:
            s = self._stats()
            if s is not None:
                s.locem_s += time.perf_counter() - t

    def done(self) -> bool:
        return self._timed(self.inner.done)

    def reply(self) -> Optional[LocemReply]:
        return self._timed(self.inner.reply)

    def cancel(self) -> None:
        self._timed(self.inner.cancel)

    def feedback(self) -> Optional[str]:
        """The inner handle's latest progress feedback (trees record it, e.g. SPRAY_AREA's section progress)."""
        return self.inner.feedback()

    def suspend(self, cause: str = "") -> None:
        self._timed(lambda: self.inner.suspend(cause))

    def resume(self, cause: str = "") -> None:
        self._timed(lambda: self.inner.resume(cause))


def _command_name(h: Any) -> str:
    words = str(getattr(h, "command", "") or "").split()
    return words[0].upper() if words else "a command"


def _cause(cause: Any, default: str) -> str:
    text = " ".join(str(cause or "").split())
    return text or default


class _ActionSkill:
    """The skill side of the running action: its state machine, its tree's context and clock (None for an action
    restored Suspended after a restart: no tree yet), the commands suspended on the devices, a suspension waiting
    for commands that cannot be suspended (``pending``: cause, their handles, their names) and a requested Halt."""

    def __init__(self, machine: ProgramStateMachine, na: NextAction, ctx: Optional[NodeContext] = None,
                 clock: Optional[PausableClock] = None) -> None:
        self.machine = machine
        self.na = na
        self.ctx = ctx
        self.clock = clock
        self.suspended: List[Any] = []
        self.pending: Optional[Tuple[str, List[Any], str]] = None
        self.halt_cause: Optional[str] = None


class HighLevelController:
    def __init__(self, pemkre: Any, locem: Any, library: TreeLibrary, store: DataManager, params: HicemParams,
                 health: Any = None, operator: Optional[OperatorDesk] = None, data_handler: Any = None,
                 clock: Callable[[], float] = time.monotonic, log: Optional[logging.Logger] = None) -> None:
        self.pemkre = pemkre
        self.locem = locem
        self.library = library
        self.store = store
        self.params = params
        self.health = health
        self.operator = operator or OperatorDesk()
        self.data_handler = data_handler
        self.clock = clock
        self.log = log or LOG
        #: how long a PEMKRE call waits for an away PEMKRE (s) before the process fails with it
        self.pemkre_wait_s = 600.0
        self._wake = threading.Event()
        self._lock = threading.Lock()
        self._stop_reason: Optional[str] = None
        self._abort_reason: Optional[str] = None
        self._thread: Optional[threading.Thread] = None
        self._listeners: List[Callable[[Dict[str, Any]], None]] = []
        self._state: Dict[str, Any] = {"process": "", "specific_process": "", "action_type": "", "task": "",
                                       "skill": "", "tree": "", "node": "", "path": "", "phase": "idle", "detail": "",
                                       "skill_state": "", "allowed": [], "skill_detail": ""}
        # skill state of the running action (see the module doc); the worker holds the lock around each tick
        self._skill_lock = threading.RLock()
        self._action: Optional[_ActionSkill] = None
        self._last_machine: Optional[ProgramStateMachine] = None
        self._last_halted: Optional[ProgramStateMachine] = None
        self._skill_detail = ""
        self._transition_listeners: List[Callable[[Transition], None]] = []
        self._tree: Optional[BuiltTree] = None
        self._current_stats: Optional[ActionStats] = None
        self.stats: List[ActionStats] = []
        self._timed_locem = _TimedLocem(locem, lambda: self._current_stats) if locem is not None else None
        if health is not None:
            health.add_fault_listener(self._on_fault)

    # -- observation ----------------------------------------------------------------------------------------
    def add_state_listener(self, cb: Callable[[Dict[str, Any]], None]) -> None:
        self._listeners.append(cb)

    def state(self) -> Dict[str, Any]:
        with self._lock:
            return dict(self._state)

    def _set_state(self, **kw: Any) -> None:
        with self._lock:
            changed = any(self._state.get(k) != v for k, v in kw.items())
            self._state.update(kw)
            snap = dict(self._state)
        if changed:
            for cb in list(self._listeners):
                try:
                    cb(snap)
                except Exception:  # a broken listener must not stop the robot's executive
                    self.log.exception("state listener failed")

    @property
    def running(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    def add_transition_listener(self, cb: Callable[[Transition], None]) -> None:
        """``cb(transition)`` on every transition of an action's skill state (called in the thread that caused it,
        with the skill lock held: return quickly, do not call the skill methods from it)."""
        self._transition_listeners.append(cb)

    def skill_state(self) -> Tuple[str, List[str]]:
        """The skill state of the running action (else of the last one; "" before any) and the methods accepted."""
        with self._skill_lock:
            return self._skill_state_name(), [m.value for m in self._allowed()]

    def _skill_state_name(self) -> str:
        m = self._action.machine if self._action is not None else self._last_machine
        return m.state.value if m is not None else ""

    def _allowed(self) -> List[Method]:
        act = self._action
        if act is not None:
            if act.pending is not None:
                return [Method.HALT]
            return operator_methods(act.machine.state)
        m = self._last_halted
        return [Method.RESET] if m is not None and m.state == ProgramState.HALTED else []

    def _publish_skill(self) -> None:
        with self._skill_lock:
            st, allowed, detail = self._skill_state_name(), [m.value for m in self._allowed()], self._skill_detail
        self._set_state(skill_state=st, allowed=allowed, skill_detail=detail)

    def _new_machine(self, na: NextAction, state: ProgramState = ProgramState.READY) -> ProgramStateMachine:
        m = ProgramStateMachine(na.task, na.skill or na.action_type, state)
        m.add_listener(functools.partial(self._on_transition, m))
        return m

    def _on_transition(self, machine: ProgramStateMachine, tr: Transition) -> None:
        if tr.target == ProgramState.HALTED:
            self._last_halted = machine
        elif self._last_halted is machine:
            self._last_halted = None
        self._skill_detail = tr.cause
        self.log.info("skill %s %s: %s -> %s (%s%s)", tr.skill, tr.instance, tr.source.value, tr.target.value,
                      "%s: " % tr.method if tr.method else "", tr.cause)
        for cb in list(self._transition_listeners):
            try:
                cb(tr)
            except Exception:  # a broken observer must not change the action's course
                self.log.exception("transition listener failed")
        self._publish_skill()

    # -- skill methods (any thread) -------------------------------------------------------------------------
    def skill_method(self, method: Union[Method, str], cause: str = "") -> ProgramState:
        """Suspend, Resume, Halt or Reset (a :class:`Method` or its name in any case); see the methods."""
        try:
            m = method if isinstance(method, Method) else Method.parse(method)
        except ValueError as exc:
            raise SkillMethodRefused(str(exc), str(method), *self.skill_state())
        if m == Method.START:
            st, allowed = self.skill_state()
            raise SkillMethodRefused("Start is not a method of HICEM's action: HICEM starts each action PEMKRE names "
                                     "(start a process with start_process); allowed now: %s"
                                     % (", ".join(allowed) or "none"), m.value, st, allowed)
        return {Method.SUSPEND: self.suspend_action, Method.RESUME: self.resume_action,
                Method.HALT: self.halt_action, Method.RESET: self.reset_action}[m](cause)

    def suspend_action(self, cause: str = "") -> ProgramState:
        """Suspend the running action (see the module doc). Returns Suspended, or Running while a command that
        cannot be suspended ends (the action becomes Suspended then, by itself); asked again meanwhile, the same."""
        cause = _cause(cause, "suspend requested")
        with self._skill_lock:
            act = self._running_action(Method.SUSPEND)
            if act.pending is not None:
                return act.machine.state
            self._check(act, Method.SUSPEND)
            if act.ctx is None or act.clock is None:      # cannot happen: a restored action comes back Suspended
                raise self._refused(Method.SUSPEND, "Suspend is not allowed: the action has no tree yet")
            self._record_action(Method.SUSPEND, phase="suspended", suspended_at=time.time(), suspend_cause=cause)
            act.clock.freeze()
            waiting: List[Any] = []
            for h in act.ctx.outstanding():
                if h.done():
                    continue
                try:
                    h.suspend(cause)
                    act.suspended.append(h)
                except Exception as exc:  # LocemCallError: LOCEM refused (not pausable, ended meanwhile)
                    if not h.done():
                        waiting.append(h)
                        self.log.warning("suspend: %s cannot be suspended (%s); it runs to its end", h.command, exc)
            if waiting:
                names = ", ".join(sorted({_command_name(h) for h in waiting}))
                act.pending = (cause, waiting, names)
                self._skill_detail = ("%s: suspension pending, %s cannot be suspended; the action is Suspended when "
                                      "it ends" % (cause, names))
                self._set_state(phase="suspending")
                self._publish_skill()
                return act.machine.state
            self._enter_suspended(act, cause)
            return ProgramState.SUSPENDED

    def resume_action(self, cause: str = "") -> ProgramState:
        """Resume the suspended action: its commands continue on the devices, the tree is ticked from where it
        stood (for an action restored Suspended after a restart: the resume policy runs, see the module doc)."""
        cause = _cause(cause, "resume requested")
        with self._skill_lock:
            act = self._running_action(Method.RESUME)
            if act.pending is not None:
                raise self._refused(Method.RESUME, "Resume is not allowed: %s is still Running, its suspension waits "
                                    "for %s, which cannot be suspended, to end (allowed: Halt)"
                                    % (act.machine.describe(), act.pending[2]))
            self._check(act, Method.RESUME)
            self._record_action(Method.RESUME, phase="running", drop=("suspended_at", "suspend_cause"))
            problems: List[str] = []
            for h in act.suspended:
                if h.done():
                    continue
                try:
                    h.resume(cause)
                except Exception as exc:  # LOCEM lost it or refuses: cancel, its node fails the action with it
                    problems.append("%s could not be resumed (%s) and was cancelled" % (_command_name(h), exc))
                    self.log.warning("resume: %s could not be resumed (%s); cancelling it", h.command, exc)
                    try:
                        h.cancel()
                    except Exception:
                        self.log.exception("cancel failed")
            act.suspended = []
            if act.clock is not None:
                act.clock.unfreeze()
            act.machine.call(Method.RESUME, "; ".join([cause] + problems))
            self._set_state(phase="running" if act.ctx is not None else "resuming")
        self._wake.set()
        return ProgramState.RUNNING

    def halt_action(self, cause: str = "") -> ProgramState:
        """Halt the running or suspended action: the worker halts its tree (commands cancelled) and reports the task
        failed ``halted: <cause>``; the process goes on with PEMKRE's next action."""
        cause = _cause(cause, "halt requested")
        with self._skill_lock:
            act = self._running_action(Method.HALT)
            self._check(act, Method.HALT)
            act.halt_cause = cause
            act.machine.call(Method.HALT, cause)
        self._wake.set()
        return ProgramState.HALTED

    def reset_action(self, cause: str = "") -> ProgramState:
        """Reset the last Halted action instance to Ready (refused while an action runs)."""
        cause = _cause(cause, "reset requested")
        with self._skill_lock:
            act = self._action
            if act is not None:
                if act.machine.state == ProgramState.HALTED:
                    raise self._refused(Method.RESET, "Reset is not allowed: %s is still being halted; try again"
                                        % act.machine.describe())
                self._check(act, Method.RESET)
            m = self._last_halted
            if m is None or m.state != ProgramState.HALTED:
                raise self._refused(Method.RESET, "Reset is not allowed: no HICEM action is Halted%s"
                                    % self._last_text())
            m.call(Method.RESET, cause)
        return ProgramState.READY

    def _running_action(self, method: Method) -> _ActionSkill:
        act = self._action
        if act is None:
            raise self._refused(method, "%s is not allowed: no HICEM action is running%s" % (method.value,
                                                                                           self._last_text()))
        return act

    def _last_text(self) -> str:
        m = self._last_machine
        allowed = ", ".join(x.value for x in self._allowed()) or "none"
        if m is None:
            return " (allowed now: %s)" % allowed
        return " (the last, %s, is %s; allowed now: %s)" % (m.describe(), m.state.value, allowed)

    def _refused(self, method: Method, text: str) -> SkillMethodRefused:
        return SkillMethodRefused(text, method.value, self._skill_state_name(), [m.value for m in self._allowed()])

    def _check(self, act: _ActionSkill, method: Method) -> None:
        try:
            act.machine.check(method)
        except TransitionRefused as exc:
            raise self._refused(method, str(exc)) from None

    def _record_action(self, method: Method, drop: Tuple[str, ...] = (), **fields: Any) -> None:
        """Update the HDICT's action record; a store failure refuses the method (nothing changed yet)."""
        try:
            rec = self.store.value(HHLC, "action") or {}
            for k in drop:
                rec.pop(k, None)
            rec.update(fields)
            self.store.put(HHLC, "action", rec, source="HHLC")
        except HicemError as exc:
            raise ControllerError("%s failed: the HDICT did not take it: %s" % (method.value, exc)) from exc

    def _enter_suspended(self, act: _ActionSkill, cause: str) -> None:
        act.pending = None
        self._set_state(phase="suspended")
        act.machine.call(Method.SUSPEND, cause)

    # -- commands from outside ------------------------------------------------------------------------------
    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> None:
        """Start a process in the worker thread; ControllerError if one is already running."""
        if not isinstance(process_iri, str) or not process_iri.strip():
            raise ControllerError("process IRI must be a non-empty string")
        if options is not None and not isinstance(options, dict):
            raise ControllerError("process options must be a mapping, got %s" % type(options).__name__)
        if self.running:
            raise ControllerError("process %s is still running; stop it first" % self._state["process"])
        self._thread = threading.Thread(target=self._guarded, args=(self.run_process, process_iri, options),
                                        name="hicem-hhlc", daemon=True)
        self._thread.start()

    def resume_in_background(self) -> bool:
        """Resume an interrupted process (see :meth:`resume`) in the worker thread; False if none."""
        rec = self.store.value(HHLC, "process")
        if not rec or rec.get("state") != "running":
            return False
        if self.running:
            raise ControllerError("a process is already running")
        self._thread = threading.Thread(target=self._guarded, args=(self.resume,), name="hicem-hhlc", daemon=True)
        self._thread.start()
        return True

    def _guarded(self, fn: Callable[..., Any], *args: Any) -> None:
        try:
            fn(*args)
        except Exception:
            self.log.exception("HHLC worker crashed")

    def stop(self, reason: str = "stop requested") -> None:
        """Halt the running action and end the process (state 'stopped'). Safe to call at any time."""
        self._stop_reason = reason or "stop requested"
        self._wake.set()

    def join(self, timeout: Optional[float] = None) -> bool:
        if self._thread is not None:
            self._thread.join(timeout)
            return not self._thread.is_alive()
        return True

    def operator_reply(self, prompt_id: str, answer: str) -> None:
        """Answer an open prompt; OperatorError (with the open prompts) if it is not open."""
        self.operator.reply(prompt_id, answer)
        self._wake.set()

    def _on_fault(self, module: str, reason: str) -> None:
        if self._tree is not None:
            action = self._state.get("action_type", "")
            if action in self.params.ride_through:    # e.g. RECOVER: its tree waits for the devices itself
                self.log.warning("health fault during %s, which rides through it: %s", action, reason)
                return
            self._abort_reason = "health fault: %s" % reason
            self._wake.set()

    # -- the loop -------------------------------------------------------------------------------------------
    def run_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        """Run a process to its end in the calling thread; returns the final phase (ended/failed/stopped)."""
        self._stop_reason = None
        self._set_state(process=process_iri, phase="starting", detail="", action_type="", task="", skill="",
                        tree="", node="")
        try:
            specific = self._pemkre_call(self.pemkre.start_process, process_iri, options)
        except Exception as exc:  # nothing started yet: just report
            return self._finish_process("failed", "PEMKRE start_process failed: %s" % exc)
        self.store.put(HHLC, "process", {"iri": process_iri, "specific": specific, "state": "running"},
                       source="HHLC")
        self.store.delete(HHLC, "action")
        self._set_state(specific_process=specific or "")
        return self._loop()

    def resume(self) -> str:
        """Continue the process the HDICT says was running when HICEM died (see module doc)."""
        rec = self.store.value(HHLC, "process")
        if not rec or rec.get("state") != "running":
            raise ControllerError("no interrupted process in the HDICT")
        self._stop_reason = None
        self._set_state(process=rec["iri"], specific_process=rec.get("specific") or "", phase="resuming")
        try:
            phase = self._settle_interrupted()
        except Exception as exc:
            self.log.exception("resume failed")
            return self._finish_process("failed", "resume failed: %s: %s" % (type(exc).__name__, exc))
        return phase if phase is not None else self._loop()

    def _settle_interrupted(self) -> Optional[str]:
        """Bring devices safe and settle the interrupted action; a final phase if the process must end. An action
        suspended when HICEM died comes back Suspended instead, with no device command (:meth:`_restore_suspended`)."""
        act = self.store.value(HHLC, "action")
        if act is not None and act.get("phase") == "suspended":
            return self._restore_suspended(act)
        self._send_safe_commands()
        if act is not None and act.get("phase") != "reported":
            return self._apply_resume_policy(act, self._na_of_record(act))
        return None

    @staticmethod
    def _na_of_record(act: Dict[str, Any]) -> NextAction:
        return NextAction(ACTION, task=act["task"], action_type=act["action_type"],
                          parameters=act.get("raw_parameters", ""), skill=act.get("skill", ""),
                          skill_kind=act.get("skill_kind", ""), values=act.get("parameters", {}))

    def _apply_resume_policy(self, act: Dict[str, Any], na: NextAction,
                             machine: Optional[ProgramStateMachine] = None) -> Optional[str]:
        """``hhlc.resume_policy`` for an action a restart interrupted; ``machine``: its skill state machine when it
        was restored Suspended and resumed (Running), ended with the outcome."""
        policy = self.params.resume_policy.get(act["action_type"], "fail")
        if act.get("phase") == "finished":
            self._report_on_resume(na, act["outcome"], act["detail"])
        elif policy == "fail" or (policy != "rerun" and not self.library.has_tree(policy)):
            detail = "interrupted: HICEM restarted during %s; not repeated (resume policy %s)" % (
                act["action_type"], policy)
            if machine is not None:
                with self._skill_lock:
                    machine.fail(detail)
            self._report_on_resume(na, FAILED, detail)
        else:
            tree = tree_for(na) if policy == "rerun" else policy
            self.log.info("resume: running %s for the interrupted %s %s", tree, act["action_type"], act["task"])
            return self._execute(na, resumed=True, tree_id=tree, machine=machine)
        return None

    def _restore_suspended(self, rec: Dict[str, Any]) -> Optional[str]:
        """The action was Suspended when HICEM died: come back Suspended (no device command sent) and wait for
        Resume (safe commands, then the resume policy), Halt (safe commands, reported failed ``halted: ...``) or
        a stop (reported failed ``stopped: ...``, the process ends)."""
        na = self._na_of_record(rec)
        machine = self._new_machine(na, ProgramState.RUNNING)
        act = _ActionSkill(machine, na)
        since = rec.get("suspended_at")
        when = (" at %s" % time.strftime("%Y-%m-%dT%H:%M:%S", time.localtime(since))
                if isinstance(since, (int, float)) else "")
        by = rec.get("suspend_cause") or ""
        self._set_state(action_type=na.action_type, task=na.task, skill=na.skill, tree="", node="", path="",
                        phase="suspended")
        with self._skill_lock:
            self._action = act
            self._last_machine = machine
            machine.call(Method.SUSPEND, "restored after a HICEM restart: the action was suspended%s%s; no device "
                                         "command sent" % (when, " (%s)" % by if by else ""))
        self.log.warning("resume: %s %s was suspended when HICEM stopped; it stays Suspended until Resume or Halt",
                         na.action_type, na.task)
        stop: Optional[str] = None
        while True:
            with self._skill_lock:
                if act.halt_cause is not None or self._stop_reason is not None or \
                        machine.state == ProgramState.RUNNING:
                    self._action = None
                    if act.halt_cause is None and self._stop_reason is not None:
                        stop = self._stop_reason
                        machine.fail("stopped: %s" % stop)
                    break
            self._wake.wait(self.params.idle_poll_s)
            self._wake.clear()
        self._publish_skill()
        if act.halt_cause is not None:
            self._send_safe_commands()
            self._report_on_resume(na, FAILED, "halted: %s" % act.halt_cause)
            return None
        if stop is not None:
            self._report_on_resume(na, FAILED, "stopped: %s" % stop)
            return self._finish_process("stopped", stop)
        self._send_safe_commands()
        return self._apply_resume_policy(rec, na, machine)

    def _report_on_resume(self, na: NextAction, outcome: str, detail: str) -> None:
        """Report an outcome found in the HDICT. PEMKRE may already have it (the crash came after its answer
        and before the HDICT update): a refusal is logged and the loop asks PEMKRE what comes next."""
        try:
            self._report(na, outcome, detail)
        except PemkreCallError as exc:
            self.log.warning("resume: PEMKRE did not take the %s outcome of %s (%s); asking it what is next",
                             outcome, na.task, exc)
            with self.store.transaction():
                self.store.put(TASKS, na.task, {"action_type": na.action_type, "skill": na.skill,
                                                "outcome": outcome, "detail": detail}, source="HHLC")
                self.store.put(HHLC, "action", {"task": na.task, "action_type": na.action_type, "skill": na.skill,
                                                "skill_kind": na.skill_kind, "phase": "reported",
                                                "outcome": outcome, "detail": detail}, source="HHLC")

    def _loop(self) -> str:
        repeats: Dict[str, int] = {}
        while True:
            if self._stop_reason is not None:
                return self._finish_process("stopped", self._stop_reason)
            if not self._wait_for_health():
                return self._finish_process("stopped", self._stop_reason or "stop requested")
            self._set_state(phase="asking", action_type="", task="", skill="", tree="", node="", path="")
            try:
                self.store.prune()  # outdated entries go between actions, never under a running tree
            except HicemError:
                self.log.exception("pruning the data store failed")
            try:
                na = parse_next_action(self._pemkre_call(self.pemkre.next_action))
            except Exception as exc:
                return self._finish_process("failed", "PEMKRE next_action: %s" % exc)
            if na.status == "ended":
                return self._finish_process("ended", na.message)
            if na.status == "failed":
                return self._finish_process("failed", "PEMKRE reports the process failed: %s" % na.message)
            done = self.store.value(TASKS, na.task)
            if done is not None:
                # PEMKRE offers a task HICEM already completed (its status update was lost): re-report, don't redo.
                repeats[na.task] = repeats.get(na.task, 0) + 1
                if repeats[na.task] > 1:
                    return self._finish_process("failed", "PEMKRE keeps offering the completed task %s" % na.task)
                try:
                    self._report(na, done["outcome"], done["detail"])
                except PemkreCallError as exc:
                    return self._finish_process("failed", "PEMKRE refused the stored outcome of %s: %s" % (
                        na.task, exc))
                continue
            phase = self._execute(na)
            if phase is not None:
                return phase

    def _execute(self, na: NextAction, resumed: bool = False, tree_id: Optional[str] = None,
                 machine: Optional[ProgramStateMachine] = None) -> Optional[str]:
        """Run one action; returns a final process phase if the process must end, else None. ``machine``: the
        action's skill state machine when it exists already (an action restored Suspended, then resumed)."""
        stats = ActionStats(na.action_type)
        self._current_stats = stats
        t0 = time.perf_counter()
        try:
            # one durable record before PEMKRE hears of it: a crash from here on is found by resume()
            rec = {"task": na.task, "action_type": na.action_type, "parameters": na.params(),
                   "raw_parameters": na.parameters, "skill": na.skill, "skill_kind": na.skill_kind,
                   "phase": "running"}
            self.store.put(HHLC, "action", rec, source="HHLC")
            self._set_state(action_type=na.action_type, task=na.task, skill=na.skill, tree="", node="",
                            phase="starting")
            try:
                self._pemkre_call(self.pemkre.set_task_status, na.task, IN_PROGRESS, "")
            except PemkreCallError as exc:
                if not resumed:
                    raise
                self.log.warning("resume: PEMKRE refused in_progress again (%s); continuing", exc)
            tree_id = tree_id or tree_for(na)
            if not self.library.has_tree(tree_id):
                # PEMKRE only accepts an outcome for a running task: in_progress first, then failed.
                reason = "no behavior tree for %s; trees: %s" % (_what(na), ", ".join(self.library.tree_ids()))
                self._report(na, FAILED, reason)
                return self._finish_process("failed", reason)
            outcome, detail = self._run_tree(na, stats, tree_id, machine)
            rec.update(phase="finished", outcome=outcome, detail=detail)
            self.store.put(HHLC, "action", rec, source="HHLC")
            self._report(na, outcome, detail)
            if self._stop_reason is not None:
                return self._finish_process("stopped", self._stop_reason)
            return None
        except Exception as exc:
            self.log.exception("action %s failed in the controller", na.action_type)
            return self._finish_process("failed", "%s during %s: %s" % (type(exc).__name__, na.action_type, exc))
        finally:
            stats.wall_s = time.perf_counter() - t0
            self.stats.append(stats)
            self._current_stats = None
            if machine is not None and machine.state in (ProgramState.RUNNING, ProgramState.SUSPENDED):
                with self._skill_lock:       # ended before its tree ran (no tree, PEMKRE refused)
                    machine.fail("the action ended before its tree ran")

    def _run_tree(self, na: NextAction, stats: ActionStats, tree_id: str,
                  machine: Optional[ProgramStateMachine] = None) -> "tuple":
        clock = PausableClock(self.clock)       # stands still while the action is suspended
        ctx = NodeContext(locem=self._timed_locem, store=self.store, health=self.health, operator=self.operator,
                          data_handler=self.data_handler, clock=clock, log=self.log)
        bb = Blackboard()
        bb.update(self.params.blackboard_entries())
        bb.update(na.blackboard_entries())
        bb.set("task", na.task)
        bb.set("action_type", na.action_type)
        bb.set("skill", na.skill)
        bb.set("skill_kind", na.skill_kind)
        tree = self.library.build(tree_id, ctx, bb)
        self._abort_reason = None
        self._tree = tree
        act = _ActionSkill(machine or self._new_machine(na), na, ctx, clock)
        self._set_state(tree=tree_id, phase="running")
        with self._skill_lock:
            self._action = act
            self._last_machine = act.machine
            if act.machine.state == ProgramState.READY:
                act.machine.call(Method.START, "HICEM runs the tree %s" % tree_id)
            else:
                self._publish_skill()
        period = self.params.tick_period_s
        end: Optional[Tuple[str, str]] = None
        try:
            while True:
                with self._skill_lock:
                    end = self._step(na, stats, tree_id, tree, ctx, bb, act)
                    if end is not None:
                        self._end_action(act, end[0], end[1])
                        return end
                    ticking = act.machine.state == ProgramState.RUNNING and act.pending is None
                tw = time.perf_counter()
                self._wake.wait(period if ticking else self.params.idle_poll_s)
                self._wake.clear()
                stats.wait_s += time.perf_counter() - tw
        finally:
            self._tree = None
            if end is None:                      # an exception: the action cannot go on
                with self._skill_lock:
                    self._end_action(act, FAILED, "internal error in HICEM's controller")

    def _step(self, na: NextAction, stats: ActionStats, tree_id: str, tree: BuiltTree, ctx: NodeContext,
              bb: Blackboard, act: _ActionSkill) -> Optional[Tuple[str, str]]:
        """One turn of the tick loop (skill lock held): halt, wait while suspended, or tick; the outcome or None."""
        halt_reason = ((act.halt_cause is not None and "halted: %s" % act.halt_cause)
                       or (self._stop_reason and "stopped: %s" % self._stop_reason) or self._abort_reason)
        if halt_reason:
            self._halt(tree, ctx)
            return FAILED, halt_reason
        if act.pending is not None:
            cause, handles, names = act.pending
            if any(not h.done() for h in handles):
                return None
            self._enter_suspended(act, "%s; suspended when %s ended (it cannot be suspended)" % (cause, names))
        if act.machine.state != ProgramState.RUNNING:
            return None                          # suspended: tree and blackboard stay as they are
        try:
            status = tree.tick()
        except Exception as exc:
            self.log.exception("tick of %s raised", na.action_type)
            self._halt(tree, ctx)
            return FAILED, "internal error while ticking %s: %s" % (na.action_type, exc)
        stats.ticks += 1
        self._set_state(node=tree.tip_name() or tree.root.name, path="/".join(tree.running_path()))
        if status == Status.SUCCESS:
            detail = bb.get_default("task_detail", "")
            return SUCCEEDED, str(detail)
        if status == Status.FAILURE:
            last = ctx.last_failure()
            self._cancel_outstanding(ctx)
            return FAILED, ("%s: %s" % last) if last else "tree %s failed" % tree_id
        return None

    def _end_action(self, act: _ActionSkill, outcome: str, detail: str) -> None:
        """The action's tree is over (skill lock held): Running/Suspended -> Ready on success, -> Halted else."""
        self._action = None
        if act.clock is not None:
            act.clock.unfreeze()
        if outcome == SUCCEEDED:
            tr = act.machine.complete("succeeded: %s" % detail if detail else "succeeded")
        else:
            tr = act.machine.fail(detail or "failed")
        if tr is None:                          # already Halted by the Halt method
            self._publish_skill()

    def _halt(self, tree: BuiltTree, ctx: NodeContext) -> None:
        tree.halt()
        self._cancel_outstanding(ctx)

    def _cancel_outstanding(self, ctx: NodeContext) -> None:
        for h in ctx.outstanding():  # belt and braces: nothing may stay running on a device
            try:
                h.cancel()
            except Exception:
                self.log.exception("cancel failed")
            ctx.untrack(h)

    def _report(self, na: NextAction, outcome: str, detail: str) -> None:
        self._set_state(phase="reporting", detail=detail)
        self._pemkre_call(self.pemkre.set_task_status, na.task, outcome, detail)
        with self.store.transaction():
            self.store.put(TASKS, na.task, {"action_type": na.action_type, "skill": na.skill, "outcome": outcome,
                                            "detail": detail}, source="HHLC")
            rec = self.store.value(HHLC, "action") or {"task": na.task, "action_type": na.action_type,
                                                       "skill": na.skill, "skill_kind": na.skill_kind}
            rec.update(phase="reported", outcome=outcome, detail=detail)
            self.store.put(HHLC, "action", rec, source="HHLC")

    def _finish_process(self, phase: str, detail: str) -> str:
        if phase == "stopped":
            self._send_safe_commands()
        rec = self.store.value(HHLC, "process") or {}
        rec["state"] = phase
        rec["detail"] = detail
        try:
            self.store.put(HHLC, "process", rec, source="HHLC")
        except HicemError:
            self.log.exception("cannot record the process end")
        self.operator.cancel_all()
        self._set_state(phase=phase, detail=detail, tree="", node="", path="")
        self.log.info("process %s: %s (%s)", self._state["process"], phase, detail)
        return phase

    def _wait_for_health(self) -> bool:
        """Block while a crucial module is faulty; False if a stop arrived meanwhile."""
        if self.health is None:
            return True
        while self.health.faults():
            if self._stop_reason is not None:
                return False
            self._set_state(phase="waiting_for_health", detail="; ".join(r for _m, r in self.health.faults()))
            self._wake.wait(self.params.idle_poll_s)
            self._wake.clear()
        return self._stop_reason is None

    def _send_safe_commands(self) -> None:
        if self.locem is None:
            return
        for cmd in self.params.safe_commands:
            try:
                h = self.locem.send(cmd)
                t_end = self.clock() + self.params.safe_timeout_s
                while not h.done() and self.clock() < t_end:
                    time.sleep(0.005)
                if h.done():
                    check_reply(h.reply(), cmd)
                else:
                    h.cancel()
                    self.log.warning("safe command %s: no reply within %.1f s", cmd, self.params.safe_timeout_s)
            except (LocemCallError, HicemError) as exc:
                self.log.warning("safe command %s failed: %s", cmd, exc)

    def _pemkre_call(self, fn: Callable[..., Any], *args: Any) -> Any:
        t = time.perf_counter()
        since: Optional[float] = None
        before: Dict[str, Any] = {}
        try:
            while True:
                try:
                    result = fn(*args)
                    if since is not None:      # back to what the call was made for
                        self.log.info("PEMKRE is back after %.1f s", time.monotonic() - since)
                        self._set_state(phase=before.get("phase", ""), detail=before.get("detail", ""))
                    return result
                except PemkreUnavailableError as exc:
                    if since is None:
                        since, before = time.monotonic(), self.state()
                    if self._stop_reason is not None or time.monotonic() - since >= self.pemkre_wait_s:
                        raise
                    self.log.warning("PEMKRE is away (%s); waiting for it", exc)
                    self._set_state(phase="waiting_for_pemkre", detail=str(exc))
                    self._wake.wait(self.params.idle_poll_s)
                    self._wake.clear()
        finally:
            if self._current_stats is not None:
                self._current_stats.pemkre_s += time.perf_counter() - t
