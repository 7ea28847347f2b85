"""The store layer: persistence across close/reopen, one process per store, atomic writes, bindings not spliced."""
import pytest
from rdflib import BNode, Literal, URIRef

import os

from locem_bridge.pemkre import JournaledStore, OxigraphStore, RdflibStore
from locem_bridge.pemkre.errors import QueryError, StoreError
from locem_bridge.pemkre.store import G_WORLD, ChangeSet

EX = "https://ex.example/"
P = {"ex": EX}


def _open(kind, path):
    return {"journal": JournaledStore, "oxigraph": OxigraphStore}[kind](path) if kind != "rdflib" else RdflibStore()


@pytest.mark.parametrize("kind", ["journal", "oxigraph", "rdflib"])
def test_same_answers_from_every_backend_with_bindings(kind, tmp_path):
    store = _open(kind, str(tmp_path / "s"))
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


@pytest.mark.parametrize("kind", ["journal", "oxigraph"])
def test_a_change_set_is_all_or_nothing(kind, tmp_path):
    s = _open(kind, str(tmp_path / "db"))
    try:
        s.apply(ChangeSet(add=[(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1), G_WORLD)]))
        with pytest.raises(StoreError, match="blank nodes"):
            s.apply(ChangeSet(remove=[(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1), G_WORLD)],
                              add=[(URIRef(EX + "b"), URIRef(EX + "p"), Literal(2), G_WORLD),
                                   (BNode(), URIRef(EX + "p"), Literal(3), G_WORLD)]))
        assert [q[:3] for q in s.quads()] == [(URIRef(EX + "a"), URIRef(EX + "p"), Literal(1))]
    finally:
        s.close()


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
