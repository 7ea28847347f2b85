"""Opt-in record of the calls one layer makes into another, for the job benchmark's split of time by layer.

ROS-free. HICEM calls PEMKRE through a ``PemkreClient`` (``start_process``, ``next_action``,
``set_task_status``, ``report_world``); from outside the HICEM process those calls can only be guessed from
HICEM's phases. :func:`instrument_from_env` wraps the named methods of such a client *in place* (the object
keeps its class, so ``isinstance`` checks and other attributes are untouched) so that each call appends one
JSON line to a file::

    {"layer": "pemkre", "call": "next_action", "t0": 1700000000.123, "t1": 1700000000.171, "ok": true}

``t0``/``t1`` are ``time.time()`` seconds (the clock of ROS message stamps), ``ok`` is false when the call
raised (the exception is re-raised unchanged). Nothing happens unless the environment variable
``LOCEM_CALL_LOG`` names a file: then the instrumentation costs one ``write`` + ``flush`` per call.
:func:`read_call_log` reads the file back (a line torn by a crash is skipped).

Lifecycle: the log file is opened on the first recorded call, in append mode (several processes or a
respawned node may share it), and closed by :meth:`CallLog.close` or at interpreter exit.
"""

import atexit
import functools
import json
import os
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Sequence

ENV_VAR = "LOCEM_CALL_LOG"
PEMKRE_CALLS = ("start_process", "next_action", "set_task_status", "report_world")


class CallLogError(ValueError):
    """Instrumentation asked for something that cannot be wrapped (a missing or non-callable method)."""


class CallLog:
    """Appends call records as JSON lines to ``path`` (thread-safe)."""

    def __init__(self, path: str, clock: Callable[[], float] = time.time) -> None:
        if not path:
            raise CallLogError("a call log needs a file path")
        self.path = path
        self.clock = clock
        self._lock = threading.Lock()
        self._handle: Any = None
        atexit.register(self.close)

    def record(self, layer: str, call: str, t0: float, t1: float, ok: bool) -> None:
        line = json.dumps({"layer": layer, "call": call, "t0": t0, "t1": t1, "ok": ok}) + "\n"
        with self._lock:
            if self._handle is None:
                self._handle = open(self.path, "a", encoding="utf-8")
            self._handle.write(line)
            self._handle.flush()

    def close(self) -> None:
        with self._lock:
            if self._handle is not None:
                self._handle.close()
                self._handle = None


def instrument(obj: Any, methods: Sequence[str], log: CallLog, layer: str) -> Any:
    """Wrap ``obj``'s ``methods`` in place so every call is recorded in ``log``; returns ``obj``."""
    for name in methods:
        original = getattr(obj, name, None)
        if not callable(original):
            raise CallLogError("%s has no method %r to time (methods asked: %s)" % (
                type(obj).__name__, name, ", ".join(methods)))

        def timed(*args: Any, __original: Callable[..., Any] = original, __name: str = name, **kwargs: Any) -> Any:
            t0 = log.clock()
            ok = False
            try:
                result = __original(*args, **kwargs)
                ok = True
                return result
            finally:
                log.record(layer, __name, t0, log.clock(), ok)
        setattr(obj, name, functools.wraps(original)(timed))
    return obj


def instrument_from_env(obj: Any, layer: str = "pemkre", methods: Sequence[str] = PEMKRE_CALLS,
                        environ: Optional[Dict[str, str]] = None) -> Any:
    """``instrument(obj, ...)`` when ``$LOCEM_CALL_LOG`` names a file, else ``obj`` unchanged."""
    path = (os.environ if environ is None else environ).get(ENV_VAR, "")
    if not path:
        return obj
    return instrument(obj, methods, CallLog(path), layer)


def read_call_log(path: str) -> List[Dict[str, Any]]:
    """The records of a call log, oldest first; ``[]`` when the file does not exist."""
    if not os.path.exists(path):
        return []
    out = []
    with open(path, encoding="utf-8") as handle:
        for line in handle:
            try:
                rec = json.loads(line)
            except ValueError:
                continue
            if isinstance(rec, dict) and {"call", "t0", "t1"} <= set(rec):
                out.append(rec)
    out.sort(key=lambda r: r["t0"])
    return out
