"""The automatic operator: answers HICEM's prompts from configuration, for headless runs and tests.

Two parts:

- :class:`AutoOperatorPolicy` is pure: given a prompt, how long it has been open, it says which answer to give
  (or that it is not time yet). It never talks to anything.
- :class:`AutoOperator` applies a policy to an :class:`~locem_bridge.hmi.backend.HmiBackend`: :meth:`step` polls
  ``prompts()`` once, remembers when each prompt was first seen and replies to the ones that are due;
  :meth:`start` runs ``step`` in a daemon thread every ``poll_period_s`` until :meth:`stop`. Every answer given is
  kept in :attr:`AutoOperator.answers` (prompt id, kind, answer, features, time) for the run report.

Configuration (a dict, e.g. the ``auto_operator`` section of a YAML file; every key optional)::

    poll_period_s: 0.1              # how often the backend is polled
    default:                        # for prompt kinds not listed below
      delay_s: 0.0
      answer: null                  # null: answer only prompts with exactly one allowed choice
    kinds:
      mount_tool:    {answer: done, delay_s: 2.0}
      validate_line: {answer: valid, delay_s: 0.5, per_feature: {invalid: [wall_1_joint_2]}}
      manual_taping: {answer: done, delay_s: 1.0}
      safety_stop:   {answer: reset, delay_s: 0.5}   # RECOVER: arm protective stop checked, reset it

``per_feature`` maps an answer to the feature ids (joints, areas, walls, tools) it is given for; a prompt
concerns a feature when one of its ``context`` values equals the id, or when the id appears as a whole word in
its text (``wall_1_joint_2`` does not match ``wall_1_joint_20``). An answer that is not among a prompt's choices
is never sent: the prompt is left for a human and the reason is logged once (a misconfiguration must not make
the robot do something nobody chose).
"""
import logging
import re
import threading
import time
from typing import Any, Callable, Dict, FrozenSet, List, Optional, Sequence

from .backend import HmiBackend, normalize_prompt
from .errors import AutoOperatorConfigError, BackendRefused, BackendUnavailable

LOG = logging.getLogger("locem_bridge.hmi.auto_operator")
_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_RULE_KEYS = ("answer", "delay_s", "per_feature")
_TOP_KEYS = ("poll_period_s", "default", "kinds")


class PromptRule:
    """How to answer one kind of prompt: ``answer`` (None: the only choice), ``delay_s``, ``per_feature``."""

    __slots__ = ("answer", "delay_s", "per_feature")

    def __init__(self, answer: Optional[str] = None, delay_s: float = 0.0,
                 per_feature: Optional[Dict[str, Sequence[str]]] = None) -> None:
        self.answer = answer
        self.delay_s = float(delay_s)
        self.per_feature: Dict[str, FrozenSet[str]] = {k: frozenset(v) for k, v in (per_feature or {}).items()}

    @classmethod
    def from_dict(cls, raw: Any, where: str) -> "PromptRule":
        if raw is None:
            return cls()
        if not isinstance(raw, dict):
            raise AutoOperatorConfigError("%s must be a mapping with keys %s, got %r" % (where, ", ".join(_RULE_KEYS),
                                                                                         raw))
        unknown = sorted(set(raw) - set(_RULE_KEYS))
        if unknown:
            raise AutoOperatorConfigError("%s: unknown key(s) %s; allowed: %s" % (where, ", ".join(map(str, unknown)),
                                                                               ", ".join(_RULE_KEYS)))
        answer = raw.get("answer")
        if answer is not None and (not isinstance(answer, str) or not answer):
            raise AutoOperatorConfigError("%s.answer must be a non-empty string or null, got %r" % (where, answer))
        delay = raw.get("delay_s", 0.0)
        if isinstance(delay, bool) or not isinstance(delay, (int, float)) or not (0.0 <= float(delay) <= 86400.0):
            raise AutoOperatorConfigError("%s.delay_s must be a number of seconds in [0, 86400], got %r" % (where,
                                                                                                         delay))
        per = raw.get("per_feature") or {}
        if not isinstance(per, dict):
            raise AutoOperatorConfigError("%s.per_feature must map an answer to a list of feature ids, got %r" % (
                where, per))
        seen: Dict[str, str] = {}
        for ans, ids in per.items():
            if not isinstance(ans, str) or not ans:
                raise AutoOperatorConfigError("%s.per_feature: answers must be non-empty strings, got %r" % (where,
                                                                                                          ans))
            if isinstance(ids, str) or not isinstance(ids, (list, tuple)):
                raise AutoOperatorConfigError("%s.per_feature.%s must be a list of feature ids, got %r" % (where, ans,
                                                                                                        ids))
            for fid in ids:
                if not isinstance(fid, str) or not _WORD.fullmatch(fid):
                    raise AutoOperatorConfigError(
                        "%s.per_feature.%s: %r is not a feature id ([A-Za-z][A-Za-z0-9_]*)" % (where, ans, fid))
                if fid in seen and seen[fid] != ans:
                    raise AutoOperatorConfigError("%s.per_feature: %s is listed under both %s and %s" % (
                        where, fid, seen[fid], ans))
                seen[fid] = ans
        return cls(answer, float(delay), per)


DEFAULT_CONFIG: Dict[str, Any] = {
    "poll_period_s": 0.1,
    "default": {"delay_s": 0.0},
    "kinds": {
        "mount_tool": {"answer": "done", "delay_s": 0.5},
        "validate_line": {"answer": "valid", "delay_s": 0.2},
        "manual_taping": {"answer": "done", "delay_s": 0.5},
        "finish_interrupted": {"answer": "done", "delay_s": 0.0},
        "safety_stop": {"answer": "reset", "delay_s": 0.5},
    },
}
"""What the automatic operator does when given no configuration: answers the plasterboard trees' prompts
(trees/GET_TOOL.xml, VALIDATE_TAPE_LINE.xml, MANUAL_TAPING.xml, RESUME_TAPE_LINE.xml, RECOVER.xml) positively,
quickly: a latched safety stop (RECOVER's ``safety_stop`` prompt) is reset, so a headless job goes on; each such
answer counts as an operator intervention in the run report."""


class AutoOperatorConfig:
    """Validated configuration: ``poll_period_s``, a ``default`` rule and one rule per prompt kind."""

    def __init__(self, kinds: Optional[Dict[str, PromptRule]] = None, default: Optional[PromptRule] = None,
                 poll_period_s: float = 0.1) -> None:
        self.kinds: Dict[str, PromptRule] = dict(kinds or {})
        self.default = default or PromptRule()
        self.poll_period_s = float(poll_period_s)

    @classmethod
    def defaults(cls) -> "AutoOperatorConfig":
        """:data:`DEFAULT_CONFIG`."""
        return cls.from_dict(DEFAULT_CONFIG)

    @classmethod
    def from_dict(cls, raw: Optional[Dict[str, Any]], base: Optional[Dict[str, Any]] = None) -> "AutoOperatorConfig":
        """Build from a plain dict (see the module docstring); raises :class:`AutoOperatorConfigError`.

        With ``base`` (e.g. :data:`DEFAULT_CONFIG`), ``raw`` overrides it: top-level keys replace, and ``kinds``
        entries replace the base's entry of the same kind (other kinds stay).
        """
        if base is not None and raw is None:
            raw = {}
        if base is not None and isinstance(raw, dict):
            merged = dict(base)
            merged.update({k: v for k, v in raw.items() if k != "kinds"})
            kinds = dict(base.get("kinds") or {})
            kinds.update(raw.get("kinds") or {})
            merged["kinds"] = kinds
            raw = merged
        raw = raw or {}
        if not isinstance(raw, dict):
            raise AutoOperatorConfigError("auto operator configuration must be a mapping, got %r" % (raw,))
        unknown = sorted(set(raw) - set(_TOP_KEYS))
        if unknown:
            raise AutoOperatorConfigError("auto operator: unknown key(s) %s; allowed: %s" % (
                ", ".join(map(str, unknown)), ", ".join(_TOP_KEYS)))
        period = raw.get("poll_period_s", 0.1)
        if isinstance(period, bool) or not isinstance(period, (int, float)) or not (0.01 <= float(period) <= 10.0):
            raise AutoOperatorConfigError("poll_period_s must be a number of seconds in [0.01, 10], got %r" % (period,))
        kinds_raw = raw.get("kinds") or {}
        if not isinstance(kinds_raw, dict):
            raise AutoOperatorConfigError("kinds must map a prompt kind to a rule, got %r" % (kinds_raw,))
        kinds = {str(k): PromptRule.from_dict(v, "kinds.%s" % k) for k, v in kinds_raw.items()}
        return cls(kinds, PromptRule.from_dict(raw.get("default"), "default"), float(period))


def prompt_features(prompt: Dict[str, Any]) -> FrozenSet[str]:
    """The words a prompt is about: its string ``context`` values and the identifier-like words of its text."""
    words = set(_WORD.findall(prompt.get("text") or ""))
    for value in (prompt.get("context") or {}).values():
        if isinstance(value, str):
            words.add(value)
    return frozenset(words)


class Decision:
    """What the policy says about one prompt: ``answer`` (None: do not answer now) and ``reason``."""

    __slots__ = ("answer", "reason", "final", "features")

    def __init__(self, answer: Optional[str], reason: str, final: bool, features: Sequence[str] = ()) -> None:
        self.answer = answer
        self.reason = reason
        self.final = final          # True: asking again later will not change the outcome
        self.features = tuple(features)

    def __repr__(self) -> str:
        return "Decision(%r, %r)" % (self.answer, self.reason)


class AutoOperatorPolicy:
    """Pure decision function over a validated :class:`AutoOperatorConfig`."""

    def __init__(self, config: AutoOperatorConfig) -> None:
        self.config = config

    def rule_for(self, kind: str) -> PromptRule:
        return self.config.kinds.get(kind, self.config.default)

    def decide(self, prompt: Dict[str, Any], open_for_s: float) -> Decision:
        """The answer to give ``prompt`` (normalized prompt dict) after it has been open ``open_for_s`` seconds."""
        rule = self.rule_for(prompt.get("kind", ""))
        choices = list(prompt.get("choices") or [])
        features = prompt_features(prompt)
        answer, matched = rule.answer, ()
        for ans, ids in sorted(rule.per_feature.items()):
            hit = sorted(ids & features)
            if hit:
                answer, matched = ans, tuple(hit)
                break
        if answer is None:
            if len(choices) != 1:
                return Decision(None, "no configured answer for kind %r and %d choices (%s): left for a human" % (
                    prompt.get("kind", ""), len(choices), ", ".join(choices)), True)
            answer = choices[0]
        if answer not in choices:
            return Decision(None, "configured answer %r for kind %r is not among the allowed %s: left for a human" % (
                answer, prompt.get("kind", ""), ", ".join(choices)), True, matched)
        if open_for_s < rule.delay_s:
            return Decision(None, "waiting %.2f s more" % (rule.delay_s - open_for_s), False, matched)
        why = ("per_feature rule for %s" % ", ".join(matched)) if matched else "configured answer"
        return Decision(answer, why, True, matched)


class AutoOperator:
    """Applies an :class:`AutoOperatorPolicy` to a backend. Lifecycle: construct, :meth:`start` (or call
    :meth:`step` yourself), :meth:`stop`. Thread-safe; at most one polling thread."""

    def __init__(self, backend: HmiBackend, config: Optional[AutoOperatorConfig] = None,
                 clock: Callable[[], float] = time.monotonic, log: Optional[logging.Logger] = None) -> None:
        self.backend = backend
        self.config = config or AutoOperatorConfig()
        self.policy = AutoOperatorPolicy(self.config)
        self.clock = clock
        self.log = log or LOG
        self.answers: List[Dict[str, Any]] = []
        self.errors: List[str] = []
        self._first_seen: Dict[str, float] = {}
        self._left_for_human: Dict[str, str] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._listeners: List[Callable[[Dict[str, Any]], None]] = []

    def add_listener(self, cb: Callable[[Dict[str, Any]], None]) -> None:
        """``cb(record)`` after every answer given (e.g. to show it in the HMI's event log)."""
        self._listeners.append(cb)

    def step(self) -> List[Dict[str, Any]]:
        """Poll the open prompts once and answer those that are due; returns the answers given in this step."""
        with self._lock:
            try:
                raw = self.backend.prompts()
            except (BackendUnavailable, BackendRefused) as err:
                self._note_error("cannot read prompts: %s" % err)
                return []
            now = self.clock()
            given: List[Dict[str, Any]] = []
            open_ids = set()
            for item in raw or []:
                try:
                    prompt = normalize_prompt(item)
                except ValueError as err:
                    self._note_error("ignoring malformed prompt: %s" % err)
                    continue
                pid = prompt["id"]
                open_ids.add(pid)
                first = self._first_seen.setdefault(pid, now)
                if pid in self._left_for_human:
                    continue
                decision = self.policy.decide(prompt, now - first)
                if decision.answer is None:
                    if decision.final:
                        self._left_for_human[pid] = decision.reason
                        self.log.warning("prompt %s (%s): %s", pid, prompt["kind"], decision.reason)
                    continue
                try:
                    self.backend.reply(pid, decision.answer)
                except BackendRefused as err:     # closed meanwhile (answered by a human, cancelled): not ours
                    self.log.info("prompt %s (%s) was not answered: %s", pid, prompt["kind"], err)
                    self._left_for_human[pid] = "refused: %s" % err
                    continue
                except BackendUnavailable as err:
                    self._note_error("reply to %s failed, will retry: %s" % (pid, err))
                    continue
                record = {"prompt_id": pid, "kind": prompt["kind"], "answer": decision.answer,
                          "features": list(decision.features), "reason": decision.reason,
                          "open_for_s": round(now - first, 3), "text": prompt["text"]}
                self._left_for_human[pid] = "answered %s" % decision.answer
                self.answers.append(record)
                given.append(record)
                self.log.info("auto operator answered %s (%s) with %r: %s", pid, prompt["kind"], decision.answer,
                              decision.reason)
                for cb in list(self._listeners):
                    try:
                        cb(record)
                    except Exception:  # a broken listener must not stop the operator
                        self.log.exception("auto operator listener failed")
            for pid in list(self._first_seen):      # forget closed prompts (bounded memory on long runs)
                if pid not in open_ids:
                    self._first_seen.pop(pid, None)
                    self._left_for_human.pop(pid, None)
            return given

    def _note_error(self, text: str) -> None:
        self.log.warning("auto operator: %s", text)
        self.errors.append(text)
        del self.errors[:-100]

    def start(self) -> None:
        """Poll in a daemon thread every ``poll_period_s`` until :meth:`stop`."""
        if self._thread is not None and self._thread.is_alive():
            return
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="auto-operator", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                self.step()
            except Exception:  # a backend bug must not kill the operator thread silently
                self.log.exception("auto operator step failed")
            self._stop.wait(self.config.poll_period_s)

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None
