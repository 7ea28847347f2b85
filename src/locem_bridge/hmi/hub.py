"""The state hub: one thread that polls the backend and keeps the document every page and stream shows.

Lifecycle: ``StateHub(backend, ...)`` -> :meth:`start` (one synchronous poll, then a daemon thread) ->
:meth:`close`. The hub calls ``snapshot()`` and ``prompts()`` every ``poll_period_s``, ``wall_pictures()`` every
``picture_period_s``, ``kpis()`` every ``kpi_period_s`` and ``list_processes()`` every ``process_period_s``, and
the backend's optional ``manual_work()`` (the planned manual work reported so far, cached by the backend) with
the snapshot, each guarded on its own (a failing call leaves the last good value and sets ``backend_error``).
Whenever the document changes its ``version`` grows by one and :meth:`wait_for_change` waiters wake up, so the
Server-Sent-Events streams push only changes; nothing is pushed while nothing changes. After a start, stop or
reply the server calls :meth:`refresh_now` (snapshot and prompts read at once in the request's thread, never
waiting behind a slow poll; the rest follows from the hub thread).

Pictures are cached: bytes as given, paths by (mtime, size) and read when served. Each wall gets a short
``version`` token that changes with the picture, so the page reloads an image only when it changed.
"""
import json
import logging
import os
import re
import threading
import time
import uuid
import zlib
from typing import Any, Callable, Dict, List, Optional, Tuple

from .backend import HmiBackend, normalize_prompt, normalize_snapshot
from .errors import BackendRefused, BackendUnavailable

LOG = logging.getLogger("locem_bridge.hmi.hub")
WALL_ID = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
PNG_END = b"IEND\xaeB`\x82"          # the IEND chunk's type and CRC: a file without it is still being written
MAX_EVENTS = 50


def _describe(err: BaseException) -> str:
    text = str(err) or type(err).__name__
    return text if isinstance(err, (BackendRefused, BackendUnavailable)) else "%s: %s" % (type(err).__name__, text)


class StateHub:
    def __init__(self, backend: HmiBackend, poll_period_s: float = 0.25, picture_period_s: float = 1.0,
                 kpi_period_s: float = 2.0, process_period_s: float = 10.0,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.backend = backend
        self.poll_period_s = float(poll_period_s)
        self.picture_period_s = float(picture_period_s)
        self.kpi_period_s = float(kpi_period_s)
        self.process_period_s = float(process_period_s)
        self.clock = clock
        self._cond = threading.Condition()
        self._poke = threading.Event()
        self._closed = threading.Event()
        self._thread: Optional[threading.Thread] = None
        self._version = 0
        self._doc_json = ""
        self._doc: Dict[str, Any] = {}
        self._snapshot: Dict[str, Any] = normalize_snapshot({})
        self._prompts: List[Dict[str, Any]] = []
        self._kpis: Dict[str, Any] = {}
        self._processes: List[Dict[str, Any]] = []
        self._manual: List[Dict[str, Any]] = []           # the backend's manual_work(), when it has one
        self._pictures: Dict[str, Tuple[str, Any]] = {}   # wall id -> (version token, bytes | path)
        self._errors: Dict[str, str] = {}                  # backend call -> last error text
        self._events: List[Dict[str, Any]] = []
        self._next: Dict[str, float] = {"pictures": 0.0, "kpis": 0.0, "processes": 0.0}
        self._poll_lock = threading.Lock()
        self.server_id = uuid.uuid4().hex[:8]   # lets a page tell a restarted server (versions start again)

    # -- lifecycle -----------------------------------------------------------------------------------------
    def start(self) -> None:
        self.poll(force=True)
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name="hmi-hub", daemon=True)
            self._thread.start()

    def close(self) -> None:
        self._closed.set()
        self._poke.set()
        with self._cond:
            self._cond.notify_all()
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    @property
    def closed(self) -> bool:
        return self._closed.is_set()

    def _run(self) -> None:
        while not self._closed.is_set():
            self._poke.wait(self.poll_period_s)
            self._poke.clear()
            if self._closed.is_set():
                break
            try:
                self.poll()
            except Exception:  # never let the hub thread die; the page shows backend_error
                LOG.exception("HMI hub poll failed")

    def poke(self) -> None:
        """Poll again as soon as possible, in the hub thread."""
        self._next["kpis"] = 0.0
        self._next["pictures"] = 0.0
        self._poke.set()

    def refresh_now(self) -> None:
        """After the operator changed something: read snapshot and prompts now, in the caller's thread, so the
        answer to the request and the next pushed document already show the change; pictures and KPIs (possibly
        slow) follow from the hub thread at once. If a poll is running (a slow backend), do not wait for it."""
        self._next["kpis"] = 0.0
        self._next["pictures"] = 0.0
        self._poke.set()
        if not self._poll_lock.acquire(blocking=False):
            return
        try:
            self._poll_locked(force=False, quick=True)
        except Exception:  # noqa: BLE001 - the hub thread will try again; the request itself succeeded
            LOG.exception("HMI hub poll failed")
        finally:
            self._poll_lock.release()

    # -- polling -------------------------------------------------------------------------------------------
    def _call(self, name: str, fn: Callable[[], Any]) -> Tuple[bool, Any]:
        try:
            value = fn()
        except Exception as err:  # noqa: BLE001 - any backend failure is shown, not raised into the server
            text = _describe(err)
            if self._errors.get(name) != text:
                LOG.warning("backend %s() failed: %s", name, text)
            self._errors[name] = text
            return False, None
        self._errors.pop(name, None)
        return True, value

    def poll(self, force: bool = False) -> None:
        """Read the backend once (the slow parts only when due) and publish a new version if anything changed."""
        with self._poll_lock:
            self._poll_locked(force)

    def _poll_locked(self, force: bool, quick: bool = False) -> None:
        now = self.clock()
        ok, snap = self._call("snapshot", self.backend.snapshot)
        if ok:
            try:
                self._snapshot = normalize_snapshot(snap)
            except TypeError as err:
                self._errors["snapshot"] = str(err)
        ok, prompts = self._call("prompts", self.backend.prompts)
        if ok:
            good = []
            for item in prompts or []:
                try:
                    good.append(normalize_prompt(item))
                except ValueError as err:
                    self._errors["prompts"] = "malformed prompt skipped: %s" % err
            self._prompts = good
        self._refresh_manual()
        if quick:
            self._publish()
            return
        if force or now >= self._next["pictures"]:
            self._next["pictures"] = now + self.picture_period_s
            self._refresh_pictures()
        if force or now >= self._next["kpis"]:
            self._next["kpis"] = now + self.kpi_period_s
            ok, kpis = self._call("kpis", self.backend.kpis)
            if ok:
                self._kpis = kpis if isinstance(kpis, dict) else {}
        if force or now >= self._next["processes"]:
            self._next["processes"] = now + self.process_period_s
            self.refresh_processes()
        self._publish()

    def refresh_processes(self) -> List[Dict[str, Any]]:
        ok, procs = self._call("list_processes", self.backend.list_processes)
        if ok:
            self._processes = [{"iri": str(p.get("iri", "")), "name": str(p.get("name", "") or p.get("iri", "")),
                                "description": str(p.get("description", "") or "")}
                               for p in (procs or []) if isinstance(p, dict) and p.get("iri")]
        return list(self._processes)

    def _refresh_manual(self) -> None:
        fn = getattr(self.backend, "manual_work", None)
        if fn is None:
            return
        ok, manual = self._call("manual_work", fn)
        if ok:
            self._manual = [dict(m) for m in (manual or []) if isinstance(m, dict)]

    def _refresh_pictures(self) -> None:
        ok, pics = self._call("wall_pictures", self.backend.wall_pictures)
        if not ok:
            return
        fresh: Dict[str, Tuple[str, Any]] = {}
        for wid, src in sorted((pics or {}).items()):
            if not isinstance(wid, str) or not WALL_ID.match(wid):
                self._errors["wall_pictures"] = "wall id %r is not a feature id ([A-Za-z][A-Za-z0-9_]*)" % (wid,)
                continue
            if isinstance(src, (bytes, bytearray)):
                fresh[wid] = ("%08x%x" % (zlib.crc32(bytes(src)) & 0xFFFFFFFF, len(src)), bytes(src))
            elif isinstance(src, (str, os.PathLike)):
                path = os.fspath(src)
                try:
                    st = os.stat(path)
                    token = "%x%x" % (st.st_mtime_ns, st.st_size)
                except OSError:
                    token = ""          # not written yet: listed, shown as "not available yet"
                fresh[wid] = (token, path)
            else:
                self._errors["wall_pictures"] = "picture of %s is %s, expected PNG bytes or a path" % (
                    wid, type(src).__name__)
        self._pictures = fresh

    def _publish(self) -> None:
        walls = [{"id": wid, "version": token,
                  "url": ("/api/walls/%s.png?v=%s" % (wid, token)) if token else ""}
                 for wid, (token, _src) in sorted(self._pictures.items())]
        with self._cond:                  # an RLock: note() holds it while appending an event
            body = {"snapshot": self._snapshot, "prompts": self._prompts, "kpis": self._kpis, "walls": walls,
                    "processes": self._processes, "manual": self._manual,
                    "backend_error": "; ".join("%s(): %s" % kv for kv in sorted(dict(self._errors).items())),
                    "events": list(self._events)}
            text = json.dumps(body, sort_keys=True, default=str)
            if text != self._doc_json:
                self._doc_json = text
                self._version += 1
                self._doc = dict(body, version=self._version, server_id=self.server_id)
                self._cond.notify_all()

    # -- readers -------------------------------------------------------------------------------------------
    def state(self) -> Dict[str, Any]:
        with self._cond:
            return dict(self._doc)

    def wait_for_change(self, seen_version: int, timeout: float) -> Optional[Dict[str, Any]]:
        """The document once its version differs from ``seen_version``; None on timeout or when closing."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while self._version == seen_version and not self._closed.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._cond.wait(left)
            if self._closed.is_set():
                return None
            return dict(self._doc)

    def processes(self) -> List[Dict[str, Any]]:
        return list(self._processes)

    def picture(self, wall_id: str) -> Tuple[str, Optional[bytes], str]:
        """``(state, png, message)``: state is ``ok``, ``unknown`` (no such wall), ``missing`` (not written yet)
        or ``bad`` (not a PNG)."""
        entry = self._pictures.get(wall_id)
        if entry is None and self._poll_lock.acquire(blocking=False):   # never wait behind a slow poll
            try:
                self._refresh_pictures()
            finally:
                self._poll_lock.release()
            entry = self._pictures.get(wall_id)
        if entry is None:
            return "unknown", None, "no wall %r; walls: %s" % (wall_id, ", ".join(sorted(self._pictures)) or "none")
        _token, src = entry
        if isinstance(src, bytes):
            data = src
        else:
            try:
                with open(src, "rb") as fh:
                    data = fh.read()
            except OSError as err:
                return "missing", None, "picture of %s is not available yet (%s)" % (wall_id, err.strerror)
        if not data.startswith(PNG_SIGNATURE):
            return "bad", None, "the backend's picture of %s is not a PNG" % wall_id
        if not data.endswith(PNG_END):
            return "missing", None, "picture of %s is incomplete (still being written); try again" % wall_id
        return "ok", data, ""

    def note(self, text: str, level: str = "info") -> None:
        """Add a line to the operator's event log (shown on the page) and publish."""
        stamp = time.strftime("%H:%M:%S")
        with self._cond:
            self._events.append({"time": stamp, "level": level, "text": text})
            del self._events[:-MAX_EVENTS]
            self._publish()
