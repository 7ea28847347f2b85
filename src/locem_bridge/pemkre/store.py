"""The triplestore interface the engine talks to, and the value types that cross it.

Lifecycle: a concrete store (:class:`~locem_bridge.pemkre.oxigraph_store.OxigraphStore`, persistent, the default;
:class:`~locem_bridge.pemkre.rdflib_store.RdflibStore`, in memory) is created, handed to the engine, and closed
by whoever created it. Every write goes through :meth:`TripleStore.apply` and is atomic: either the whole
:class:`ChangeSet` is stored or none of it. When ``apply`` returns on a persistent store the change survives a
``kill -9`` of the process.

Queries are prepared once (:meth:`TripleStore.prepare`, with the vocabulary prefixes as ``initNs``) and run with
*bindings*: values are handed to the query engine as RDF terms (SPARQL substitution / rdflib ``initBindings``),
never spliced into query text. Terms at this interface are rdflib terms, so people script against rdflib.

A change may be *conditional*: :attr:`ChangeSet.expect` lists quads that must be in the store for it to apply,
checked in the same transaction as the write (the embedded stores under their write lock, the SPARQL store in one
``DELETE {..} INSERT {..} WHERE {..}`` request). A status update that expects the previous status cannot be won by
two writers: the loser gets :class:`~locem_bridge.pemkre.errors.StoreConflict` naming the quad that was not there,
and nothing of its change is written.

*Watching writes.* A store that is the only way into its dataset (:attr:`TripleStore.sole_writer`: the embedded
stores) tells :meth:`TripleStore.watch` callbacks about every applied change, and about every replaced graph
(with ``None``: anything may have changed), so an index kept beside the store (:mod:`~locem_bridge.pemkre.first_member`)
stays exact. A store other clients write to (the SPARQL store) cannot, and says so.

Backends: :class:`~locem_bridge.pemkre.journal_store.JournaledStore` and
:class:`~locem_bridge.pemkre.oxigraph_store.OxigraphStore` (embedded, one process per store),
:class:`~locem_bridge.pemkre.rdflib_store.RdflibStore` (in memory) and
:class:`~locem_bridge.pemkre.sparql_store.SparqlStore` (a remote SPARQL 1.1 server, any number of clients).
"""
import logging
import weakref
from abc import ABC, abstractmethod
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Callable, Dict, Iterable, Iterator, List, Mapping, Optional, Sequence, Tuple, Union

from rdflib import BNode, Literal, URIRef
from rdflib.term import Node

from .vocab import GRAPHS

_log = logging.getLogger(__name__)

Term = Union[URIRef, BNode, Literal]
Triple = Tuple[Node, Node, Node]
Quad = Tuple[Node, Node, Node, URIRef]
Row = Dict[str, Node]

#: Asserted ontology files (TBox and process models), replaced as a whole when the files change.
G_ONTOLOGY = GRAPHS.ontology
#: The OWL 2 RL closure of the ontology graph, materialised once.
G_SCHEMA_INFERRED = GRAPHS["schema-inferred"]
#: Asserted world state (scan results, semantic effects).
G_WORLD = GRAPHS.world
#: Specific processes and task executions: the execution log.
G_LOG = GRAPHS.log
#: The robots' resource models (skills, devices, tools; generated from the robot files), replaced as a whole.
G_RESOURCES = GRAPHS.resources
#: Inferences about world and log instances, maintained incrementally.
G_ABOX_INFERRED = GRAPHS["abox-inferred"]
#: Bookkeeping (ontology hash, counters).
G_META = GRAPHS.meta

ASSERTED_GRAPHS: Tuple[URIRef, ...] = (G_ONTOLOGY, G_WORLD, G_LOG, G_RESOURCES)
INFERRED_GRAPHS: Tuple[URIRef, ...] = (G_SCHEMA_INFERRED, G_ABOX_INFERRED)


#: the most IRIs :func:`cached_uri` keeps (then it starts afresh)
IRI_CACHE_MAX = 200_000
_IRI_CACHE: Dict[str, URIRef] = {}


def cached_uri(value: str) -> URIRef:
    """The URIRef for ``value``, one object per IRI: stores turn the same few thousand IRIs of their answers into
    rdflib terms again and again (query results, quads)."""
    u = _IRI_CACHE.get(value)
    if u is None:
        if len(_IRI_CACHE) >= IRI_CACHE_MAX:
            _IRI_CACHE.clear()
        u = _IRI_CACHE[value] = URIRef(value)
    return u

@dataclass
class ChangeSet:
    """Quads to remove, then quads to add, applied atomically by :meth:`TripleStore.apply`; only if every quad of
    ``expect`` is in the store at that moment (else :class:`~locem_bridge.pemkre.errors.StoreConflict`)."""

    remove: List[Quad] = field(default_factory=list)
    add: List[Quad] = field(default_factory=list)
    expect: List[Quad] = field(default_factory=list)

    def __bool__(self) -> bool:
        return bool(self.remove or self.add or self.expect)

    def extend(self, other: "ChangeSet") -> None:
        self.remove.extend(other.remove)
        self.add.extend(other.add)
        self.expect.extend(other.expect)


@dataclass(frozen=True)
class PreparedQuery:
    """A query parsed once; ``kind`` is ``ASK``, ``SELECT`` or ``CONSTRUCT``; ``name`` identifies it in errors."""

    name: str
    text: str
    kind: str
    variables: Tuple[str, ...]
    compiled: object = field(default=None, compare=False, repr=False)
    #: SELECT: the projected variables (bindable ones must be among them: SPARQL substitution, SEP-0007)
    projected: Tuple[str, ...] = ()

    def bindable(self, name: str) -> bool:
        """Can ``name`` be given a value? (it occurs in the query and, for SELECT, is projected)"""
        return name in self.variables and (self.kind != "SELECT" or name in self.projected)


@dataclass
class QueryResult:
    """An ASK answer (``boolean``) or SELECT rows (``variables`` + ``rows``)."""

    kind: str
    variables: List[str] = field(default_factory=list)
    rows: List[Row] = field(default_factory=list)
    boolean: Optional[bool] = None

    def to_sparql_json(self) -> Dict[str, object]:
        """The W3C SPARQL 1.1 Query Results JSON form."""
        if self.kind == "ASK":
            return {"head": {}, "boolean": bool(self.boolean)}
        bindings = []
        for row in self.rows:
            out: Dict[str, object] = {}
            for name, term in row.items():
                if term is None:
                    continue
                if isinstance(term, URIRef):
                    out[name] = {"type": "uri", "value": str(term)}
                elif isinstance(term, BNode):
                    out[name] = {"type": "bnode", "value": str(term)}
                else:
                    entry: Dict[str, str] = {"type": "literal", "value": str(term)}
                    if term.language:
                        entry["xml:lang"] = term.language
                    elif term.datatype is not None:
                        entry["datatype"] = str(term.datatype)
                    out[name] = entry
            bindings.append(out)
        return {"head": {"vars": list(self.variables)}, "results": {"bindings": bindings}}


class TripleStore(ABC):
    """One small interface over an RDF dataset with named graphs; see the module docstring."""

    #: True when an applied change survives a crash and a restart.
    persistent: bool = False
    #: True when every change of the data this object's reads see goes through it (then :meth:`watch` sees them
    #: all): the embedded stores, and the store that keeps a copy of a server's data (its copy changes only by its
    #: own writes and by loading it again, which it tells as ``None``).
    sole_writer: bool = False

    def follows_every_change(self) -> bool:
        """Do the :meth:`watch` callbacks see every change of what this thread's reads see now? (The store that
        keeps a copy of a server's data: not while it reads from the server.)"""
        return self.sole_writer

    def watch(self, callback: "Callable[[Optional[ChangeSet]], None]") -> bool:
        """Call ``callback(changes)`` after each applied change and ``callback(None)`` after each replaced graph,
        in the writing thread, once the write is done. A bound method is held weakly (an index that is gone stops
        being called). A callback that raises is logged and never fails the write, which is done: the callback
        must recover by itself (the first-member index builds again). Returns False (and never calls) on a store
        that is not the :attr:`sole_writer` of its dataset: what other clients write it cannot see."""
        if not self.sole_writer:
            return False
        ref = weakref.WeakMethod(callback) if hasattr(callback, "__self__") else (lambda: callback)  # type: ignore
        self.__dict__.setdefault("_watchers", []).append(ref)
        return True

    def _written(self, changes: Optional["ChangeSet"]) -> None:
        """Tell the watchers about a write that is done (concrete stores call this after each write)."""
        refs = self.__dict__.get("_watchers")
        if not refs:
            return
        for ref in list(refs):
            callback = ref()
            if callback is None:
                try:
                    refs.remove(ref)
                except ValueError:  # another writer's thread removed it first
                    pass
                continue
            try:
                callback(changes)
            except Exception:  # the write is done; a watcher's failure is its own (logged, not the writer's)
                _log.exception("a store watcher failed after a write")

    @abstractmethod
    def prepare(self, text: str, name: str, prefixes: Mapping[str, str]) -> PreparedQuery:
        """Parse ``text`` once; raise :class:`~locem_bridge.pemkre.errors.QueryError` naming ``name`` if invalid."""

    @abstractmethod
    def run(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> QueryResult:
        """Evaluate over the union of all graphs with ``bindings`` substituted as terms."""

    @staticmethod
    def _check_bindings(query: PreparedQuery, bindings: Optional[Mapping[str, Node]]) -> None:
        from .errors import QueryError

        for name in bindings or {}:
            if not query.bindable(name):
                raise QueryError("query %s cannot take a value for ?%s: %s" % (
                    query.name, name, "it does not use it" if name not in query.variables else
                    "SELECT queries must project the variables they are given values for (add ?%s to the "
                    "SELECT clause)" % name), query.name)

    def ask(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> bool:
        result = self.run(query, bindings)
        if result.kind == "ASK":
            return bool(result.boolean)
        return bool(result.rows)

    def select(self, query: PreparedQuery, bindings: Optional[Mapping[str, Node]] = None) -> List[Row]:
        return self.run(query, bindings).rows

    @abstractmethod
    def quads(self, s: Optional[Node] = None, p: Optional[Node] = None, o: Optional[Node] = None,
              graphs: Optional[Sequence[URIRef]] = None) -> Iterator[Quad]:
        """Quads matching the pattern (``None`` = any) in ``graphs`` (``None`` = every graph)."""

    def objects(self, s: Node, p: Node, graphs: Optional[Sequence[URIRef]] = None) -> List[Node]:
        seen: List[Node] = []
        for _, _, o, _ in self.quads(s, p, None, graphs):
            if o not in seen:
                seen.append(o)
        return seen

    def value(self, s: Node, p: Node, graphs: Optional[Sequence[URIRef]] = None) -> Optional[Node]:
        for _, _, o, _ in self.quads(s, p, None, graphs):
            return o
        return None

    @abstractmethod
    def apply(self, changes: ChangeSet) -> None:
        """Remove then add, atomically, if every ``changes.expect`` quad is present (else
        :class:`~locem_bridge.pemkre.errors.StoreConflict`, nothing written); blank nodes are not allowed."""

    def _check_expected(self, changes: ChangeSet) -> None:
        """Raise :class:`~locem_bridge.pemkre.errors.StoreConflict` for the first expected quad that is not stored
        (the embedded stores call this under the lock their writes hold)."""
        for q in changes.expect:
            if not any(True for _ in self.quads(q[0], q[1], q[2], (q[3],))):
                raise conflict_error(self, q)

    @abstractmethod
    def replace_graph(self, graph: URIRef, triples: Iterable[Triple]) -> None:
        """Replace a whole graph (blank nodes kept as given). Not atomic: callers mark completion in G_META."""

    @abstractmethod
    def count(self, graph: Optional[URIRef] = None) -> int:
        """Number of quads in ``graph`` (``None``: all graphs)."""

    def close(self) -> None:
        """Release files and locks; the store must not be used afterwards."""

    def flush(self) -> None:
        """Push buffered writes to disk (no-op for stores that never buffer)."""

    @contextmanager
    def reading(self) -> Iterator[None]:
        """A stretch of work (one decision) whose look-ups by subject may be answered from one fetch of each
        subject's quads: a store whose every read is a round trip (a server) keeps what it fetched until the
        outermost ``reading()`` ends, and forgets a subject when it writes one of its quads. Another client's write
        meanwhile is seen at the next stretch (conditional changes are still checked by the store). The embedded
        stores read directly: a no-op."""
        yield

    def prefetch(self, subjects: Iterable[Node]) -> None:
        """Within :meth:`reading`: fetch every quad of these subjects at once (a hint; no-op by default)."""

    def maintain(self) -> None:
        """Housekeeping when due (cheap to call often; the engine calls it after each change): drop what removed
        triples left behind in the indexes, so lookups do not slow down over a long life. No-op by default."""

    def snapshot(self, graphs: Optional[Sequence[URIRef]] = None):
        """An rdflib ``Dataset`` copy of ``graphs`` (default: all) for scripting and reference reasoning."""
        from rdflib import Dataset

        ds = Dataset()
        for s, p, o, g in self.quads(None, None, None, graphs):
            ds.graph(g).add((s, p, o))
        return ds


def conflict_error(store: TripleStore, quad: Quad, where: str = ""):
    """The :class:`~locem_bridge.pemkre.errors.StoreConflict` for ``quad`` (expected, not found): one line naming
    the quad and what its subject and predicate hold in that graph now."""
    from .errors import StoreConflict

    s, p, o, g = quad
    try:
        now = [t for t in store.objects(s, p, (g,))]
    except Exception:  # the conflict is the news; what is there now is a courtesy
        now = None
    held = "unknown" if now is None else (", ".join(t.n3() for t in now[:5]) if now else "nothing")
    return StoreConflict("conflict%s: the change expects %s %s %s in graph %s, but another writer changed it (it "
                         "holds %s now); nothing was written" % (where, s.n3(), p.n3(), o.n3(), g.n3(), held), quad)
