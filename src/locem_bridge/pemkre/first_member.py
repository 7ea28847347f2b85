"""The first member of a class by a numeric order property, kept up to date beside the store.

A task parameter such as "the next pending joint line" is the member of a class (``ppr:TapingPending``) with the
lowest value of an order property (``ppr:scanOrder``). As a SPARQL query (``ORDER BY ?order LIMIT 1``) that reads
and sorts every member: at 100,000 features it cost hundreds of milliseconds per decision. A parameter declared
with ``proc:selectsMemberOf`` and ``proc:orderedBy`` (ontologies/process.ttl) is answered instead by
:class:`FirstMember`, a heap of (order, member) entries that is

* **built** once from the store (the class's members and their order values) when the engine starts, after a
  graph was replaced, and whenever it could not follow a write;
* **fed** by every change the store applies (:meth:`~locem_bridge.pemkre.store.TripleStore.watch`): an added
  ``rdf:type`` of the class pushes the subject's order values, an added order value of a member pushes that value;
  nothing is removed on a write;
* **checked when read**: the top entry counts only if its subject still is a member and still has that order
  value (two index lookups); stale entries are popped. An entry is pushed once while it is queued, so the heap
  holds at most one entry per (member since the last build, order value), and choosing costs the same at any
  world size.

The answer is the one of the equivalent query (:func:`query_text`): the lowest order, numerically, ties broken by
the member's IRI. Order values must be numbers of one
kind of arithmetic: integers with decimals, or integers with floats/doubles (SPARQL compares a decimal with a
double as doubles, Python exactly). A value that is not a number (or NaN), decimals mixed with doubles, a blank
node member (no parameter value: the engine refuses it), or a store whose changes it cannot all see (the plain
SPARQL store: other clients write to the server; the store that keeps a copy of the server's data tells it about
each of its own writes and each time it loads its copy again), and the index steps aside:
:attr:`FirstMember.why_not` says why, :meth:`FirstMember.first` raises :class:`Unanswerable` and the caller runs
the query. Once the offending values are gone the index builds again and answers.
"""
import heapq
import itertools
import math
import threading
from decimal import Decimal
from typing import Dict, List, Optional, Set, Tuple, Union

from rdflib import RDF, Literal, URIRef
from rdflib.term import Node

from .store import ChangeSet, TripleStore

Number = Union[int, float, Decimal]


class Unanswerable(Exception):
    """The index cannot answer (see :attr:`FirstMember.why_not`); run the equivalent query instead."""


_Entry = Tuple[Number, str, int, URIRef, Literal]


def query_text(cls: URIRef, order: URIRef) -> str:
    """The SPARQL SELECT with the answer of :meth:`FirstMember.first` wherever that can answer (the order values are joined from a
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
    if (isinstance(v, float) and math.isnan(v)) or (isinstance(v, Decimal) and not v.is_finite()):
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
        #: (member, order value) pairs the index cannot hold, with the reason (see the module docstring)
        self._odd: Dict[Tuple[Node, Node], str] = {}
        self._kinds: Set[type] = set()    # Decimal and/or float among the values pushed since the last build
        self._sole = store.watch(self._on_write)

    @property
    def why_not(self) -> str:
        """Why the index cannot answer now ("" while it can)."""
        if not self._sole:
            return "the store is not the only writer of its data"
        for key in sorted(self._odd):
            return self._odd[key]
        if Decimal in self._kinds and float in self._kinds:
            return "the order values mix decimals and doubles"
        return ""

    @property
    def usable(self) -> bool:
        return not self.why_not

    # ---------------------------------------------------------------- feeding
    def _push(self, subject: Node, value: Node) -> None:
        if (subject, value) in self._queued:
            return
        if not isinstance(subject, URIRef):
            self._odd[(subject, value)] = "a blank node is a member (%s %s)" % (subject.n3(), value.n3())
            return
        number = _number(value)
        if number is None:
            self._odd[(subject, value)] = "%s has the order value %s, which is not a number" % (subject.n3(),
                                                                                              value.n3())
            return
        if not isinstance(number, int):
            self._kinds.add(type(number))
        self._queued.add((subject, value))  # type: ignore[arg-type]
        heapq.heappush(self._heap, (number, str(subject), next(self._seq), subject, value))  # type: ignore[arg-type]

    def _is_member(self, subject: Node) -> bool:
        return any(True for _ in self.store.quads(subject, RDF.type, self.cls, None))

    def _on_write(self, changes: Optional[ChangeSet]) -> None:
        with self._lock:
            if changes is None or self._stale:  # a whole graph was replaced: build again when next read
                self._stale = True
                return
            try:
                for s, p, o, _ in changes.add:
                    if p == self.order:
                        if self._is_member(s):
                            self._push(s, o)
                    elif p == RDF.type and o == self.cls:
                        for _, _, value, _ in self.store.quads(s, self.order, None, None):
                            self._push(s, value)
            except Exception:
                self._stale = True  # could not follow this write: build again when next read
                raise

    def _build(self) -> None:
        self._heap, self._queued, self._odd, self._kinds = [], set(), {}, set()
        members = {s for s, _, _, _ in self.store.quads(None, RDF.type, self.cls, None)}
        for s in members:
            for _, _, value, _ in self.store.quads(s, self.order, None, None):
                self._push(s, value)
        self._stale = False

    # ---------------------------------------------------------------- reading
    def _holds(self, subject: Node, value: Node) -> bool:
        return self._is_member(subject) and any(True for _ in self.store.quads(subject, self.order, value, None))

    def first(self) -> Optional[URIRef]:
        """The member with the lowest order (ties: the lowest IRI), or None when the class has no ordered member.
        Raises :class:`Unanswerable` when the index cannot answer (then run :func:`query_text`)."""
        # one consistent view for the whole answer: a store that keeps a copy of a server's data checks it here,
        # once, and tells its watchers (this index) about a copy it loaded again before the lock is taken
        with self.store.reading(), self._lock:
            if self._sole and not self.store.follows_every_change():
                # a store that keeps a copy reads from the server for now: what the index followed may be behind
                raise Unanswerable("the first %s by %s: the store reads from the server for now"
                                   % (self.cls.n3(), self.order.n3()))
            if self._sole and not self._stale and (
                    self._kinds == {Decimal, float}
                    or (self._odd and not any(self._holds(s, v) for s, v in self._odd))):
                # values it could not compare: build again to see whether they are gone (a mix of decimals and
                # doubles costs one build per read while it lasts; the answer is then the query's)
                self._stale = True
            if self._stale and self._sole:
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
        """Entries held: at most one per (member since the last build, order value)."""
        return len(self._heap)
