"""The store layer, the same contract on every backend (the embedded ones and a SparqlStore on a real ``oxigraph
serve``): persistence across close/reopen, atomic and conditional writes, bindings not spliced, the union default
graph; one process per embedded store."""
import threading

import pytest
from rdflib import BNode, Literal, URIRef

import os

from locem_bridge.pemkre import JournaledStore, OxigraphStore, RdflibStore
from locem_bridge.pemkre.errors import QueryError, StoreConflict, StoreError
from locem_bridge.pemkre.store import G_LOG, G_META, G_WORLD, ChangeSet

EX = "https://ex.example/"
P = {"ex": EX}
#: every backend of the TripleStore contract; "sparql" is a SparqlStore on the session's oxigraph server, "mirror"
#: a MirroredSparqlStore on it (reads from its copy)
BACKENDS = ["journal", "oxigraph", "rdflib", "sparql", "mirror"]


@pytest.fixture
def opener(request):
    """``opener(kind, path)``: a store of ``kind``; the sparql one on the session's (emptied) server."""
    opened = []

    def open_(kind, path):
        if kind in ("sparql", "mirror"):
            return request.getfixturevalue("sparql_store")(mirror=kind == "mirror")
        store = _open(kind, path)
        opened.append(store)
        return store

    yield open_
    for s in opened:
        s.close()


def _open(kind, path):
    return {"journal": JournaledStore, "oxigraph": OxigraphStore}[kind](path) if kind != "rdflib" else RdflibStore()


@pytest.mark.parametrize("kind", BACKENDS)
def test_same_answers_from_every_backend_with_bindings(kind, tmp_path, opener):
    store = opener(kind, str(tmp_path / "s"))
    store.apply(ChangeSet(add=[(URIRef(EX + "a"), URIRef(EX + "name"), Literal('x" } ; DROP ALL ; {'), G_WORLD),
                               (URIRef(EX + "b"), URIRef(EX + "name"), Literal("plain"), G_WORLD)]))
    q = store.prepare("SELECT ?s ?n WHERE { ?s ex:name ?n }", "names", P)
    assert [r["s"] for r in store.select(q, {"n": Literal('x" } ; DROP ALL ; {')})] == [URIRef(EX + "a")]
    assert store.count() == 2
    ask = store.prepare("ASK { ?s ex:name ?n }", "any", P)
    assert store.ask(ask, {"s": URIRef(EX + "b")}) and not store.ask(ask, {"s": URIRef(EX + "c")})
    with pytest.raises(QueryError, match="does not parse"):
        store.prepare("SELECT ?s WHERE { ?s ex:name ", "broken", P)
    hidden = store.prepare("SELECT ?n WHERE { ?s ex:name ?n }", "hidden", P)
    with pytest.raises(QueryError, match="project"):
        store.select(hidden, {"s": URIRef(EX + "a")})


@pytest.mark.parametrize("kind", ["journal", "oxigraph"])
def test_prefixes_work_as_declarations_in_the_text_too_as_pyoxigraph_0_4_needs_them(kind, tmp_path, monkeypatch):
    """pyoxigraph 0.4 (the last line for Python 3.8, Noetic's on Ubuntu 20.04) takes no ``prefixes=`` argument:
    the store then puts PREFIX declarations in front of the query text. Same answers; a query's own declaration
    of a prefix still wins over the map's."""
    from locem_bridge.pemkre import oxigraph_store
    monkeypatch.setattr(oxigraph_store, "_PREFIXES_ARGUMENT", False)
    store = _open(kind, str(tmp_path / "s"))
    store.apply(ChangeSet(add=[(URIRef(EX + "a"), URIRef(EX + "name"), Literal("x"), G_WORLD),
                               (URIRef("urn:other:a"), URIRef("urn:other:name"), Literal("y"), G_WORLD)]))
    q = store.prepare("SELECT ?n WHERE { ?s ex:name ?n }", "names", P)
    assert q.compiled.startswith("PREFIX ex: <%s>\n" % EX)
    assert [r["n"] for r in store.select(q)] == [Literal("x")]
    own = store.prepare("PREFIX ex: <urn:other:>\nSELECT ?n WHERE { ?s ex:name ?n }", "own", P)
    assert [r["n"] for r in store.select(own)] == [Literal("y")]
    assert store.ask(store.prepare("ASK { ex:a ex:name ?n }", "ask", P), {"n": Literal("x")})


@pytest.mark.parametrize("kind", ["journal", "oxigraph"])
def test_persists_and_locks(kind, tmp_path):
    path = str(tmp_path / "db")
    s = _open(kind, path)
    s.apply(ChangeSet(add=[(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1), G_WORLD)]))
    with pytest.raises(StoreError, match="in use|cannot open"):
        _open(kind, path)
    s.close()
    s2 = _open(kind, path)
    try:
        assert s2.value(URIRef(EX + "a"), URIRef(EX + "p")) == Literal(1)
    finally:
        s2.close()


@pytest.mark.parametrize("kind", ["journal", "oxigraph", "sparql", "mirror"])
def test_a_change_set_is_all_or_nothing(kind, tmp_path, opener):
    s = opener(kind, str(tmp_path / "db"))
    s.apply(ChangeSet(add=[(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1), G_WORLD)]))
    with pytest.raises(StoreError, match="blank nodes"):
        s.apply(ChangeSet(remove=[(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1), G_WORLD)],
                          add=[(URIRef(EX + "b"), URIRef(EX + "p"), Literal(2), G_WORLD),
                               (BNode(), URIRef(EX + "p"), Literal(3), G_WORLD)]))
    assert [q[:3] for q in s.quads()] == [(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1))]


@pytest.mark.parametrize("kind", BACKENDS)
def test_the_default_graph_is_the_union_of_the_named_graphs(kind, tmp_path, opener):
    s = opener(kind, str(tmp_path / "db"))
    a, b, name, age, knows = (URIRef(EX + x) for x in ("a", "b", "name", "age", "knows"))
    other = URIRef(EX + "graph/other")
    s.apply(ChangeSet(add=[(a, name, Literal("Ann", lang="en"), G_WORLD), (a, age, Literal(41), G_LOG),
                           (a, knows, b, other), (b, name, Literal("line\nbreak \\ \"q\""), G_WORLD)]))
    # a join across three graphs, a value that only a FILTER uses (the FILTER must see it)
    q = s.prepare("SELECT ?n ?age ?who ?min WHERE { ?x ex:name ?n ; ex:age ?age ; ex:knows ?y . ?y ex:name ?who "
                  "FILTER(?age > ?min) }", "join", P)
    rows = s.select(q, {"min": Literal(40)})
    assert rows == [{"n": Literal("Ann", lang="en"), "age": Literal(41), "who": Literal('line\nbreak \\ "q"'),
                     "min": Literal(40)}]
    assert s.select(q, {"min": Literal(41)}) == []
    graphs = s.prepare("SELECT ?g WHERE { GRAPH ?g { ?s ex:knows ?o } }", "graphs", P)
    assert s.select(graphs) == [{"g": other}]
    assert s.count() == 4 and s.count(G_WORLD) == 2 and s.count(other) == 1 and s.count(G_META) == 0
    assert sorted(q[3] for q in s.quads(a)) == sorted([G_WORLD, G_LOG, other])
    assert list(s.quads(a, None, None, (G_LOG,))) == [(a, age, Literal(41), G_LOG)]
    assert s.objects(a, knows) == [b] and s.value(b, name, (G_LOG,)) is None
    assert len(s.snapshot()) == 4


@pytest.mark.parametrize("kind", BACKENDS)
def test_replace_graph_keeps_blank_nodes_together(kind, tmp_path, opener):
    s = opener(kind, str(tmp_path / "db"))
    if kind in ("sparql", "mirror"):
        s.chunk_triples = 3  # several requests; the three triples around one blank node stay in one
    g = URIRef(EX + "graph/ontology")
    s.apply(ChangeSet(add=[(URIRef(EX + "old"), URIRef(EX + "p"), Literal(0), g)]))
    r = BNode()
    triples = [(URIRef(EX + "c%d" % i), URIRef(EX + "p"), Literal(i)) for i in range(7)]
    triples += [(URIRef(EX + "C"), URIRef(EX + "sub"), r), (r, URIRef(EX + "on"), URIRef(EX + "q")),
                (r, URIRef(EX + "some"), URIRef(EX + "D"))]
    s.replace_graph(g, triples)
    assert s.count(g) == 10 and s.value(URIRef(EX + "old"), URIRef(EX + "p")) is None
    q = s.prepare("SELECT ?on ?d WHERE { ex:C ex:sub ?r . ?r ex:on ?on ; ex:some ?d }", "restriction", P)
    assert s.select(q) == [{"on": URIRef(EX + "q"), "d": URIRef(EX + "D")}]
    s.replace_graph(g, [])
    assert s.count(g) == 0


@pytest.mark.parametrize("kind", BACKENDS)
def test_a_conditional_change_applies_only_while_the_expected_quads_are_there(kind, tmp_path, opener):
    s = opener(kind, str(tmp_path / "db"))
    task, status = URIRef(EX + "task_1"), URIRef(EX + "status")
    issued, running, done = (URIRef(EX + x) for x in ("issued", "in_progress", "succeeded"))
    s.apply(ChangeSet(add=[(task, status, issued, G_LOG)]))
    s.apply(ChangeSet(remove=[(task, status, issued, G_LOG)], add=[(task, status, running, G_LOG)],
                      expect=[(task, status, issued, G_LOG)]))
    assert s.objects(task, status) == [running]
    with pytest.raises(StoreConflict) as err:  # a second writer that still believes the task is issued
        s.apply(ChangeSet(remove=[(task, status, issued, G_LOG)],
                          add=[(task, status, done, G_LOG), (task, URIRef(EX + "note"), Literal("x"), G_LOG)],
                          expect=[(task, status, issued, G_LOG)]))
    assert err.value.quad == (task, status, issued, G_LOG)
    msg = str(err.value)
    assert "\n" not in msg and "<%s> <%s> <%s>" % (task, status, issued) in msg and "<%s>" % running in msg
    assert s.objects(task, status) == [running] and s.value(task, URIRef(EX + "note")) is None
    assert s.count() == 1  # bookkeeping (the SPARQL store's claim tokens) is not part of the data


@pytest.mark.parametrize("kind", ["journal", "sparql", "mirror"])
def test_two_writers_racing_on_one_status_exactly_one_wins(kind, tmp_path, opener, request):
    """Each round, two threads move the same task from issued to their own status; the SPARQL backend gives each
    thread its own SparqlStore (two PEMKRE clients of one server), the embedded one shares its store."""
    first = opener(kind, str(tmp_path / "db"))
    stores = [first, first if kind == "journal" else request.getfixturevalue("sparql_store")(mirror=kind == "mirror")]
    status = URIRef(EX + "status")
    issued = URIRef(EX + "issued")
    for rnd in range(12):
        task = URIRef(EX + "task_%d" % rnd)
        first.apply(ChangeSet(add=[(task, status, issued, G_LOG)]))
        start = threading.Barrier(2)
        outcome = [None, None]

        def write(i):
            mine = URIRef(EX + "writer_%d" % i)
            start.wait()
            try:
                stores[i].apply(ChangeSet(remove=[(task, status, issued, G_LOG)], add=[(task, status, mine, G_LOG)],
                                          expect=[(task, status, issued, G_LOG)]))
                outcome[i] = "won"
            except StoreConflict as exc:
                outcome[i] = exc

        threads = [threading.Thread(target=write, args=(i,)) for i in (0, 1)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(30)
        assert sorted(type(o).__name__ for o in outcome) == ["StoreConflict", "str"], outcome
        winner = outcome.index("won")
        assert first.objects(task, status) == [URIRef(EX + "writer_%d" % winner)]
        assert "another writer" in str(outcome[1 - winner])


def test_journal_drops_a_torn_last_record_and_compaction_keeps_everything(tmp_path):
    path = str(tmp_path / "db")
    s = JournaledStore(path)
    a, p = URIRef(EX + "a"), URIRef(EX + "p")
    for i in range(5):
        s.apply(ChangeSet(remove=[(a, p, Literal(i - 1), G_WORLD)], add=[(a, p, Literal(i), G_WORLD)]))
    s.close()
    journal = os.path.join(path, "journal.log")
    good = os.path.getsize(journal)
    with open(journal, "ab") as fh:                 # a process killed inside write(): half a record
        fh.write(b"@TX 120 0badc0de\n+ <https://ex.example/a> <https://ex.example/p> \"9")
    s = JournaledStore(path)
    assert s.replayed_records == 5 and s.dropped_bytes > 0
    assert os.path.getsize(journal) == good
    assert s.objects(a, p) == [Literal(4)]
    s.compact()
    assert os.path.getsize(journal) == 0
    s.apply(ChangeSet(add=[(a, URIRef(EX + "q"), Literal("after"), G_WORLD)]))
    s.close()
    s = JournaledStore(path)
    try:
        assert s.objects(a, p) == [Literal(4)] and s.value(a, URIRef(EX + "q")) == Literal("after")
    finally:
        s.close()


@pytest.mark.parametrize("kind", ["journal", "oxigraph"])
def test_maintain_keeps_every_live_triple(kind, tmp_path):
    path = str(tmp_path / "db")
    s = JournaledStore(path, rebuild_after_removals=10 ** 6) if kind == "journal" else OxigraphStore(path)
    s.rebuild_after_removals = 10 ** 6  # only the explicit call below
    a, p, q = URIRef(EX + "a"), URIRef(EX + "p"), URIRef(EX + "q")
    s.apply(ChangeSet(add=[(a, q, Literal("kept"), G_WORLD)]))
    for i in range(300):  # the same subject/predicate replaced over and over, as a process pointer is
        s.apply(ChangeSet(remove=[(a, p, Literal(i - 1), G_WORLD)], add=[(a, p, Literal(i), G_WORLD)]))
    before = sorted(s.quads())
    assert s.removals == 300
    s.rebuild_after_removals = 100
    s.maintain()
    assert sorted(s.quads()) == before and s.objects(a, p) == [Literal(299)]
    assert s.removals == 0
    if kind == "journal":
        assert os.path.getsize(os.path.join(path, "journal.log")) == 0
    s.apply(ChangeSet(remove=[(a, p, Literal(299), G_WORLD)], add=[(a, p, Literal(300), G_WORLD)]))
    s.close()
    s = JournaledStore(path) if kind == "journal" else OxigraphStore(path)
    try:
        assert s.objects(a, p) == [Literal(300)] and s.value(a, q) == Literal("kept")
    finally:
        s.close()
