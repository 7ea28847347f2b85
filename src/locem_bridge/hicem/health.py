"""HEM (the paper's HICEM Environment Monitor): the environment/health monitor.

Inputs: module heartbeats (:meth:`HealthMonitor.heartbeat`) and status/diagnostic reports
(:meth:`report`, levels of :mod:`locem_bridge.common.health`: OK 0, WARN 1, ERROR 2, STALE 3). A module
is *faulty* when its last report is ERROR or STALE, or when it has a heartbeat timeout and no heartbeat
arrived within it. A *crucial* module turning faulty calls every fault listener once (the controller halts the
running tree); it is called from the reporting thread at once, or from the watchdog thread (period
``watchdog_period_s``) for heartbeat timeouts. Statuses are mirrored into the HDM volatile collection
``modules`` when a store is given.
"""
import threading
import time
from typing import Any, Callable, Dict, Iterable, List, Optional, Tuple, Union

from ..common.health import ERROR, LEVEL_NAMES, level_of
from .errors import HealthError


class ModuleSpec:
    def __init__(self, name: str, crucial: bool = False, heartbeat_timeout_s: Optional[float] = None) -> None:
        if not name:
            raise HealthError("a module needs a name")
        if heartbeat_timeout_s is not None and not heartbeat_timeout_s > 0:
            raise HealthError("module %s: heartbeat_timeout_s must be > 0, got %r" % (name, heartbeat_timeout_s))
        self.name = name
        self.crucial = crucial
        self.heartbeat_timeout_s = heartbeat_timeout_s

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "ModuleSpec":
        bad = set(d) - {"name", "crucial", "heartbeat_timeout_s"}
        if bad:
            raise HealthError("module entry %r: unknown keys %s; allowed: name, crucial, heartbeat_timeout_s"
                              % (d, sorted(bad)))
        return cls(d.get("name", ""), bool(d.get("crucial", False)), d.get("heartbeat_timeout_s"))


class _State:
    __slots__ = ("level", "message", "last_heartbeat", "stamp", "faulty")

    def __init__(self, now: float) -> None:
        self.level = 0
        self.message = ""
        self.last_heartbeat = now
        self.stamp = now
        self.faulty = False


class HealthMonitor:
    def __init__(self, modules: Iterable[ModuleSpec] = (), clock: Callable[[], float] = time.monotonic,
                 store: Any = None) -> None:
        self.clock = clock
        self.store = store
        self._lock = threading.Lock()
        self._specs: Dict[str, ModuleSpec] = {}
        self._state: Dict[str, _State] = {}
        self._listeners: List[Callable[[str, str], None]] = []
        self._stop = threading.Event()
        self._thread: Optional[threading.Thread] = None
        for m in modules:
            self.add_module(m)

    def add_module(self, spec: ModuleSpec) -> None:
        with self._lock:
            self._specs[spec.name] = spec
            self._state[spec.name] = _State(self.clock())

    def add_fault_listener(self, cb: Callable[[str, str], None]) -> None:
        self._listeners.append(cb)

    def heartbeat(self, module: str) -> None:
        with self._lock:
            st = self._ensure(module)
            st.last_heartbeat = self.clock()
        self.check()

    def report(self, module: str, level: Union[int, str], message: str = "") -> None:
        lv = self._level(level)
        with self._lock:
            st = self._ensure(module)
            st.level = lv
            st.message = message
            st.stamp = self.clock()
            st.last_heartbeat = st.stamp  # a report is also a sign of life
        if self.store is not None:
            self.store.put("modules", module, {"level": LEVEL_NAMES[lv], "message": message}, source="HEM")
        self.check()

    @staticmethod
    def _level(level: Union[int, str]) -> int:
        try:
            return level_of(level)
        except ValueError as exc:
            raise HealthError(str(exc))

    def _ensure(self, module: str) -> _State:
        if not isinstance(module, str) or not module:
            raise HealthError("module name must be a non-empty string, got %r" % (module,))
        if module not in self._state:
            self._specs[module] = ModuleSpec(module)  # unknown modules are tracked, never crucial
            self._state[module] = _State(self.clock())
        return self._state[module]

    def _fault_of(self, name: str, st: _State, now: float) -> Optional[str]:
        spec = self._specs[name]
        if st.level >= ERROR:
            return "%s reports %s: %s" % (name, LEVEL_NAMES[st.level], st.message or "no message")
        if spec.heartbeat_timeout_s is not None and now - st.last_heartbeat > spec.heartbeat_timeout_s:
            return "%s silent for %.2f s (heartbeat timeout %.2f s)" % (
                name, now - st.last_heartbeat, spec.heartbeat_timeout_s)
        return None

    def check(self) -> List[Tuple[str, str]]:
        """Evaluate every module; notify listeners of crucial modules that just became faulty."""
        now = self.clock()
        fired = []
        faults = []
        with self._lock:
            for name, st in self._state.items():
                reason = self._fault_of(name, st, now)
                if reason is not None and self._specs[name].crucial:
                    faults.append((name, reason))
                    if not st.faulty:
                        fired.append((name, reason))
                st.faulty = reason is not None
        for name, reason in fired:
            for cb in list(self._listeners):
                cb(name, reason)
        return faults

    def faults(self, modules: Optional[Iterable[str]] = None) -> List[Tuple[str, str]]:
        """(module, reason) for faulty modules: the crucial ones, or exactly the ``modules`` named."""
        now = self.clock()
        out = []
        with self._lock:
            names = list(modules) if modules else [n for n, s in self._specs.items() if s.crucial]
            for n in names:
                if n not in self._state:
                    out.append((n, "%s: no such module (known: %s)" % (n, ", ".join(sorted(self._state)))))
                    continue
                r = self._fault_of(n, self._state[n], now)
                if r is not None:
                    out.append((n, r))
        return out

    def snapshot(self) -> Dict[str, Dict[str, Any]]:
        now = self.clock()
        with self._lock:
            return {n: {"level": LEVEL_NAMES[s.level], "message": s.message, "crucial": self._specs[n].crucial,
                        "fault": self._fault_of(n, s, now)} for n, s in self._state.items()}

    def start_watchdog(self, period_s: float) -> None:
        if self._thread is not None:
            return
        self._stop.clear()

        def run() -> None:
            while not self._stop.wait(period_s):
                self.check()

        self._thread = threading.Thread(target=run, name="hicem-hem-watchdog", daemon=True)
        self._thread.start()

    def stop_watchdog(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
