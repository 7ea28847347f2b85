"""The default persistent store: pyoxigraph in memory + an N-Quads snapshot + an append-only journal.

Why (measured by ``bench/bench_pemkre.py``, section "store choice"): the per-decision queries of the shipped
processes run about 1.7x faster on oxigraph's in-memory indexes than on its RocksDB backend, and much faster than
on rdflib's own store; a journal gives the same crash safety for a fraction of the write cost.

Layout of the directory ``path``: ``LOCK`` (an exclusive ``flock``: one process per store), ``snapshot.nq`` (the
whole dataset at the last compaction) and ``journal.log``. Each :meth:`apply` first appends one self-checking
record ``@TX <length> <crc32>\\n<body>`` (body lines ``- <quad>`` / ``+ <quad>`` / ``C <graph>`` in N-Quads
syntax, written with one ``write`` call), then changes the in-memory dataset. Once ``apply`` has returned, the
record is in the operating system's page cache, which a ``kill -9`` of this process cannot lose; pass
``fsync=True`` to also survive power loss (at the cost of one disk flush per change). On open the snapshot is
loaded and the journal replayed; a torn last record (the process died inside ``write``) is detected by its length
or checksum, dropped and cut off. :meth:`compact` (also run on open when the journal is large) rewrites the
snapshot atomically and empties the journal; replaying a journal over a newer snapshot is harmless because each
record sets the final presence of the quads it names.
"""
import fcntl
import io
import os
import zlib
from typing import Iterable, List, Optional

import pyoxigraph as ox
from rdflib import BNode, URIRef

from .errors import StoreError
from .oxigraph_store import OxigraphStore, to_ox
from .store import ChangeSet, Triple

_SNAPSHOT = "snapshot.nq"
_JOURNAL = "journal.log"


class JournaledStore(OxigraphStore):
    """See the module docstring. ``close()`` releases the lock; the data stays in ``path``."""

    def __init__(self, path: str, fsync: bool = False, compact_bytes: int = 64 * 1024 * 1024,
                 rebuild_after_removals: int = 10_000) -> None:
        try:
            os.makedirs(path, exist_ok=True)
            self._lock_fd: Optional[int] = os.open(os.path.join(path, "LOCK"), os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise StoreError("cannot open the triplestore directory %r: %s" % (path, exc)) from None
        try:
            fcntl.flock(self._lock_fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(self._lock_fd)
            self._lock_fd = None
            raise StoreError("the triplestore at %r is in use by another process (lock held)" % path) from None
        super().__init__(None)
        self.rebuild_after_removals = rebuild_after_removals
        self.path = path
        self.persistent = True
        self.fsync = fsync
        self.replayed_records = 0
        self.dropped_bytes = 0
        self.removals = 0  # since the in-memory indexes were last rebuilt
        snap = os.path.join(path, _SNAPSHOT)
        try:
            if os.path.exists(snap):
                self._store.bulk_load(path=snap, format=ox.RdfFormat.N_QUADS)
            self._replay(os.path.join(path, _JOURNAL))
            self._jfd: Optional[int] = os.open(os.path.join(path, _JOURNAL), os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        except StoreError:
            self._release()
            raise
        except Exception as exc:
            self._release()
            raise StoreError("cannot load the triplestore at %r: %s" % (path, exc)) from None
        if os.path.getsize(os.path.join(path, _JOURNAL)) > compact_bytes:
            self.compact()

    # ---------------------------------------------------------------- journal
    def _replay(self, journal: str) -> None:
        if not os.path.exists(journal):
            return
        with open(journal, "rb") as fh:
            data = fh.read()
        pos, good = 0, 0
        while pos < len(data):
            nl = data.find(b"\n", pos)
            if nl < 0:
                break
            head = data[pos:nl].split()
            if len(head) != 3 or head[0] != b"@TX":
                break
            try:
                length, crc = int(head[1]), int(head[2], 16)
            except ValueError:
                break
            body = data[nl + 1:nl + 1 + length]
            if len(body) != length or zlib.crc32(body) != crc:
                break
            self._apply_body(body)
            pos = nl + 1 + length
            good = pos
            self.replayed_records += 1
        if good < len(data):
            self.dropped_bytes = len(data) - good
            with open(journal, "r+b") as fh:
                fh.truncate(good)

    def _apply_body(self, body: bytes) -> None:
        removes, adds = [], []
        for line in body.split(b"\n"):
            if not line:
                continue
            tag, rest = line[:1], line[2:]
            if tag == b"C":
                g = ox.NamedNode(rest.decode("utf-8").strip()[1:-1])
                if self._store.contains_named_graph(g):
                    self._store.clear_graph(g)
            elif tag == b"-":
                removes.append(rest)
            elif tag == b"+":
                adds.append(rest)
        if removes:
            for q in ox.parse(b"\n".join(removes) + b"\n", format=ox.RdfFormat.N_QUADS):
                self._store.remove(q)
        if adds:
            self._store.extend(list(ox.parse(b"\n".join(adds) + b"\n", format=ox.RdfFormat.N_QUADS)))

    def _append(self, body: str) -> None:
        raw = body.encode("utf-8")
        rec = b"@TX %d %08x\n" % (len(raw), zlib.crc32(raw)) + raw
        if self._jfd is None:
            raise StoreError("the triplestore is closed")
        try:
            view = memoryview(rec)
            while view:
                n = os.write(self._jfd, view)
                view = view[n:]
            if self.fsync:
                os.fsync(self._jfd)
        except OSError as exc:
            raise StoreError("journal write failed (the change was not applied): %s" % exc) from None

    # ---------------------------------------------------------------- writes
    def apply(self, changes: ChangeSet) -> None:
        if not changes:
            return
        lines: List[str] = []
        rem, add = [], []
        for q in changes.remove:
            if any(isinstance(t, BNode) for t in q[:3]):
                raise StoreError("blank nodes cannot be written through apply(): %r" % (q,))
            oq = ox.Quad(to_ox(q[0]), to_ox(q[1]), to_ox(q[2]), self._g(q[3]))
            rem.append(oq)
            lines.append("- %s .\n" % oq)
        for q in changes.add:
            if any(isinstance(t, BNode) for t in q[:3]):
                raise StoreError("blank nodes cannot be written through apply(): %r" % (q,))
            oq = ox.Quad(to_ox(q[0]), to_ox(q[1]), to_ox(q[2]), self._g(q[3]))
            add.append(oq)
            lines.append("+ %s .\n" % oq)
        with self._write_lock:
            self._check_expected(changes)
            if not lines:
                return
            self._append("".join(lines))
            for oq in rem:
                self._store.remove(oq)
            self._store.extend(add)
            self.removals += len(rem)
        self._written(changes)

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        g = self._g(graph)
        quads = [ox.Quad(to_ox(s), to_ox(p), to_ox(o), g) for s, p, o in triples]
        with self._write_lock:
            self._append("C %s\n" % g + "".join("+ %s .\n" % q for q in quads))
            if self._store.contains_named_graph(g):
                self._store.clear_graph(g)
            self._store.extend(quads)
        self._written(None)

    def maintain(self) -> None:
        """After ``rebuild_after_removals`` removals: rebuild the in-memory indexes from the live quads (removed
        entries otherwise stay in the way of lookups of the same subject/predicate) and compact the journal."""
        if self.removals >= self.rebuild_after_removals:
            self.compact(rebuild=True)

    def compact(self, rebuild: bool = False) -> None:
        """Write a new snapshot atomically, then empty the journal; ``rebuild`` also renews the in-memory store."""
        snap = os.path.join(self.path, _SNAPSHOT)
        tmp = snap + ".tmp"
        buf = io.BytesIO()
        self._store.dump(buf, format=ox.RdfFormat.N_QUADS)
        if rebuild:
            fresh = ox.Store()
            fresh.bulk_load(buf.getvalue(), format=ox.RdfFormat.N_QUADS)
            self._store = fresh
            self.removals = 0
        with open(tmp, "wb") as fh:
            fh.write(buf.getvalue())
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, snap)
        dfd = os.open(self.path, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
        if self._jfd is not None:
            os.ftruncate(self._jfd, 0)
            os.fsync(self._jfd)

    def flush(self) -> None:
        if self._jfd is not None:
            os.fsync(self._jfd)

    def _release(self) -> None:
        for attr in ("_jfd", "_lock_fd"):
            fd = getattr(self, attr, None)
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass
                setattr(self, attr, None)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                if self._jfd is not None:
                    os.fsync(self._jfd)
            finally:
                self._release()
