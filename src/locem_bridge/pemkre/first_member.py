"""The first member of a class by a numeric order property, kept up to date beside the store.

A task parameter such as "the next pending joint line" is the member of a class (``ppr:TapingPending``) with the
lowest value of an order property (``ppr:scanOrder``). As a SPARQL query (``ORDER BY ?order LIMIT 1``) that reads
and sorts every member: at 100,000 features it cost hundreds of milliseconds per decision. A parameter declared
with ``proc:selectsMemberOf`` and ``proc:orderedBy`` (ontologies/process.ttl) is answered instead by
:class:`FirstMember`, a heap of (order, member) entries that is

* **built** once from the store (one query over the class) when the engine starts or after a graph was replaced;
* **fed** by every change the store applies (:meth:`~locem_bridge.pemkre.store.TripleStore.watch`): an added
  ``rdf:type`` of the class or an added order value pushes the subject's entries; nothing is removed on a write;
* **checked when read**: the top entry counts only if its subject still is a member and still has that order
  value (two index lookups); stale entries are popped. Each subject leaves the heap once per time it stops being a
  member, so a decision costs the same at any world size.

The answer is the one of the equivalent query (:func:`query_text`): the lowest order, numerically, ties broken by
the member's IRI. Only order values that are numbers can be kept; a store with another kind of value there, or a
store that is not the only writer of its data (a SPARQL server other clients write to), is answered by the query
(:attr:`FirstMember.usable` is False then, with the reason in :attr:`FirstMember.why_not`).
"""
import heapq
import itertools
import threading
from decimal import Decimal
from typing import List, Optional, Set, Tuple, Union

from rdflib import RDF, Literal, URIRef
from rdflib.term import Node

from .store import ChangeSet, TripleStore

Number = Union[int, float, Decimal]


class Unanswerable(Exception):
    """The index cannot answer (see :attr:`FirstMember.why_not`); run the equivalent query instead."""


_Entry = Tuple[Number, str, int, URIRef, Literal]


def query_text(cls: URIRef, order: URIRef) -> str:
    """The SPARQL SELECT with the same answer as :meth:`FirstMember.first` (the order values are joined from a
    sub-query, so a server hashes the two sets instead of one lookup per member)."""
    return ("SELECT ?value WHERE { ?value a %s . { SELECT ?value ?order WHERE { ?value %s ?order } } } "
            "ORDER BY ?order ?value LIMIT 1" % (cls.n3(), order.n3()))


def _number(value: Node) -> Optional[Number]:
    """The numeric value of a literal, None for anything else (booleans are not numbers here)."""
    if not isinstance(value, Literal):
        return None
    v = value.toPython()
    if isinstance(v, bool) or not isinstance(v, (int, float, Decimal)):
        return None
    return v


class FirstMember:
    """The lowest-ordered member of ``cls`` by ``order`` on ``store``; see the module docstring."""

    def __init__(self, store: TripleStore, cls: URIRef, order: URIRef) -> None:
        self.store = store
        self.cls = cls
        self.order = order
        self._heap: List[_Entry] = []
        self._queued: Set[Tuple[URIRef, Literal]] = set()
        self._seq = itertools.count()
        self._lock = threading.Lock()
        self._stale = True
        #: why the index cannot answer (then the caller runs the query); "" while it can
        self.why_not = ""
        if not store.watch(self._on_write):
            self.why_not = "the store is not the only writer of its data"

    @property
    def usable(self) -> bool:
        return not self.why_not

    # ---------------------------------------------------------------- feeding
    def _push(self, subject: Node, value: Node) -> None:
        if not isinstance(subject, URIRef) or (subject, value) in self._queued:
            return
        number = _number(value)
        if number is None:
            self.why_not = "%s has the order value %s, which is not a number" % (subject.n3(), value.n3())
            return
        self._queued.add((subject, value))  # type: ignore[arg-type]
        heapq.heappush(self._heap, (number, str(subject), next(self._seq), subject, value))  # type: ignore[arg-type]

    def _on_write(self, changes: Optional[ChangeSet]) -> None:
        with self._lock:
            if changes is None:  # a whole graph was replaced: build again when next read
                self._stale = True
                return
            if self._stale or not self.usable:
                return
            for s, p, o, _ in changes.add:
                if p == self.order:
                    self._push(s, o)
                elif p == RDF.type and o == self.cls:
                    for _, _, value, _ in self.store.quads(s, self.order, None, None):
                        self._push(s, value)

    def _build(self) -> None:
        self._heap, self._queued, self.why_not = [], set(), ""
        members = {s for s, _, _, _ in self.store.quads(None, RDF.type, self.cls, None)}
        for s in members:
            for _, _, value, _ in self.store.quads(s, self.order, None, None):
                self._push(s, value)
        self._stale = False

    # ---------------------------------------------------------------- reading
    def _holds(self, subject: URIRef, value: Literal) -> bool:
        return (any(True for _ in self.store.quads(subject, RDF.type, self.cls, None))
                and any(True for _ in self.store.quads(subject, self.order, value, None)))

    def first(self) -> Optional[URIRef]:
        """The member with the lowest order (ties: the lowest IRI), or None when the class has no ordered member.
        Raises :class:`Unanswerable` when the index cannot answer (then run :func:`query_text`)."""
        with self._lock:
            if self._stale and self.store.sole_writer:
                self._build()
            if not self.usable:
                raise Unanswerable("the first %s by %s: %s" % (self.cls.n3(), self.order.n3(), self.why_not))
            while self._heap:
                _, _, _, subject, value = self._heap[0]
                if self._holds(subject, value):
                    return subject
                heapq.heappop(self._heap)
                self._queued.discard((subject, value))
            return None

    def __len__(self) -> int:
        """Entries held (members, plus stale entries not yet popped)."""
        return len(self._heap)
