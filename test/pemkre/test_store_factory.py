"""The one store factory (PEMKRE's node and HICEM's embedded PEMKRE): each kind opens its store, the on-disk
kinds keep a write across close/reopen, ``fresh`` starts empty, an unknown kind is refused naming the kinds."""
import os

import pytest
from rdflib import Literal, URIRef

from locem_bridge.pemkre import JournaledStore, OxigraphStore
from locem_bridge.pemkre.store import G_WORLD, ChangeSet
from locem_bridge.pemkre.store_factory import STORE_KINDS, open_store

A, P = URIRef("https://ex.example/a"), URIRef("https://ex.example/p")


@pytest.mark.parametrize("kind, cls, kept", [("journal", JournaledStore, True), ("rocksdb", OxigraphStore, True),
                                             ("memory", OxigraphStore, False)])
def test_each_kind_opens_its_store_and_the_disk_kinds_keep_a_write(kind, cls, kept, tmp_path):
    path = str(tmp_path / "store")
    store = open_store(kind, path)
    assert isinstance(store, cls)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    store.close()
    assert os.path.isdir(path) == kept
    again = open_store(kind, path)
    try:
        assert again.value(A, P) == (Literal(1) if kept else None)
    finally:
        again.close()


@pytest.mark.parametrize("kind", ["journal", "rocksdb"])
def test_fresh_starts_from_an_empty_store(kind, tmp_path):
    path = str(tmp_path / "store")
    store = open_store(kind, path)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    store.close()
    store = open_store(kind, path, fresh=True)
    try:
        assert store.value(A, P) is None and store.count() == 0
    finally:
        store.close()


def test_an_unknown_kind_is_refused_before_anything_is_touched(tmp_path):
    path = tmp_path / "store"
    path.mkdir()
    (path / "keep").write_text("data")
    with pytest.raises(ValueError, match=r"store must be journal, rocksdb, memory or sparql, got 'sqlite'"):
        open_store("sqlite", str(path), fresh=True)
    assert (path / "keep").read_text() == "data" and STORE_KINDS == ("journal", "rocksdb", "memory", "sparql")


def test_sparql_opens_a_server_store_that_keeps_a_write_and_fresh_drops_only_pemkre_graphs(oxigraph_server,
                                                                                          tmp_path):
    from oxigraph_server import clear_server  # not 'conftest': another test folder's conftest may hold that name
    from locem_bridge.pemkre.sparql_store import SparqlStore

    oxigraph_server.start()
    clear_server(oxigraph_server)
    urls = dict(query_url=oxigraph_server.query_url, update_url=oxigraph_server.update_url)
    other = URIRef("https://mes.example/graph/orders")  # another system's data on the same server
    store = open_store("sparql", str(tmp_path / "unused"), **urls)
    assert isinstance(store, SparqlStore) and store.persistent
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD), (A, P, Literal(2), other)]))
    store.close()
    assert not (tmp_path / "unused").exists()
    again = open_store("sparql", "", **urls)
    try:
        assert again.objects(A, P, (G_WORLD,)) == [Literal(1)]
    finally:
        again.close()
    fresh = open_store("sparql", "", fresh=True, **urls)
    try:
        assert fresh.value(A, P, (G_WORLD,)) is None and fresh.value(A, P, (other,)) == Literal(2)  # dropped, kept
        assert fresh.count() == 0 and fresh.value(A, P) is None  # reads without a graph never see other systems
    finally:
        fresh.close()
    with pytest.raises(ValueError, match="store sparql needs the server's query_url and update_url"):
        open_store("sparql", "", query_url=oxigraph_server.query_url)
