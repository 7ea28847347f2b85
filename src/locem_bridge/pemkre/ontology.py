"""Loading ontology files and compiling the process models they describe.

Lifecycle: :func:`load_files` parses Turtle files (each separately, so a syntax error names its file and line)
into a *schema* graph (vocabularies and process models) and a *seed* graph (initial world state: files whose
``owl:Ontology`` header says ``proc:isWorldSeed true``). :func:`compile_model` reads the closed schema graph into
plain Python objects (:class:`ProcessModel`) whose queries are prepared once on the store; the engine keeps that
model for its lifetime. Nothing in this module writes to the store.
"""
import hashlib
import os
import re
from dataclasses import dataclass, field
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from rdflib import Graph, Literal, URIRef
from rdflib.namespace import OWL, RDF
from rdflib.term import Node

from ..common.paths import shipped_dir
from ..common.task_status import TASK_STATUSES
from .errors import OntologyError, OntologySyntaxError, ProcessModelError, QueryError
from .first_member import query_text as first_member_query
from .store import PreparedQuery, TripleStore
from .vocab import PREFIXES, PROC

#: The annotation on an ``owl:Ontology`` header that marks a file as initial world state.
IS_WORLD_SEED = PROC.isWorldSeed


def default_ontology_dir() -> str:
    """``$LOCEM_BRIDGE_ONTOLOGIES`` if set, else the package's ``ontologies/`` folder (source tree or install)."""
    env = os.environ.get("LOCEM_BRIDGE_ONTOLOGIES")
    if env:
        return env
    found = shipped_dir("ontologies")
    if os.path.isdir(found):
        return found
    raise OntologyError("no ontologies folder found; set LOCEM_BRIDGE_ONTOLOGIES or pass the file paths")


def default_ontology_files() -> List[str]:
    d = default_ontology_dir()
    return sorted(os.path.join(d, f) for f in os.listdir(d) if f.endswith(".ttl"))


@dataclass
class LoadedOntologies:
    schema: Graph
    seed: Graph
    schema_hash: str
    seed_hash: str
    files: List[str]
    prefixes: Dict[str, str]


_LINE_RE = re.compile(r"line (\d+)", re.IGNORECASE)


def load_files(paths: Sequence[str]) -> LoadedOntologies:
    """Parse each file; raise :class:`OntologySyntaxError` naming the file (and line) on the first bad one, and
    :class:`OntologyError` naming both files when two declare the same ``owl:Ontology`` IRI (e.g. an
    integrator's folder holding a copy of a shipped file)."""
    if not paths:
        raise OntologyError("no ontology files given")
    schema, seed = Graph(), Graph()
    h_schema, h_seed = hashlib.sha256(), hashlib.sha256()
    prefixes: Dict[str, str] = {k: str(v) for k, v in PREFIXES.items()}
    declared: Dict[str, str] = {}    # ontology IRI -> the file that declares it
    for path in paths:
        try:
            with open(path, "rb") as fh:
                data = fh.read()
        except OSError as exc:
            raise OntologyError("cannot read ontology file: %s" % (exc.strerror or exc), source=path) from None
        g = Graph()
        try:
            g.parse(data=data.decode("utf-8"), format="turtle", publicID="file://" + os.path.abspath(path))
        except UnicodeDecodeError as exc:
            raise OntologySyntaxError("ontology file is not UTF-8: %s" % exc.reason, source=path) from None
        except Exception as exc:  # rdflib raises several types for syntax errors
            msg = str(exc).strip().splitlines()
            m = _LINE_RE.search(str(exc))
            line = int(m.group(1)) if m else None
            text = re.sub(r"^at line \d+ of <[^>]*>:\s*", "", " ".join(msg))
            raise OntologySyntaxError("Turtle syntax error: %s" % text[:300], source=path,
                                      line=line) from None
        for onto in g.subjects(RDF.type, OWL.Ontology):
            if isinstance(onto, URIRef):        # one file per ontology IRI: an integrator's copy would mix in
                first = declared.setdefault(str(onto), path)
                if first != path:
                    raise OntologyError("ontology IRI <%s> is declared here and in %s; give this file an "
                                        "ontology IRI of its own" % (onto, first), source=path)
        is_seed = any(True for o in g.subjects(RDF.type, OWL.Ontology) if (o, IS_WORLD_SEED, Literal(True)) in g)
        target, h = (seed, h_seed) if is_seed else (schema, h_schema)
        for t in g:
            target.add(t)
        h.update(os.path.basename(path).encode() + b"\0" + data + b"\0")
        for pfx, ns in g.namespaces():
            if pfx and pfx not in prefixes:
                prefixes[pfx] = str(ns)
    return LoadedOntologies(schema, seed, h_schema.hexdigest(), h_seed.hexdigest(), list(paths), prefixes)


# ===================================================================== the compiled process model
@dataclass
class Parameter:
    iri: Node
    name: str
    prop: URIRef
    query: PreparedQuery
    required: bool = True
    #: (class, order property) of a parameter declared with proc:selectsMemberOf / proc:orderedBy: its value is
    #: the class's member with the lowest order (``query`` is the equivalent SELECT; see pemkre/first_member.py)
    first_of: Optional[Tuple[URIRef, URIRef]] = None


@dataclass
class Effect:
    iri: Node
    on_status: str
    on_detail: Optional[str]
    prop: URIRef
    subject_param: Optional[str] = None
    subject_node: Optional[URIRef] = None
    value_param: Optional[str] = None
    value_node: Optional[Node] = None


@dataclass
class TaskType:
    iri: URIRef
    action_type: str
    effects: List[Effect] = field(default_factory=list)
    involves_operator: bool = False
    manual_fallback: bool = False
    result_format: Optional[URIRef] = None


@dataclass
class Transition:
    iri: Node
    source: URIRef
    target: URIRef
    priority: int
    condition: Optional[PreparedQuery]
    #: ``proc:onTaskFailure true``: taken only when the source task node's task failed (never when leaving it)
    on_failure: bool = False


@dataclass
class FlowNode:
    iri: URIRef
    kind: str  # start | end | decision | merge | task
    task_type: Optional[TaskType] = None
    parameters: List[Parameter] = field(default_factory=list)
    outgoing: List[Transition] = field(default_factory=list)
    end_outcome: Optional[str] = None
    effects: List[Effect] = field(default_factory=list)
    #: failure transitions (task nodes only), in the order they are tried; empty = a failed task fails the process
    on_failure: List[Transition] = field(default_factory=list)

    def all_effects(self) -> List[Effect]:
        return list(self.task_type.effects if self.task_type else []) + list(self.effects)


@dataclass
class ProcessOption:
    iri: Node
    name: str
    prop: URIRef
    default: Optional[Literal]


@dataclass
class AbstractProcess:
    iri: URIRef
    start: URIRef
    nodes: Dict[URIRef, FlowNode]
    options: Dict[str, ProcessOption]


@dataclass
class NamedQuery:
    iri: Node
    name: str
    query: PreparedQuery
    variables: Tuple[str, ...]


@dataclass
class ProcessModel:
    processes: Dict[URIRef, AbstractProcess]
    queries: Dict[str, NamedQuery]
    task_types: Dict[URIRef, TaskType]
    status_iri: Dict[str, URIRef]
    status_name: Dict[URIRef, str]
    task_node_index: Dict[URIRef, Tuple[URIRef, FlowNode]] = field(default_factory=dict)


def _check_projection(q: PreparedQuery, names: Sequence[str], owner: Node) -> None:
    for n in names:
        if n in q.variables and not q.bindable(n):
            raise ProcessModelError("query of <%s> uses ?%s, which PEMKRE binds, but does not project it; add ?%s "
                                    "to the SELECT clause (values are substituted, SPARQL 1.1 SEP-0007)" % (owner, n, n))


_KIND_BY_CLASS = ((PROC.StartNode, "start"), (PROC.EndNode, "end"), (PROC.DecisionNode, "decision"),
                  (PROC.MergeNode, "merge"), (PROC.TaskNode, "task"))


def _str(g: Graph, s: Node, p: URIRef) -> Optional[str]:
    v = g.value(s, p)
    return None if v is None else str(v)


def _bool(g: Graph, s: Node, p: URIRef, default: bool) -> bool:
    v = g.value(s, p)
    if v is None:
        return default
    return bool(v.toPython()) if isinstance(v, Literal) else default


def _failure_flag(g: Graph, t: Node) -> bool:
    """``proc:onTaskFailure`` of transition ``t`` (default false); anything but one boolean is refused."""
    values = list(g.objects(t, PROC.onTaskFailure))
    if not values:
        return False
    v = values[0]
    if len(values) > 1 or not isinstance(v, Literal) or not isinstance(v.toPython(), bool):
        raise ProcessModelError("transition <%s>: proc:onTaskFailure must be one boolean (true or false), got %s"
                                % (t, ", ".join(x.n3() for x in values)))
    return bool(v.toPython())


def compile_model(g: Graph, store: TripleStore, prefixes: Mapping[str, str]) -> ProcessModel:
    """Read every abstract process, task type and named query from the closed schema graph ``g``.

    Raises :class:`ProcessModelError` naming the node/transition at fault, or :class:`QueryError` naming the
    query's IRI when a stored query does not parse.
    """
    def prep(text: str, owner: Node, what: str) -> PreparedQuery:
        try:
            return store.prepare(text, "%s of <%s>" % (what, owner), prefixes)
        except QueryError as exc:
            raise QueryError(str(exc), str(owner)) from None

    status_iri: Dict[str, URIRef] = {}
    for st, _, name in g.triples((None, PROC.statusName, None)):
        status_iri[str(name)] = st  # type: ignore[assignment]
    status_name = {v: k for k, v in status_iri.items()}

    effects: Dict[Node, Effect] = {}

    def effect(e: Node) -> Effect:
        if e in effects:
            return effects[e]
        on = g.value(e, PROC.onStatus)
        prop = g.value(e, PROC.effectProperty)
        if on is None or on not in status_name:
            raise ProcessModelError("effect <%s> needs proc:onStatus with one of %s" % (e, sorted(status_name)))
        if prop is None:
            raise ProcessModelError("effect <%s> needs proc:effectProperty" % e)
        ef = Effect(iri=e, on_status=status_name[on], on_detail=_str(g, e, PROC.onDetail), prop=prop,  # type: ignore
                    subject_param=_str(g, e, PROC.subjectParameter), subject_node=g.value(e, PROC.effectSubject),
                    value_param=_str(g, e, PROC.valueParameter), value_node=g.value(e, PROC.effectValue))
        if (ef.subject_param is None) == (ef.subject_node is None):
            raise ProcessModelError("effect <%s> needs exactly one of proc:subjectParameter, proc:effectSubject" % e)
        if (ef.value_param is None) == (ef.value_node is None):
            raise ProcessModelError("effect <%s> needs exactly one of proc:valueParameter, proc:effectValue" % e)
        effects[e] = ef
        return ef

    task_types: Dict[URIRef, TaskType] = {}
    for tt, _, at in g.triples((None, PROC.actionType, None)):
        task_types[tt] = TaskType(  # type: ignore[index]
            iri=tt, action_type=str(at),  # type: ignore[arg-type]
            effects=[effect(e) for e in sorted(g.objects(tt, PROC.hasEffect))],
            involves_operator=_bool(g, tt, PROC.involvesOperator, False),
            manual_fallback=_bool(g, tt, PROC.isManualFallback, False),
            result_format=g.value(tt, PROC.resultFormat))  # type: ignore[arg-type]
        if not re.match(r"^[A-Z][A-Z0-9_]*$", str(at)):
            raise ProcessModelError("task type <%s>: action type %r must be UPPER_SNAKE_CASE" % (tt, str(at)))

    processes: Dict[URIRef, AbstractProcess] = {}
    task_node_index: Dict[URIRef, Tuple[URIRef, FlowNode]] = {}
    for proc_iri in sorted(set(g.subjects(RDF.type, PROC.AbstractProcess))):
        nodes: Dict[URIRef, FlowNode] = {}
        for n in sorted(set(g.objects(proc_iri, PROC.hasNode))):
            types = set(g.objects(n, RDF.type))
            kinds = [k for c, k in _KIND_BY_CLASS if c in types]
            if "task" in kinds:
                kind = "task"
            elif len(kinds) == 1 or (kinds and all(k == kinds[0] for k in kinds)):
                kind = kinds[0]
            else:
                raise ProcessModelError("node <%s> of <%s> must be exactly one of proc:StartNode, EndNode, "
                                        "DecisionNode, MergeNode, TaskNode (found %s)" % (n, proc_iri, kinds or "none"))
            node = FlowNode(iri=n, kind=kind, end_outcome=_str(g, n, PROC.endOutcome))  # type: ignore[arg-type]
            if kind == "task":
                tt = g.value(n, PROC.taskType)
                if tt is None or tt not in task_types:
                    raise ProcessModelError("task node <%s> needs proc:taskType pointing at a class with "
                                            "proc:actionType (got %s)" % (n, tt))
                node.task_type = task_types[tt]  # type: ignore[index]
                names = set()
                for prm in sorted(g.objects(n, PROC.hasParameter)):
                    prop = g.value(prm, PROC.parameterProperty)
                    text = _str(g, prm, PROC.bindingQuery)
                    member_of, ordered_by = g.value(prm, PROC.selectsMemberOf), g.value(prm, PROC.orderedBy)
                    first_of: Optional[Tuple[URIRef, URIRef]] = None
                    if member_of is not None or ordered_by is not None:
                        if text is not None or not isinstance(member_of, URIRef) or not isinstance(ordered_by, URIRef):
                            raise ProcessModelError(
                                "parameter <%s> of <%s> needs either proc:bindingQuery or both proc:selectsMemberOf "
                                "(a class IRI) and proc:orderedBy (a property IRI), not %s" % (prm, n, ", ".join(
                                    name for name, v in (("proc:bindingQuery", text), ("proc:selectsMemberOf", member_of),
                                                         ("proc:orderedBy", ordered_by)) if v is not None)))
                        first_of = (member_of, ordered_by)
                        text = first_member_query(member_of, ordered_by)
                    if prop is None or text is None:
                        raise ProcessModelError("parameter <%s> of <%s> needs proc:parameterProperty and "
                                                "proc:bindingQuery (or proc:selectsMemberOf and proc:orderedBy)"
                                                % (prm, n))
                    name = re.split(r"[#/]", str(prop))[-1]
                    if name in names:
                        raise ProcessModelError("task node <%s> has two parameters named %r" % (n, name))
                    names.add(name)
                    q = prep(text, prm, "binding query")
                    if q.kind != "SELECT" or "value" not in q.projected:
                        raise ProcessModelError("binding query of <%s> must be a SELECT returning ?value" % prm)
                    _check_projection(q, ("process", "task"), prm)
                    node.parameters.append(Parameter(prm, name, prop, q, _bool(g, prm, PROC.required, True),  # type: ignore
                                                     first_of))
                node.effects = [effect(e) for e in sorted(g.objects(n, PROC.hasEffect))]
                for ef in node.all_effects():
                    for pn in (ef.subject_param, ef.value_param):
                        if pn is not None and pn not in names:
                            raise ProcessModelError("effect <%s> uses parameter %r, which task node <%s> does not "
                                                    "have (it has %s)" % (ef.iri, pn, n, sorted(names)))
            nodes[n] = node  # type: ignore[index]
        for t in sorted(set(g.subjects(RDF.type, PROC.Transition))):
            src, dst = g.value(t, PROC.source), g.value(t, PROC.target)
            if src not in nodes:
                continue
            if dst not in nodes:
                raise ProcessModelError("transition <%s> leads from <%s> to <%s>, which is not a node of <%s>"
                                        % (t, src, dst, proc_iri))
            text = _str(g, t, PROC.condition)
            cond = None
            if text is not None:
                cond = prep(text, t, "condition")
                if cond.kind not in ("ASK", "SELECT"):
                    raise ProcessModelError("condition of <%s> must be ASK or SELECT, not %s" % (t, cond.kind))
                _check_projection(cond, ("process",), t)
            prio = g.value(t, PROC.priority)
            on_failure = _failure_flag(g, t)
            if on_failure and nodes[src].kind != "task":  # type: ignore[index]
                raise ProcessModelError("transition <%s> has proc:onTaskFailure true but its source <%s> is a %s node; "
                                        "only a task node (proc:TaskNode) has a task that can fail"
                                        % (t, src, nodes[src].kind))  # type: ignore[index]
            tr = Transition(t, src, dst, int(prio.toPython()) if prio is not None else 1_000_000,  # type: ignore
                            cond, on_failure)
            (nodes[src].on_failure if on_failure else nodes[src].outgoing).append(tr)  # type: ignore[index]
        for node in nodes.values():
            node.outgoing.sort(key=lambda tr: (tr.condition is None, tr.priority, str(tr.iri)))
            node.on_failure.sort(key=lambda tr: (tr.condition is None, tr.priority, str(tr.iri)))
            if node.kind == "end" and node.outgoing:
                raise ProcessModelError("end node <%s> must not have outgoing transitions" % node.iri)
            if node.kind != "end" and not node.outgoing:
                raise ProcessModelError("node <%s> of <%s> has no outgoing transition%s" % (
                    node.iri, proc_iri, " (its failure transitions are only taken when its task fails)"
                    if node.on_failure else ""))
            for kind, trs in (("", node.outgoing), ("failure ", node.on_failure)):
                if sum(1 for tr in trs if tr.condition is None) > 1:
                    raise ProcessModelError("node <%s> has more than one %stransition without condition"
                                            % (node.iri, kind))
            if node.kind == "task":
                task_node_index[node.iri] = (proc_iri, node)  # type: ignore[index]
        starts = [s for s in g.objects(proc_iri, PROC.startNode)]
        if len(starts) != 1 or starts[0] not in nodes or nodes[starts[0]].kind != "start":  # type: ignore
            raise ProcessModelError("abstract process <%s> needs exactly one proc:startNode that is a proc:StartNode "
                                    "among its nodes" % proc_iri)
        options: Dict[str, ProcessOption] = {}
        for o in g.objects(proc_iri, PROC.hasOption):
            name, prop = _str(g, o, PROC.optionName), g.value(o, PROC.optionProperty)
            if name is None or prop is None:
                raise ProcessModelError("option <%s> needs proc:optionName and proc:optionProperty" % o)
            options[name] = ProcessOption(o, name, prop, g.value(o, PROC.defaultValue))  # type: ignore
        processes[proc_iri] = AbstractProcess(proc_iri, starts[0], nodes, options)  # type: ignore

    queries: Dict[str, NamedQuery] = {}
    for q in sorted(set(g.subjects(RDF.type, PROC.NamedQuery))):
        name, text = _str(g, q, PROC.queryName), _str(g, q, PROC.queryText)
        if name is None or text is None:
            raise ProcessModelError("named query <%s> needs proc:queryName and proc:queryText" % q)
        if name in queries:
            raise ProcessModelError("two named queries are called %r: <%s> and <%s>" % (name, queries[name].iri, q))
        variables = tuple(sorted(str(v) for v in g.objects(q, PROC.queryVariable)))
        pq = prep(text, q, "named query %r" % name)
        for v in variables:
            if v not in pq.variables:
                raise ProcessModelError("named query <%s> declares variable %r (proc:queryVariable) but does not "
                                        "use ?%s" % (q, v, v))
        _check_projection(pq, variables, q)
        queries[name] = NamedQuery(q, name, pq, variables)
    for needed in TASK_STATUSES + ("issued", "running", "ended"):
        if needed not in status_iri:
            raise ProcessModelError("status %r is not declared (proc:statusName) in the ontologies" % needed)
    return ProcessModel(processes, queries, task_types, status_iri, status_name, task_node_index)
