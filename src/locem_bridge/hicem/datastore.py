"""HICEM data: the paper's HDM (HICEM Data Manager; volatile, in memory) and HDICT (HICEM Dictionary;
non-volatile, SQLite: :class:`SqliteStore`) behind one interface.

Both stores hold JSON values addressed by ``(collection, key)`` with a stamp (wall-clock seconds of the last
write) and a source tag. ``transaction()`` groups writes atomically: everything inside commits together or,
on an exception, not at all (in SQLite: one ``BEGIN IMMEDIATE`` … ``COMMIT``; the database runs in WAL mode,
so a committed transaction survives ``kill -9``; with ``synchronous=FULL``, the default, also a power loss).

:class:`DataManager` is the paper's HDM: it owns the volatile store, manages the HDICT (which collections are
persistent is configuration) and removes outdated entries by :class:`PruneRule`.
Thread safety: every store method takes the store's lock; a transaction holds it until it ends.
"""
import abc
import contextlib
import json
import math
import os
import sqlite3
import threading
import time
from typing import Any, Callable, Dict, Iterable, Iterator, List, Optional

from .errors import DataStoreError


class Entry:
    __slots__ = ("collection", "key", "value", "stamp", "source")

    def __init__(self, collection: str, key: str, value: Any, stamp: float, source: str = "") -> None:
        self.collection = collection
        self.key = key
        self.value = value
        self.stamp = stamp
        self.source = source

    def __repr__(self) -> str:
        return "Entry(%s/%s=%r @%.3f)" % (self.collection, self.key, self.value, self.stamp)


def _check_name(what: str, name: Any) -> None:
    if not isinstance(name, str) or not name or len(name) > 256:
        raise DataStoreError("%s must be a non-empty string of at most 256 characters, got %r" % (what, name))


def _encode(collection: str, key: str, value: Any) -> str:
    try:
        return json.dumps(value, allow_nan=False, sort_keys=True, separators=(",", ":"))
    except (TypeError, ValueError) as exc:
        raise DataStoreError("value for %s/%s is not storable as JSON (finite numbers, strings, lists, "
                             "objects only): %s" % (collection, key, exc))


class DataStore(abc.ABC):
    """One interface for HDM and HDICT."""

    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        self.clock = clock
        self._lock = threading.RLock()

    @abc.abstractmethod
    def get(self, collection: str, key: str) -> Optional[Entry]: ...

    @abc.abstractmethod
    def put(self, collection: str, key: str, value: Any, stamp: Optional[float] = None,
            source: str = "") -> Entry: ...

    @abc.abstractmethod
    def delete(self, collection: str, key: str) -> bool: ...

    @abc.abstractmethod
    def entries(self, collection: str) -> List[Entry]: ...

    @abc.abstractmethod
    def collections(self) -> List[str]: ...

    @abc.abstractmethod
    def transaction(self) -> "contextlib.AbstractContextManager[DataStore]": ...

    def close(self) -> None:
        pass

    def value(self, collection: str, key: str, default: Any = None) -> Any:
        e = self.get(collection, key)
        return default if e is None else e.value


class MemoryStore(DataStore):
    """HDM's volatile store: a dict of dicts; transactions snapshot the data and restore it on error."""

    def __init__(self, clock: Callable[[], float] = time.time) -> None:
        super().__init__(clock)
        self._data: Dict[str, Dict[str, Entry]] = {}

    def get(self, collection: str, key: str) -> Optional[Entry]:
        with self._lock:
            e = self._data.get(collection, {}).get(key)
            return None if e is None else Entry(e.collection, e.key, json.loads(json.dumps(e.value)),
                                                e.stamp, e.source)

    def put(self, collection: str, key: str, value: Any, stamp: Optional[float] = None,
            source: str = "") -> Entry:
        _check_name("collection", collection)
        _check_name("key", key)
        text = _encode(collection, key, value)
        e = Entry(collection, key, json.loads(text), self.clock() if stamp is None else stamp, source)
        with self._lock:
            self._data.setdefault(collection, {})[key] = e
        return e

    def delete(self, collection: str, key: str) -> bool:
        with self._lock:
            return self._data.get(collection, {}).pop(key, None) is not None

    def entries(self, collection: str) -> List[Entry]:
        with self._lock:
            return [Entry(e.collection, e.key, e.value, e.stamp, e.source)
                    for e in self._data.get(collection, {}).values()]

    def collections(self) -> List[str]:
        with self._lock:
            return sorted(c for c, d in self._data.items() if d)

    @contextlib.contextmanager
    def transaction(self) -> Iterator["MemoryStore"]:
        with self._lock:
            snapshot = {c: dict(d) for c, d in self._data.items()}
            try:
                yield self
            except BaseException:
                self._data = snapshot
                raise


class SqliteStore(DataStore):
    """HDICT: one SQLite file; every write outside a transaction is its own committed transaction."""

    SCHEMA = ("CREATE TABLE IF NOT EXISTS entries (collection TEXT NOT NULL, key TEXT NOT NULL, "
              "value TEXT NOT NULL, stamp REAL NOT NULL, source TEXT NOT NULL DEFAULT '', "
              "PRIMARY KEY (collection, key))")

    def __init__(self, path: str, clock: Callable[[], float] = time.time, timeout_s: float = 5.0,
                 synchronous: str = "FULL") -> None:
        """``synchronous``: FULL (default) = a commit is on disk when put() returns (survives power loss);
        NORMAL = on a process kill nothing committed is lost, on power loss the last commits may be."""
        super().__init__(clock)
        if synchronous not in ("FULL", "NORMAL"):
            raise DataStoreError("HDICT synchronous must be FULL or NORMAL, got %r" % (synchronous,))
        self.path = path
        d = os.path.dirname(os.path.abspath(path))
        if not os.path.isdir(d):
            raise DataStoreError("HDICT directory %s does not exist" % d)
        try:
            self._db = sqlite3.connect(path, timeout=timeout_s, isolation_level=None, check_same_thread=False)
            self._db.execute("PRAGMA journal_mode=WAL")
            self._db.execute("PRAGMA synchronous=%s" % synchronous)
            self._db.execute(self.SCHEMA)
        except sqlite3.DatabaseError as exc:
            raise DataStoreError("cannot open HDICT database %s: %s" % (path, exc))
        self._depth = 0

    def _exec(self, sql: str, args: tuple = ()) -> sqlite3.Cursor:
        if self._db is None:
            raise DataStoreError("HDICT %s is closed" % self.path)
        try:
            return self._db.execute(sql, args)
        except sqlite3.DatabaseError as exc:
            raise DataStoreError("HDICT %s: %s" % (self.path, exc))

    def get(self, collection: str, key: str) -> Optional[Entry]:
        with self._lock:
            row = self._exec("SELECT value, stamp, source FROM entries WHERE collection=? AND key=?",
                             (collection, key)).fetchone()
        return None if row is None else Entry(collection, key, json.loads(row[0]), row[1], row[2])

    def put(self, collection: str, key: str, value: Any, stamp: Optional[float] = None,
            source: str = "") -> Entry:
        _check_name("collection", collection)
        _check_name("key", key)
        text = _encode(collection, key, value)
        st = self.clock() if stamp is None else float(stamp)
        if not math.isfinite(st):
            raise DataStoreError("stamp for %s/%s must be finite" % (collection, key))
        with self._lock:
            self._exec("INSERT OR REPLACE INTO entries (collection, key, value, stamp, source) "
                       "VALUES (?, ?, ?, ?, ?)", (collection, key, text, st, source))
        return Entry(collection, key, json.loads(text), st, source)

    def delete(self, collection: str, key: str) -> bool:
        with self._lock:
            return self._exec("DELETE FROM entries WHERE collection=? AND key=?", (collection, key)).rowcount > 0

    def entries(self, collection: str) -> List[Entry]:
        with self._lock:
            rows = self._exec("SELECT key, value, stamp, source FROM entries WHERE collection=? ORDER BY key",
                              (collection,)).fetchall()
        return [Entry(collection, r[0], json.loads(r[1]), r[2], r[3]) for r in rows]

    def collections(self) -> List[str]:
        with self._lock:
            return [r[0] for r in self._exec("SELECT DISTINCT collection FROM entries ORDER BY 1").fetchall()]

    @contextlib.contextmanager
    def transaction(self) -> Iterator["SqliteStore"]:
        with self._lock:
            outer = self._depth == 0
            if outer:
                self._exec("BEGIN IMMEDIATE")
            self._depth += 1
            try:
                yield self
            except BaseException:
                self._depth -= 1
                if outer:
                    self._exec("ROLLBACK")
                raise
            self._depth -= 1
            if outer:
                self._exec("COMMIT")

    def close(self) -> None:
        with self._lock:
            if self._db is not None:
                self._db.close()
                self._db = None  # type: ignore[assignment]


class PruneRule:
    """When an entry of ``collection`` is outdated. Any combination of:

    ``max_age_s``: older than this (by stamp); ``keep_latest``: only the newest N are kept;
    ``below``: ``(field, ref_collection, ref_key)`` — the entry's ``value[field]`` is lower than the value
    stored at ``ref_collection/ref_key`` (e.g. features from a scan older than the latest scan of their wall
    are dropped: ``("scan_seq", "scan", "latest_seq")``).
    """

    def __init__(self, collection: str, max_age_s: Optional[float] = None, keep_latest: Optional[int] = None,
                 below: Optional[Iterable[str]] = None) -> None:
        self.collection = collection
        self.max_age_s = max_age_s
        self.keep_latest = keep_latest
        self.below = tuple(below) if below else None
        if self.below is not None and len(self.below) != 3:
            raise DataStoreError("prune rule 'below' needs [field, ref_collection, ref_key], got %r" % (below,))

    @classmethod
    def from_dict(cls, d: Dict[str, Any]) -> "PruneRule":
        allowed = {"collection", "max_age_s", "keep_latest", "below"}
        bad = set(d) - allowed
        if bad or "collection" not in d:
            raise DataStoreError("prune rule %r: needs 'collection'; allowed keys: %s" % (d, ", ".join(sorted(allowed))))
        return cls(d["collection"], d.get("max_age_s"), d.get("keep_latest"), d.get("below"))


class DataManager:
    """HDM: one facade over the volatile store and the HDICT, with pruning of outdated entries."""

    def __init__(self, volatile: Optional[DataStore] = None, persistent: Optional[DataStore] = None,
                 persistent_collections: Iterable[str] = (), rules: Iterable[PruneRule] = (),
                 clock: Callable[[], float] = time.time) -> None:
        self.volatile = volatile or MemoryStore(clock)
        self.persistent = persistent or self.volatile
        self.persistent_collections = set(persistent_collections)
        self.rules = list(rules)
        self.clock = clock

    def store_for(self, collection: str) -> DataStore:
        return self.persistent if collection in self.persistent_collections else self.volatile

    def get(self, collection: str, key: str) -> Optional[Entry]:
        return self.store_for(collection).get(collection, key)

    def value(self, collection: str, key: str, default: Any = None) -> Any:
        return self.store_for(collection).value(collection, key, default)

    def put(self, collection: str, key: str, value: Any, stamp: Optional[float] = None, source: str = "") -> Entry:
        return self.store_for(collection).put(collection, key, value, stamp, source)

    def delete(self, collection: str, key: str) -> bool:
        return self.store_for(collection).delete(collection, key)

    def entries(self, collection: str) -> List[Entry]:
        return self.store_for(collection).entries(collection)

    def transaction(self):
        """Atomic group of writes to the persistent collections (and volatile ones, best effort)."""
        return self.persistent.transaction()

    def prune(self, now: Optional[float] = None) -> Dict[str, List[str]]:
        """Apply every rule; returns the removed keys per collection."""
        now = self.clock() if now is None else now
        removed: Dict[str, List[str]] = {}
        for rule in self.rules:
            store = self.store_for(rule.collection)
            with store.transaction():
                entries = store.entries(rule.collection)
                drop = set()
                if rule.max_age_s is not None:
                    drop |= {e.key for e in entries if now - e.stamp > rule.max_age_s}
                if rule.keep_latest is not None:
                    ordered = sorted(entries, key=lambda e: e.stamp, reverse=True)
                    drop |= {e.key for e in ordered[rule.keep_latest:]}
                if rule.below is not None:
                    field, rc, rk = rule.below
                    ref = self.value(rc, rk)
                    if isinstance(ref, (int, float)):
                        drop |= {e.key for e in entries if isinstance(e.value, dict)
                                 and isinstance(e.value.get(field), (int, float)) and e.value[field] < ref}
                for k in sorted(drop):
                    store.delete(rule.collection, k)
            if drop:
                removed.setdefault(rule.collection, []).extend(sorted(drop))
        return removed

    def close(self) -> None:
        self.volatile.close()
        if self.persistent is not self.volatile:
            self.persistent.close()
