"""The index of "the first member of a class by an order property" (pemkre/first_member.py) gives the answer of its
SPARQL query after any sequence of writes, on every embedded store; where it cannot (a store other clients write
to, an order value that is not a number) it says why and the engine runs the query; the engine picks the next
pending line from it, also after a restart on the same store."""
import random

import pytest
from rdflib import RDF, BNode, Literal, URIRef
from rdflib.namespace import XSD

from locem_bridge.pemkre import PLB, PPR, JournaledStore, OxigraphStore, ProcessEngine, RdflibStore
from locem_bridge.pemkre.first_member import FirstMember, Unanswerable, query_text
from locem_bridge.pemkre.store import G_ABOX_INFERRED, G_LOG, G_WORLD, ChangeSet

EX = "https://ex.example/"
C = URIRef(EX + "Pending")
ORDER = URIRef(EX + "order")


def _open(kind, path):
    return {"journal": lambda: JournaledStore(path), "oxigraph": lambda: OxigraphStore(path),
            "rdflib": RdflibStore}[kind]()


def _query_answer(store, q):
    rows = store.select(q)
    return rows[0]["value"] if rows else None


@pytest.mark.parametrize("kind,fraction", [("journal", XSD.decimal), ("oxigraph", XSD.double),
                                            ("rdflib", XSD.decimal), ("rdflib", XSD.double)])
def test_the_index_answers_as_its_query_after_any_writes(kind, fraction, tmp_path):
    store = _open(kind, str(tmp_path / "s"))
    try:
        q = store.prepare(query_text(C, ORDER), "first pending", {})
        index = FirstMember(store, C, ORDER)
        assert index.usable and index.first() is None
        rng = random.Random(7)
        subjects = [URIRef(EX + "f%02d" % i) for i in range(25)]
        checked = 0
        for step in range(600):
            s = rng.choice(subjects)
            graph = rng.choice([G_WORLD, G_ABOX_INFERRED])
            cs = ChangeSet()
            roll = rng.random()
            if roll < 0.35:    # becomes a member (in one graph or the other)
                cs.add.append((s, RDF.type, C, graph))
            elif roll < 0.6:   # stops being a member there
                cs.remove += [q4 for q4 in store.quads(s, RDF.type, C, None)][:1]
            elif roll < 0.85:  # an order value changes (integers and decimals, ties on purpose)
                cs.remove += list(store.quads(s, ORDER, None, None))
                value = rng.choice([Literal(rng.randint(0, 9)), Literal("%d.5" % rng.randint(0, 9), datatype=fraction)])
                cs.add.append((s, ORDER, value, G_WORLD))
            elif roll < 0.93:  # a second order value beside the first
                cs.add.append((s, ORDER, Literal(rng.randint(0, 12)), G_WORLD))
            elif roll < 0.95 and kind == "rdflib":  # a blank node member for a while (no parameter value: the query's)
                b = BNode()
                store.apply(ChangeSet(add=[(b, RDF.type, C, G_WORLD), (b, ORDER, Literal(-1), G_WORLD)]))
                with pytest.raises(Unanswerable, match="a blank node is a member"):
                    index.first()
                cs.remove += [(b, RDF.type, C, G_WORLD), (b, ORDER, Literal(-1), G_WORLD)]
            else:              # a whole graph replaced: the index builds again
                kept = [(a, b, c) for a, b, c, _ in store.quads(None, None, None, (G_ABOX_INFERRED,))
                        if rng.random() < 0.7]
                store.replace_graph(G_ABOX_INFERRED, kept)
            if cs:
                store.apply(cs)
            try:
                got = index.first()
            except Unanswerable as exc:  # doubles mixed with decimals: see the test below
                assert "mix decimals and doubles" in str(exc)
                continue
            assert got == _query_answer(store, q), "step %d" % step
            checked += 1
        assert checked >= 300, checked
        # what it holds stays bounded by what is stored (each stale entry leaves once)
        assert len(index) <= sum(1 for _ in store.quads(None, ORDER, None, None))
    finally:
        store.close()


def test_values_it_cannot_compare_make_the_index_step_aside_until_they_are_gone(tmp_path):
    store = JournaledStore(str(tmp_path / "s"))
    try:
        q = store.prepare(query_text(C, ORDER), "first pending", {})
        index = FirstMember(store, C, ORDER)
        a, b, c, d, e, f = (URIRef(EX + x) for x in "abcdef")
        # a non-member's odd value changes nothing
        store.apply(ChangeSet(add=[(a, RDF.type, C, G_WORLD), (a, ORDER, Literal(2), G_WORLD),
                                   (c, ORDER, Literal("whatever"), G_WORLD)]))
        assert index.first() == a
        store.apply(ChangeSet(add=[(b, RDF.type, C, G_WORLD), (b, ORDER, Literal("first"), G_WORLD)]))
        with pytest.raises(Unanswerable, match=r"ex.example/b> has the order value .first., which is not a number"):
            index.first()
        store.apply(ChangeSet(remove=[(b, ORDER, Literal("first"), G_WORLD)], add=[(b, ORDER, Literal(1), G_WORLD)]))
        assert index.first() == b == _query_answer(store, q)
        # NaN is no number either
        store.apply(ChangeSet(add=[(d, RDF.type, C, G_WORLD), (d, ORDER, Literal("NaN", datatype=XSD.double), G_WORLD)]))
        with pytest.raises(Unanswerable, match="not a number"):
            index.first()
        store.apply(ChangeSet(remove=[(d, RDF.type, C, G_WORLD)]))
        assert index.first() == b
        # decimals and doubles mixed: SPARQL compares them as doubles, so the query answers
        store.apply(ChangeSet(add=[(f, RDF.type, C, G_WORLD), (f, ORDER, Literal("0.1", datatype=XSD.double), G_WORLD),
                                   (e, RDF.type, C, G_WORLD), (e, ORDER, Literal("0.1", datatype=XSD.decimal), G_WORLD)]))
        with pytest.raises(Unanswerable, match="mix decimals and doubles"):
            index.first()
        store.apply(ChangeSet(remove=[(e, RDF.type, C, G_WORLD)]))
        assert index.first() == f == _query_answer(store, q)
    finally:
        store.close()


def test_a_watcher_that_fails_does_not_fail_the_write_and_the_index_builds_again(tmp_path, monkeypatch):
    store = JournaledStore(str(tmp_path / "s"))
    try:
        index = FirstMember(store, C, ORDER)
        a, b = URIRef(EX + "a"), URIRef(EX + "b")
        store.apply(ChangeSet(add=[(a, RDF.type, C, G_WORLD), (a, ORDER, Literal(5), G_WORLD)]))
        assert index.first() == a

        def broken(*args, **kwargs):
            raise OSError("disk gone")
        monkeypatch.setattr(index, "_push", broken)
        store.apply(ChangeSet(add=[(b, RDF.type, C, G_WORLD), (b, ORDER, Literal(1), G_WORLD)]))  # no exception
        assert any(True for _ in store.quads(b, ORDER, Literal(1), None))
        monkeypatch.undo()
        assert index.first() == b
    finally:
        store.close()


def test_a_store_other_clients_write_to_is_left_to_the_query(sparql_store):
    store = sparql_store()
    index = FirstMember(store, C, ORDER)
    assert not index.usable and "not the only writer" in index.why_not
    with pytest.raises(Unanswerable, match="not the only writer"):
        index.first()


def test_on_the_copy_of_a_server_the_index_follows_this_clients_writes_and_another_clients(sparql_store):
    """MirroredSparqlStore (what store:=sparql opens) tells the index about its own writes and about each time it
    loads its copy again (another client wrote): the index answers as the query on the server after every write of
    either client."""
    store, other = sparql_store(mirror=True), sparql_store()
    store.RELOAD_SHARE = 1.0     # load the copy whenever it is stale (no reads from the server meanwhile)
    index = FirstMember(store, C, ORDER)
    assert index.usable and index.first() is None
    truth = other.prepare(query_text(C, ORDER), "first pending", {})
    rng = random.Random(11)
    subjects = [URIRef(EX + "f%02d" % i) for i in range(12)]
    loaded, answered = store.reloads, 0
    for step in range(150):
        writer = store if rng.random() < 0.6 else other
        s = rng.choice(subjects)
        cs = ChangeSet()
        roll = rng.random()
        if roll < 0.4:
            cs.add.append((s, RDF.type, C, rng.choice([G_WORLD, G_ABOX_INFERRED])))
        elif roll < 0.6:
            cs.remove += list(other.quads(s, RDF.type, C, None))[:1]
        else:
            cs.remove += list(other.quads(s, ORDER, None, None))
            cs.add.append((s, ORDER, Literal(rng.randint(0, 20)), G_WORLD))
        if cs:
            writer.apply(cs)
        got = index.first()
        assert got == _query_answer(other, truth), "step %d" % step
        answered += 1
    assert answered == 150 and index.usable
    assert store.reloads > loaded        # the other client's writes were seen by loading the copy again


def _scan(n):
    return {"stamp": 1.0, "walls": [{"id": "w", "p0": [0, 0], "p1": [4.8, 0], "height": 2.5}],
            "joints": [{"id": "j%d" % i, "wall": "w", "kind": "vertical", "start": [0.6 * i, 0, 0],
                        "end": [0.6 * i, 0, 2.5], "width": 0.05} for i in range(n)],
            "areas": []}


def test_the_engine_issues_lines_in_scan_order_from_the_index_and_after_a_restart(tmp_path, clock):
    path = str(tmp_path / "db")
    store = JournaledStore(path)
    engine = ProcessEngine(store, clock=clock)
    assert engine._firsts and all(ix.usable for ix in engine._firsts.values())
    engine.update_world(_scan(6))
    engine.start_process(str(PLB.TapingProcess), {"validateLines": False})
    lines = []
    while True:
        a = engine.next_action()
        if a.action_type == "TAPE_LINE":
            lines.append(engine.store.value(URIRef(a.task), PLB.line, (G_LOG,)))
            if len(lines) == 3:
                break
        engine.set_task_status(a.task, "in_progress")
        engine.set_task_status(a.task, "succeeded")
    assert [str(x).rsplit("/", 1)[-1] for x in lines] == ["j0", "j1", "j2"]
    # j2's task is issued, not finished: PEMKRE dies here and starts again on the same store
    store.close()
    store = JournaledStore(path)
    try:
        engine = ProcessEngine(store, clock=clock)
        a = engine.next_action()
        assert a.action_type == "TAPE_LINE" and engine.store.value(URIRef(a.task), PLB.line, (G_LOG,)) == lines[2]
        engine.set_task_status(a.task, "in_progress")
        engine.set_task_status(a.task, "succeeded")
        a = engine.next_action()
        assert str(engine.store.value(URIRef(a.task), PLB.line, (G_LOG,))).endswith("/j3")
        # a line made pending again by hand comes first again (the index was fed by the write)
        j0 = lines[0]
        st = list(store.quads(j0, PPR.tapingStatus, None, (G_WORLD,)))
        store.apply(engine.reasoner.infer(store, ChangeSet(remove=st, add=[(j0, PPR.tapingStatus, PPR.unprocessed,
                                                                             G_WORLD)])))
        index = engine._firsts[(PPR.TapingPending, PPR.scanOrder)]
        assert index.first() == j0
    finally:
        store.close()
