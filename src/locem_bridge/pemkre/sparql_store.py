"""PEMKRE's store on a remote SPARQL 1.1 server, behind :class:`~locem_bridge.pemkre.store.TripleStore`.

Any server that speaks the W3C SPARQL 1.1 Protocol (query and update over HTTP) will do: Oxigraph
(``oxigraph serve --location DIR``: query ``http://HOST:7878/query``, update ``http://HOST:7878/update``; the tests
run one), Apache Jena Fuseki (``/DATASET/query``, ``/DATASET/update``), GraphDB (``/repositories/REPO``,
``/repositories/REPO/statements``), Virtuoso (``/sparql`` for both, with update rights). Any number of PEMKRE
clients may share one server; ``persistent`` is True (the server keeps the data).

**The default graph is the union of the named graphs**, as on the embedded stores (PEMKRE writes only named
graphs). Standard SPARQL has no "union default graph" switch, so each query names its dataset in the request with
the protocol's ``default-graph-uri`` parameters, one per named graph the store knows (RDF-merged into the default
graph by the server), and the same list as ``named-graph-uri`` so ``GRAPH ?g`` patterns keep working. The graphs
known are PEMKRE's own (:data:`~locem_bridge.pemkre.store.ASSERTED_GRAPHS`, the inferred graphs, ``G_META``), those
under PEMKRE's graph namespace found on the server when the store is opened (other systems' graphs stay out), and those this client writes; a graph another client creates later
is seen after :meth:`SparqlStore.refresh_graphs`. The query text is not rewritten for this. A server already set up
to serve the union as its default graph (``oxigraph serve --union-default-graph``, Fuseki's
``tdb2:unionDefaultGraph``) may be used with ``union_default_graph=True``, which sends no dataset at all.

**Values** (bindings) join the prepared query as a ``VALUES`` block of N-Triples terms placed at the start of its
WHERE group (:func:`~locem_bridge.pemkre.sparql_text.values_position`), never as spliced text.

**Writes.** :meth:`SparqlStore.apply` is ONE update request, ``DELETE DATA {..} ; INSERT DATA {..}``, which servers
that run one request as one transaction apply all or nothing (Oxigraph does, tested here; Fuseki with TDB2 and
GraphDB say they do, not tested here). A change whose text is longer than ``max_update_bytes`` (16 MiB by default: a
world scan of more than about 4,500 features; form-encoded, a scan of more than about 27,000 would be over
``oxigraph serve``'s 128 MiB body limit) is *staged*: written in parts into staging graphs outside PEMKRE's graphs
(``urn:pemkre:staging:..``; no PEMKRE query sees them, but a client that reads every graph of the server does), then
applied by one request that moves the staged quads into place and drops the staging graphs, so it still shows all at
once or not at all (:meth:`SparqlStore._apply_staged`). With ``union_default_graph`` the staging graphs would be
part of every query's default graph: there a change is always one request (a server that refuses one so big says so
in one line, nothing is written). Every
write also inserts a *token* (a triple naming a fresh ``urn:uuid:`` in the bookkeeping graph :data:`G_CLAIMS`,
which queries, :meth:`~SparqlStore.quads` and :meth:`~SparqlStore.count` never see): when the answer to a write is
lost on the way back, the store asks the server whether the token is there and reports ``applied`` True in
:class:`~locem_bridge.pemkre.errors.StoreUnavailable` when it is, else ``None``: a write sent whose answer timed out
or whose connection was lost may still be applied (the server may still be working on it, or a proxy may have it
queued); then :meth:`SparqlStore.was_applied` asks later. Such a write stays *unknown*
(:attr:`SparqlStore.unknown_writes`) until its token is found or ``claim_ttl_s`` has passed since it was sent: a
token not found once proves nothing while the write may still be on its way. This assumes the server finishes (or
drops) an update within ``claim_ttl_s`` of receiving it. While any write is unknown, every further write of this
client raises :class:`~locem_bridge.pemkre.errors.StoreUnavailable` (``applied=False``, the node answers
NOT_READY) naming the unknown write and its age: after one lost answer of a write that never lands, writes wait up
to ``claim_ttl_s`` (about 200 s with the defaults). A write refused before it was sent (connection refused) is
``applied=False`` at once. The store never sends a write twice; the
engine decides. Tokens of applied writes are deleted by the next write of this client (in the same request) and
on :meth:`close`.

**Conditional changes** (:attr:`~locem_bridge.pemkre.store.ChangeSet.expect`): one transaction per request is not
enough, because a server's update transactions need not be serializable. Oxigraph's are snapshot-isolated: two
concurrent ``DELETE {old} INSERT {new} WHERE {old}`` requests both see ``old`` and both write (measured: two
writers racing on one status both won). So a conditional change first *claims* the expected quads: one request
inserts a claim (token, the hash of the expected quads, the server's ``NOW()``) only WHERE the expected quads are
there, then the client reads every live claim on them. Alone, it writes the change as ``DELETE {..} INSERT {..}
WHERE {expected}`` together with removing its claim, in one request, and reads its token back; with rivals, every
claimant withdraws and tries again after a random pause (at most ``claim_attempts`` times; when another
claimant is still there after that, :class:`~locem_bridge.pemkre.errors.StoreUnavailable` names it and its claim's
age: a claim left by a client that died is no conflict, it blocks the quads until it is ``claim_ttl_s`` old).
A claim whose final write's fate is unknown is not withdrawn: it keeps other writers away until that write shows
or the claim dies. Exactly one writer can
win: a winner's claim is visible from before its read until its change is committed, so a second writer either
sees it (and steps back) or reads after the change (and its own conditional write finds the quads changed). The
loser gets :class:`~locem_bridge.pemkre.errors.StoreConflict` naming the expected quad that was not there. A claim
older than ``claim_ttl_s`` (a client that died between claim and write) no longer counts and is deleted by the next claim request; the ttl must exceed twice the longest read-and-write path (default: that plus 30 s), and a client that took more than half the ttl since its claim withdraws instead of writing. Cost: four requests for
a conditional change (claim, read claims, write, read token), one for any other change (a staged one: one for its
record, one per part, the final request and a token read).

**Blank nodes are skolem IRIs on the server.** The store takes blank nodes only through
:meth:`~SparqlStore.replace_graph` (the ontology graphs' restrictions and lists) and writes each as the IRI
``<urn:pemkre:bnode:LABEL>`` (:data:`~locem_bridge.pemkre.sparql_text.SKOLEM_PREFIX`), so one node stays one node
across requests and graphs; results, :meth:`~SparqlStore.quads` and CONSTRUCT answers turn these IRIs back into
blank nodes. Queries run *on the server* see IRIs, not blank nodes: ``isBlank(?x)`` is false and ``isIRI(?x)``
true for them, ``STR(?x)`` gives the skolem IRI, and ``ORDER BY`` sorts them among the IRIs (blank nodes sort
before IRIs). An integrator's query (MES, dashboard) that tells blank nodes apart must test
``STRSTARTS(STR(?x), "urn:pemkre:bnode:")`` instead. The labels are the engine's canonical ones (the same for
every client loading the same ontology files).

**Reads are scoped to PEMKRE's graphs.** :meth:`~SparqlStore.quads` and :meth:`~SparqlStore.count` without a
graph read the graphs this store knows (as the union default graph above), never every graph on the server.

Failures are one line naming the endpoint: :class:`~locem_bridge.pemkre.errors.StoreUnavailable` (refused,
unknown host, timeout, connection lost; reads are retried with backoff first, see
:class:`~locem_bridge.pemkre.sparql_http.RetryPolicy`), :class:`~locem_bridge.pemkre.errors.StoreError` for an
HTTP error answer (with the server's message) or an answer that is not SPARQL (an HTML page, broken JSON),
:class:`~locem_bridge.pemkre.errors.QueryError` when the server refuses a query. Opening the store checks it
(``check=True``): the query endpoint must answer SPARQL, and a probe written through the update endpoint must show
through the query endpoint (both URLs name the same dataset).
"""
import hashlib
import json
import logging
import os
import random
import re
import socket
import time
import threading
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Callable, Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Set, Tuple

from rdflib import BNode, Graph, Literal, URIRef
from rdflib.namespace import XSD
from rdflib.term import Node

from .errors import InvalidParameterError, QueryError, StoreError, StoreUnavailable
from .oxigraph_store import check_query
from .sparql_http import Answer, Endpoint, HttpStatusError, RetryPolicy
from .sparql_text import SKOLEM_PREFIX, iri_text, json_rows, term_text, unskolem, values_block, values_position
from .store import (ASSERTED_GRAPHS, G_META, INFERRED_GRAPHS, ChangeSet, PreparedQuery, Quad, QueryResult, Triple,
                    TripleStore, conflict_error)
from .vocab import GRAPHS, META

#: Bookkeeping graph of the write claim tokens (see the module docstring); outside the union default graph.
G_CLAIMS = GRAPHS.claims
#: ``<urn:uuid:..> meta:writeClaim "client"``: one claim token.
P_WRITE_CLAIM = META.writeClaim
#: a conditional change's claim: ``<token> meta:claimOn <urn:pemkre-claim:HASH of the expected quads>``
P_CLAIM_ON = META.claimOn
#: ... and ``<token> meta:claimAt NOW()`` (the server's clock; claims older than ``claim_ttl_s`` are dead)
P_CLAIM_AT = META.claimAt
#: the dataset's version marker, in the bookkeeping graph: ``meta:dataset meta:version <urn:pemkre:version:UUID>``;
#: every data write of a PEMKRE client replaces it by a fresh version in the same request (see
#: :meth:`SparqlStore.version_update`), so a client that keeps a copy of the data
#: (:class:`~locem_bridge.pemkre.mirror_store.MirroredSparqlStore`) learns from one read whether anyone wrote
VERSION_MARKER = META.dataset
P_VERSION = META.version
#: ``<version> meta:after <the version it replaced>``: written by the clients that keep a copy, for their own check
P_VERSION_AFTER = META.after
VERSION_PREFIX = "urn:pemkre:version:"

#: A change whose SPARQL text is longer than this many bytes (UTF-8) is staged (:meth:`SparqlStore._apply_staged`):
#: form-encoded, 16 MiB of text are at most 48 MiB on the wire, well under ``oxigraph serve``'s 128 MiB limit
MAX_UPDATE_BYTES = 16 * 1024 * 1024
#: the graph of staging records (outside PEMKRE's graph namespace, so no query, load or drop of PEMKRE's graphs
#: touches it): ``<urn:pemkre:staging:UUID> meta:stagedAt NOW() (renewed by each part) ; meta:stagedTtl
#: seconds (the writer's claim ttl) ; meta:stagedBy "client" ; meta:stagedGraph <g>``
G_STAGING = URIRef("urn:pemkre:staging")
STAGING_PREFIX = "urn:pemkre:staging:"
P_STAGED_AT = META.stagedAt
P_STAGED_TTL = META.stagedTtl
P_STAGED_BY = META.stagedBy
P_STAGED_GRAPH = META.stagedGraph

_TOKEN_RE = re.compile(r"^urn:uuid:[0-9a-f-]{36}$")
_ACCEPT_RESULTS = "application/sparql-results+json"
_ACCEPT_GRAPH = "application/n-triples"
_JSON_TYPES = ("application/sparql-results+json", "application/json")


@dataclass(frozen=True)
class _Compiled:
    """A prepared query as it is sent: prologue + text, and where a VALUES block goes (None: at the end)."""

    text: str
    values_at: Optional[int]


@dataclass(frozen=True)
class _Unknown:
    """A write whose answer was lost: when it was sent (the store's clock), whether it timed out (the server may
    have been working on it), whether the server answered it (2xx: then a token not found means not applied)."""

    sent: float
    timed_out: bool
    answered: bool = False


@dataclass(frozen=True)
class _Claim:
    """A live claim read from the server: its token, its age in seconds, the client that made it."""

    token: str
    age: float
    client: str


_log = logging.getLogger(__name__)


class SparqlStore(TripleStore):
    """A :class:`TripleStore` on a SPARQL 1.1 server (see the module docstring). ``close()`` drops the connection;
    the data stays on the server."""

    persistent = True

    def __init__(self, query_url: str, update_url: str, timeout_s: float = 10.0,
                 retry: RetryPolicy = RetryPolicy(), union_default_graph: bool = False, check: bool = True,
                 chunk_triples: int = 5000, claim_ttl_s: Optional[float] = None, claim_attempts: int = 12,
                 max_update_bytes: int = MAX_UPDATE_BYTES) -> None:
        self.query_endpoint = Endpoint(query_url, "query", timeout_s, retry)
        self.update_endpoint = Endpoint(update_url, "update", timeout_s, retry)
        self.union_default_graph = union_default_graph
        self.chunk_triples = max(1, int(chunk_triples))
        if int(max_update_bytes) < 1000:
            raise InvalidParameterError("max_update_bytes %r is too small: a staged part must hold at least one "
                                        "triple; use 1000 or more (default %d)" % (max_update_bytes,
                                                                                  MAX_UPDATE_BYTES))
        #: a change whose SPARQL text is longer (UTF-8 bytes) is staged (see _apply_staged): written in parts of
        #: at most this size into staging graphs, then applied by one small request
        self.max_update_bytes = int(max_update_bytes)
        #: the longest a claim may have to wait for its write: reading the claims and writing, each with every
        #: retry timing out
        self.claim_path_s = sum(e.retry.attempts * timeout_s + sum(e.retry.delays())
                                for e in (self.query_endpoint, self.update_endpoint))
        if claim_ttl_s is None:
            claim_ttl_s = 2 * self.claim_path_s + 30.0
        if float(claim_ttl_s) <= 2 * self.claim_path_s:
            raise InvalidParameterError(
                "claim_ttl_s %.1f s is too short: a claim must outlive twice the longest read-and-write path "
                "(%.1f s with timeout_s %.1f and %d attempts); use more than %.1f s, or a shorter timeout / fewer "
                "attempts" % (float(claim_ttl_s), self.claim_path_s, timeout_s, retry.attempts,
                              2 * self.claim_path_s))
        self.claim_ttl_s = float(claim_ttl_s)
        self._first_seen: Dict[str, float] = {}  # claim token -> when this client first saw it (monotonic)
        self.claim_attempts = max(1, int(claim_attempts))
        self._pause = time.sleep
        #: the clock of claim ages and unknown writes (monotonic seconds); tests put a fake one here
        self.clock: Callable[[], float] = time.monotonic
        self.client = "%s pid %d store %s" % (socket.gethostname(), os.getpid(), uuid.uuid4().hex[:8])
        self._graphs: Set[URIRef] = set(ASSERTED_GRAPHS) | set(INFERRED_GRAPHS) | {G_META}
        self._dataset: List[Tuple[str, str]] = []
        self._done_tokens: List[str] = []  # claims of applied writes, deleted by the next write
        #: this client's conditional-change claims that may still be on the server (a withdrawal failed): never
        #: counted as rivals, deleted by the next claim request
        self._my_claims: Set[str] = set()
        #: writes whose answer was lost and whose fate is not known yet, by token (see was_applied)
        self._unknown: Dict[str, _Unknown] = {}
        self._lock = threading.RLock()
        self._closed = False
        #: within reading() (per thread: the engine's decisions): every quad of each subject fetched (PEMKRE's
        #: graphs), by subject; a write or a change of the graphs bumps the generation (a fetch under way when it
        #: happened is not kept)
        self._reading = threading.local()
        #: versions this client wrote whose links (``meta:after``) no one needs any more, deleted by its next write
        self._spent_versions: List[str] = []
        #: the server's Server header as the check at opening saw it ("" unchecked or not sent)
        self.server_software = ""
        self._by_subject: Dict[Node, List[Quad]] = {}
        self._generation = 0
        self._refresh_dataset()
        if check:
            self.check()

    # ---------------------------------------------------------------- opening
    def check(self) -> None:
        """Make sure the endpoints are a SPARQL 1.1 server holding one dataset: the query endpoint answers an ASK
        in SPARQL JSON, a probe written through the update endpoint is seen through the query endpoint (then
        removed); learn the named graphs on the server."""
        answer = self.query_endpoint.post([("query", "ASK { }")], _ACCEPT_RESULTS)
        self._boolean(self._json_answer(answer, "the check at opening"), "the check at opening")
        self.server_software = answer.server
        token = self._new_token()
        self._update("INSERT DATA { %s }" % self._claim_text(token), "the write probe at opening")
        if not self._token_stored(token):
            raise StoreError("%s accepted a write that %s does not show: do both URLs name the same dataset?"
                             % (self.update_endpoint.name, self.query_endpoint.name))
        self._done_tokens.append(token)
        self.refresh_graphs()

    def refresh_graphs(self) -> List[URIRef]:
        """Ask the server for its named graphs under PEMKRE's graph namespace (:data:`~locem_bridge.pemkre.vocab.GRAPHS`)
        and make them part of the union default graph; returns them. Other graphs on the server stay out."""
        doc = self._select_doc("SELECT DISTINCT ?g WHERE { GRAPH ?g { } }", "the list of named graphs", dataset=False)
        _, rows = json_rows(doc, self.query_endpoint.name)
        found = [r["g"] for r in rows if isinstance(r.get("g"), URIRef) and r["g"] != G_CLAIMS
                 and str(r["g"]).startswith(str(GRAPHS))]  # other systems' graphs on the server stay out
        with self._lock:
            self._graphs.update(found)  # type: ignore[arg-type]
            self._refresh_dataset()
        return sorted(found)  # type: ignore[arg-type]

    def _refresh_dataset(self) -> None:
        self._forget_all()                  # fetched over the graphs known until now
        if self.union_default_graph:
            self._dataset = []
            return
        graphs = sorted(str(g) for g in self._graphs)
        self._dataset = [("default-graph-uri", g) for g in graphs] + [("named-graph-uri", g) for g in graphs]

    def _know_graphs(self, graphs: Iterable[URIRef]) -> None:
        new = [g for g in graphs if g not in self._graphs and g != G_CLAIMS]
        if new:
            with self._lock:
                self._graphs.update(new)
                self._refresh_dataset()

    def _known_graphs(self) -> List[URIRef]:
        """The graphs reads without a graph look at: PEMKRE's own, those found on the server under its graph
        namespace, those this client wrote (never the claims graph, never another system's graphs)."""
        with self._lock:
            return sorted(g for g in self._graphs if g != G_CLAIMS)

    # ---------------------------------------------------------------- queries
    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        q = check_query(text, name, prefixes)
        try:
            prologue = "".join("PREFIX %s: %s\n" % (k, iri_text(v)) for k, v in q.prefixes.items())
        except InvalidParameterError as exc:
            raise QueryError("query %s: a prefix is unusable: %s" % (name, exc), name) from None
        full = prologue + text
        return PreparedQuery(name=name, text=text, kind=q.kind, variables=q.variables, projected=q.projected,
                             compiled=_Compiled(full, values_position(full, q.kind)))

    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        self._check_bindings(query, bindings)
        compiled = query.compiled
        if not isinstance(compiled, _Compiled):
            raise QueryError("query %s was not prepared by this store" % query.name, query.name)
        text = compiled.text
        if bindings and any(v is not None for v in bindings.values()):
            try:
                block = values_block(bindings)
            except InvalidParameterError as exc:
                raise QueryError("query %s: %s" % (query.name, exc), query.name) from None
            if compiled.values_at is None:
                text = "%s\n%s" % (text, block)
            else:
                text = "%s %s %s" % (text[:compiled.values_at], block, text[compiled.values_at:])
        graph_form = query.kind in ("CONSTRUCT", "DESCRIBE")
        what = "query %s" % query.name
        try:
            answer = self.query_endpoint.post([("query", text)] + self._dataset,
                                              _ACCEPT_GRAPH if graph_form else _ACCEPT_RESULTS)
        except HttpStatusError as exc:
            if 400 <= exc.status < 500:
                raise QueryError("query %s failed on the server: %s" % (query.name, exc), query.name) from None
            raise HttpStatusError("query %s: %s" % (query.name, exc), exc.status) from None
        if graph_form:
            triples = self._graph_answer(answer, what)
            return QueryResult(kind="CONSTRUCT", variables=["subject", "predicate", "object"],
                               rows=[{"subject": s, "predicate": p, "object": o} for s, p, o in triples])
        doc = self._json_answer(answer, what)
        if query.kind == "ASK":
            return QueryResult(kind="ASK", boolean=self._boolean(doc, what))
        names, rows = json_rows(doc, "%s (%s)" % (self.query_endpoint.name, what))
        return QueryResult(kind="SELECT", variables=names, rows=rows)

    # ---------------------------------------------------------------- reads
    @contextmanager
    def reading(self) -> Iterator[None]:
        depth = getattr(self._reading, "depth", 0)
        self._reading.depth = depth + 1
        try:
            yield
        finally:
            self._reading.depth = depth
            if not depth:
                self._forget_all()

    #: subjects per prefetch request
    PREFETCH_CHUNK = 200

    def prefetch(self, subjects: Iterable[Node]) -> None:
        if not getattr(self._reading, "depth", 0):
            return
        with self._lock:
            graphs = self._known_graphs()
            generation = self._generation
            missing = sorted({x for x in subjects if isinstance(x, URIRef) and not x.startswith(SKOLEM_PREFIX)
                              and x not in self._by_subject})
        if not graphs:
            return
        for i in range(0, len(missing), self.PREFETCH_CHUNK):
            chunk = missing[i:i + self.PREFETCH_CHUNK]
            text = "SELECT ?s ?p ?o ?g WHERE { VALUES ?g { %s } VALUES ?s { %s } GRAPH ?g { ?s ?p ?o } }" % (
                " ".join(term_text(g) for g in graphs), " ".join(term_text(x) for x in chunk))
            doc = self._select_doc(text, "the quads of %d subjects" % len(chunk), dataset=False)
            _, rows = json_rows(doc, self.query_endpoint.name)
            found: Dict[Node, List[Quad]] = {x: [] for x in chunk}
            for r in rows:
                held = found.get(r["s"])  # type: ignore[arg-type]
                if held is not None:
                    held.append((r["s"], r["p"], r["o"], r["g"]))  # type: ignore[arg-type]
            with self._lock:
                if self._generation != generation:    # written meanwhile: what was fetched may be older
                    return
                self._by_subject.update(found)

    def _forget(self, quads: Iterable[Quad]) -> None:
        """A write touches these quads: their subjects are fetched again when next looked up."""
        with self._lock:
            self._generation += 1
            for q in quads:
                self._by_subject.pop(q[0], None)

    def _forget_all(self) -> None:
        with self._lock:
            self._generation += 1
            self._by_subject.clear()

    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        if getattr(self._reading, "depth", 0) and isinstance(s, URIRef):
            self.prefetch([s])
            with self._lock:
                held = self._by_subject.get(s)
                known = None if held is None else set(self._known_graphs())
            if held is not None and known is not None and (graphs is None or all(g in known for g in graphs)):
                wanted = known if graphs is None else set(graphs)
                if isinstance(o, Literal) and o.datatype == XSD.string and not o.language:
                    o = Literal(str(o))           # as the server's answers give it (sparql_text.json_term)
                return iter([q for q in held if q[3] in wanted and (p is None or q[1] == p)
                             and (o is None or q[2] == o)])
        pattern: List[str] = []
        for name, term in (("s", s), ("p", p), ("o", o)):
            if term is None:
                pattern.append("?" + name)
            else:  # a blank node too: it is stored as its skolem IRI
                pattern.append(term_text(term))
        if graphs is None:  # the graphs this store knows (PEMKRE's), not every graph on the server
            graphs = self._known_graphs()
        if not graphs:
            return iter(())
        head = "VALUES ?g { %s } " % " ".join(term_text(g) for g in graphs)
        text = "SELECT ?s ?p ?o ?g WHERE { %sGRAPH ?g { %s } }" % (head, " ".join(pattern))
        doc = self._select_doc(text, "a quad lookup", dataset=False)
        _, rows = json_rows(doc, self.query_endpoint.name)
        out: List[Quad] = []
        for r in rows:
            out.append((s if s is not None else r["s"], p if p is not None else r["p"],
                        o if o is not None else r["o"], r["g"]))  # type: ignore[arg-type]
        return iter(out)

    def count(self, graph: Optional[URIRef] = None) -> int:
        if graph is None:
            text = "SELECT (COUNT(*) AS ?n) WHERE { VALUES ?g { %s } GRAPH ?g { ?s ?p ?o } }" % " ".join(
                term_text(g) for g in self._known_graphs())
        else:
            text = "SELECT (COUNT(*) AS ?n) WHERE { GRAPH %s { ?s ?p ?o } }" % term_text(graph)
        doc = self._select_doc(text, "a count", dataset=False)
        _, rows = json_rows(doc, self.query_endpoint.name)
        try:
            return int(rows[0]["n"])  # type: ignore[call-overload]
        except (IndexError, KeyError, ValueError):
            raise StoreError("%s: a COUNT query answered %r, not a number" % (self.query_endpoint.name, rows)) \
                from None

    # ---------------------------------------------------------------- writes
    def apply(self, changes: ChangeSet) -> None:
        if not changes:
            return
        for q in list(changes.remove) + list(changes.add) + list(changes.expect):
            if any(isinstance(t, BNode) for t in q[:3]):
                raise StoreError("blank nodes cannot be written through apply(): %r" % (q,))
        try:
            removes = " ".join(self._quad_text(q) for q in changes.remove)
            adds = " ".join(self._quad_text(q) for q in changes.add)
            expects = " ".join(self._quad_text(q) for q in changes.expect)
        except InvalidParameterError as exc:
            raise StoreError("cannot write this change (nothing was written): %s" % exc) from None
        with self._lock:
            if self._unknown:               # a write whose fate is found out now may show up in any subject
                self._forget_all()
            self._forget(list(changes.remove) + list(changes.add) + list(changes.expect))
            self._settle_unknown_writes()
            if changes.expect:
                self._apply_conditional(changes, removes, adds, expects)
            else:
                token = self._new_token()
                what = "a change of %d removals and %d additions" % (len(changes.remove), len(changes.add))
                if not self.union_default_graph and \
                        len(removes.encode("utf-8")) + len(adds.encode("utf-8")) > self.max_update_bytes:
                    self._apply_staged(changes, token, what)
                else:
                    ops = self._cleanup_ops()
                    if removes:
                        ops.append("DELETE DATA { %s }" % removes)
                    ops.append("INSERT DATA { %s %s }" % (adds, self._claim_text(token)))
                    ops += self._version_ops()
                    self._write(ops, token, what)
                self._done_tokens.append(token)
            self._know_graphs(q[3] for q in changes.add)

    def _apply_staged(self, changes: ChangeSet, token: str, what: str) -> None:
        """Apply a change too big for one request (its text over ``max_update_bytes``; a world scan of more than
        about 4,500 features) all or nothing: its removals and additions go, in parts of at most
        ``max_update_bytes``, into fresh *staging graphs* (``urn:pemkre:staging:UUID:remove:N`` / ``:add:N``, one
        per target graph and kind, outside PEMKRE's graphs: no PEMKRE query sees them), then ONE request deletes
        the staged removals from their graphs, inserts the staged additions, moves the version marker and inserts
        the token, like any other change, and drops the staging graphs.

        A *record* in :data:`G_STAGING` keeps the stage alive: ``meta:stagedAt`` (the server's ``NOW()``, renewed by
        every part) and ``meta:stagedTtl`` (this client's ``claim_ttl_s``). A stage whose record is older than its
        ttl has expired (its client died or gave up): the next staged change of any client drops it. The final
        request moves data only while the record is there, and its token is read back: a stage found dead is
        ``applied=False``, never half applied. A failure while staging leaves PEMKRE's graphs untouched
        (``applied=False``) and drops the parts at once (the record stays until it expires: a part whose answer was
        lost may still land). Called with the lock held."""
        stage = "%s%s" % (STAGING_PREFIX, uuid.uuid4())
        parts: Dict[Tuple[str, URIRef], List[Quad]] = {}
        for kind, quads in (("remove", changes.remove), ("add", changes.add)):
            for q in quads:
                parts.setdefault((kind, q[3]), []).append(q)
        names = {key: URIRef("%s:%s:%d" % (stage, key[0], i)) for i, key in enumerate(sorted(parts))}
        try:
            self._drop_dead_stages()
        except StoreError as exc:  # housekeeping: the change does not depend on it
            _log.warning("PEMKRE store %s: could not drop the staged changes left unfinished (%s)",
                         self.update_endpoint.name, exc)
        g_stage, me = term_text(G_STAGING), "<%s>" % stage
        live = "GRAPH %s { %s %s ?live }" % (g_stage, me, term_text(P_STAGED_AT))
        renew = "DELETE { %s } INSERT { GRAPH %s { %s %s ?now } } WHERE { %s BIND(NOW() AS ?now) }" % (
            live, g_stage, me, term_text(P_STAGED_AT), live)
        sent = 0
        try:
            record = "%s %s ?now ; %s %s ; %s %s ; %s %s" % (
                me, term_text(P_STAGED_AT), term_text(P_STAGED_TTL), term_text(Literal(int(self.claim_ttl_s))),
                term_text(P_STAGED_BY), term_text(Literal(self.client)),
                term_text(P_STAGED_GRAPH), ", ".join(term_text(n) for n in names.values()))
            self._update("INSERT { GRAPH %s { %s } } WHERE { BIND(NOW() AS ?now) }" % (g_stage, record),
                         "staging %s (its record)" % what)
            total = sum(len(q) for q in parts.values())
            done = 0
            for key in sorted(parts):
                body: List[str] = []
                size = 0
                for q in parts[key] + [None]:  # type: ignore[operator]
                    line = "" if q is None else "%s %s %s ." % (term_text(q[0]), term_text(q[1]), term_text(q[2]))
                    weight = len(line.encode("utf-8")) + 1
                    if body and (q is None or size + weight > self.max_update_bytes - 400):
                        self._update("%s ;\nINSERT DATA { GRAPH %s { %s } }" % (renew, term_text(names[key]),
                                                                               " ".join(body)),
                                     "staging %s (part %d)" % (what, sent + 1))
                        sent += 1
                        done += len(body)
                        _log.info("PEMKRE store %s: staged %d of %d quads of %s", self.update_endpoint.name,
                                  done, total, what)
                        body, size = [], 0
                    if q is not None:
                        body.append(line)
                        size += weight
        except StoreError as exc:
            self._drop_stage_quietly(stage, names.values(), record=False, what=what)
            if isinstance(exc, StoreUnavailable):
                raise StoreUnavailable("%s; nothing of it was applied (it was being staged: %d parts stored)"
                                       % (exc, sent), exc.endpoint, exc.reason, applied=False,
                                       timed_out=exc.timed_out) from None
            raise
        lead, version = self._new_version()
        v_delete, v_insert, v_where = self._version_parts(version, self.links_versions)
        ops = self._cleanup_ops() + lead
        for kind, template in (("remove", "DELETE { GRAPH %s { ?s ?p ?o } }"),
                               ("add", "INSERT { GRAPH %s { ?s ?p ?o } }")):
            for key in sorted(k for k in parts if k[0] == kind):
                ops.append("%s WHERE { %s GRAPH %s { ?s ?p ?o } }" % (template % term_text(key[1]), live,
                                                                     term_text(names[key])))
        ops.append("DELETE { %s } INSERT { %s %s } WHERE { %s %s }" % (v_delete, self._claim_text(token), v_insert,
                                                                       live, v_where))
        ops += self._drop_stage_ops(stage, names.values())
        what_final = "%s (applying its %d staged parts)" % (what, sent)
        sent_at = self.clock()
        try:
            self._write(ops, token, what_final)
        except StoreError as exc:
            if isinstance(exc, HttpStatusError) or (isinstance(exc, StoreUnavailable) and exc.applied is False):
                self._drop_stage_quietly(stage, names.values(), record=True, what=what)
            raise  # applied None: the final request may still land and needs the parts (they expire otherwise)
        if not self._condition_held(token, sent_at, what_final):
            raise StoreUnavailable(
                "%s: %s was not applied: its staged parts were dropped as unfinished before it (staging took "
                "longer than the claim ttl of %.0f s between two parts); nothing of it was applied, try again"
                % (self.update_endpoint.name, what_final, self.claim_ttl_s), self.update_endpoint.name,
                "staged parts dropped", applied=False)

    def _condition_held(self, token: str, sent: float, what: str) -> bool:
        """After an answered conditional write: was it applied (its token is there)? When the token cannot be
        read, the write is done but its fate unknown: noted, and StoreUnavailable with ``applied=None``."""
        try:
            return self._token_stored(token)
        except StoreError as exc:
            self._note_unknown(token, sent, timed_out=False, answered=True)
            raise StoreUnavailable(
                "%s: %s was answered, but reading its token back failed (%s); whether it was applied is unknown; "
                "was_applied(%r) tells later" % (self.update_endpoint.name, what, exc, token),
                self.update_endpoint.name, "token read failed", applied=None, token=token) from None

    def _drop_stage_quietly(self, stage: str, graphs: Iterable[URIRef], record: bool, what: str) -> None:
        """Drop a stage's parts (and with ``record`` its record), best effort: what is left expires."""
        try:
            self._update(" ;\n".join(self._drop_stage_ops(stage, graphs, record)),
                         "dropping the staging graphs of %s" % what)
        except StoreError:
            pass  # dropped by the next staged change of any client once the record has expired

    @staticmethod
    def _drop_stage_ops(stage: str, graphs: Iterable[URIRef], record: bool = True) -> List[str]:
        return ["DROP SILENT GRAPH %s" % term_text(g) for g in graphs] + (
            ["DELETE WHERE { GRAPH %s { <%s> ?p ?o } }" % (term_text(G_STAGING), stage)] if record else [])

    def _drop_dead_stages(self) -> None:
        """Drop the staging graphs and records of staged changes whose record has expired (``meta:stagedAt`` more
        than its ``meta:stagedTtl`` before the server's ``NOW()``: the client that wrote them died or gave up)."""
        where = "%s (reading the staging records)" % self.query_endpoint.name
        _, rows = json_rows(self._select_doc(
            'SELECT ?s ?g WHERE { GRAPH %s { ?s %s ?at ; %s ?ttl OPTIONAL { ?s %s ?g } } FILTER(?at < NOW() - '
            'STRDT(CONCAT("PT", STR(?ttl), "S"), <http://www.w3.org/2001/XMLSchema#dayTimeDuration>)) }'
            % (term_text(G_STAGING), term_text(P_STAGED_AT), term_text(P_STAGED_TTL), term_text(P_STAGED_GRAPH)),
            "reading the staging records", dataset=False), where)
        dead: Dict[str, List[URIRef]] = {}
        for r in rows:
            s, g = r.get("s"), r.get("g")
            if isinstance(s, URIRef) and str(s).startswith(STAGING_PREFIX):
                graphs = dead.setdefault(str(s), [])
                if isinstance(g, URIRef) and str(g).startswith(STAGING_PREFIX):
                    graphs.append(g)
        if dead:
            ops: List[str] = []
            for stage, graphs in sorted(dead.items()):
                ops += self._drop_stage_ops(stage, graphs)
            _log.warning("PEMKRE store %s: dropping %d staged change(s) left unfinished (%s)",
                         self.update_endpoint.name, len(dead), ", ".join(sorted(dead)))
            self._update(" ;\n".join(ops), "dropping staging graphs left unfinished")

    #: does each write note the version it replaced (``meta:after``)? Only a client that checks its own chain of
    #: writes needs that (:class:`~locem_bridge.pemkre.mirror_store.MirroredSparqlStore`)
    links_versions = False

    @staticmethod
    def version_update(version: str, link: bool = False) -> str:
        """The SPARQL update operation that replaces the dataset's version marker by ``version`` (an IRI), and with
        ``link`` also records which version(s) it replaced. Every write of PEMKRE's data carries it in its request;
        another system that writes PEMKRE's graphs (an MES) must add it to its update requests too, with a fresh
        ``urn:uuid:`` or ``urn:pemkre:version:`` IRI each time, or the PEMKRE clients that keep a copy of the data
        do not see its write."""
        delete, insert, where = SparqlStore._version_parts(version, link)
        return "DELETE { %s } INSERT { %s } WHERE { %s }" % (delete, insert, where)

    @staticmethod
    def _version_parts(version: str, link: bool) -> Tuple[str, str, str]:
        """The DELETE and INSERT templates and the WHERE pattern of :meth:`version_update` (a conditional write
        joins them to its own, so the marker moves only when its condition holds). A link carries the server's
        time (``meta:claimAt``): links older than ``claim_ttl_s`` go with the dead claims."""
        g, m, v, new = term_text(G_CLAIMS), term_text(VERSION_MARKER), term_text(P_VERSION), "<%s>" % version
        insert = "%s %s %s ." % (m, v, new)
        where = "OPTIONAL { GRAPH %s { %s %s ?old_version } }" % (g, m, v)
        if link:
            insert += " %s %s ?old_version ; %s ?version_at ." % (new, term_text(P_VERSION_AFTER),
                                                                 term_text(P_CLAIM_AT))
            where += " BIND(NOW() AS ?version_at)"
        return ("GRAPH %s { %s %s ?old_version }" % (g, m, v), "GRAPH %s { %s }" % (g, insert), where)

    def _new_version(self) -> Tuple[List[str], str]:
        """A fresh version for a data write: the operations deleting the links of this client's versions no one
        needs any more (to lead the request), and the version (recorded by :meth:`_wrote_version`)."""
        version = "%s%s" % (VERSION_PREFIX, uuid.uuid4())
        ops = [self._delete_tokens_text(self._spent_versions)] if self._spent_versions else []
        self._spent_versions = []
        self._wrote_version(version)
        return ops, version

    def _version_ops(self) -> List[str]:
        """The operations an unconditional data write carries: a fresh version replacing the marker
        (:meth:`version_update`), after deleting the links no one needs."""
        ops, version = self._new_version()
        return ops + [self.version_update(version, self.links_versions)]

    def _wrote_version(self, version: str) -> None:
        """A data write with ``version`` is about to be sent (a store that keeps a copy of the data records it)."""

    @staticmethod
    def claim_key(expect: Sequence[Quad]) -> URIRef:
        """The IRI a conditional change's claims name: the hash of its expected quads (any order)."""
        return URIRef("urn:pemkre-claim:" + hashlib.sha256(
            "\n".join(sorted(SparqlStore._quad_text(q) for q in expect)).encode("utf-8")).hexdigest())

    def _apply_conditional(self, changes: ChangeSet, removes: str, adds: str, expects: str) -> None:
        """Claim the expected quads, write if the claim is the only live one, else withdraw and try again (see the
        module docstring: a server's update transaction need not be serializable, Oxigraph's is not)."""
        key = self.claim_key(changes.expect)
        what = "a conditional change of %d removals and %d additions" % (len(changes.remove), len(changes.add))
        rivals: List[_Claim] = []
        for attempt in range(1, self.claim_attempts + 1):
            claim = self._new_token()
            stale = sorted(self._my_claims)
            self._my_claims.add(claim)  # from here on it may be on the server
            claimed_at = self.clock()
            self._write(self._cleanup_ops() + ([self._delete_tokens_text(stale)] if stale else []) + [
                self._delete_dead_claims_text(),
                "INSERT { %s GRAPH %s { <%s> %s %s ; %s ?now } } WHERE { %s BIND(NOW() AS ?now) }"
                % (self._claim_text(claim), term_text(G_CLAIMS), claim, term_text(P_CLAIM_ON), term_text(key),
                   term_text(P_CLAIM_AT), expects)], claim, "claiming " + what)
            self._my_claims.difference_update(stale)
            try:
                live = self._live_claims(key)
                if claim not in [c.token for c in live]:
                    self._my_claims.discard(claim)
                    self._raise_conflict(changes)
                rivals = [c for c in live if c.token != claim and c.token not in self._my_claims]
                if not rivals:
                    waited = self.clock() - claimed_at
                    if waited > self.claim_ttl_s / 2:
                        raise StoreUnavailable(
                            "%s: %s took %.1f s from the claim, more than half the claim ttl (%.1f s): the claim "
                            "was withdrawn, nothing was written" % (self.update_endpoint.name, what, waited,
                                                                    self.claim_ttl_s),
                            self.update_endpoint.name, "claim too old", applied=False)
                    token = self._new_token()
                    # the marker moves with the change, only when its condition holds
                    lead, version = self._new_version()
                    v_delete, v_insert, v_where = self._version_parts(version, self.links_versions)
                    ops = [self._delete_tokens_text([claim])] + lead + [
                        "DELETE { %s %s } INSERT { %s %s %s } WHERE { %s %s }" % (
                            removes, v_delete, adds, self._claim_text(token), v_insert, expects, v_where)]
                    sent = self.clock()
                    self._write(ops, token, what)
                    self._my_claims.discard(claim)  # deleted by the write
                    if not self._condition_held(token, sent, what):
                        self._raise_conflict(changes)
                    self._done_tokens.append(token)
                    return
            except BaseException as exc:
                if not (isinstance(exc, StoreUnavailable) and exc.applied is None):
                    self._withdraw(claim)
                # else the final write's fate is unknown: the claim stays (it keeps other writers off the quads
                # until that write shows, which deletes it, or the claim dies of age)
                raise
            # another writer claimed the same quads at the same time: both step back, each tries again after a
            # random pause (one of them will find itself alone; the other then finds the quads changed)
            self._update(self._delete_tokens_text([claim]), "withdrawing a claim")
            self._my_claims.discard(claim)
            self._pause(random.uniform(0.002, 0.02) * attempt)
        # a claimant that stays through every attempt is no rival writing at the same time: a client that died
        # (or hangs) between its claim and its write; its claim blocks these quads until it dies of age
        s, p, o, g = changes.expect[0]
        oldest = max(rivals, key=lambda c: c.age)
        raise StoreUnavailable(
            "%s: %s %s %s in graph %s is claimed by another writer (%s, claimed %.0f s ago%s) through %d attempts; "
            "nothing was written; a claim that is not completed dies %.0f s after it was made (claim_ttl_s), so "
            "this change can be tried again in %.0f s at the latest" % (
                self.update_endpoint.name, s.n3(), p.n3(), o.n3(), g.n3(), oldest.client or oldest.token,
                oldest.age, ", and %d more" % (len(rivals) - 1) if len(rivals) > 1 else "", self.claim_attempts,
                self.claim_ttl_s, max(0.0, self.claim_ttl_s - min(c.age for c in rivals))),
            self.update_endpoint.name, "claimed by another writer", applied=False)

    def _note_unknown(self, token: str, sent: float, timed_out: bool, answered: bool = False) -> None:
        """Remember a write whose fate is unknown (see :meth:`was_applied`)."""
        with self._lock:
            self._unknown[token] = _Unknown(sent, timed_out, answered)

    @property
    def unknown_writes(self) -> List[str]:
        """Tokens of the writes whose answer was lost and whose fate is not known yet (oldest first)."""
        with self._lock:
            return sorted(self._unknown, key=lambda t: self._unknown[t].sent)

    def _settle_unknown_writes(self) -> None:
        """Before a new write: ask the server about every earlier write whose answer was lost
        (:meth:`was_applied`); :class:`~locem_bridge.pemkre.errors.StoreUnavailable` while any stays unknown (a
        write must not build blindly on one that may or may not have happened, or still happen)."""
        for token in self.unknown_writes:
            try:
                fate = self.was_applied(token)
            except StoreError as exc:
                raise StoreUnavailable(
                    "%s: an earlier write's fate is unknown (its answer was lost, token %s) and the server cannot "
                    "be asked (%s); nothing was written; was_applied(%r) settles it" % (
                        self.update_endpoint.name, token, exc, token), self.update_endpoint.name,
                    "earlier write unknown", applied=False) from None
            if fate is None:
                info = self._unknown.get(token)
                age = self.clock() - info.sent if info is not None else 0.0
                raise StoreUnavailable(
                    "%s: an earlier write's fate is unknown (sent %.1f s ago, its answer %s, token %s): the server "
                    "does not have it yet but may still apply it; nothing was written; writes go on once it shows "
                    "or %.0f s (claim_ttl_s) after it was sent" % (
                        self.update_endpoint.name, age, "timed out" if info is not None and info.timed_out else
                        "was lost", token, self.claim_ttl_s), self.update_endpoint.name,
                    "earlier write unknown", applied=False)

    def _delete_dead_claims_text(self) -> str:
        """The operation deleting every claim older than ``claim_ttl_s`` by the server's clock (led by each claim
        request, so dead claims do not pile up)."""
        g = term_text(G_CLAIMS)
        return ('DELETE { GRAPH %s { ?t ?p ?o } } WHERE { GRAPH %s { ?t %s ?at ; ?p ?o } '
                'FILTER(?at < NOW() - "PT%dS"^^<http://www.w3.org/2001/XMLSchema#dayTimeDuration>) }'
                % (g, g, term_text(P_CLAIM_AT), int(self.claim_ttl_s) + 1))

    def _withdraw(self, claim: str) -> None:
        """Delete this client's claim, best effort (one request, not retried); when that fails too, the claim is
        kept in ``_my_claims`` (not a rival to this client, deleted by its next claim request)."""
        if claim not in self._my_claims:
            return
        try:
            self.update_endpoint.post([("update", self._delete_tokens_text([claim]))], "*/*", write=True,
                                      retry=RetryPolicy(attempts=1))
        except StoreError:
            return
        self._my_claims.discard(claim)

    def _live_claims(self, key: URIRef) -> List[_Claim]:
        """The claims on ``key`` younger than ``claim_ttl_s`` (by the server's clock; by this client's clock since
        it first saw a claim whose time it cannot read)."""
        doc = self._select_doc("SELECT ?t ?at ?c (NOW() AS ?now) WHERE { GRAPH %s { ?t %s %s ; %s ?at "
                               "OPTIONAL { ?t %s ?c } } }"
                               % (term_text(G_CLAIMS), term_text(P_CLAIM_ON), term_text(key),
                                  term_text(P_CLAIM_AT), term_text(P_WRITE_CLAIM)),
                               "the claims of a conditional change", dataset=False)
        _, rows = json_rows(doc, self.query_endpoint.name)
        out: List[_Claim] = []
        seen_now = self.clock()
        for r in rows:
            at, now = r.get("at"), r.get("now")
            token = str(r.get("t"))
            first = self._first_seen.setdefault(token, seen_now)
            try:
                age = (now.toPython() - at.toPython()).total_seconds()  # type: ignore[union-attr]
            except Exception:  # a server clock we cannot read: the age by this client's clock since first seen
                age = seen_now - first
            if len(self._first_seen) > 10000:
                self._first_seen.clear()
            if age < self.claim_ttl_s:
                out.append(_Claim(token, age, str(r.get("c") or "")))
        return out

    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        """``DROP SILENT GRAPH`` and the first chunk in one request, further chunks of ``chunk_triples`` each.
        Triples that share a blank node stay in one request (a blank node label names a node in one request)."""
        g = term_text(graph)
        try:
            chunks = [" ".join("%s %s %s ." % (term_text(s, True), term_text(p), term_text(o, True))
                               for s, p, o in chunk) for chunk in _chunks_keeping_blank_nodes(triples,
                                                                                               self.chunk_triples)]
        except InvalidParameterError as exc:
            raise StoreError("cannot replace graph %s: %s" % (graph, exc)) from None
        self._know_graphs([graph])
        with self._lock:
            self._forget_all()
            self._settle_unknown_writes()   # a late write must not land in the graph after it was replaced
            first = ["DROP SILENT GRAPH %s" % g]
            if chunks:
                first.append("INSERT DATA { GRAPH %s { %s } }" % (g, chunks[0]))
            self._update(" ;\n".join(first + self._version_ops()), "replacing graph %s" % graph)
            for i, body in enumerate(chunks[1:], 2):
                self._update(" ;\n".join(["INSERT DATA { GRAPH %s { %s } }" % (g, body)] + self._version_ops()),
                             "replacing graph %s (part %d of %d)" % (graph, i, len(chunks)))

    def drop_pemkre_graphs(self) -> List[URIRef]:
        """Drop every named graph under PEMKRE's graph namespace (one request; other graphs stay): a fresh
        store on a server that may hold other data too. Returns the graphs dropped."""
        graphs = sorted(g for g in set(self.refresh_graphs()) | self._graphs | {G_CLAIMS}
                        if str(g).startswith(str(GRAPHS)))
        with self._lock:
            self._forget_all()
            self._settle_unknown_writes()   # a late write must not bring data back into the fresh store
            self._done_tokens = []
            self._spent_versions = []       # their links go with the claims graph
            self._update(" ;\n".join(["DROP SILENT GRAPH %s" % term_text(g) for g in graphs] + self._version_ops()),
                         "dropping PEMKRE's graphs")
        return graphs

    def was_applied(self, token: str) -> Optional[bool]:
        """Was the write with claim ``token`` applied? (asks the server; for a
        :class:`~locem_bridge.pemkre.errors.StoreUnavailable` with ``applied=None``). True: its token is there.
        None: not there yet, but the write may still arrive (it stays in :attr:`unknown_writes`). False: not
        applied and it will not be (the server answered it, or ``claim_ttl_s`` has passed since it was sent).
        :class:`~locem_bridge.pemkre.errors.StoreError` when the server cannot be asked."""
        if not _TOKEN_RE.match(str(token)):
            raise StoreError("was_applied: %r is not a write token (allowed: urn:uuid:<36 hex digits and dashes>, as "
                             "StoreUnavailable.token gives it)" % (token,))
        found = self._token_stored(token)
        with self._lock:
            info = self._unknown.get(token)
            if found:
                self._unknown.pop(token, None)
                if token not in self._done_tokens:
                    self._done_tokens.append(token)
                return True
            if info is None or info.answered or self.clock() - info.sent >= self.claim_ttl_s:
                self._unknown.pop(token, None)
                return False
            return None

    def close(self) -> None:
        """Delete the claim tokens of applied writes (one request, not retried) and drop the connection."""
        if self._closed:
            return
        self._closed = True
        try:
            with self._lock:
                ops = self._cleanup_ops()
                if ops:
                    try:
                        self.update_endpoint.post([("update", ops[0])], "*/*", write=True,
                                                  retry=RetryPolicy(attempts=1))
                    except StoreError:
                        pass  # a leftover token is harmless (outside every query); the store is closing anyway
        finally:
            self.query_endpoint.close()
            self.update_endpoint.close()

    # ---------------------------------------------------------------- internals
    @staticmethod
    def _quad_text(q: Quad) -> str:
        return "GRAPH %s { %s %s %s }" % (term_text(q[3]), term_text(q[0]), term_text(q[1]), term_text(q[2]))

    @staticmethod
    def _new_token() -> str:  # matches _TOKEN_RE
        return "urn:uuid:%s" % uuid.uuid4()

    def _claim_text(self, token: str) -> str:
        return "GRAPH %s { <%s> %s %s }" % (term_text(G_CLAIMS), token, term_text(P_WRITE_CLAIM),
                                            term_text(Literal(self.client)))

    def _cleanup_ops(self) -> List[str]:
        """The operation deleting the tokens of applied writes, to lead the next write (then forgotten here)."""
        if not self._done_tokens:
            return []
        ops = [self._delete_tokens_text(self._done_tokens)]
        self._done_tokens = []
        return ops

    @staticmethod
    def _delete_tokens_text(tokens: Sequence[str]) -> str:
        return "DELETE { GRAPH %s { ?t ?p ?o } } WHERE { VALUES ?t { %s } GRAPH %s { ?t ?p ?o } }" % (
            term_text(G_CLAIMS), " ".join("<%s>" % t for t in tokens), term_text(G_CLAIMS))

    def _token_stored(self, token: str) -> bool:
        return self._ask_text("ASK { GRAPH %s { <%s> %s ?c } }" % (term_text(G_CLAIMS), token,
                                                                     term_text(P_WRITE_CLAIM)),
                              "reading back a write claim")

    def _write(self, ops: List[str], token: str, what: str) -> None:
        """Send ``ops`` as one update request; when its answer is lost, learn from ``token`` whether it was
        applied (a token of an applied write is left for the next write to delete)."""
        sent = self.clock()
        try:
            self._update(" ;\n".join(ops), what)
        except StoreUnavailable as exc:
            if exc.applied is not None:
                raise
            lost = str(exc).replace("; whether it was applied is unknown", "")
            try:
                applied = self._token_stored(token)
            except StoreError as again:
                self._note_unknown(token, sent, exc.timed_out)
                raise StoreUnavailable("%s; the server cannot be asked whether it was applied either (%s); "
                                       "was_applied(%r) tells later" % (lost, again, token), exc.endpoint,
                                       exc.reason, applied=None, token=token, timed_out=exc.timed_out) from None
            if not applied:
                # sent, and no answer: the server may still be working on it (a timeout), or have it in a queue
                # behind a proxy that closed the connection; not written yet is not "never written"
                self._note_unknown(token, sent, exc.timed_out)
                raise StoreUnavailable("%s; asked again, the server does not have it yet, but it may still apply "
                                       "it; was_applied(%r) tells later" % (lost, token), exc.endpoint, exc.reason,
                                       applied=None, token=token, timed_out=exc.timed_out) from None
            # written: only the answer was lost, which is no failure of the change

    def _update(self, text: str, what: str) -> None:
        try:
            self.update_endpoint.post([("update", text)], "*/*", write=True)
        except HttpStatusError as exc:
            raise HttpStatusError("%s was refused (nothing was written): %s" % (what, exc), exc.status) from None

    def _raise_conflict(self, changes: ChangeSet) -> None:
        for q in changes.expect:
            if not any(True for _ in self.quads(q[0], q[1], q[2], (q[3],))):
                raise conflict_error(self, q)
        raise conflict_error(self, changes.expect[0], " (it was missing when the change was tried and is back now)")

    def _select_doc(self, text: str, what: str, dataset: bool = True) -> object:
        answer = self.query_endpoint.post([("query", text)] + (self._dataset if dataset else []), _ACCEPT_RESULTS)
        return self._json_answer(answer, what)

    def _ask_text(self, text: str, what: str) -> bool:
        answer = self.query_endpoint.post([("query", text)], _ACCEPT_RESULTS)
        return self._boolean(self._json_answer(answer, what), what)

    def _json_answer(self, answer: Answer, what: str) -> object:
        where = self.query_endpoint.name
        if answer.media_type not in _JSON_TYPES:
            raise StoreError("%s answered %s with %s, not SPARQL results JSON%s" % (
                where, what, _describe(answer), ": is this the query URL of a SPARQL 1.1 server?"))
        try:
            return json.loads(answer.body.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as exc:
            raise StoreError("%s answered %s with broken JSON (%s), not SPARQL results" % (where, what, exc)) \
                from None

    def _boolean(self, doc: object, what: str) -> bool:
        value = doc.get("boolean") if isinstance(doc, dict) else None
        if not isinstance(value, bool):
            raise StoreError("%s answered %s with JSON that is not a SPARQL ASK result (no boolean)"
                             % (self.query_endpoint.name, what))
        return value

    def _graph_answer(self, answer: Answer, what: str) -> List[Triple]:
        where = self.query_endpoint.name
        if answer.media_type not in ("application/n-triples", "text/plain"):
            raise StoreError("%s answered %s with %s, not N-Triples" % (where, what, _describe(answer)))
        g = Graph()
        try:
            g.parse(data=answer.text(), format="nt")
        except Exception as exc:
            raise StoreError("%s answered %s with N-Triples that do not parse: %s"
                             % (where, what, str(exc).splitlines()[0][:200])) from None
        out: List[Triple] = []
        for s, p, o in g:
            s, o = unskolem(s), unskolem(o)
            if isinstance(o, Literal) and o.datatype == XSD.string:
                o = Literal(str(o))
            out.append((s, p, o))
        return out


def _describe(answer: Answer) -> str:
    """What an unexpected answer is, in a few words: an HTML page (with its title), or its media type."""
    text = answer.text()
    if answer.media_type == "text/html" or text.lstrip()[:15].lower().startswith(("<!doctype html", "<html")):
        m = re.search(r"(?is)<title[^>]*>(.*?)</title>", text)
        return "an HTML page%s" % (" (%r)" % " ".join(m.group(1).split())[:80] if m else "")
    return "%s (HTTP %d)" % (answer.media_type or "no content type", answer.status)


def _chunks_keeping_blank_nodes(triples: Iterable[Triple], size: int) -> List[List[Triple]]:
    """``triples`` in chunks of about ``size``; all triples that are connected through blank nodes in one chunk."""
    items = list(triples)
    parent: Dict[BNode, BNode] = {}

    def find(b: BNode) -> BNode:
        root = b
        while parent.setdefault(root, root) != root:
            root = parent[root]
        while parent[b] != root:
            parent[b], b = root, parent[b]
        return root

    for s, _, o in items:
        if isinstance(s, BNode) and isinstance(o, BNode):
            a, b = find(s), find(o)
            if a != b:
                parent[a] = b
    groups: Dict[object, List[Triple]] = {}
    plain: List[Triple] = []
    for t in items:
        b = t[0] if isinstance(t[0], BNode) else t[2] if isinstance(t[2], BNode) else None
        if b is None:
            plain.append(t)
        else:
            groups.setdefault(find(b), []).append(t)
    chunks: List[List[Triple]] = []
    current: List[Triple] = []
    for group in list(groups.values()) + [[t] for t in plain]:
        if current and len(current) + len(group) > size:
            chunks.append(current)
            current = []
        current.extend(group)
    if current:
        chunks.append(current)
    return chunks
