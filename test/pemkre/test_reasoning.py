"""The fast path (schema closure once + incremental ABox inference on oxigraph) answers exactly like a full owlrl
OWL 2 RL closure of the same data evaluated by rdflib; closures respect their bounds and keep the last good state."""
from decimal import Decimal
from typing import Dict, Iterable, List, Set, Tuple

import pytest
from pemkre_testkit import json_dumps, quads_snapshot, scan_result
from rdflib import BNode, Graph, Literal, URIRef
from rdflib.namespace import OWL, RDF

from locem_bridge.pemkre import PLB, PPR, PROC, RdflibStore
from locem_bridge.pemkre.errors import ReasoningBoundError
from locem_bridge.pemkre.reasoning import bounded_closure
from locem_bridge.pemkre.store import ASSERTED_GRAPHS, G_LOG, G_WORLD


def _norm_value(v):
    if not isinstance(v, Literal):
        return str(v)
    py = v.toPython()
    # xsd:decimal division: oxigraph keeps 18 fraction digits, Python's Decimal 28 (e.g. a success rate of 2/3)
    return float(py) if isinstance(py, Decimal) else py


def _norm_rows(rows: Iterable[Dict]) -> Set[frozenset]:
    out = set()
    for r in rows:
        out.add(frozenset((k, _norm_value(v)) for k, v in r.items()))
    return out


def _mid_run_engine(make_engine):
    """A store with every kind of state: taped/manual/validated lines, sprayed/sanded areas, a failed and recovered
    spraying task, a running process."""
    e = make_engine()
    e.update_world(scan_result(walls=2, joints_per_wall=3, areas_per_wall=2))
    e.start_process(str(PLB.SprayingProcess))
    # get tool, spray one area, the second fails (failure transition), recover, spray it again
    for status in ("succeeded", "succeeded", "failed", "succeeded", "succeeded"):
        a = e.next_action()
        e.set_task_status(a.task, status, "compressor link down" if status == "failed" else "")
    e.abort_process(reason="operator stop")
    e.start_process(str(PLB.SandingProcess))
    for _ in range(2):  # get tool, sand one area
        a = e.next_action()
        e.set_task_status(a.task, "succeeded")
    e.abort_process(reason="operator stop")
    e.start_process(str(PLB.TapingProcess), {"validateLines": True})
    details = iter(["", "invalid", "", "valid", "", "valid"])
    for _ in range(6):  # tool, validate(invalid), manual, validate(valid), tape, validate(valid) -> left validated
        a = e.next_action()
        e.set_task_status(a.task, "in_progress")
        e.set_task_status(a.task, "succeeded", next(details))
    return e


def _reference_store(e) -> RdflibStore:
    asserted = Graph()
    for s, p, o, _ in e.store.quads(None, None, None, ASSERTED_GRAPHS):
        asserted.add((s, p, o))
    closed = bounded_closure(asserted, max_seconds=120)
    ref = RdflibStore()
    g = ref.dataset.graph(URIRef("urn:reference"))
    for t in closed:
        g.add(t)
    return ref


def test_fast_path_answers_every_query_like_a_full_owlrl_closure(make_engine):
    e = _mid_run_engine(make_engine)
    ref = _reference_store(e)
    sp = URIRef(e.current_process())
    task = URIRef(str(sp) + "_task_99")
    checked = 0
    for ap in e.model.processes.values():
        for node in ap.nodes.values():
            for tr in node.outgoing:
                if tr.condition is None:
                    continue
                q2 = ref.prepare(tr.condition.text, tr.condition.name, e.prefixes)
                b = {"process": sp} if tr.condition.bindable("process") else None
                assert e.store.ask(tr.condition, b) == ref.ask(q2, b), tr.iri
                checked += 1
            for prm in node.parameters:
                q2 = ref.prepare(prm.query.text, prm.query.name, e.prefixes)
                b = {k: v for k, v in (("process", sp), ("task", task)) if prm.query.bindable(k)}
                assert _norm_rows(e.store.select(prm.query, b)) == _norm_rows(ref.select(q2, b)), prm.iri
                checked += 1
    features = [s for s, _, _, _ in e.store.quads(None, PPR.featureId, None, (G_WORLD,))]
    for name, nq in e.model.queries.items():
        q2 = ref.prepare(nq.query.text, nq.query.name, e.prefixes)
        binding_sets: List[Dict] = [{}]
        if "feature" in nq.variables:
            binding_sets = [{"feature": f} for f in features]
        if "id" in nq.variables:
            binding_sets = [{"id": Literal(str(f).rsplit("/", 1)[-1])} for f in features]
        if "process" in nq.variables:
            binding_sets = [{}, {"process": sp}]
        for b in binding_sets:
            fast, slow = e.store.run(nq.query, b), ref.run(q2, b)
            if fast.kind == "ASK":
                assert fast.boolean == slow.boolean, name
            else:
                assert _norm_rows(fast.rows) == _norm_rows(slow.rows), (name, b)
            checked += 1
    assert checked > 60
    # the state is non-trivial: each kind of inferred class is populated
    assert e.query("has_pending_lines").boolean is True
    assert any(True for _ in e.store.quads(None, RDF.type, PPR.SandingReady))


def test_fast_path_holds_the_same_abox_triples_as_owlrl(make_engine):
    e = _mid_run_engine(make_engine)
    ref = _reference_store(e)
    subjects = {s for s, _, _, _ in e.store.quads(None, None, None, (G_WORLD, G_LOG))}

    def keep(t: Tuple) -> bool:
        s, p, o = t
        if s not in subjects or isinstance(o, BNode) or isinstance(s, BNode):
            return False
        if p == OWL.sameAs and s == o:  # eq-ref: every individual is itself
            return False
        return True

    fast = {(s, p, o) for s, p, o, _ in e.store.quads() if keep((s, p, o))}
    slow = {(s, p, o) for s, p, o, _ in ref.quads() if keep((s, p, o))}
    assert fast - slow == set()
    assert slow - fast == set()
    assert len(fast) > 300


def test_bounded_closure_keeps_the_input_and_raises_on_the_time_bound(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=3, joints_per_wall=10, areas_per_wall=5))
    g = Graph()
    for s, p, o, _ in e.store.quads(None, None, None, ASSERTED_GRAPHS):
        g.add((s, p, o))
    before = len(g)
    with pytest.raises(ReasoningBoundError, match="time bound"):
        bounded_closure(g, max_seconds=0.0)
    with pytest.raises(ReasoningBoundError, match="size bound"):
        bounded_closure(g, max_triples=10)
    assert len(g) == before


def test_incremental_bound_hit_writes_nothing(make_engine):
    e = make_engine(reasoning_max_triples=50)
    snap = quads_snapshot(e.store)
    with pytest.raises(ReasoningBoundError, match="size bound"):
        e.update_world(scan_result(walls=2, joints_per_wall=10))
    assert quads_snapshot(e.store) == snap
    assert e.check_consistency(full_inference=True) == []


def test_incremental_inference_matches_a_full_recompute_after_many_changes(make_engine):
    e = make_engine()
    scan = scan_result(walls=2, joints_per_wall=4, areas_per_wall=2)
    e.start_process(str(PLB.TapingProcess), {"validateLines": True})
    verdicts = iter(["invalid", "valid"] * 10)
    for _ in range(40):
        a = e.next_action()
        if a.status != "action":
            break
        det = json_dumps(scan) if a.action_type == "SCAN" else next(verdicts) if a.action_type == "VALIDATE_TAPE_LINE" else ""
        e.set_task_status(a.task, "succeeded", det)
        assert e.check_consistency(full_inference=True) == [], a.action_type
    # a re-scan that moves a joint only refreshes geometry; inferences stay exact
    scan["joints"][0]["start"] = [1.3, 3.0, 0.0]
    e.update_world(scan)
    assert e.check_consistency(full_inference=True) == []
    assert e.store.value(URIRef(str(e.site) + "wall_1"), PPR.hasFeature) is not None  # inverse inferred


class SteppingClock:
    """A monotonic clock for the reasoning bound: each reading advances by ``step`` seconds (0 = time stands still)."""

    def __init__(self) -> None:
        self.t = 100.0
        self.step = 0.0
        self.readings = 0

    def __call__(self) -> float:
        self.readings += 1
        self.t += self.step
        return self.t


def test_incremental_time_bound_hit_writes_nothing_and_keeps_the_last_good_state(make_engine):
    rc = SteppingClock()
    e = make_engine(reasoning_max_seconds=5.0, reasoning_clock=rc)
    e.update_world(scan_result(walls=1, joints_per_wall=2))         # time stands still: within the bound
    snap = quads_snapshot(e.store)
    rc.step = 10.0                                                  # every reading: 10 s later, over the 5 s bound
    n = rc.readings
    with pytest.raises(ReasoningBoundError, match=r"time bound of 5\.000 s; nothing was written"):
        e.update_world(scan_result(walls=2, joints_per_wall=3))
    assert rc.readings > n                                          # the bound was decided on the injected clock
    assert quads_snapshot(e.store) == snap                          # nothing written
    rc.step = 0.0
    assert e.check_consistency(full_inference=True) == []
    assert [r["id"].toPython() for r in e.query("pending_joint_lines").rows] == ["wall_1_joint_1", "wall_1_joint_2"]
    # the same update within the bound goes through on the kept state
    assert e.update_world(scan_result(walls=2, joints_per_wall=3)) > 0
    assert len(e.query("pending_joint_lines").rows) == 6
    assert e.check_consistency(full_inference=True) == []


def test_time_bound_hit_during_set_task_status_leaves_the_store_unchanged(make_engine):
    rc = SteppingClock()
    e = make_engine(reasoning_max_seconds=5.0, reasoning_clock=rc)
    e.start_process(str(PLB.TapingProcess), {"validateLines": False})
    scan = e.next_action()
    assert scan.action_type == "SCAN"
    e.set_task_status(scan.task, "in_progress")
    snap = quads_snapshot(e.store)
    rc.step = 10.0
    # the SCAN result as detail: task status, world features and their inferences in one change -- refused whole
    with pytest.raises(ReasoningBoundError, match="time bound"):
        e.set_task_status(scan.task, "succeeded", json_dumps(scan_result(joints_per_wall=2)))
    assert quads_snapshot(e.store) == snap
    again = e.next_action()
    assert (again.task, again.task_status) == (scan.task, "in_progress")   # still the running SCAN task
    rc.step = 0.0
    assert e.check_consistency(full_inference=True) == []
    # reported again within the bound: accepted, and the run goes on with the scanned lines
    e.set_task_status(scan.task, "succeeded", json_dumps(scan_result(joints_per_wall=2)))
    tool = e.next_action()
    assert tool.action_type == "GET_TOOL"
    # a plain status report (effects only, no world merge) hitting the bound is refused the same way
    snap = quads_snapshot(e.store)
    rc.step = 10.0
    with pytest.raises(ReasoningBoundError, match="time bound"):
        e.set_task_status(tool.task, "succeeded")
    assert quads_snapshot(e.store) == snap
    rc.step = 0.0
    assert e.next_action().task == tool.task                         # GET_TOOL is still the current task
    e.set_task_status(tool.task, "succeeded")
    assert e.next_action().params() == {"line": "wall_1_joint_1"}
    assert e.check_consistency(full_inference=True) == []
