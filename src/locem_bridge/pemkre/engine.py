"""The PEMKRE process engine: abstract processes in, next actions out, the execution log written as it goes.

Lifecycle: ``ProcessEngine(store, ontology_files)`` loads and checks the ontologies (materialising the schema
closure once per ontology version, cached in the store), compiles the process models, prepares every query,
and finds the process that was running when the store was last used. Then, from any number of threads:

* :meth:`ProcessEngine.start_process` creates a *specific process* realizing an abstract one;
* :meth:`ProcessEngine.next_action` walks the flow chart from where the token is -- evaluating branch conditions
  against the world state, binding task parameters to world instances -- and returns the next task (its action
  type, IRI and parameters as N-Triples), or ``ended`` / ``failed``. Asking again before the task is reported
  returns the same task: the answer is stored before it is returned, so a restart never repeats or skips a task;
* :meth:`ProcessEngine.set_task_status` records ``in_progress`` / ``succeeded`` / ``failed`` with timestamps and
  applies the task type's semantic effects (and, for SCAN tasks, merges the SCAN result into the world). A failed
  task fails its process, unless its node has failure transitions (``proc:onTaskFailure``): then the process
  stays running and the next :meth:`~ProcessEngine.next_action` walks the first failure transition whose
  condition holds (none holding fails the process then). The failed task stays failed in the log and the KPIs.
  A report may carry a *request id* (any text, unique per report): it is stored with the status in the same
  atomic change, so the same report sent again -- a client retrying after PEMKRE died before answering -- is
  answered as already applied and changes nothing, also after a restart. ``start_process`` takes one too.
  The change is conditional on the status it was read with (:attr:`ChangeSet.expect`): when another engine on the
  same store moved the task on in between, the report raises
  :class:`~locem_bridge.pemkre.errors.StoreConflict` and writes nothing.
* :meth:`ProcessEngine.query` runs a predefined query of the ontology with values passed as bindings.

Every state change is one atomic :meth:`TripleStore.apply` holding the asserted triples and the inferred triples
that follow from them (:class:`IncrementalReasoner`), so the store is consistent after any crash. Errors leave the
store untouched and name the culprit (see :mod:`locem_bridge.pemkre.errors`). The engine does not own the store.
The inference of each change is bounded by ``reasoning_max_seconds`` (read on ``reasoning_clock``, a monotonic
clock) and ``reasoning_max_triples``: a change that hits a bound -- a world update, a status report, a next action
-- raises :class:`~locem_bridge.pemkre.errors.ReasoningBoundError` and writes nothing, so the store keeps the last
good state and the same call can be repeated.
"""
import datetime
import hashlib
import json
import logging
import secrets
import threading
import time
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from rdflib import BNode, Graph, Literal, Namespace, URIRef
from rdflib.namespace import RDF, XSD
from rdflib.term import Node

from ..common.next_action import NextAction
from ..common.task_status import TASK_STATUSES
from .errors import (BindingError, ConditionError, InvalidParameterError, InvalidStatusError, OntologyError,
                     ProcessModelError, QueryError, TaskStateError, UnknownProcessError, UnknownQueryError,
                     UnknownTaskError, UnmatchableProcessError)
from .first_member import FirstMember, Unanswerable
from .matching import ARG, SKILL, TEMPLATE, MatchingQueries, NodeMatch, ProcessMatch, SkillCatalog, match_process
from .ontology import (AbstractProcess, FlowNode, Parameter, ProcessModel, Transition, compile_model,
                       default_ontology_files, load_files)
from .reasoning import IncrementalReasoner, SchemaRules, bounded_closure, inferred_part
from .store import (G_LOG, G_META, G_ONTOLOGY, G_RESOURCES, G_SCHEMA_INFERRED, G_WORLD, ChangeSet, QueryResult,
                    TripleStore)
from .terms import check_iri, local_name, parameter_document, to_term
from .vocab import LOG, META, PROC, SITE, SK
from .world import scan_changes

_log = logging.getLogger(__name__)

# Vocabulary terms (pemkre/vocab.py) looked up once: attribute access on a DefinedNamespace is slow on the
# per-decision path.
_RDF_TYPE = RDF.type
_P_ScanResultJson = PROC.ScanResultJson
_P_SpecificProcess = PROC.SpecificProcess
_P_currentNode = PROC.currentNode
_P_currentTask = PROC.currentTask
_P_detail = PROC.detail
_P_durationSeconds = PROC.durationSeconds
_P_endedAt = PROC.endedAt
_P_executes = PROC.executes
_P_issuedAt = PROC.issuedAt
_P_partOfProcess = PROC.partOfProcess
_P_realizes = PROC.realizes
_P_sequenceNumber = PROC.sequenceNumber
_P_startedAt = PROC.startedAt
_P_status = PROC.status
_P_taskCount = PROC.taskCount
_P_TaskExecution = PROC.TaskExecution
_S_realizedBy = SK.realizedBy
_S_expandedFrom = SK.expandedFrom

MAX_DETAIL_CHARS = 1_000_000
_STORED_DETAIL_CHARS = 2000
#: The deepest nesting of a JSON argument (options, SCAN results) PEMKRE takes; a SCAN result needs 4.
MAX_JSON_DEPTH = 32
#: The longest request id of a status report or a process start.
MAX_REQUEST_ID_CHARS = 200
#: Where request ids are remembered: bookkeeping, not the execution log (the KPIs never see them).
_M_statusRequest = META.statusRequestId
_M_startRequest = META.startRequestId
#: The hash of the resource model stored in G_RESOURCES (a model loaded again unchanged writes nothing).
_M_resourceHash = META.resourceModelHash
#: The fingerprint of what the stored resource model was built from (given by the loader; see resume_resource_model).
_M_resourceKey = META.resourceModelKey
#: Schema closures by ontology hash, shared by the engines of one process (a closure is never modified).
#: schema hash -> (the schema graph, its closure): the schema is cached with its closure because a reload of the
#: same files gives its blank nodes new labels, and the ontology graph and the inferred schema graph written from
#: them must share their blank nodes
_CLOSURE_CACHE: Dict[str, Tuple[Graph, Graph]] = {}


@dataclass
class TaskStatusReport:
    task: str
    status: str
    process: str
    effects_applied: int = 0
    world_triples_changed: int = 0
    #: True when the request id was seen before: the report had already been applied, nothing changed now
    repeated: bool = False


def _json_depth(value: Any, what: str, limit: int) -> None:
    """InvalidParameterError when ``value`` nests lists/objects deeper than ``limit`` (iterative: no recursion)."""
    stack = [(value, 1)]
    while stack:
        v, depth = stack.pop()
        if isinstance(v, Mapping):
            children: Sequence[Any] = list(v.values())
        elif isinstance(v, (list, tuple)):
            children = v
        else:
            continue
        if depth > limit:
            raise InvalidParameterError("%s nests JSON arrays/objects deeper than the allowed %d levels"
                                        % (what, limit))
        stack.extend((c, depth + 1) for c in children)


def load_json(text: Union[str, bytes], what: str, limit: int = MAX_JSON_DEPTH) -> Any:
    """Parse a JSON argument of a PEMKRE call, refusing nesting deeper than ``limit`` levels.

    Raises :class:`InvalidParameterError` naming ``what`` for a too deep document; ``ValueError`` for text that
    is not JSON (callers report that in their own words).
    """
    try:
        value = json.loads(text)
    except RecursionError:
        raise InvalidParameterError("%s nests JSON arrays/objects deeper than the allowed %d levels"
                                    % (what, limit)) from None
    _json_depth(value, what, limit)
    return value


def _check_request_id(request_id: Optional[str]) -> str:
    if request_id is None:
        return ""
    if not isinstance(request_id, str):
        raise InvalidParameterError("request id must be text, got %s" % type(request_id).__name__)
    if len(request_id) > MAX_REQUEST_ID_CHARS or not all(" " < c < "\x7f" for c in request_id):
        raise InvalidParameterError("request id %r is not allowed: at most %d printable ASCII characters without "
                                    "spaces" % (request_id[:60], MAX_REQUEST_ID_CHARS))
    return request_id


@dataclass
class _State:
    sp: URIRef
    abstract: URIRef
    status: str
    node: URIRef
    task: Optional[URIRef]
    task_count: int


def _grounded(graph: Graph) -> List[Tuple[Node, Node, Node]]:
    """The triples of ``graph`` with blank nodes replaced by stable IRIs (the store takes no blank nodes)."""
    if not any(isinstance(x, BNode) for t in graph for x in t):
        return list(graph)
    from rdflib.compare import to_canonical_graph

    canonical = to_canonical_graph(graph)
    return list(canonical.skolemize(authority=str(LOG).rstrip("/").rsplit("/", 1)[0], basepath="/resource-node/"))


def _canonical_labels(graph: Graph) -> Graph:
    """``graph`` with its blank nodes relabelled canonically (rdflib.compare): the labels depend only on the
    triples, so any process loading the same ontology files gets the same labels. Prefix bindings are kept."""
    if not any(isinstance(x, BNode) for t in graph for x in t):
        return graph
    from rdflib.compare import to_canonical_graph

    out = Graph()
    for prefix, namespace in graph.namespaces():
        out.bind(prefix, namespace, override=True, replace=True)
    for t in to_canonical_graph(graph):
        out.add(t)
    return out


def _argument_literal(text: str) -> Literal:
    """A template step's literal argument: an integer or a number typed as such, else text."""
    try:
        return Literal(int(text))
    except ValueError:
        pass
    try:
        return Literal(float(text), datatype=XSD.double)
    except ValueError:
        return Literal(text)


def _now_literal(t: float) -> Literal:
    return Literal(datetime.datetime.fromtimestamp(t, tz=datetime.timezone.utc).isoformat(), datatype=XSD.dateTime)


def _time_of(lit: Optional[Node]) -> Optional[float]:
    if not isinstance(lit, Literal):
        return None
    v = lit.toPython()
    if isinstance(v, datetime.datetime):
        if v.tzinfo is None:
            v = v.replace(tzinfo=datetime.timezone.utc)
        return v.timestamp()
    return None


class ProcessEngine:
    """See the module docstring. All public methods are thread-safe (one lock)."""

    def __init__(self, store: TripleStore, ontology_files: Optional[Sequence[str]] = None, *,
                 site_namespace: Optional[str] = None, log_namespace: Optional[str] = None,
                 clock: Callable[[], float] = time.time, reasoning_max_seconds: float = 5.0,
                 reasoning_max_triples: int = 500_000, schema_max_seconds: float = 300.0,
                 schema_max_triples: int = 2_000_000, max_walk_steps: int = 10_000,
                 allow_unsupported_owl: bool = False,
                 reasoning_clock: Callable[[], float] = time.monotonic,
                 resource_model: Optional[Graph] = None, robot: Optional[str] = None) -> None:
        self.store = store
        self._schema_bounds = (schema_max_seconds, schema_max_triples)
        self.site = Namespace(str(check_iri(site_namespace, "site namespace"))) if site_namespace else SITE
        self.log_ns = Namespace(str(check_iri(log_namespace, "log namespace"))) if log_namespace else LOG
        self.clock = clock
        self.max_walk_steps = max_walk_steps
        self._lock = threading.RLock()
        files = list(ontology_files) if ontology_files is not None else default_ontology_files()
        loaded = load_files(files)
        self.prefixes = loaded.prefixes
        stored_hash = store.value(META.ontology, META.schemaHash, (G_META,))
        if stored_hash is None or str(stored_hash) != loaded.schema_hash:
            cached = _CLOSURE_CACHE.get(loaded.schema_hash)
            if cached is None:
                # canonical blank node labels: every client loading the same files writes the same labels, so an
                # ontology graph written by one client and an inferred schema graph written by another (two
                # clients starting on one empty server) still share their blank nodes
                schema = _canonical_labels(loaded.schema)
                closed = bounded_closure(schema, schema_max_seconds, schema_max_triples)
                _CLOSURE_CACHE.clear()
                _CLOSURE_CACHE[loaded.schema_hash] = (schema, closed)
            else:
                schema, closed = cached
            rules = SchemaRules(closed, schema)
            self._check_unsupported(rules, allow_unsupported_owl)
            model = compile_model(closed, store, self.prefixes)  # before any write: a bad model changes nothing
            store.replace_graph(G_ONTOLOGY, schema)
            store.replace_graph(G_SCHEMA_INFERRED, inferred_part(schema, closed))
            self.reasoner = IncrementalReasoner(rules, reasoning_max_seconds, reasoning_max_triples,
                                                 reasoning_clock)
            cs = self.reasoner.recompute_all(store, max_seconds=schema_max_seconds, max_triples=schema_max_triples)
            cs.remove += [(s, p, o, G_META) for s, p, o, _ in store.quads(META.ontology, META.schemaHash, None, (G_META,))]
            cs.add.append((META.ontology, META.schemaHash, Literal(loaded.schema_hash), G_META))
            store.apply(cs)
        else:
            closed = Graph()
            for s, p, o, _ in store.quads(None, None, None, (G_ONTOLOGY, G_SCHEMA_INFERRED)):
                closed.add((s, p, o))
            rules = SchemaRules(closed, loaded.schema)
            self._check_unsupported(rules, allow_unsupported_owl)
            model = compile_model(closed, store, self.prefixes)
            self.reasoner = IncrementalReasoner(rules, reasoning_max_seconds, reasoning_max_triples,
                                                 reasoning_clock)
        self.model: ProcessModel = model
        self.rules = rules
        seed_hash = store.value(META.ontology, META.seedHash, (G_META,))
        if len(loaded.seed) and (seed_hash is None or str(seed_hash) != loaded.seed_hash):
            cs = ChangeSet()
            for s, p, o in loaded.seed:
                if isinstance(s, BNode) or isinstance(o, BNode):
                    raise OntologyError("world seed files may not contain blank nodes (found in %s); "
                                        "give the instance an IRI" % ((s, p, o),))
                cs.add.append((s, p, o, G_WORLD))
            cs = self.reasoner.infer(store, cs, max_seconds=schema_max_seconds, max_triples=schema_max_triples)
            cs.remove += [(s, p, o, G_META) for s, p, o, _ in store.quads(META.ontology, META.seedHash, None, (G_META,))]
            cs.add.append((META.ontology, META.seedHash, Literal(loaded.seed_hash), G_META))
            store.apply(cs)
        # parameters declared as "the first member of a class by an order property": kept indexed on an embedded
        # store (pemkre/first_member.py), built here so the first decision does not pay for it
        self._firsts: Dict[Tuple[URIRef, URIRef], FirstMember] = {}
        for ap in self.model.processes.values():
            for fnode in ap.nodes.values():
                for prm in fnode.parameters:
                    if prm.first_of is not None and prm.first_of not in self._firsts:
                        index = self._firsts[prm.first_of] = FirstMember(store, *prm.first_of)
                        try:
                            index.first()
                        except Unanswerable:
                            pass
        self._active: Optional[URIRef] = self._find_running()
        # capability matching (pemkre/matching.py): off until a resource model is loaded
        self._matching = False
        self._robot: Optional[URIRef] = check_iri(robot, "robot IRI") if robot else None
        self._match_queries: Optional[MatchingQueries] = None
        self._catalog: Optional[SkillCatalog] = None
        self._matches: Dict[URIRef, ProcessMatch] = {}
        if resource_model is not None:
            self.load_resource_model(resource_model)

    @staticmethod
    def _check_unsupported(rules: SchemaRules, allow: bool) -> None:
        if rules.unsupported and not allow:
            raise OntologyError("the ontologies use OWL constructs the incremental reasoner does not support for "
                                "individuals: %s (pass allow_unsupported_owl=True to accept answers that may differ "
                                "from a full OWL 2 RL closure)" % ", ".join(rules.unsupported))

    # ================================================================= state helpers
    def _v(self, s: Node, p: URIRef, graphs=(G_LOG,)) -> Optional[Node]:
        return self.store.value(s, p, graphs)

    def _find_running(self) -> Optional[URIRef]:
        """The running specific process, else the one started last (None on a fresh store)."""
        best: Optional[Tuple[int, float, URIRef]] = None
        running = self.model.status_iri["running"]
        for sp, _, _, _ in self.store.quads(None, _RDF_TYPE, _P_SpecificProcess, (G_LOG,)):
            t = _time_of(self._v(sp, _P_startedAt)) or 0.0
            key = (1 if self._v(sp, _P_status) == running else 0, t, sp)
            if best is None or key[:2] > best[:2]:
                best = key  # type: ignore[assignment]
        return best[2] if best else None

    def _state(self, sp: URIRef) -> _State:
        abstract = self._v(sp, _P_realizes)
        if abstract is None:
            raise UnknownProcessError("<%s> is not a specific process started by start_process" % sp)
        st = self._v(sp, _P_status)
        node = self._v(sp, _P_currentNode)
        task = self._v(sp, _P_currentTask)
        count = self._v(sp, _P_taskCount)
        return _State(sp, abstract, self.model.status_name.get(st, str(st)), node, task,  # type: ignore[arg-type]
                      int(count.toPython()) if isinstance(count, Literal) else 0)

    def _commit(self, cs: ChangeSet, max_seconds: Optional[float] = None) -> None:
        full = self.reasoner.infer(self.store, cs, max_seconds=max_seconds)
        self.store.apply(full)
        self.store.maintain()  # index housekeeping when enough triples were removed (rare, see the store)

    def _replace(self, cs: ChangeSet, s: URIRef, p: URIRef, o: Optional[Node], graph: URIRef = G_LOG) -> None:
        for s2, p2, o2, _ in self.store.quads(s, p, None, (graph,)):
            if o2 != o:
                cs.remove.append((s2, p2, o2, graph))
        if o is not None and not any(True for _ in self.store.quads(s, p, o, (graph,))):
            cs.add.append((s, p, o, graph))

    # ================================================================= public API
    def processes(self) -> List[str]:
        """IRIs of the abstract processes the ontologies define."""
        return sorted(str(p) for p in self.model.processes)

    def active_process(self) -> Optional[str]:
        """The running specific process, if any."""
        with self._lock:
            if self._active is None or self._state(self._active).status != "running":
                return None
            return str(self._active)

    def current_process(self) -> Optional[str]:
        """The specific process ``next_action()`` talks about: the running one, else the last one started."""
        with self._lock:
            return str(self._active) if self._active is not None else None

    # ================================================================= capability matching
    def resume_resource_model(self, key: str, robot: Optional[str] = None) -> bool:
        """Match with the resource model already in the store when it was loaded with the same ``key`` (a
        fingerprint of what it was built from): a restarted node need not build it again. False: load it."""
        with self._lock:
            stored = self.store.value(META.ontology, _M_resourceKey, (G_META,))
            if not key or stored is None or str(stored) != key or \
                    next(iter(self.store.quads(None, None, None, (G_RESOURCES,))), None) is None:
                return False
            if robot:
                self._robot = check_iri(robot, "robot IRI")
            self._catalog = None
            self._matches.clear()
            self._matching = True
            return True

    def load_resource_model(self, graph: Optional[Graph], robot: Optional[str] = None, key: str = "") -> int:
        """Put a resource model (skills, devices, tools of one or more robots) into the store and match from now on.

        The model replaces the one stored before (graph ``G_RESOURCES``; inferences follow in the same atomic
        change; a model equal to the stored one writes nothing). ``robot`` names the robot processes run on
        (default: the one given at construction, else the model's first robot by IRI); ``key`` is remembered for
        :meth:`resume_resource_model`. ``None`` turns matching off (the stored model stays). Returns the number of
        triples of the model.
        """
        with self._lock:
            if graph is not None and not isinstance(graph, Graph):
                raise InvalidParameterError("the resource model must be an rdflib Graph, got %s" % type(graph).__name__)
            if robot:
                self._robot = check_iri(robot, "robot IRI")
            self._catalog = None
            self._matches.clear()
            if graph is None:
                self._matching = False
                return 0
            triples = _grounded(graph)
            digest = hashlib.sha256("\n".join(sorted("%s %s %s" % (s.n3(), p.n3(), o.n3())
                                                     for s, p, o in triples)).encode("utf-8")).hexdigest()
            stored = self.store.value(META.ontology, _M_resourceHash, (G_META,))
            stored_key = self.store.value(META.ontology, _M_resourceKey, (G_META,))
            if stored is None or str(stored) != digest or str(stored_key or "") != key:
                cs = ChangeSet()
                cs.remove += list(self.store.quads(None, None, None, (G_RESOURCES,)))
                cs.add += [(s, p, o, G_RESOURCES) for s, p, o in triples]
                cs = self.reasoner.infer(self.store, cs, max_seconds=self._schema_bounds[0],
                                         max_triples=self._schema_bounds[1])
                cs.remove += list(self.store.quads(META.ontology, _M_resourceHash, None, (G_META,)))
                cs.add.append((META.ontology, _M_resourceHash, Literal(digest), G_META))
                cs.remove += list(self.store.quads(META.ontology, _M_resourceKey, None, (G_META,)))
                if key:
                    cs.add.append((META.ontology, _M_resourceKey, Literal(key), G_META))
                self.store.apply(cs)
            self._matching = True
            self._catalog_now()
            return len(triples)

    @property
    def matching(self) -> bool:
        """True when a resource model is loaded: processes are matched to the robot's skills."""
        return self._matching

    def _catalog_now(self) -> SkillCatalog:
        if self._catalog is None:
            if self._match_queries is None:
                self._match_queries = MatchingQueries(self.store)
            self._catalog = SkillCatalog.read(self._match_queries)
        return self._catalog

    def _bind_for_match(self, node: FlowNode, prm: Any) -> Optional[Node]:
        """A task parameter's value in the current world (no process yet: ?process and ?task stay unbound)."""
        try:
            value = self._parameter_value(prm, None)
        except QueryError:
            return None
        return None if isinstance(value, BNode) else value

    def _parameter_value(self, prm: Parameter, binds: Optional[Mapping[str, Node]]) -> Optional[Node]:
        """The value of a task parameter now: from its index when it has one that can answer, else the first
        ?value of its binding query (QueryError when that fails)."""
        index = self._firsts.get(prm.first_of) if prm.first_of is not None else None
        if index is not None:
            try:
                return index.first()
            except Unanswerable:
                pass
        rows = self.store.select(prm.query, binds)
        return rows[0].get("value") if rows else None

    def _match(self, ap: AbstractProcess) -> ProcessMatch:
        return match_process(self._catalog_now(), ap, self._bind_for_match, self._robot)

    def match_process(self, process: str) -> ProcessMatch:
        """Every task node of the abstract ``process`` matched to this robot's skills, with the rejected
        candidates and their reasons (:mod:`locem_bridge.pemkre.matching`). Read-only."""
        with self._lock, self.store.reading():
            iri = check_iri(process, "process IRI")
            ap = self.model.processes.get(iri)
            if ap is None:
                raise UnknownProcessError("<%s> is not an abstract process; known processes: %s"
                                          % (iri, ", ".join(self.processes()) or "none"))
            if not self._matching:
                raise TaskStateError("no resource model is loaded, so nothing is matched (start PEMKRE with the "
                                     "robot's resource model, or call load_resource_model)")
            return self._match(ap)

    def _node_match(self, sp: URIRef, ap: AbstractProcess, node: FlowNode) -> Optional[NodeMatch]:
        """How the task of ``node`` is realized in process ``sp`` (None: no matching, the tree is the action type)."""
        if not self._matching:
            return None
        pm = self._matches.get(sp)
        if pm is None:                  # a process started before a restart: match it again
            pm = self._matches[sp] = self._match(ap)
        nm = pm.node(str(node.iri))
        if not nm.ok:
            raise UnmatchableProcessError("process <%s>: %s" % (sp, "; ".join(pm.problems())), pm)
        return nm

    def start_process(self, process: str, options: Optional[Mapping[str, Any]] = None, *,
                      abort_running: bool = False, request_id: str = "") -> str:
        """Create a specific process realizing the abstract ``process``; return its IRI.

        ``options`` maps option names declared by the process (e.g. ``validateLines``) to values. A process that
        is still running makes this fail unless ``abort_running`` (then it is marked failed first). A
        ``request_id`` seen before returns the process that request started (nothing new is started).
        """
        with self._lock, self.store.reading():
            rid = _check_request_id(request_id)
            iri = check_iri(process, "process IRI")
            if rid:
                for sp0, _, _, _ in self.store.quads(None, _M_startRequest, Literal(rid), (G_META,)):
                    if self._v(sp0, _P_realizes) != iri:
                        raise InvalidParameterError("request id %r already started <%s>, a process realizing "
                                                    "<%s>, not <%s>" % (rid, sp0, self._v(sp0, _P_realizes), iri))
                    # a start whose write landed but whose answer was lost (the store raised NOT_READY): the
                    # process it started is the current one, as if the first call had been answered
                    self._active = self._find_running()
                    return str(sp0)
            if options is not None:
                _json_depth(options, "options", MAX_JSON_DEPTH)
            ap = self.model.processes.get(iri)
            if ap is None:
                raise UnknownProcessError("<%s> is not an abstract process; known processes: %s"
                                          % (iri, ", ".join(self.processes()) or "none"))
            opt_values = self._option_values(ap, options or {})
            pm: Optional[ProcessMatch] = None
            if self._matching:
                pm = self._match(ap)
                if not pm.ok:
                    raise UnmatchableProcessError(
                        "process <%s> cannot run on robot <%s>: %s" % (iri, pm.robot, "; ".join(pm.problems())), pm)
            cs = ChangeSet()
            if self._active is not None and self._state(self._active).status == "running":
                if not abort_running:
                    raise TaskStateError("process <%s> is still running; finish it (next_action until ended) or "
                                         "start with abort_running=True" % self._active)
                cs.extend(self._fail_changes(self._state(self._active), "aborted by start_process of <%s>" % iri))
            now = self.clock()
            sp = self.log_ns["%s_%s_%s" % (local_name(iri), time.strftime("%Y%m%dT%H%M%S", time.gmtime(now)),
                                           secrets.token_hex(3))]
            st = self.model.status_iri
            cs.add += [(sp, _RDF_TYPE, _P_SpecificProcess, G_LOG), (sp, _P_realizes, iri, G_LOG),
                       (sp, _P_status, st["running"], G_LOG), (sp, _P_startedAt, _now_literal(now), G_LOG),
                       (sp, _P_currentNode, ap.start, G_LOG), (sp, _P_taskCount, Literal(0), G_LOG)]
            for prop, value in opt_values:
                cs.add.append((sp, prop, value, G_LOG))
            if rid:
                cs.add.append((sp, _M_startRequest, Literal(rid), G_META))
            self._commit(cs)
            self._active = sp
            if pm is not None:
                self._matches[sp] = pm
            return str(sp)

    def _option_values(self, ap: AbstractProcess, options: Mapping[str, Any]) -> List[Tuple[URIRef, Node]]:
        if not isinstance(options, Mapping):
            raise InvalidParameterError("options must be a mapping of option name to value")
        for name in options:
            if name not in ap.options:
                raise InvalidParameterError("unknown option %r for <%s>; allowed: %s"
                                            % (name, ap.iri, ", ".join(sorted(ap.options)) or "none"))
        out = []
        for name, opt in sorted(ap.options.items()):
            value = options.get(name, None)
            default = opt.default
            if value is None:
                if default is None:
                    continue
                out.append((opt.prop, default))
                continue
            if isinstance(default, Literal) and default.datatype == XSD.boolean:
                if isinstance(value, str) and value.lower() in ("true", "false", "1", "0"):
                    value = value.lower() in ("true", "1")
                if not isinstance(value, bool):
                    raise InvalidParameterError("option %r must be a boolean (true/false), got %r" % (name, value))
            out.append((opt.prop, to_term(value, "option %r" % name)))
        return out

    def next_action(self, process: Optional[str] = None) -> NextAction:
        """The next high-level action of ``process`` (default: the running one); see the module docstring."""
        with self._lock, self.store.reading():   # one fetch per subject (a server's round trip) per decision
            sp = check_iri(process, "process IRI") if process else self._active
            if sp is None:
                raise TaskStateError("no process has been started; call start_process first")
            state = self._state(sp)
            if state.task is not None:
                self.store.prefetch([state.task])
            if state.status == "ended":
                return NextAction("ended", str(sp), message=self._outcome(state))
            if state.status == "failed":
                return NextAction("failed", str(sp), message=str(self._v(sp, _P_detail) or "process failed"))
            leaving = recovering = False
            if state.task is not None and state.node in self.model.task_node_index:
                tstatus = self.model.status_name.get(self._v(state.task, _P_status), "")
                if tstatus in ("issued", "in_progress"):
                    return self._describe(state.task, state, tstatus)
                if tstatus == "succeeded" and self._matching:
                    parent = self._v(state.task, _S_expandedFrom)
                    if parent is not None and self.model.status_name.get(self._v(parent, _P_status), "") != "succeeded":
                        return self._issue_step(state, parent)   # the template has steps left
                if tstatus == "succeeded":
                    leaving = True
                elif tstatus == "failed" and self.model.task_node_index[state.node][1].on_failure:
                    recovering = True
                else:
                    return NextAction("failed", str(sp), message="task <%s> is %s" % (state.task, tstatus))
            ap = self.model.processes[state.abstract]
            node = ap.nodes.get(state.node)
            if node is None:
                raise ProcessModelError("specific process <%s> sits at <%s>, which is not a node of <%s> "
                                        "(ontology changed under a running process?)" % (sp, state.node, ap.iri))
            if recovering:  # the task failed and its node has failure transitions: walk one of them
                tr = self._choose_failure(node, sp)
                if tr is None:
                    assert state.task is not None
                    message = "%s; no failure transition of <%s> applies (%s)" % (
                        self._failure_message(state.task, node), node.iri,
                        ", ".join("<%s>" % t.iri for t in node.on_failure))
                    self._commit(self._fail_changes(state, message))
                    return NextAction("failed", str(sp), message=message)
                node = ap.nodes[tr.target]
            for _ in range(self.max_walk_steps):
                if not leaving:
                    if node.kind == "task":
                        return self._issue(state, ap, node)
                    if node.kind == "end":
                        return self._end(state, node)
                leaving = False
                node = ap.nodes[self._choose(node, sp).target]
            raise ProcessModelError("process <%s> walked %d control nodes without reaching a task or an end "
                                    "(loop without a task around <%s>)" % (ap.iri, self.max_walk_steps, node.iri))

    def _choose(self, node: FlowNode, sp: URIRef) -> Transition:
        tr = self._first_applicable(node, node.outgoing, sp, "transition")
        if tr is None:
            raise ProcessModelError("no transition applies at <%s>: every condition is false and there is no "
                                    "transition without condition (%s)"
                                    % (node.iri, ", ".join("<%s>" % t.iri for t in node.outgoing)))
        return tr

    def _choose_failure(self, node: FlowNode, sp: URIRef) -> Optional[Transition]:
        """The failure transition to take from ``node`` (first whose condition holds), or None if none applies."""
        return self._first_applicable(node, node.on_failure, sp, "failure transition")

    def _first_applicable(self, node: FlowNode, transitions: Sequence[Transition], sp: URIRef,
                          what: str) -> Optional[Transition]:
        """The first of ``transitions`` (in priority order) without a condition or whose condition holds."""
        for tr in transitions:
            if tr.condition is None:
                return tr
            binds = {"process": sp} if tr.condition.bindable("process") else None
            try:
                if self.store.ask(tr.condition, binds):
                    return tr
            except QueryError as exc:
                raise ConditionError("condition of %s <%s> (from <%s>) failed: %s"
                                     % (what, tr.iri, node.iri, exc), str(tr.iri)) from None
        return None

    def _failure_message(self, task: URIRef, node: FlowNode) -> str:
        tt = node.task_type
        detail = self._v(task, _P_detail)
        return "task <%s> (%s) failed: %s" % (task, tt.action_type if tt else "?", detail if detail is not None else "")

    def _issue(self, state: _State, ap: AbstractProcess, node: FlowNode) -> NextAction:
        sp = state.sp
        seq = state.task_count + 1
        task = URIRef("%s_task_%d" % (sp, seq))
        params: List[Tuple[URIRef, URIRef, Node]] = []
        for prm in node.parameters:
            binds = {k: v for k, v in (("process", sp), ("task", task)) if prm.query.bindable(k)}
            try:
                value = self._parameter_value(prm, binds)
            except QueryError as exc:
                raise BindingError("binding query of parameter %r (<%s>) of task node <%s> failed: %s"
                                   % (prm.name, prm.iri, node.iri, exc), str(prm.iri)) from None
            if value is None:
                if prm.required:
                    raise BindingError("parameter %r of task node <%s> has no value: its binding query <%s> "
                                       "returned no ?value in the current world state" % (prm.name, node.iri, prm.iri),
                                       str(prm.iri))
                continue
            if isinstance(value, BNode):
                raise BindingError("binding query <%s> returned a blank node; parameters must be IRIs or literals"
                                   % prm.iri, str(prm.iri))
            params.append((task, prm.prop, value))
        nm = self._node_match(sp, ap, node)
        now = self.clock()
        tt = node.task_type
        assert tt is not None
        cs = ChangeSet()
        cs.add += [(task, _RDF_TYPE, tt.iri, G_LOG), (task, _P_executes, node.iri, G_LOG),
                   (task, _P_partOfProcess, sp, G_LOG), (task, _P_status, self.model.status_iri["issued"], G_LOG),
                   (task, _P_issuedAt, _now_literal(now), G_LOG), (task, _P_sequenceNumber, Literal(seq), G_LOG)]
        cs.add += [(s, p, o, G_LOG) for s, p, o in params]
        self._replace(cs, sp, _P_currentNode, node.iri)
        real = nm.realization if nm is not None else None
        if real is not None and real.kind == TEMPLATE:
            # the task is expanded: its first step is issued now, as a task of its own
            sub, answer = self._step_changes(cs, sp, task, real, 0, {p: o for _, p, o in params}, seq + 1, now)
            self._replace(cs, sp, _P_currentTask, sub)
            self._replace(cs, sp, _P_taskCount, Literal(seq + 1))
            self._commit(cs)
            return answer
        if real is not None:
            cs.add.append((task, _S_realizedBy, URIRef(real.skill), G_LOG))
        self._replace(cs, sp, _P_currentTask, task)
        self._replace(cs, sp, _P_taskCount, Literal(seq))
        self._commit(cs)
        return NextAction("action", str(sp), str(task), tt.action_type, parameter_document(task, sorted(params)),
                          "issued", skill=real.name if real else "", skill_kind=real.skill_kind if real else "")

    def _step_changes(self, cs: ChangeSet, sp: URIRef, parent: URIRef, real: Any, index: int,
                      parent_params: Mapping[URIRef, Node], seq: int, now: float) -> Tuple[URIRef, NextAction]:
        """Add the subtask for step ``index`` of the template realizing ``parent`` to ``cs``; its next action."""
        step = real.steps[index]
        sub = URIRef("%s_task_%d" % (sp, seq))
        by_name = {local_name(p): o for p, o in parent_params.items()}
        args: List[Tuple[URIRef, URIRef, Node]] = []
        for name, text in step.arguments:
            if text.startswith("{") and text.endswith("}"):
                value = by_name.get(text[1:-1])
                if value is None:
                    raise BindingError("step %d of template <%s> passes %s=%s, but task <%s> has no value for %r"
                                       % (step.index, real.template, name, text, parent, text[1:-1]), real.template)
                names = self._catalog_now().tool_names.get(value)  # type: ignore[arg-type]
                if names:                   # a tool: the skill takes its name (as the robot file spells it)
                    value = Literal(sorted(names)[0])
            else:
                value = _argument_literal(text)
            args.append((sub, ARG[name], value))
        cs.add += [(sub, _RDF_TYPE, _P_TaskExecution, G_LOG), (sub, _P_partOfProcess, sp, G_LOG),
                   (sub, _S_expandedFrom, parent, G_LOG), (sub, _S_realizedBy, URIRef(step.skill), G_LOG),
                   (sub, _P_status, self.model.status_iri["issued"], G_LOG),
                   (sub, _P_issuedAt, _now_literal(now), G_LOG), (sub, _P_sequenceNumber, Literal(seq), G_LOG)]
        cs.add += [(s, p, o, G_LOG) for s, p, o in args]
        return sub, NextAction("action", str(sp), str(sub), step.name, parameter_document(sub, sorted(args)),
                               "issued", skill=step.name, skill_kind=step.skill_kind)

    def _steps_of(self, parent: URIRef) -> List[URIRef]:
        return [s for s, _, _, _ in self.store.quads(None, _S_expandedFrom, parent, (G_LOG,))]

    def _template_of(self, state: _State, parent: URIRef) -> Any:
        ap = self.model.processes[state.abstract]
        nm = self._node_match(state.sp, ap, self.model.task_node_index[state.node][1])
        real = nm.realization if nm is not None else None
        if real is None or real.kind != TEMPLATE:
            raise UnmatchableProcessError("task <%s> was expanded by a task template, but its node <%s> is no longer "
                                          "realized by one (was the resource model changed under a running process?)"
                                          % (parent, state.node))
        return real

    def _issue_step(self, state: _State, parent: URIRef) -> NextAction:
        """The next step of the template that expands ``parent`` (the previous step succeeded)."""
        real = self._template_of(state, parent)
        done = len(self._steps_of(parent))
        _, node = self.model.task_node_index[state.node]
        params = {prm.prop: v for prm in node.parameters for v in [self._v(parent, prm.prop)] if v is not None}
        cs = ChangeSet()
        seq = state.task_count + 1
        sub, answer = self._step_changes(cs, state.sp, parent, real, done, params, seq, self.clock())
        self._replace(cs, state.sp, _P_currentTask, sub)
        self._replace(cs, state.sp, _P_taskCount, Literal(seq))
        self._commit(cs)
        return answer

    def _describe(self, task: URIRef, state: _State, tstatus: str) -> NextAction:
        proc_iri, node = self.model.task_node_index[state.node]
        tt = node.task_type
        assert tt is not None
        skill, kind = "", ""
        realized = self._v(task, _S_realizedBy) if self._matching else None
        if realized is not None:
            info = self._catalog_now().skills.get(realized)  # type: ignore[arg-type]
            skill, kind = (info.name, info.kind) if info is not None else (local_name(realized), "")
        if realized is not None and self._v(task, _S_expandedFrom) is not None:   # a template step
            args = [(task, p, o) for _, p, o, _ in self.store.quads(task, None, None, (G_LOG,))
                    if str(p).startswith(str(ARG))]
            return NextAction("action", str(state.sp), str(task), skill, parameter_document(task, sorted(args)),
                              tstatus, skill=skill, skill_kind=kind)
        params = []
        for prm in node.parameters:
            v = self._v(task, prm.prop)
            if v is not None:
                params.append((task, prm.prop, v))
        return NextAction("action", str(state.sp), str(task), tt.action_type, parameter_document(task, sorted(params)),
                          tstatus, skill=skill, skill_kind=kind)

    def _end(self, state: _State, node: FlowNode) -> NextAction:
        now = self.clock()
        cs = ChangeSet()
        self._replace(cs, state.sp, _P_currentNode, node.iri)
        self._replace(cs, state.sp, _P_status, self.model.status_iri["ended"])
        cs.add.append((state.sp, _P_endedAt, _now_literal(now), G_LOG))
        started = _time_of(self._v(state.sp, _P_startedAt))
        if started is not None:
            cs.add.append((state.sp, _P_durationSeconds, Literal(max(0.0, now - started), datatype=XSD.double), G_LOG))
        self._commit(cs)
        return NextAction("ended", str(state.sp), message=node.end_outcome or "ended")

    def _outcome(self, state: _State) -> str:
        ap = self.model.processes.get(state.abstract)
        node = ap.nodes.get(state.node) if ap else None
        return (node.end_outcome if node is not None else None) or "ended"

    def _fail_changes(self, state: _State, message: str, now: Optional[float] = None) -> ChangeSet:
        now = self.clock() if now is None else now
        cs = ChangeSet()
        self._replace(cs, state.sp, _P_status, self.model.status_iri["failed"])
        cs.add.append((state.sp, _P_endedAt, _now_literal(now), G_LOG))
        cs.add.append((state.sp, _P_detail, Literal(message[:_STORED_DETAIL_CHARS]), G_LOG))
        if state.task is not None:  # an open task of an aborted process fails with it
            tstatus = self.model.status_name.get(self._v(state.task, _P_status), "")
            if tstatus in ("issued", "in_progress"):
                self._replace(cs, state.task, _P_status, self.model.status_iri["failed"])
                cs.add.append((state.task, _P_endedAt, _now_literal(now), G_LOG))
                if self._v(state.task, _P_detail) is None:
                    cs.add.append((state.task, _P_detail, Literal(message[:_STORED_DETAIL_CHARS]), G_LOG))
            parent = self._v(state.task, _S_expandedFrom)     # a template step: its parent task fails with it
            if parent is not None and self.model.status_name.get(self._v(parent, _P_status), "") in (
                    "issued", "in_progress"):
                self._replace(cs, parent, _P_status, self.model.status_iri["failed"])
                cs.add.append((parent, _P_endedAt, _now_literal(now), G_LOG))
        started = _time_of(self._v(state.sp, _P_startedAt))
        if started is not None:
            cs.add.append((state.sp, _P_durationSeconds, Literal(max(0.0, now - started), datatype=XSD.double), G_LOG))
        return cs

    def set_task_status(self, task: str, status: str, detail: str = "", request_id: str = "") -> TaskStatusReport:
        """Record a task status reported by HICEM and apply the task's semantic effects (see module docstring).

        A ``request_id`` already applied to this task answers ``repeated=True`` and changes nothing.
        """
        with self._lock, self.store.reading():
            if status not in TASK_STATUSES:
                raise InvalidStatusError("task status %r is not allowed; use one of %s" % (status, ", ".join(TASK_STATUSES)))
            rid = _check_request_id(request_id)
            t = check_iri(task, "task IRI")
            if rid:
                seen = self._status_request(rid)
                if seen is not None:
                    if seen != (t, status):
                        raise InvalidParameterError("request id %r was already used for status %s of <%s>; a "
                                                    "request id names one report" % (rid, seen[1], seen[0]))
                    sp0 = self._v(t, _P_partOfProcess)
                    return TaskStatusReport(str(t), status, str(sp0), repeated=True)
            if detail is None:
                detail = ""
            if not isinstance(detail, str):
                raise InvalidParameterError("detail must be text, got %s" % type(detail).__name__)
            if len(detail) > MAX_DETAIL_CHARS:
                raise InvalidParameterError("detail is %d characters long; at most %d are allowed"
                                            % (len(detail), MAX_DETAIL_CHARS))
            sp = self._v(t, _P_partOfProcess)
            if sp is None:
                raise UnknownTaskError("no task <%s> is known; task IRIs come from next_action" % t)
            self.store.prefetch([sp])
            state = self._state(sp)  # type: ignore[arg-type]
            current_iri = self._v(t, _P_status)
            current = self.model.status_name.get(current_iri, "")
            if state.status != "running" or state.task != t or current not in ("issued", "in_progress"):
                raise TaskStateError("task <%s> is not running (its status is %s, its process <%s> is %s, the "
                                     "process's current task is %s); only the current issued/in_progress task "
                                     "takes a status" % (t, current or "unknown", sp, state.status,
                                                         "<%s>" % state.task if state.task else "none"))
            if current == "in_progress" and status == "in_progress":
                raise TaskStateError("task <%s> is already in_progress; report succeeded or failed" % t)
            _, node = self.model.task_node_index[state.node]
            tt = node.task_type
            assert tt is not None
            now = self.clock()
            cs = ChangeSet()
            # conditional: the status read above must still be there when the change is written, so two writers
            # sharing a store (two PEMKRE clients of one SPARQL server) cannot both move this task on
            cs.expect.append((t, _P_status, current_iri, G_LOG))  # type: ignore[arg-type]
            self._replace(cs, t, _P_status, self.model.status_iri[status])
            effects_applied, world_changed = 0, 0
            # a template step: its parent task (the node's task) takes its status along; the node's effects
            # apply once, with the parent's parameters, when the last step succeeds
            parent = self._v(t, _S_expandedFrom) if self._matching else None
            owner = parent if parent is not None else t
            with_effects = True
            if parent is not None:
                with_effects = self._step_status(cs, state, t, parent, status, detail, now)
            if status == "in_progress":
                cs.add.append((t, _P_startedAt, _now_literal(now), G_LOG))
            else:
                cs.add.append((t, _P_endedAt, _now_literal(now), G_LOG))
                begin = _time_of(self._v(t, _P_startedAt)) or _time_of(self._v(t, _P_issuedAt))
                if begin is not None:
                    cs.add.append((t, _P_durationSeconds, Literal(max(0.0, now - begin), datatype=XSD.double), G_LOG))
                stored_detail = detail
                world = ChangeSet()
                if status == "succeeded" and tt.result_format == _P_ScanResultJson and detail.strip() and with_effects:
                    world = scan_changes(self._scan_argument(detail, "detail (the SCAN result)"), self.store,
                                         self.site)
                    stored_detail = "scan result: %d world triples added, %d removed" % (len(world.add), len(world.remove))
                    world_changed = len(world.add) + len(world.remove)
                if stored_detail:
                    cs.add.append((t, _P_detail, Literal(stored_detail[:_STORED_DETAIL_CHARS]), G_LOG))
                effects = [e for e in node.all_effects() if e.on_status == status] if with_effects else []
                conditional = [e for e in effects if e.on_detail is not None]
                if conditional and not any(e.on_detail == detail for e in conditional):
                    raise InvalidStatusError("a %s %s task needs detail %s, got %r"
                                             % (status, tt.action_type,
                                                " or ".join(sorted(repr(e.on_detail) for e in conditional)), detail[:100]))
                for e in effects:
                    if e.on_detail is not None and e.on_detail != detail:
                        continue
                    subj = e.subject_node if e.subject_node is not None else self._param(owner, node, e.subject_param)
                    value = e.value_node if e.value_node is not None else self._param(owner, node, e.value_param)
                    if subj is None or value is None:
                        raise ProcessModelError("effect <%s> of task <%s> cannot be applied: parameter %r has no "
                                                "value" % (e.iri, t, e.subject_param or e.value_param))
                    for s2, p2, o2, _ in self.store.quads(subj, e.prop, None, (G_WORLD,)):
                        if o2 != value:
                            cs.remove.append((s2, p2, o2, G_WORLD))
                    cs.add.append((subj, e.prop, value, G_WORLD))  # type: ignore[arg-type]
                    effects_applied += 1
                cs.extend(world)
                if status == "failed" and not node.on_failure:
                    # no failure transition: the process fails with its task (else next_action walks one)
                    cs.extend(self._fail_changes(state, "task <%s> (%s) failed: %s" % (t, tt.action_type, detail),
                                                 now))
            if rid:
                cs.add.append((t, _M_statusRequest, Literal("%s %s" % (status, rid)), G_META))
            self._commit(cs, max_seconds=None)
            return TaskStatusReport(str(t), status, str(sp), effects_applied, world_changed)

    def _step_status(self, cs: ChangeSet, state: _State, sub: URIRef, parent: URIRef, status: str, detail: str,
                     now: float) -> bool:
        """Carry a template step's status to its parent task; True when the node's effects apply now."""
        pstatus = self.model.status_name.get(self._v(parent, _P_status), "")
        if status == "in_progress":
            if pstatus == "issued":
                self._replace(cs, parent, _P_status, self.model.status_iri["in_progress"])
                cs.add.append((parent, _P_startedAt, _now_literal(now), G_LOG))
            return False
        if status == "succeeded":
            real = self._template_of(state, parent)
            if len(self._steps_of(parent)) < len(real.steps):
                return False
        else:
            realized = self._v(sub, _S_realizedBy)
            info = self._catalog_now().skills.get(realized) if realized is not None else None  # type: ignore[arg-type]
            detail = "step %d (%s) failed: %s" % (len(self._steps_of(parent)),
                                                   info.name if info is not None else realized, detail)
            cs.add.append((parent, _P_detail, Literal(detail[:_STORED_DETAIL_CHARS]), G_LOG))
        self._replace(cs, parent, _P_status, self.model.status_iri[status])
        cs.add.append((parent, _P_endedAt, _now_literal(now), G_LOG))
        begin = _time_of(self._v(parent, _P_startedAt)) or _time_of(self._v(parent, _P_issuedAt))
        if begin is not None:
            cs.add.append((parent, _P_durationSeconds, Literal(max(0.0, now - begin), datatype=XSD.double), G_LOG))
        return True

    def _status_request(self, rid: str) -> Optional[Tuple[URIRef, str]]:
        """(task, status) of the report that carried request id ``rid``, if one was applied."""
        for status in TASK_STATUSES:
            for t0, _, _, _ in self.store.quads(None, _M_statusRequest, Literal("%s %s" % (status, rid)), (G_META,)):
                return t0, status  # type: ignore[return-value]
        return None

    @staticmethod
    def _scan_argument(scan: Union[str, bytes, Mapping[str, Any]], what: str) -> Union[str, bytes, Mapping[str, Any]]:
        """A SCAN result with its nesting checked (parsed when it is text and parses)."""
        if isinstance(scan, (str, bytes)):
            try:
                return load_json(scan, what)
            except InvalidParameterError:
                raise
            except ValueError:
                return scan  # not JSON: the SCAN parser says so in its words
        _json_depth(scan, what, MAX_JSON_DEPTH)
        return scan

    def _param(self, task: URIRef, node: FlowNode, name: Optional[str]) -> Optional[Node]:
        for prm in node.parameters:
            if prm.name == name:
                return self._v(task, prm.prop)
        return None

    def update_world(self, scan: Union[str, bytes, Mapping[str, Any]], max_seconds: Optional[float] = None) -> int:
        """Merge a SCAN result (docs/contracts.md) into the world state; returns the number of triples changed."""
        with self._lock, self.store.reading():
            cs = scan_changes(self._scan_argument(scan, "scan"), self.store, self.site)
            n = len(cs.add) + len(cs.remove)
            self._commit(cs, max_seconds=max_seconds)
            return n

    def query(self, name: str, bindings: Optional[Mapping[str, Any]] = None) -> QueryResult:
        """Run the named query of the ontology with ``bindings`` (variable name -> IRI/literal/Python value)."""
        with self._lock:
            nq = self.model.queries.get(name) if isinstance(name, str) else None
            if nq is None:
                raise UnknownQueryError("no predefined query is named %r; known: %s"
                                        % (name, ", ".join(sorted(self.model.queries))))
            terms: Dict[str, Node] = {}
            for var, value in (bindings or {}).items():
                if var not in nq.variables:
                    raise InvalidParameterError("query %r takes no binding %r; it accepts %s"
                                                % (name, var, ", ".join(nq.variables) or "no bindings"))
                terms[var] = to_term(value, "binding %r" % var)
            return self.store.run(nq.query, terms)

    def abort_process(self, process: Optional[str] = None, reason: str = "aborted") -> None:
        """Mark a running specific process failed (operator abort)."""
        with self._lock, self.store.reading():
            sp = check_iri(process, "process IRI") if process else self._active
            if sp is None:
                raise TaskStateError("no process is running")
            state = self._state(sp)
            if state.status != "running":
                raise TaskStateError("process <%s> is %s, not running" % (sp, state.status))
            self._commit(self._fail_changes(state, reason))

    # ================================================================= checks
    def check_consistency(self, full_inference: bool = False) -> List[str]:
        """Problems found in the store (empty list = consistent); ``full_inference`` also re-derives all inferences."""
        with self._lock, self.store.reading():
            problems: List[str] = []
            st = self.model.status_name
            running = []
            for sp, _, _, _ in self.store.quads(None, _RDF_TYPE, _P_SpecificProcess, (G_LOG,)):
                statuses = self.store.objects(sp, _P_status, (G_LOG,))
                if len(statuses) != 1:
                    problems.append("process <%s> has %d statuses" % (sp, len(statuses)))
                    continue
                status = st.get(statuses[0], "?")
                nodes = self.store.objects(sp, _P_currentNode, (G_LOG,))
                if len(nodes) != 1:
                    problems.append("process <%s> has %d current nodes" % (sp, len(nodes)))
                if status == "running":
                    running.append(sp)
                count = self._v(sp, _P_taskCount)
                tasks = [s for s, _, _, _ in self.store.quads(None, _P_partOfProcess, sp, (G_LOG,))]
                if count is None or int(count.toPython()) != len(tasks):  # type: ignore[union-attr]
                    problems.append("process <%s>: taskCount %s but %d tasks" % (sp, count, len(tasks)))
                cur = self._v(sp, _P_currentTask)
                for t in tasks:
                    ts = self.store.objects(t, _P_status, (G_LOG,))
                    if len(ts) != 1:
                        problems.append("task <%s> has %d statuses" % (t, len(ts)))
                        continue
                    name = st.get(ts[0], "?")
                    if name in ("issued", "in_progress") and (t != cur or status != "running") and not (
                            status == "running" and cur is not None and self._v(cur, _S_expandedFrom) == t):
                        problems.append("task <%s> is %s but is not the current task of a running process" % (t, name))
            if len(running) > 1:
                problems.append("%d processes are running: %s" % (len(running), running))
            if full_inference:
                drift = self.reasoner.recompute_all(self.store, max_seconds=600.0, max_triples=10 ** 9)
                if drift:
                    problems.append("inferred graph differs from a full recompute: %d to add, %d to remove (e.g. %s)"
                                    % (len(drift.add), len(drift.remove), (drift.add or drift.remove)[:3]))
            return problems
