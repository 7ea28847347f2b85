"""The default store: pyoxigraph (RocksDB on disk, or in memory), behind :class:`TripleStore`.

Why this engine (measured by ``bench/bench_pemkre.py``, section "store"): point lookups and the process
queries run one to two orders of magnitude faster than rdflib's in-memory SPARQL engine, it persists without a
separate journal, and each SPARQL update is one transaction. Lifecycle: ``OxigraphStore(path)`` opens (and
locks) the directory; ``close()`` releases it. Only one process may hold a store directory at a time; a
second opener gets :class:`~locem_bridge.pemkre.errors.StoreError`.

Durability: ``apply`` is one SPARQL update (``DELETE DATA ; INSERT DATA``) executed in one transaction; when it
returns, the write is in RocksDB's write-ahead log, which a ``kill -9`` of this process does not lose.
"""
import re
import threading
from typing import Any, Dict, Iterable, Iterator, List, Mapping, NamedTuple, Optional, Sequence, Tuple

import pyoxigraph as ox
from rdflib import BNode, Literal, URIRef
from rdflib.namespace import XSD
from rdflib.term import Node

from .errors import QueryError, StoreError
from .store import IRI_CACHE_MAX, ChangeSet, PreparedQuery, Quad, QueryResult, Triple, TripleStore, cached_uri

_XSD_STRING = str(XSD.string)
_KIND_RE = re.compile(r"\b(ASK|SELECT|CONSTRUCT|DESCRIBE)\b", re.IGNORECASE)
_VAR_RE = re.compile(r"[?$]([A-Za-z_][A-Za-z0-9_]*)")


_OX_CACHE: Dict[str, "ox.NamedNode"] = {}

#: pyoxigraph takes a query's prefixes as an argument from 0.5 on; 0.4 (the last line with wheels for Python 3.8,
#: Noetic's Python on Ubuntu 20.04) gets them as PREFIX declarations in front of the text
_PREFIXES_ARGUMENT = tuple(int(v) for v in re.findall(r"\d+", ox.__version__)[:2]) >= (0, 5)


def with_prefixes(text: str, prefixes: Mapping[str, str]) -> str:
    """``text`` after one ``PREFIX`` declaration per entry (the text's own declarations come later and win)."""
    return "".join("PREFIX %s: <%s>\n" % (k, v) for k, v in prefixes.items()) + text


def to_ox(term: Node):
    """rdflib term -> pyoxigraph term (blank node ids kept)."""
    if isinstance(term, URIRef):
        n = _OX_CACHE.get(term)
        if n is None:
            if len(_OX_CACHE) >= IRI_CACHE_MAX:
                _OX_CACHE.clear()
            n = _OX_CACHE[term] = ox.NamedNode(str(term))
        return n
    if isinstance(term, BNode):
        return ox.BlankNode(str(term))
    if isinstance(term, Literal):
        if term.language:
            return ox.Literal(str(term), language=term.language)
        if term.datatype is not None:
            return ox.Literal(str(term), datatype=ox.NamedNode(str(term.datatype)))
        return ox.Literal(str(term))
    raise TypeError("not an RDF term: %r" % (term,))


def from_ox(term) -> Node:
    """pyoxigraph term -> rdflib term (xsd:string literals become plain literals, as RDF 1.1 says they are)."""
    if isinstance(term, ox.NamedNode):
        return cached_uri(term.value)
    if isinstance(term, ox.BlankNode):
        return BNode(term.value)
    if isinstance(term, ox.Literal):
        if term.language:
            return Literal(term.value, lang=term.language)
        dt = term.datatype.value
        if dt == _XSD_STRING:
            return Literal(term.value)
        return Literal(term.value, datatype=URIRef(dt))
    if isinstance(term, ox.DefaultGraph):
        return None  # type: ignore[return-value]
    raise TypeError("unsupported pyoxigraph term %r" % (term,))


def query_kind(text: str) -> str:
    """ASK / SELECT / CONSTRUCT / DESCRIBE: the first query-form keyword after the prologue."""
    body = re.sub(r"#[^\n]*", "", text)
    body = re.sub(r"(?is)^\s*((PREFIX\s+[^\s:]*:\s*<[^>]*>|BASE\s*<[^>]*>)\s*)*", "", body)
    m = _KIND_RE.search(body)
    if not m:
        raise QueryError("not a SPARQL query (no ASK/SELECT/CONSTRUCT/DESCRIBE)")
    return m.group(1).upper()


class CheckedQuery(NamedTuple):
    """A query text checked once by rdflib's SPARQL 1.1 parser (see :func:`check_query`)."""

    kind: str                       # ASK / SELECT / CONSTRUCT / DESCRIBE
    prefixes: Dict[str, str]
    variables: Tuple[str, ...]      # every variable named in the text, in order
    projected: Tuple[str, ...]      # a SELECT's projected variables (() for the other kinds)
    parsed: Any                     # rdflib's prepared query


def check_query(text: str, name: str, prefixes: Mapping[str, str]) -> CheckedQuery:
    """Parse ``text`` once now (rdflib's SPARQL 1.1 parser; nothing is evaluated, so SERVICE calls are not
    made), so a broken query is reported at load time, not at the first decision:
    :class:`~locem_bridge.pemkre.errors.QueryError` naming the query. Every store's ``prepare`` starts here."""
    try:
        kind = query_kind(text)
    except QueryError as exc:
        raise QueryError("query %s: %s" % (name, exc), name) from None
    prefix_map = {k: str(v) for k, v in prefixes.items()}
    from rdflib.plugins.sparql import prepareQuery

    try:
        parsed = prepareQuery(text, initNs=prefix_map)
    except Exception as exc:
        raise QueryError("query %s does not parse: %s" % (name, str(exc).splitlines()[0][:300]), name) from None
    variables = tuple(dict.fromkeys(_VAR_RE.findall(text)))
    projected: Tuple[str, ...] = ()
    if kind == "SELECT":
        pv = parsed.algebra.get("PV")
        projected = tuple(str(v) for v in pv) if pv is not None else variables
    return CheckedQuery(kind, prefix_map, variables, projected, parsed)


class OxigraphStore(TripleStore):
    """pyoxigraph-backed store; ``path=None`` keeps everything in memory (not persistent)."""

    def __init__(self, path: Optional[str] = None) -> None:
        try:
            self._store = ox.Store(path) if path is not None else ox.Store()
        except OSError as exc:
            raise StoreError("cannot open the triplestore at %r: %s (is another PEMKRE process using it?)"
                             % (path, exc)) from exc
        self.path = path
        self.persistent = path is not None
        self.sole_writer = True  # one process per store (RocksDB's lock) or in memory
        self._graph_cache: Dict[URIRef, ox.NamedNode] = {}
        self._closed = False
        #: held by each write, so a conditional change's check and its write are one step for this process
        self._write_lock = threading.RLock()
        self.removals = 0  # since the last maintain() that did something
        self.rebuild_after_removals = 20_000

    # ---------------------------------------------------------------- queries
    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        q = check_query(text, name, prefixes)
        compiled = q.prefixes if _PREFIXES_ARGUMENT else with_prefixes(text, q.prefixes)
        return PreparedQuery(name=name, text=text, kind=q.kind, variables=q.variables, compiled=compiled,
                             projected=q.projected)

    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        self._check_bindings(query, bindings)
        subs = None
        if bindings:
            subs = {ox.Variable(k): to_ox(v) for k, v in bindings.items() if v is not None}
        try:
            if _PREFIXES_ARGUMENT:
                res = self._store.query(query.text, prefixes=query.compiled, use_default_graph_as_union=True,
                                        substitutions=subs)
            else:
                res = self._store.query(query.compiled, use_default_graph_as_union=True, substitutions=subs)
            if isinstance(res, ox.QueryBoolean):
                return QueryResult(kind="ASK", boolean=bool(res))
            if isinstance(res, ox.QuerySolutions):
                names = [v.value for v in res.variables]
                rows: List[Dict[str, Node]] = []
                for sol in res:
                    row: Dict[str, Node] = {}
                    for i, n in enumerate(names):
                        t = sol[i]
                        if t is not None:
                            row[n] = from_ox(t)
                    rows.append(row)
                return QueryResult(kind="SELECT", variables=names, rows=rows)
            triples = [(from_ox(t.subject), from_ox(t.predicate), from_ox(t.object)) for t in res]
            return QueryResult(kind="CONSTRUCT", variables=["subject", "predicate", "object"],
                               rows=[{"subject": s, "predicate": p, "object": o} for s, p, o in triples])
        except QueryError:
            raise
        except Exception as exc:
            raise QueryError("query %s failed: %s" % (query.name, exc), query.name) from None

    # ---------------------------------------------------------------- reads
    def _g(self, graph: URIRef) -> "ox.NamedNode":
        g = self._graph_cache.get(graph)
        if g is None:
            g = self._graph_cache[graph] = ox.NamedNode(str(graph))
        return g

    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        xs = to_ox(s) if s is not None else None
        xp = to_ox(p) if p is not None else None
        xo = to_ox(o) if o is not None else None
        targets = [None] if graphs is None else [self._g(g) for g in graphs]
        for g in targets:
            for q in self._store.quads_for_pattern(xs, xp, xo, g):
                yield (s if s is not None else from_ox(q.subject),
                       p if p is not None else from_ox(q.predicate),
                       o if o is not None else from_ox(q.object),
                       URIRef(q.graph_name.value) if isinstance(q.graph_name, ox.NamedNode) else None)

    def count(self, graph: Optional[URIRef] = None) -> int:
        if graph is None:
            return len(self._store)
        return sum(1 for _ in self._store.quads_for_pattern(None, None, None, self._g(graph)))

    # ---------------------------------------------------------------- writes
    @staticmethod
    def _quad_text(q: Quad) -> str:
        s, p, o, g = q
        for t in (s, p, o):
            if isinstance(t, BNode):
                raise StoreError("blank nodes cannot be written through apply(): %r" % (q,))
        return "GRAPH %s { %s %s %s }" % (to_ox(g), to_ox(s), to_ox(p), to_ox(o))

    def apply(self, changes: ChangeSet) -> None:
        if not changes:
            return
        parts = []
        if changes.remove:
            parts.append("DELETE DATA { %s }" % " ".join(self._quad_text(q) for q in changes.remove))
        if changes.add:
            parts.append("INSERT DATA { %s }" % " ".join(self._quad_text(q) for q in changes.add))
        with self._write_lock:
            self._check_expected(changes)
            if not parts:
                return
            try:
                self._store.update(" ;\n".join(parts))
            except Exception as exc:
                raise StoreError("store write failed (nothing was written): %s" % exc) from None
            self.removals += len(changes.remove)
        self._written(changes)

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        g = self._g(graph)
        try:
            self._store.clear_graph(g) if self._store.contains_named_graph(g) else None
            self._store.extend([ox.Quad(to_ox(s), to_ox(p), to_ox(o), g) for s, p, o in triples])
        except Exception as exc:
            raise StoreError("cannot replace graph %s: %s" % (graph, exc)) from None
        finally:
            self._written(None)

    def flush(self) -> None:
        if self.persistent:
            self._store.flush()

    def maintain(self) -> None:
        """After many removals, compact (removed triples leave entries that range scans walk over)."""
        if self.removals >= self.rebuild_after_removals:
            self.removals = 0
            if self.persistent:
                self._store.optimize()

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            try:
                self.flush()
            finally:
                del self._store
