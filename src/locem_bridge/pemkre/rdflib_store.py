"""rdflib's own in-memory ``Dataset`` behind :class:`TripleStore` (not persistent).

Used as the naive baseline in the benchmark, for reference reasoning in tests, and wherever a throwaway store
is enough. Queries are prepared once with ``rdflib.plugins.sparql.prepareQuery(initNs=...)`` and run with
``initBindings``. rdflib's persistent stores (BerkeleyDB, SQLAlchemy plugins) need extra native modules; the
benchmark's store section says why the default is pyoxigraph instead.
"""
import threading
from typing import Iterable, Iterator, Mapping, Optional, Sequence

from rdflib import Dataset, URIRef
from rdflib.term import Node

from .errors import QueryError
from .oxigraph_store import check_query
from .store import ChangeSet, PreparedQuery, Quad, QueryResult, Triple, TripleStore


class RdflibStore(TripleStore):
    """An in-memory rdflib ``Dataset`` whose default graph is the union of the named graphs."""

    persistent = False
    sole_writer = True

    def __init__(self) -> None:
        self.dataset = Dataset(default_union=True)
        self._write_lock = threading.RLock()

    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        q = check_query(text, name, prefixes)
        return PreparedQuery(name=name, text=text, kind=q.kind, variables=q.variables, compiled=q.parsed,
                             projected=q.projected)

    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        self._check_bindings(query, bindings)
        init = {k: v for k, v in (bindings or {}).items() if v is not None}
        try:
            res = self.dataset.query(query.compiled, initBindings=init)
            if res.type == "ASK":
                return QueryResult(kind="ASK", boolean=bool(res.askAnswer))
            if res.type == "SELECT":
                names = [str(v) for v in res.vars]
                rows = []
                for r in res:
                    row = {}
                    for n in names:
                        t = r[n]
                        if t is not None:
                            row[n] = t
                    rows.append(row)
                return QueryResult(kind="SELECT", variables=names, rows=rows)
            rows = [{"subject": s, "predicate": p, "object": o} for s, p, o in res]
            return QueryResult(kind="CONSTRUCT", variables=["subject", "predicate", "object"], rows=rows)
        except Exception as exc:
            raise QueryError("query %s failed: %s" % (query.name, exc), query.name) from None

    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        if graphs is None:
            for s2, p2, o2, g in self.dataset.quads((s, p, o, None)):
                yield s2, p2, o2, (g.identifier if hasattr(g, "identifier") else g)
            return
        for gid in graphs:
            for s2, p2, o2 in self.dataset.graph(gid).triples((s, p, o)):
                yield s2, p2, o2, gid

    def apply(self, changes: ChangeSet) -> None:
        with self._write_lock:
            self._check_expected(changes)
            for s, p, o, g in changes.remove:
                self.dataset.graph(g).remove((s, p, o))
            for s, p, o, g in changes.add:
                self.dataset.graph(g).add((s, p, o))
        self._written(changes)

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        gr = self.dataset.graph(graph)
        gr.remove((None, None, None))
        for t in triples:
            gr.add(t)
        self._written(None)

    def count(self, graph: Optional[URIRef] = None) -> int:
        if graph is None:
            return sum(1 for _ in self.dataset.quads((None, None, None, None)))
        return len(self.dataset.graph(graph))
