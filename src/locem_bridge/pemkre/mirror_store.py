"""PEMKRE's store on a SPARQL 1.1 server, read from an exact copy in this process: the server's cost per decision
close to the embedded store's.

Over HTTP every read is a round trip (0.2-0.4 ms to a server on the same machine, more across a network), and a
decision makes dozens of reads; an embedded store answers them in microseconds. So
:class:`MirroredSparqlStore` keeps the server as the store of record -- every write goes there first, as with
:class:`~locem_bridge.pemkre.sparql_store.SparqlStore`, conditional changes with the same claims -- and keeps a
*copy* of PEMKRE's graphs (the graphs the plain store's reads see) in an in-memory Oxigraph store for every read.
The copy holds exactly what an Oxigraph server holds, blank nodes as the server's skolem IRIs (answers turn them
back into blank nodes, as the server's answers do), so a query answers the same from the copy as from the server.
Beside another server (the ``Server`` header of its answer at opening does not name Oxigraph) the copy is off
(:attr:`MirroredSparqlStore.copy_off` says why, logged once) and every read goes to the server as with the plain
store: Oxigraph keeps literals in their canonical form (``"01"^^xsd:integer`` as ``"1"``, times in UTC), another
server as written, and a removal built from the copy's form would miss the server's.

**Knowing the copy is current: the version marker.** Every data write of every PEMKRE client (this class and the
plain :class:`SparqlStore`) replaces the dataset's version marker in the same request
(:meth:`SparqlStore.version_update`; a conditional write only when its condition holds); this class's writes also
note the version(s) they replaced (``<new> meta:after <old>``, with the server's time: links older than the claim
ttl go with the dead claims, the rest are deleted once checked and at :meth:`close`). Before it reads -- once per
decision (the engine's :meth:`reading` stretch), and before each read outside one -- the store reads the marker
and the links of its own writes since its last check, in ONE query. The copy is current when the marker is the
copy's version, or this client's last write, and each of its writes since replaced exactly the version before it
(the copy's version for the first): then no one else wrote in between, and the copy plus this client's writes
(applied to the copy as the server acknowledged them) is the server's data. Anything else -- another writer's
version, two versions at once (two writers at the same moment both replace the same marker), a link missing, a
write of this client whose fate is unknown or that the copy could not follow -- makes the copy be loaded again
from the server: each graph as N-Triples, between two readings of the marker that must agree. A write known to
have changed nothing (a conflict, a refusal) leaves the copy as it is.

**Loading costs; reading from the server meanwhile.** Loading the copy takes the server's time to serialise every
PEMKRE graph. It takes at most about :attr:`~MirroredSparqlStore.RELOAD_SHARE` (a tenth) of the time: a copy found
stale again sooner after a load is not loaded -- that stretch reads from the server as the plain store does (the
first-member index steps aside, the engine asks the query) -- and neither is one whose data kept changing under
two loads in a row. So a second PEMKRE or an MES writing often costs the plain store's speed, never more, and
never NOT_READY while the server answers.

As with the plain store, what another client writes during a decision is seen at the next decision; conditional
changes are checked on the server (the copy is never the judge of a condition).

**Other writers must replace the marker.** A system other than PEMKRE that writes PEMKRE's graphs on the server
(an MES, a script) must add :meth:`SparqlStore.version_update` with a fresh version IRI to each of its update
requests; a write without it is not seen by a client that keeps a copy until that client loads its copy again
(:meth:`MirroredSparqlStore.reload`, or when another PEMKRE write makes it).

Costs: a decision's reads are one request (the marker) plus the embedded store's time; an unconditional write one
request, a conditional one four (as on the plain store): a taping decision (next action and its two status
reports) 12 requests, 23 on the plain store (``bench/bench_pemkre.py`` measures both).
"""
import logging
import threading
from contextlib import contextmanager
from typing import Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Set, Tuple

import pyoxigraph as ox
from rdflib import BNode, URIRef
from rdflib.term import Node

from .errors import StoreConflict, StoreError, StoreUnavailable
from .oxigraph_store import OxigraphStore
from .sparql_http import HttpStatusError, RetryPolicy
from .sparql_store import (G_CLAIMS, P_VERSION, P_VERSION_AFTER, VERSION_MARKER, SparqlStore, json_rows,
                           term_text)
from .sparql_text import SKOLEM_PREFIX, unskolem
from .store import ChangeSet, PreparedQuery, Quad, QueryResult, Triple

_log = logging.getLogger(__name__)

#: how often :meth:`MirroredSparqlStore.reload` tries to load the copy while the marker keeps changing under it
RELOAD_ATTEMPTS = 5
#: ... and the check before a read (then it reads from the server for a while)
RELOAD_ATTEMPTS_WHILE_READING = 2


def _skolem(term: Node) -> Node:
    """A blank node as the server holds it (its skolem IRI); other terms as they are."""
    return URIRef(SKOLEM_PREFIX + str(term)) if isinstance(term, BNode) else term


class _Churn(StoreUnavailable):
    """The copy could not be loaded: the marker changed under every attempt."""


class MirroredSparqlStore(SparqlStore):
    """A :class:`SparqlStore` whose reads are answered from an exact in-process copy of PEMKRE's graphs (see the
    module docstring). Takes the same arguments."""

    links_versions = True
    #: the copy changes only by this store's writes and by loading it again: :meth:`watch` callbacks see each
    #: (loading again as ``None``), so an index kept beside the store (the first-member index) stays exact
    sole_writer = True
    #: loading the copy takes at most about this share of the time: after a load, a copy found stale again within
    #: (1 / share - 1) times the load's duration is not loaded; reads go to the server meanwhile
    RELOAD_SHARE = 0.1

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
        #: while stale, no load before this time (clock): reads go to the server
        self._no_load_before = 0.0
        #: how often the copy was loaded from the server (for tests and benchmarks)
        self.reloads = 0
        #: why the copy is not used at all ("": it is)
        self.copy_off = ""
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        if self.server_software and not self.server_software.lower().startswith("oxigraph"):
            # the copy is an Oxigraph store, which keeps literals in their canonical form ("01"^^xsd:integer as
            # "1", timestamps in UTC): exact only beside a server that does the same
            self.copy_off = ("the server is %s, not Oxigraph: reading from the server (the copy keeps literals in "
                             "Oxigraph's canonical form, which this server may not)" % self.server_software)
            self.sole_writer = False
            _log.info("PEMKRE store %s: %s", self.query_endpoint.name, self.copy_off)

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

    def _sync(self) -> bool:
        """Make the copy the server's data: check the marker (one query), load the copy again when it is not.
        False: read from the server instead (the copy is off, or stale and loaded too recently, or it could not be
        loaded because the data kept changing)."""
        if self.copy_off:
            return False
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
                    return True
                self._stale = True
                self._tell_watchers(None)     # the index must not answer from what it followed until now
            if self.clock() < self._no_load_before:
                return False
            started = self.clock()
            try:
                self._load(RELOAD_ATTEMPTS_WHILE_READING)
                return True
            except _Churn:
                _log.info("PEMKRE store %s: the data kept changing while the copy was loaded; reading from the "
                          "server for a while", self.query_endpoint.name)
                return False
            finally:   # the next load not before: loading takes at most RELOAD_SHARE of the time
                self._no_load_before = self.clock() + (self.clock() - started) * (1 / self.RELOAD_SHARE - 1)

    def reload(self) -> None:
        """Load the copy again from the server now: every known graph (after looking for new ones under PEMKRE's
        graph namespace) as N-Triples, between two readings of the marker that must agree
        (:class:`~locem_bridge.pemkre.errors.StoreUnavailable` after :data:`RELOAD_ATTEMPTS` tries)."""
        with self._mirror_lock:
            self._load(RELOAD_ATTEMPTS)

    def _load(self, attempts: int) -> None:
        before: List[str] = []
        after: List[str] = []
        for _ in range(attempts):
            before, _ = self._marker_rows(())
            SparqlStore.refresh_graphs(self)       # new graphs under PEMKRE's namespace join the known ones
            graphs = self._known_graphs()
            copy = OxigraphStore(None)
            for graph in graphs:
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
        raise _Churn(
            "%s: PEMKRE's data changed while it was being loaded, %d times in a row (version %s, then %s); "
            "nothing was read" % (self.query_endpoint.name, attempts, ", ".join(before) or "none",
                                  ", ".join(after) or "none"),
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
            raise StoreError("%s answered the triples of graph %s with N-Triples that do not parse: %s"
                             % (self.query_endpoint.name, graph, str(exc).splitlines()[0][:200])) from None

    def _copy_to_read(self) -> Optional[OxigraphStore]:
        """The copy to answer a read from, checked first unless within a :meth:`reading` stretch (checked at its
        start); None: ask the server."""
        if self._is_direct() or self.copy_off:
            return None
        if getattr(self._reading, "depth", 0):
            return self._copy
        return self._copy if self._sync() else None

    def follows_every_change(self) -> bool:
        return not self.copy_off and not self._is_direct()

    @contextmanager
    def _in_stretch(self) -> Iterator[None]:
        """Reads in here answer from the copy as it is (the check was made, or must not be made now)."""
        depth = getattr(self._reading, "depth", 0)
        self._reading.depth = depth + 1
        try:
            yield
        finally:
            self._reading.depth = depth

    def _tell_watchers(self, changes: Optional[ChangeSet]) -> None:
        """:meth:`watch` callbacks, reading the copy as it is now (no check of the marker in the middle of a
        write or a load)."""
        with self._in_stretch():
            self._written(changes)

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
        # within a stretch: as the outermost one decided; else the copy, checked once now, or the server's reads
        if getattr(self._reading, "depth", 0) or (not self._is_direct() and self._sync()):
            with self._in_stretch():
                yield
            return
        with self._server_reads(), SparqlStore.reading(self):   # the plain store's stretch: fetched per subject
            yield

    def prefetch(self, subjects: Iterable[Node]) -> None:
        if self._is_direct():
            super().prefetch(subjects)
        # else nothing to fetch: the copy holds every subject

    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        mine = self._copy.prepare(text, name, prefixes)
        server = super().prepare(text, name, prefixes)
        return PreparedQuery(name=mine.name, text=mine.text, kind=mine.kind, variables=mine.variables,
                             projected=mine.projected, compiled=(mine.compiled, server.compiled))

    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        compiled = query.compiled
        if not (isinstance(compiled, tuple) and len(compiled) == 2):
            return super().run(query, bindings)
        self._check_bindings(query, bindings)
        copy = self._copy_to_read()
        if copy is None:
            return super().run(PreparedQuery(query.name, query.text, query.kind, query.variables, compiled[1],
                                             query.projected), bindings)
        local = PreparedQuery(query.name, query.text, query.kind, query.variables, compiled[0], query.projected)
        result = copy.run(local, {k: _skolem(v) for k, v in bindings.items()} if bindings else bindings)
        if result.kind == "ASK":
            return result
        for row in result.rows:
            for k, t in row.items():
                row[k] = unskolem(t)
        return result

    def _mirrored(self, graphs: Optional[Iterable[URIRef]]) -> bool:
        return graphs is None or all(g in self._copy_graphs or g in self._graphs for g in graphs)

    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        copy = self._copy_to_read() if self._mirrored(graphs) else None
        if copy is None:
            return super().quads(s, p, o, graphs)
        found = copy.quads(_skolem(s) if s is not None else None, p, _skolem(o) if o is not None else None,
                           graphs)
        return iter([(unskolem(a) if s is None else s, b, unskolem(c) if o is None else o, g)
                     for a, b, c, g in found])

    def count(self, graph: Optional[URIRef] = None) -> int:
        copy = self._copy_to_read() if self._mirrored(None if graph is None else [graph]) else None
        if copy is None:
            return super().count(graph)
        return copy.count(graph)

    # ---------------------------------------------------------------- writes
    def _failed_write(self, exc: BaseException, chain_before: int) -> None:
        """A write raised: when it is known not to have changed anything (a conflict, refused before or by the
        server), its version leaves the chain and the copy stays; otherwise the copy is loaded again."""
        unapplied = isinstance(exc, StoreConflict) or (isinstance(exc, StoreUnavailable) and exc.applied is False) \
            or isinstance(exc, HttpStatusError) or type(exc) is StoreError
        if unapplied:
            del self._chain[chain_before:]
        else:
            self._stale = True

    def _mirror_failed(self, what: str, exc: Exception) -> None:
        """The server took a write the copy could not: the copy is loaded again at the next read (the write is
        done: the server is the store of record)."""
        self._stale = True
        _log.warning("PEMKRE store %s: the copy could not follow %s (%s); it is loaded again from the server",
                     self.query_endpoint.name, what, exc)

    def apply(self, changes: ChangeSet) -> None:
        if not changes:
            return
        with self._mirror_lock:
            chain_before = len(self._chain)
            try:
                with self._server_reads():
                    super().apply(changes)
            except BaseException as exc:
                self._failed_write(exc, chain_before)
                raise
            if self.copy_off:
                return
            mirrored = self._copy_graphs | set(self._known_graphs())
            local = ChangeSet(remove=[q for q in changes.remove if q[3] in mirrored],
                              add=[q for q in changes.add if q[3] in mirrored])
            if not local:
                return
            try:
                self._copy.apply(local)
            except Exception as exc:
                self._mirror_failed("a change", exc)
                return
            self._copy_graphs.update(q[3] for q in local.add)
            self._tell_watchers(local)

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        items = list(triples)
        with self._mirror_lock:
            chain_before = len(self._chain)
            try:
                with self._server_reads():
                    super().replace_graph(graph, items)
            except BaseException as exc:
                if len(self._chain) > chain_before + 1:   # a later request failed: the first ones are written
                    self._stale = True
                else:
                    self._failed_write(exc, chain_before)
                raise
            if self.copy_off or graph == G_CLAIMS:
                return
            try:
                self._copy.replace_graph(graph, [(_skolem(s), p, _skolem(o)) for s, p, o in items])
            except Exception as exc:
                self._mirror_failed("replacing graph %s" % graph, exc)
                return
            self._copy_graphs.add(graph)
            self._tell_watchers(None)

    def drop_pemkre_graphs(self) -> List[URIRef]:
        with self._mirror_lock:
            self._stale = True        # loaded again (empty) at the next read
            self._no_load_before = 0.0
            with self._server_reads():
                return super().drop_pemkre_graphs()

    def refresh_graphs(self) -> List[URIRef]:
        found = super().refresh_graphs()
        with self._mirror_lock:
            if any(g not in self._copy_graphs for g in found):
                self._stale = True    # a graph another client made: loaded with the copy
        return found

    def close(self) -> None:
        """Delete the links of this client's versions (one request, not retried), then as the plain store."""
        if not self._closed:
            with self._mirror_lock:
                links = self._spent_versions + self._chain
                self._spent_versions, self._chain = [], []
                if links:
                    try:
                        self.update_endpoint.post([("update", self._delete_tokens_text(links))], "*/*",
                                                  write=True, retry=RetryPolicy(attempts=1))
                    except StoreError:
                        pass  # left links are harmless and go with the dead claims after claim_ttl_s
        super().close()
