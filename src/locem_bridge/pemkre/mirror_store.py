"""PEMKRE's store on a SPARQL 1.1 server, read from an exact copy in this process: the server's cost per decision
close to the embedded store's.

Over HTTP every read is a round trip (0.2-0.4 ms to a server on the same machine, more across a network), and a
decision makes dozens of reads; an embedded store answers them in microseconds. So
:class:`MirroredSparqlStore` keeps the server as the store of record -- every write goes there first, as with
:class:`~locem_bridge.pemkre.sparql_store.SparqlStore`, conditional changes with the same claims -- and keeps a
*copy* of PEMKRE's graphs (those :meth:`~SparqlStore.known graphs <locem_bridge.pemkre.sparql_store.SparqlStore>`
reads see) in an in-memory Oxigraph store for every read. The copy holds exactly what the server holds, blank
nodes as the server's skolem IRIs (answers turn them back into blank nodes, as the server's answers do), so a
query answers the same from the copy as from the server.

**Knowing the copy is current: the version marker.** Every data write of every PEMKRE client (this class and the
plain :class:`SparqlStore`) replaces the dataset's version marker in the same request
(:meth:`SparqlStore.version_update`); this class's writes also note the version they replaced
(``<new> meta:after <old>``). Before it reads -- once per decision (the engine's :meth:`reading` stretch), and
before each read outside one -- the store reads the marker and the links of its own writes since its last check,
in ONE query. The copy is current when the marker is the copy's version, or this client's last write, and each of
its writes since replaced exactly the version before it (the copy's version for the first): then no one else wrote
in between, and the copy plus this client's writes (applied to the copy as the server acknowledged them) is the
server's data. Anything else -- another writer's version, two versions at once (two writers at the same moment
both replace the same marker), a link missing, a write of this client that failed or whose fate is unknown, a
conflict -- makes the copy be loaded again from the server: each graph as N-Triples, between two readings of the
marker that must agree (else it is loaded again; after five tries the store is
:class:`~locem_bridge.pemkre.errors.StoreUnavailable`).

As with the plain store, what another client writes during a decision is seen at the next decision; conditional
changes are checked on the server (the copy is never the judge of a condition).

**Other writers must replace the marker.** A system other than PEMKRE that writes PEMKRE's graphs on the server
(an MES, a script) must add :meth:`SparqlStore.version_update` with a fresh version IRI to each of its update
requests; a write without it is not seen by a client that keeps a copy until that client loads its copy again
(:meth:`MirroredSparqlStore.reload`, or when the next PEMKRE write comes from another client).

Costs: a decision's reads are one round trip (the marker) plus the embedded store's time; an unconditional write
one round trip, a conditional one four (as on the plain store). Loading the copy costs one request per graph and
the server's time to serialise it (measured by ``bench/bench_pemkre.py``).
"""
import threading
import uuid
from contextlib import contextmanager
from typing import Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Set, Tuple

import pyoxigraph as ox
from rdflib import BNode, Literal, URIRef
from rdflib.term import Node

from .errors import StoreUnavailable
from .oxigraph_store import OxigraphStore
from .sparql_store import (G_CLAIMS, P_VERSION, P_VERSION_AFTER, VERSION_MARKER, SparqlStore, json_rows,
                           term_text)
from .sparql_text import SKOLEM_PREFIX, unskolem
from .store import ChangeSet, PreparedQuery, Quad, QueryResult, Triple

#: how often loading the copy is tried while the marker keeps changing under it
RELOAD_ATTEMPTS = 5


def _skolem(term: Node) -> Node:
    """A blank node as the server holds it (its skolem IRI); other terms as they are."""
    return URIRef(SKOLEM_PREFIX + str(term)) if isinstance(term, BNode) else term


class MirroredSparqlStore(SparqlStore):
    """A :class:`SparqlStore` whose reads are answered from an exact in-process copy of PEMKRE's graphs (see the
    module docstring). Takes the same arguments."""

    links_versions = True
    #: the copy changes only by this store's writes and by loading it again: :meth:`watch` callbacks see each
    #: (loading again as ``None``), so an index kept beside the store (the first-member index) stays exact
    sole_writer = True

    def __init__(self, *args: object, **kwargs: object) -> None:
        self._mirror_lock = threading.RLock()
        self._copy = OxigraphStore(None)
        self._copy_graphs: Set[URIRef] = set()
        #: the version(s) of the server's data the copy holds (none: no marker on the server yet; two: two writers
        #: replaced the same version at the same moment); valid unless stale
        self._copy_version: Tuple[str, ...] = ()
        self._stale = True
        #: versions of this client's writes applied to the copy since the last check, oldest first
        self._chain: List[str] = []
        self._direct = threading.local()     # >0: reads go to the server (the plain store's own checks)
        #: how often the copy was loaded from the server (for tests and benchmarks)
        self.reloads = 0
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    # ---------------------------------------------------------------- the copy
    def _wrote_version(self, version: str) -> None:
        self._chain.append(version)

    def _marker_rows(self, chain: Sequence[str]) -> Tuple[List[str], Dict[str, Set[str]]]:
        """ONE query: the marker's version(s) now, and the version(s) each of ``chain`` replaced."""
        g, m, v, after = term_text(G_CLAIMS), term_text(VERSION_MARKER), term_text(P_VERSION), \
            term_text(P_VERSION_AFTER)
        text = "SELECT ?cur ?w ?prev WHERE { { GRAPH %s { %s %s ?cur } }" % (g, m, v)
        if chain:
            text += " UNION { VALUES ?w { %s } GRAPH %s { ?w %s ?prev } }" % (
                " ".join("<%s>" % w for w in chain), g, after)
        text += " }"
        doc = self._select_doc(text, "the store's version marker", dataset=False)
        _, rows = json_rows(doc, self.query_endpoint.name)
        current: List[str] = []
        links: Dict[str, Set[str]] = {}
        for r in rows:
            if r.get("cur") is not None:
                current.append(str(r["cur"]))
            elif r.get("w") is not None and r.get("prev") is not None:
                links.setdefault(str(r["w"]), set()).add(str(r["prev"]))
        return sorted(set(current)), links

    def _sync(self) -> None:
        """Make the copy the server's data: check the marker (one query), load the copy again when it is not."""
        with self._mirror_lock:
            if not self._stale:
                chain = list(self._chain)
                current, links = self._marker_rows(chain)
                expected = (chain[-1],) if chain else self._copy_version
                ok = tuple(current) == expected
                before = set(self._copy_version)
                for w in chain:
                    if not ok:
                        break
                    ok = links.get(w, set()) == before
                    before = {w}
                if ok:
                    self._copy_version = expected
                    self._chain = []
                    # the links of the versions checked are needed no more: deleted by the next write
                    self._spent_versions.extend(chain)
                    return
            self.reload()

    def reload(self) -> None:
        """Load the copy again from the server: every known graph (after looking for new ones under PEMKRE's graph
        namespace) as N-Triples, between two readings of the marker that must agree."""
        with self._mirror_lock:
            for _ in range(RELOAD_ATTEMPTS):
                before, _ = self._marker_rows(())
                graphs = [URIRef(g) for g in SparqlStore.refresh_graphs(self)] + self._known_graphs()
                copy = OxigraphStore(None)
                for graph in sorted(set(graphs)):
                    self._load_graph(copy, graph)
                after, _ = self._marker_rows(())
                if before == after:
                    self._copy, self._copy_graphs = copy, set(graphs)
                    self._copy_version = tuple(before)
                    self._spent_versions.extend(self._chain)
                    self._chain = []
                    self._stale = False
                    self.reloads += 1
                    self._tell_watchers(None)
                    return
            raise StoreUnavailable(
                "%s: PEMKRE's data changed while it was being loaded, %d times in a row (version %s, then %s); "
                "nothing was read" % (self.query_endpoint.name, RELOAD_ATTEMPTS, ", ".join(before) or "none", ", ".join(after) or "none"),
                self.query_endpoint.name, "data keeps changing", applied=False)

    def _load_graph(self, copy: OxigraphStore, graph: URIRef) -> None:
        answer = self.query_endpoint.post(
            [("query", "CONSTRUCT { ?s ?p ?o } WHERE { GRAPH %s { ?s ?p ?o } }" % term_text(graph))],
            "application/n-triples")
        if answer.media_type not in ("application/n-triples", "text/plain"):
            self._graph_answer(answer, "the triples of graph %s" % graph)   # raises, naming what came instead
        try:
            copy._store.load(answer.body, format=ox.RdfFormat.N_TRIPLES, to_graph=ox.NamedNode(str(graph)))
        except (SyntaxError, ValueError, OSError) as exc:
            from .errors import StoreError

            raise StoreError("%s answered the triples of graph %s with N-Triples that do not parse: %s"
                             % (self.query_endpoint.name, graph, str(exc).splitlines()[0][:200])) from None

    def _current(self) -> OxigraphStore:
        """The copy, checked first unless within a :meth:`reading` stretch (checked at its start)."""
        if not getattr(self._reading, "depth", 0):
            self._sync()
        return self._copy

    def _tell_watchers(self, changes: Optional[ChangeSet]) -> None:
        """:meth:`watch` callbacks, reading the copy as it is now (no check of the marker in the middle of a
        write or a load)."""
        depth = getattr(self._reading, "depth", 0)
        self._reading.depth = depth + 1
        try:
            self._written(changes)
        finally:
            self._reading.depth = depth

    def _is_direct(self) -> bool:
        return bool(getattr(self._direct, "depth", 0))

    @contextmanager
    def _server_reads(self) -> Iterator[None]:
        self._direct.depth = getattr(self._direct, "depth", 0) + 1
        try:
            yield
        finally:
            self._direct.depth -= 1

    # ---------------------------------------------------------------- reads
    @contextmanager
    def reading(self) -> Iterator[None]:
        depth = getattr(self._reading, "depth", 0)
        if not depth:
            self._sync()
        self._reading.depth = depth + 1
        try:
            yield
        finally:
            self._reading.depth = depth

    def prefetch(self, subjects: Iterable[Node]) -> None:
        """Nothing to fetch: the copy holds every subject."""

    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        mine = self._copy.prepare(text, name, prefixes)
        server = super().prepare(text, name, prefixes)
        return PreparedQuery(name=mine.name, text=mine.text, kind=mine.kind, variables=mine.variables,
                             projected=mine.projected, compiled=(mine.compiled, server.compiled))

    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        compiled = query.compiled
        if not (isinstance(compiled, tuple) and len(compiled) == 2):
            return super().run(query, bindings)
        if self._is_direct():
            return super().run(PreparedQuery(query.name, query.text, query.kind, query.variables, compiled[1],
                                             query.projected), bindings)
        self._check_bindings(query, bindings)
        copy = self._current()
        local = PreparedQuery(query.name, query.text, query.kind, query.variables, compiled[0], query.projected)
        result = copy.run(local, {k: _skolem(v) for k, v in bindings.items()} if bindings else bindings)
        if result.kind == "ASK":
            return result
        for row in result.rows:
            for k, t in row.items():
                if isinstance(t, URIRef) and t.startswith(SKOLEM_PREFIX):
                    row[k] = unskolem(t)
        return result

    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        if self._is_direct() or (graphs is not None and not all(g in self._copy_graphs or g in
                                                                 self._known_graphs() for g in graphs)):
            return super().quads(s, p, o, graphs)
        copy = self._current()
        found = copy.quads(_skolem(s) if s is not None else None, p, _skolem(o) if o is not None else None,
                           graphs)
        return iter([(unskolem(a) if s is None else s, b, unskolem(c) if o is None else o, g)
                     for a, b, c, g in found])

    def count(self, graph: Optional[URIRef] = None) -> int:
        if self._is_direct() or (graph is not None and graph not in self._copy_graphs
                                 and graph not in self._known_graphs()):
            return super().count(graph)
        return self._current().count(graph)

    # ---------------------------------------------------------------- writes
    def apply(self, changes: ChangeSet) -> None:
        if not changes:
            return
        with self._mirror_lock:
            try:
                with self._server_reads():
                    super().apply(changes)
            except BaseException:
                self._stale = True   # a conflict, a write of unknown fate, or refused: the copy is loaded again
                raise
            mirrored = self._copy_graphs | set(self._known_graphs())
            local = ChangeSet(remove=[q for q in changes.remove if q[3] in mirrored],
                              add=[q for q in changes.add if q[3] in mirrored])
            self._copy_graphs.update(q[3] for q in local.add)
            if local:
                self._copy.apply(local)
                self._tell_watchers(local)

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        items = list(triples)
        with self._mirror_lock:
            try:
                with self._server_reads():
                    super().replace_graph(graph, items)
            except BaseException:
                self._stale = True
                raise
            if graph == G_CLAIMS:
                return
            self._copy_graphs.add(graph)
            self._copy.replace_graph(graph, [(_skolem(s), p, _skolem(o)) for s, p, o in items])
            self._tell_watchers(None)

    def drop_pemkre_graphs(self) -> List[URIRef]:
        with self._mirror_lock:
            self._stale = True        # loaded again (empty) at the next read
            with self._server_reads():
                return super().drop_pemkre_graphs()

    def refresh_graphs(self) -> List[URIRef]:
        found = super().refresh_graphs()
        with self._mirror_lock:
            if any(g not in self._copy_graphs for g in found):
                self._stale = True    # a graph another client made: loaded with the copy
        return found
