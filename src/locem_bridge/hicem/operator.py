"""Operator prompts: HICEM asks (mount this tool, is this line valid?), the operator answers.

A prompt is *open* from :meth:`OperatorDesk.open` until it is answered (:meth:`reply`) or cancelled (the node
that opened it was halted). Listeners get ``("opened" | "answered" | "cancelled", prompt)`` events; the ROS
adapter publishes them, the web HMI shows them. Replying to a prompt that is not open, or with an answer not
among its choices, raises :class:`OperatorError` naming the open prompts / allowed answers.
Thread-safe: replies arrive from adapter threads while the tree ticks in its own thread.
"""
import threading
import time
import uuid
from typing import Any, Callable, Dict, List, Optional, Sequence

from .errors import OperatorError


class Prompt:
    __slots__ = ("id", "kind", "text", "choices", "context", "opened", "answer", "state")

    def __init__(self, pid: str, kind: str, text: str, choices: Sequence[str], context: Dict[str, Any],
                 opened: float) -> None:
        self.id = pid
        self.kind = kind
        self.text = text
        self.choices = tuple(choices)
        self.context = dict(context)
        self.opened = opened
        self.answer: Optional[str] = None
        self.state = "open"

    def as_dict(self) -> Dict[str, Any]:
        return {"id": self.id, "kind": self.kind, "text": self.text, "choices": list(self.choices),
                "context": self.context, "state": self.state, "answer": self.answer}


class OperatorDesk:
    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        self.clock = clock
        self._lock = threading.Lock()
        self._prompts: Dict[str, Prompt] = {}
        self._listeners: List[Callable[[str, Prompt], None]] = []
        self.interventions = 0

    def add_listener(self, cb: Callable[[str, Prompt], None]) -> None:
        self._listeners.append(cb)

    def _emit(self, event: str, p: Prompt) -> None:
        for cb in list(self._listeners):
            cb(event, p)

    def open(self, kind: str, text: str, choices: Sequence[str], context: Optional[Dict[str, Any]] = None) -> Prompt:
        if not choices:
            raise OperatorError("a prompt needs at least one allowed answer")
        p = Prompt(uuid.uuid4().hex[:12], kind, text, choices, context or {}, self.clock())
        with self._lock:
            self._prompts[p.id] = p
        self._emit("opened", p)
        return p

    def open_prompts(self) -> List[Prompt]:
        with self._lock:
            return [p for p in self._prompts.values() if p.state == "open"]

    def reply(self, prompt_id: str, answer: str) -> Prompt:
        with self._lock:
            p = self._prompts.get(prompt_id)
            if p is None or p.state != "open":
                open_ids = [q.id for q in self._prompts.values() if q.state == "open"]
                why = "is not known" if p is None else "is already %s" % p.state
                raise OperatorError("prompt '%s' %s; open prompts: %s" % (
                    prompt_id, why, ", ".join(open_ids) or "none"))
            if answer not in p.choices:
                raise OperatorError("answer %r is not allowed for prompt '%s' (%s); allowed: %s" % (
                    answer, p.id, p.kind, ", ".join(p.choices)))
            p.answer = answer
            p.state = "answered"
            self.interventions += 1
        self._emit("answered", p)
        return p

    def get(self, prompt_id: str) -> Optional[Prompt]:
        with self._lock:
            return self._prompts.get(prompt_id)

    def cancel(self, prompt_id: str) -> None:
        with self._lock:
            p = self._prompts.get(prompt_id)
            if p is None or p.state != "open":
                return
            p.state = "cancelled"
        self._emit("cancelled", p)

    def cancel_all(self) -> None:
        for p in self.open_prompts():
            self.cancel(p.id)
