"""The health line of the operator page: ``{"status": "ok" | "degraded" | "fault" | "unknown", "detail": str}``.

Levels are :mod:`locem_bridge.common.health`'s, read on the page as: ERROR -> fault, WARN and STALE -> degraded,
OK -> ok (:data:`PAGE_STATUS`). Two sources, one reading:

- :func:`health_summary`: HICEM's health monitor snapshot (a HICEM executive in the same process): a faulty
  crucial module is a fault; a faulty non-crucial module, or any module at WARN or worse, degrades;
- :class:`DiagnosticsHealth`: ``/diagnostics`` entries (the ROS adapter), with HICEM's own liveness and its
  ``waiting_for_health`` phase: HICEM not running or waiting for its crucial modules is a fault; entries older
  than ``fresh_s`` no longer count.

No I/O, no ROS.
"""
import threading
import time
from typing import Any, Callable, Dict, Mapping, Optional, Tuple

from ..common.health import ERROR, LEVEL_NAMES, OK, STALE, WARN, level_of

PAGE_STATUS = {OK: "ok", WARN: "degraded", STALE: "degraded", ERROR: "fault"}


def _level(value: Any, unreadable: int) -> int:
    try:
        return level_of(value)
    except ValueError:
        return unreadable


def health_summary(modules: Optional[Dict[str, Dict[str, Any]]]) -> Dict[str, str]:
    """The page's health from a HEM snapshot (``{module: {"level", "message", "crucial", "fault"}}``); unknown
    when no module has reported at all (see the module docstring)."""
    if not modules:
        return {"status": "unknown", "detail": "no module has reported yet"}
    crucial = ["%s" % m.get("fault") for _n, m in sorted(modules.items()) if m.get("fault") and m.get("crucial")]
    if crucial:
        return {"status": "fault", "detail": "; ".join(crucial)}
    other = ["%s" % m.get("fault") for _n, m in sorted(modules.items()) if m.get("fault")]
    other += ["%s reports %s%s" % (n, m.get("level"), (": %s" % m["message"]) if m.get("message") else "")
              for n, m in sorted(modules.items())
              if not m.get("fault") and _level(m.get("level", "OK"), OK) != OK]
    if other:
        return {"status": "degraded", "detail": "; ".join(other)}
    return {"status": "ok", "detail": "%d module%s alive: %s" % (len(modules), "" if len(modules) == 1 else "s",
                                                                ", ".join(sorted(modules)))}


class DiagnosticsHealth:
    """The page's health from ``/diagnostics`` entries and HICEM's liveness (see the module docstring).
    Thread-safe: :meth:`note` is called from a subscriber thread, :meth:`summary` from the page's."""

    def __init__(self, fresh_s: float = 10.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.fresh_s = fresh_s
        self.clock = clock
        self._lock = threading.Lock()
        self._latest: Dict[str, Tuple[int, str, float]] = {}     # name -> (level, message, received at)

    def note(self, name: str, level: Any, message: str) -> None:
        """One ``/diagnostics`` entry; a level that is none of OK..STALE counts as ERROR."""
        with self._lock:
            self._latest[name] = (_level(level, ERROR), message, self.clock())

    def summary(self, hicem: str, hicem_alive: bool, state: Optional[Mapping[str, Any]]) -> Dict[str, str]:
        """The health line for HICEM at ``hicem`` (its namespace, for the texts), whether it runs, and its
        latest state (None: none received yet)."""
        if not hicem_alive:
            return {"status": "fault", "detail": "HICEM is not running (no %s/stop service)" % hicem}
        if state is None:
            return {"status": "unknown", "detail": "no %s/state received yet" % hicem}
        if state.get("phase") == "waiting_for_health":
            return {"status": "fault", "detail": state.get("detail") or "HICEM waits for crucial modules"}
        now = self.clock()
        with self._lock:
            recent = {n: v for n, v in self._latest.items() if now - v[2] < self.fresh_s}
        for status in ("fault", "degraded"):
            lines = ["%s %s: %s" % (n, LEVEL_NAMES[lvl], m) for n, (lvl, m, _t) in sorted(recent.items())
                     if PAGE_STATUS[lvl] == status]
            if lines:
                return {"status": status, "detail": "; ".join(lines)}
        return {"status": "ok", "detail": "HICEM up" + (", %d diagnostics OK" % len(recent) if recent else "")}
