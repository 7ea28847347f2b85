"""OWL 2 RL reasoning: owlrl's full closure as the reference, and a fast, targeted ABox reasoner.

Two parts with one contract: *what is true after reasoning is what owlrl's OWL 2 RL closure says*.

* :func:`bounded_closure` runs owlrl's complete OWL 2 RL closure on a copy of a graph, bounded by wall time and
  number of inferred triples. When a bound is hit it raises :class:`ReasoningBoundError` and the caller keeps its
  last good state (the input graph is never modified). The engine uses it once per ontology version to
  materialise the schema (TBox and process models), never on the per-decision path.
* :class:`SchemaRules` compiles the closed schema into lookup tables for the OWL 2 RL rules whose conclusions are
  about individuals: cax-sco (and cax-eqc via the closed subClassOf), prp-spo1, prp-dom, prp-rng, prp-inv1/2,
  prp-symp, prp-trp, cls-hv1/2, cls-int1/2 (and cls-uni via scm-uni). Other ABox-relevant constructs (sameAs,
  functional/inverse-functional properties, property chains, keys, some/allValuesFrom, cardinalities) are listed in
  :attr:`SchemaRules.unsupported`; the engine refuses ontologies that use them unless told otherwise, because the
  fast path would then answer differently from the reference.
* :class:`IncrementalReasoner` turns a change of asserted ABox triples into the matching change of inferred triples
  by recomputing the closure *locally*, for the individuals the change touches only (their own triples plus one
  witness per range-bearing property pointing at them), and diffing it with what is stored. Bounded by time and
  size like the full closure; on a bound nothing is written. Time is read from an injected monotonic ``clock``
  (default :func:`time.monotonic`), so the bound can be tested without depending on the machine's speed.
"""
import time
from collections import defaultdict
from typing import Callable, Dict, FrozenSet, Iterable, List, Optional, Set, Tuple

import owlrl
from rdflib import BNode, Graph, Literal, URIRef
from rdflib.collection import Collection
from rdflib.namespace import OWL, RDF, RDFS, XSD
from rdflib.term import Node

from .errors import ReasoningBoundError
from .store import ASSERTED_GRAPHS, G_ABOX_INFERRED, G_SCHEMA_INFERRED, ChangeSet, Triple, TripleStore

#: rdf:type as a plain URIRef (DefinedNamespace attribute access is slow on hot paths)
RDF_TYPE = RDF.type
DEFAULT_MAX_SECONDS = 60.0
DEFAULT_MAX_TRIPLES = 2_000_000


# ===================================================================== reference: bounded owlrl closure
def bounded_closure(graph: Graph, max_seconds: float = DEFAULT_MAX_SECONDS,
                    max_triples: int = DEFAULT_MAX_TRIPLES) -> Graph:
    """Return a new graph holding ``graph`` plus its OWL 2 RL closure (owlrl), or raise on a bound.

    ``graph`` itself is left untouched, so on :class:`ReasoningBoundError` the caller still has its last good state.
    """
    deadline = time.monotonic() + max_seconds
    work = Graph()
    for t in graph:
        work.add(t)
    start_len = len(work)

    class _Bounded(owlrl.OWLRL_Semantics):
        _checks = 0

        def store_triple(self, t):  # type: ignore[override]
            _Bounded._checks += 1
            if _Bounded._checks % 512 == 0:
                if time.monotonic() > deadline:
                    raise ReasoningBoundError("OWL 2 RL closure exceeded its time bound of %.1f s "
                                              "(graph of %d triples); last good state kept" % (max_seconds, start_len))
                if len(self.destination) + len(self.added_triples) - start_len > max_triples:
                    raise ReasoningBoundError("OWL 2 RL closure exceeded its size bound of %d inferred triples; "
                                              "last good state kept" % max_triples)
            super().store_triple(t)

    owlrl.DeductiveClosure(_Bounded, improved_datatypes=False, axiomatic_triples=False,
                           datatype_axioms=False).expand(work)
    return work


def inferred_part(base: Graph, closed: Graph) -> Graph:
    """The triples of ``closed`` that are not in ``base`` (generalized triples with literal subjects dropped)."""
    out = Graph()
    for t in closed:
        if t not in base and not isinstance(t[0], Literal) and isinstance(t[1], URIRef):
            out.add(t)
    return out


# ===================================================================== schema rules
_UNSUPPORTED = (
    (OWL.sameAs, "owl:sameAs"), (OWL.propertyChainAxiom, "owl:propertyChainAxiom"), (OWL.hasKey, "owl:hasKey"),
    (OWL.someValuesFrom, "owl:someValuesFrom"), (OWL.allValuesFrom, "owl:allValuesFrom"),
    (OWL.maxCardinality, "owl:maxCardinality"), (OWL.maxQualifiedCardinality, "owl:maxQualifiedCardinality"),
    (OWL.equivalentProperty, "owl:equivalentProperty"), (OWL.oneOf, "owl:oneOf"),
)
_UNSUPPORTED_TYPES = (
    (OWL.FunctionalProperty, "owl:FunctionalProperty"), (OWL.InverseFunctionalProperty, "owl:InverseFunctionalProperty"),
    (OWL.AsymmetricProperty, "owl:AsymmetricProperty"), (OWL.IrreflexiveProperty, "owl:IrreflexiveProperty"),
)


class SchemaRules:
    """Lookup tables compiled from a closed schema graph (see the module docstring for the rule list)."""

    def __init__(self, closed_schema: Graph, asserted_schema: Optional[Graph] = None) -> None:
        g = closed_schema
        self.supers: Dict[Node, FrozenSet[Node]] = {}
        sub: Dict[Node, Set[Node]] = defaultdict(set)
        for c, _, d in g.triples((None, RDFS.subClassOf, None)):
            sub[c].add(d)
        for c in list(sub):
            self.supers[c] = frozenset(_transitive(c, sub))
        sp: Dict[Node, Set[Node]] = defaultdict(set)
        for p, _, q in g.triples((None, RDFS.subPropertyOf, None)):
            sp[p].add(q)
        self.superprops: Dict[Node, FrozenSet[Node]] = {p: frozenset(_transitive(p, sp)) for p in list(sp)}
        self.domain: Dict[Node, Set[Node]] = defaultdict(set)
        self.range: Dict[Node, Set[Node]] = defaultdict(set)
        for p, _, c in g.triples((None, RDFS.domain, None)):
            self.domain[p].add(c)
        for p, _, c in g.triples((None, RDFS.range, None)):
            self.range[p].add(c)
        # domain/range are inherited by sub-properties (scm-dom2 / scm-rng2), whether or not the closure says so
        for p, qs in self.superprops.items():
            for q in qs:
                self.domain[p] |= self.domain.get(q, set())
                self.range[p] |= self.range.get(q, set())
        self.inverse: Dict[Node, Set[Node]] = defaultdict(set)
        for p, _, q in g.triples((None, OWL.inverseOf, None)):
            self.inverse[p].add(q)
            self.inverse[q].add(p)
        self.symmetric: Set[Node] = set(g.subjects(RDF_TYPE, OWL.SymmetricProperty))
        self.transitive: Set[Node] = set(g.subjects(RDF_TYPE, OWL.TransitiveProperty))
        self.has_value: Dict[Node, List[Tuple[Node, Node]]] = defaultdict(list)      # class -> [(p, v)]
        self.hv_by_pv: Dict[Tuple[Node, Node], Set[Node]] = defaultdict(set)        # (p, v) -> classes
        for r in set(g.subjects(OWL.hasValue, None)):
            v = g.value(r, OWL.hasValue)
            for p in g.objects(r, OWL.onProperty):
                self.has_value[r].append((p, v))
                self.hv_by_pv[(p, v)].add(r)
        self.intersections: Dict[Node, Tuple[Node, ...]] = {}
        self.int_by_member: Dict[Node, Set[Node]] = defaultdict(set)
        for c, _, lst in g.triples((None, OWL.intersectionOf, None)):
            members = tuple(Collection(g, lst))
            self.intersections[c] = members
            for m in members:
                self.int_by_member[m].add(c)
        # Properties whose triples conclude something about their *object*.
        self.object_side: Set[Node] = set()
        datatypes = set(g.subjects(RDF_TYPE, RDFS.Datatype))
        data_props = set(g.subjects(RDF_TYPE, OWL.DatatypeProperty))
        for p in set(self.range) | set(self.inverse) | self.symmetric | self.transitive:
            if p in data_props:
                continue
            class_range = {c for c in self.range.get(p, ()) if c not in datatypes and
                           not str(c).startswith(str(XSD)) and c != RDFS.Literal}
            if class_range or self.inverse.get(p) or p in self.symmetric or p in self.transitive:
                self.object_side.add(p)
        for p, qs in self.superprops.items():
            if qs & self.object_side and p not in data_props:
                self.object_side.add(p)
        self.unsupported: List[str] = []
        src = asserted_schema if asserted_schema is not None else g
        for pred, label in _UNSUPPORTED:
            if (None, pred, None) in src:
                self.unsupported.append(label)
        for typ, label in _UNSUPPORTED_TYPES:
            if (None, RDF_TYPE, typ) in src:
                self.unsupported.append(label)

    # ----------------------------------------------------------------- in-memory forward chaining
    def derive(self, facts: Set[Triple], lookup: Optional[Callable[[Node, Node, Node], Iterable[Triple]]] = None,
               budget: Optional["_Budget"] = None) -> Set[Triple]:
        """Close ``facts`` under the supported rules; returns the new triples (``facts`` is not modified).

        ``lookup(s, p, o)`` may fetch more triples for the transitive-property rule.
        """
        known: Set[Triple] = set(facts)
        types: Dict[Node, Set[Node]] = defaultdict(set)
        for s, p, o in facts:
            if p == RDF_TYPE:
                types[s].add(o)
        queue = list(facts)
        new: Set[Triple] = set()

        def emit(t: Triple) -> None:
            if t not in known:
                known.add(t)
                new.add(t)
                queue.append(t)
                if t[1] == RDF_TYPE:
                    types[t[0]].add(t[2])
                if budget is not None:
                    budget.tick()

        while queue:
            s, p, o = queue.pop()
            if p == RDF_TYPE:
                for d in self.supers.get(o, ()):
                    emit((s, RDF_TYPE, d))
                for hp, hv in self.has_value.get(o, ()):
                    emit((s, hp, hv))
                for m in self.intersections.get(o, ()):
                    emit((s, RDF_TYPE, m))
                for c in self.int_by_member.get(o, ()):
                    if all(m in types[s] for m in self.intersections[c]):
                        emit((s, RDF_TYPE, c))
                continue
            for q in self.superprops.get(p, ()):
                emit((s, q, o))
            for d in self.domain.get(p, ()):
                emit((s, RDF_TYPE, d))
            for c in self.hv_by_pv.get((p, o), ()):
                emit((s, RDF_TYPE, c))
            if isinstance(o, Literal):
                continue
            for r in self.range.get(p, ()):
                emit((o, RDF_TYPE, r))
            for q in self.inverse.get(p, ()):
                emit((o, q, s))
            if p in self.symmetric:
                emit((o, p, s))
            if p in self.transitive:
                nxt = [t for t in known if t[0] == o and t[1] == p]
                prv = [t for t in known if t[2] == s and t[1] == p]
                if lookup is not None:
                    nxt += list(lookup(o, p, None))
                    prv += list(lookup(None, p, s))
                for _, _, x in nxt:
                    emit((s, p, x))
                for x, _, _ in prv:
                    emit((x, p, o))
        return new


def _transitive(start: Node, edges: Dict[Node, Set[Node]]) -> Set[Node]:
    out = {start}
    stack = [start]
    while stack:
        for n in edges.get(stack.pop(), ()):
            if n not in out:
                out.add(n)
                stack.append(n)
    return out


class _Budget:
    """The time and size bound of one inference: :meth:`tick` per derived triple (the clock is read every 256
    ticks), :meth:`check_time` at the end; either raises :class:`ReasoningBoundError` before anything is written."""

    def __init__(self, max_seconds: float, max_triples: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.clock = clock
        self.deadline = clock() + max_seconds
        self.max_seconds = max_seconds
        self.max_triples = max_triples
        self.count = 0

    def tick(self, n: int = 1) -> None:
        self.count += n
        if self.count > self.max_triples:
            raise ReasoningBoundError("ABox inference exceeded its size bound of %d triples; nothing was written"
                                      % self.max_triples)
        if self.count % 256 == 0 and self.clock() > self.deadline:
            raise ReasoningBoundError("ABox inference exceeded its time bound of %.3f s; nothing was written"
                                      % self.max_seconds)

    def check_time(self) -> None:
        if self.clock() > self.deadline:
            raise ReasoningBoundError("ABox inference exceeded its time bound of %.3f s; nothing was written"
                                      % self.max_seconds)


# ===================================================================== incremental ABox reasoning
class IncrementalReasoner:
    """Keeps ``G_ABOX_INFERRED`` equal to the supported-rule closure of the asserted graphs, incrementally.

    ``infer(store, changes)`` returns ``changes`` extended by the matching inferred-triple changes; the caller
    applies the result atomically, so asserted and inferred triples never drift apart (also across crashes).
    Additions are handled semi-naively (only consequences of the new triples are derived); removals by
    delete-and-rederive (DRed): the consequences of removed triples are over-deleted, then every one that still has
    a one-step derivation from surviving triples is put back, until nothing changes. Each step is a handful of
    point lookups, so the cost follows the size of the change, not of the world. Changes touching a transitive
    property fall back to :meth:`recompute_all`.
    """

    def __init__(self, rules: SchemaRules, max_seconds: float = 5.0, max_triples: int = 500_000,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.rules = rules
        self.max_seconds = max_seconds
        self.max_triples = max_triples
        self.clock = clock
        r = rules
        self._domain_of: Dict[Node, Set[Node]] = defaultdict(set)   # class -> properties with it as domain
        self._range_of: Dict[Node, Set[Node]] = defaultdict(set)    # class -> properties with it as range
        for p, cs in r.domain.items():
            for c in cs:
                self._domain_of[c].add(p)
        for p, cs in r.range.items():
            for c in cs:
                self._range_of[c].add(p)
        self._subprops: Dict[Node, Set[Node]] = defaultdict(set)
        for p, qs in r.superprops.items():
            for q in qs:
                if q != p:
                    self._subprops[q].add(p)
        self._subclasses: Dict[Node, Set[Node]] = defaultdict(set)
        for c, ds in r.supers.items():
            for d in ds:
                if d != c:
                    self._subclasses[d].add(c)
        self._hv_owner: Dict[Tuple[Node, Node], Set[Node]] = defaultdict(set)
        for c, pvs in r.has_value.items():
            for pv in pvs:
                self._hv_owner[pv].add(c)
        self._transitive_family: Set[Node] = set()
        for p, qs in r.superprops.items():
            if qs & r.transitive:
                self._transitive_family.add(p)
        self._transitive_family |= r.transitive

    # ----------------------------------------------------------------- helpers
    def _one_step(self, t: Triple) -> Iterable[Triple]:
        """Every fact one rule application could conclude with ``t`` among its premises (int1 optimistic)."""
        r = self.rules
        s, p, o = t
        if p == RDF_TYPE:
            for d in r.supers.get(o, ()):
                if d != o:
                    yield (s, RDF_TYPE, d)
            for hp, hv in r.has_value.get(o, ()):
                yield (s, hp, hv)
            for m in r.intersections.get(o, ()):
                yield (s, RDF_TYPE, m)
            for c in r.int_by_member.get(o, ()):
                yield (s, RDF_TYPE, c)
            return
        for q in r.superprops.get(p, ()):
            if q != p:
                yield (s, q, o)
        for d in r.domain.get(p, ()):
            yield (s, RDF_TYPE, d)
        for c in r.hv_by_pv.get((p, o), ()):
            yield (s, RDF_TYPE, c)
        if isinstance(o, Literal):
            return
        for c in r.range.get(p, ()):
            yield (o, RDF_TYPE, c)
        for q in r.inverse.get(p, ()):
            yield (o, q, s)
        if p in r.symmetric:
            yield (o, p, s)

    def infer(self, store: TripleStore, changes: ChangeSet, max_seconds: Optional[float] = None,
              max_triples: Optional[int] = None) -> ChangeSet:
        budget = _Budget(self.max_seconds if max_seconds is None else max_seconds,
                         self.max_triples if max_triples is None else max_triples, self.clock)
        asserted_set = frozenset(ASSERTED_GRAPHS)
        removed = {(s, p, o) for s, p, o, g in changes.remove if g in asserted_set}
        added = {(s, p, o) for s, p, o, g in changes.add if g in asserted_set}
        removed -= added
        if not removed and not added:
            return changes
        if any(t[1] in self._transitive_family for t in removed | added):
            return self._with_full_recompute(store, changes, budget)
        # the look-ups below are about these nodes: one fetch on a store whose reads are round trips
        store.prefetch({x for t in removed | added for x in (t[0], t[2]) if not isinstance(x, Literal)})
        r = self.rules
        inf_g = (G_ABOX_INFERRED,)
        dead: Set[Triple] = set(removed)
        new_inf: Set[Triple] = set()

        def stored(t: Triple, graphs=None) -> bool:
            return any(True for _ in store.quads(t[0], t[1], t[2], graphs))

        def alive(t: Triple) -> bool:
            if t in added or t in new_inf:
                return True
            if t in dead:
                return False
            return stored(t)

        by_s: Dict[Node, List[Triple]] = defaultdict(list)   # added + new inferred, indexed for lookups
        by_o: Dict[Node, List[Triple]] = defaultdict(list)

        def index(t: Triple) -> None:
            by_s[t[0]].append(t)
            by_o[t[2]].append(t)

        for t in added:
            index(t)

        def any_alive(s: Optional[Node], p: Node, o: Optional[Node]) -> bool:
            pool = by_s.get(s, ()) if s is not None else by_o.get(o, ())
            for t in pool:
                if t[1] == p and (s is None or t[0] == s) and (o is None or t[2] == o):
                    return True
            for s2, p2, o2, _ in store.quads(s, p, o, None):
                if (s2, p2, o2) not in dead:
                    return True
            return False

        def types_of(x: Node) -> Set[Node]:
            out = {o for _, _, o, _ in store.quads(x, RDF_TYPE, None, None) if (x, RDF_TYPE, o) not in dead}
            out |= {t[2] for t in by_s.get(x, ()) if t[1] == RDF_TYPE}
            return out

        def bnode_type_holds(x: Node, b: Node, visiting: Set[Node]) -> bool:
            """Is x an instance of the anonymous class b (never stored) given the surviving triples?"""
            if b in visiting:
                return False
            visiting = visiting | {b}
            for hp, hv in r.has_value.get(b, ()):
                if alive((x, hp, hv)):
                    return True
            members = r.intersections.get(b)
            if members and all(type_ok(x, m, visiting) for m in members):
                return True
            for q in self._domain_of.get(b, ()):
                if any_alive(x, q, None):
                    return True
            for q in self._range_of.get(b, ()):
                if any_alive(None, q, x):
                    return True
            for d in self._subclasses.get(b, ()):
                if type_ok(x, d, visiting):
                    return True
            return False

        def type_ok(x: Node, c: Node, visiting: Set[Node]) -> bool:
            if isinstance(c, BNode):
                return bnode_type_holds(x, c, visiting)
            return alive((x, RDF_TYPE, c))

        def supported(t: Triple) -> bool:
            budget.tick()
            s, p, o = t
            if p == RDF_TYPE:
                c = o
                for d in types_of(s):
                    if d != c and c in r.supers.get(d, ()):
                        return True
                for q in self._domain_of.get(c, ()):
                    if any_alive(s, q, None):
                        return True
                for q in self._range_of.get(c, ()):
                    if any_alive(None, q, s):
                        return True
                for hp, hv in r.has_value.get(c, ()):
                    if alive((s, hp, hv)):
                        return True
                members = r.intersections.get(c)
                if members and all(type_ok(s, m, {c}) for m in members):
                    return True
                for b in self._subclasses.get(c, ()):
                    if isinstance(b, BNode) and bnode_type_holds(s, b, {c}):
                        return True
                return False
            for q in self._subprops.get(p, ()):
                if alive((s, q, o)):
                    return True
            for q in r.inverse.get(p, ()):
                if not isinstance(o, Literal) and alive((o, q, s)):
                    return True
            if p in r.symmetric and alive((o, p, s)):
                return True
            for c in self._hv_owner.get((p, o), ()):
                if type_ok(s, c, set()):
                    return True
            return False

        # 1. over-delete: everything the removed triples may have supported that is stored as inferred
        over: Set[Triple] = set()
        seen_anon: Set[Triple] = set()
        queue = list(removed)
        while queue:
            t = queue.pop()
            for c in self._one_step(t):
                if c in over or c in seen_anon:
                    continue
                if any(isinstance(x, BNode) for x in c):
                    seen_anon.add(c)  # never stored, but its consequences may be
                    queue.append(c)
                elif stored(c, inf_g):
                    over.add(c)
                    queue.append(c)
                budget.tick()
        dead |= over
        # 2. additions, semi-naively (types of the subjects are context for the intersection rule)
        if added:
            context: Set[Triple] = set()
            if r.intersections:  # cls-int1 needs the other types the subjects already have
                for x in {t[0] for t in added} | {t[2] for t in added if not isinstance(t[2], Literal)}:
                    context |= {(x, RDF_TYPE, d) for d in types_of(x)}
            derived = r.derive(set(added) | context, budget=budget)
            for t in derived:
                if any(isinstance(x, BNode) for x in t):
                    continue
                if t in over:
                    over.discard(t)
                    dead.discard(t)
                    continue
                if t in dead or not stored(t):
                    new_inf.add(t)
                    index(t)
        # 3. re-derive what still has support
        changed = True
        while changed and over:
            changed = False
            for t in list(over):
                if supported(t):
                    over.discard(t)
                    dead.discard(t)
                    changed = True
        budget.check_time()
        out = ChangeSet(list(changes.remove), list(changes.add), list(changes.expect))
        for t in over:
            out.remove.append(t + (G_ABOX_INFERRED,))
        # removed assertions that are still entailed stay, as inferred triples
        for t in removed:
            if not any(isinstance(x, BNode) for x in t) and supported(t):
                new_inf.add(t)
                index(t)
        for t in new_inf:
            if t in added:
                continue
            if not stored(t, inf_g) or t in over:
                out.add.append(t + (G_ABOX_INFERRED,))
        # an assertion that was inferred before: drop the inferred copy (no duplicates in the union graph)
        for t in added:
            if stored(t, inf_g):
                out.remove.append(t + (G_ABOX_INFERRED,))
        budget.tick(len(out.add) + len(out.remove))
        return out

    def _with_full_recompute(self, store: TripleStore, changes: ChangeSet, budget: "_Budget") -> ChangeSet:
        out = ChangeSet(list(changes.remove), list(changes.add), list(changes.expect))
        out.extend(self.recompute_all(store, pending=changes, max_seconds=budget.max_seconds,
                                      max_triples=budget.max_triples))
        return out

    def recompute_all(self, store: TripleStore, pending: Optional[ChangeSet] = None,
                      max_seconds: Optional[float] = None, max_triples: Optional[int] = None) -> ChangeSet:
        """The change that makes ``G_ABOX_INFERRED`` exact for the whole ABox (after ``pending``, if given).

        Cost grows with the world; used after an ontology change and as the fallback for transitive properties.
        """

        budget = _Budget(self.max_seconds if max_seconds is None else max_seconds,
                         self.max_triples if max_triples is None else max_triples, self.clock)
        removed: Set[Triple] = set()
        added: Set[Triple] = set()
        if pending is not None:
            removed = {(s, p, o) for s, p, o, g in pending.remove if g in ASSERTED_GRAPHS}
            added = {(s, p, o) for s, p, o, g in pending.add if g in ASSERTED_GRAPHS}
        seed: Set[Triple] = set(added)
        for s2, p2, o2, _ in store.quads(None, None, None, ASSERTED_GRAPHS):
            t = (s2, p2, o2)
            if t not in removed:
                seed.add(t)
        budget.tick(len(seed) // 64 + 1)
        derived = self.rules.derive(seed, lookup=None, budget=budget)
        schema = {(s2, p2, o2) for s2, p2, o2, _ in store.quads(None, None, None, (G_SCHEMA_INFERRED,))}
        wanted = {t for t in derived if not any(isinstance(x, BNode) for x in t)} - schema
        have = {(s2, p2, o2) for s2, p2, o2, _ in store.quads(None, None, None, (G_ABOX_INFERRED,))}
        out = ChangeSet()
        for t in have - wanted:
            out.remove.append(t + (G_ABOX_INFERRED,))
        for t in wanted - have:
            out.add.append(t + (G_ABOX_INFERRED,))
        return out
