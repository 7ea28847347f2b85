"""The store that reads from its copy of the server's data (MirroredSparqlStore, what ``store:=sparql`` opens),
against a real ``oxigraph serve``: a decision's reads cost one request; another writer's change is seen at the next
decision, whoever wrote it (a second PEMKRE client, the plain store, a system that adds the version update); two
writes at the same moment, a write whose answer was lost and a conflict all make the copy load again; a copy that
cannot be read consistently is a clear NOT_READY; a write of a system that does not replace the marker is not seen
(the documented contract) until the copy is loaded again."""
import urllib.parse
import urllib.request
import uuid

import pytest
from rdflib import BNode, Literal, URIRef

from locem_bridge.pemkre.errors import StoreConflict, StoreError, StoreUnavailable
from locem_bridge.pemkre.mirror_store import MirroredSparqlStore
from locem_bridge.pemkre.sparql_http import RetryPolicy
from locem_bridge.pemkre.sparql_store import VERSION_PREFIX, SparqlStore
from locem_bridge.pemkre.store import G_LOG, G_WORLD, ChangeSet

EX = "https://ex.example/"
A, B, P = URIRef(EX + "a"), URIRef(EX + "b"), URIRef(EX + "p")
QUICK = RetryPolicy(attempts=2, first_delay_s=0.01, max_delay_s=0.01)


def _raw_update(server, text):
    """An update another system sends straight to the server (not through a PEMKRE store)."""
    body = urllib.parse.urlencode({"update": text}).encode("ascii")
    urllib.request.urlopen(urllib.request.Request(server.update_url, data=body), timeout=10).close()


def _mirror(sparql_store, **kwargs):
    """A MirroredSparqlStore that loads its copy whenever it finds it stale (no rate limit, so the tests can count
    the loads)."""
    store = sparql_store(mirror=True, **kwargs)
    store.RELOAD_SHARE = 1.0
    return store


def _count_requests(store):
    """Count the requests ``store`` sends to each endpoint: returns the dict counting them."""
    sent = {"query": 0, "update": 0}
    for name, endpoint in (("query", store.query_endpoint), ("update", store.update_endpoint)):
        post = endpoint.post

        def counted(*args, _post=post, _name=name, **kwargs):
            sent[_name] += 1
            return _post(*args, **kwargs)
        endpoint.post = counted
    return sent


def test_a_decision_reads_from_the_copy_after_one_request_and_sees_its_own_writes(sparql_store):
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD), (B, P, A, G_LOG)]))
    q = store.prepare("SELECT ?x WHERE { ?s ex:p ?x }", "p", {"ex": EX})
    store.value(A, P)                                   # the copy is loaded (a fresh client) and checked
    sent = _count_requests(store)
    loaded = store.reloads
    with store.reading():                              # one decision: the marker read once, then only the copy
        for _ in range(20):
            assert store.value(A, P) == Literal(1) and store.value(B, P, (G_LOG,)) == A
            assert sorted(r["x"] for r in store.select(q)) == sorted([Literal(1), A])
            assert store.count() == 2 and store.count(G_LOG) == 1
        assert sent == {"query": 1, "update": 0}
        store.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)]))
        assert sent == {"query": 1, "update": 1}        # an unconditional write: one request
        assert store.value(A, P) == Literal(2)          # its own write, from the copy
        assert sent["query"] == 1
    assert store.value(A, P) == Literal(2)              # outside a decision: the marker read first
    assert sent["query"] == 2 and store.reloads == loaded  # its own write did not make it load the copy again


@pytest.mark.parametrize("other_kind", ["mirror", "plain"])
def test_another_clients_write_is_seen_at_the_next_decision_not_in_the_middle_of_one(sparql_store, other_kind):
    store = _mirror(sparql_store)
    other = _mirror(sparql_store) if other_kind == "mirror" else sparql_store()
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    loaded = store.reloads
    with store.reading():
        assert store.value(A, P) == Literal(1)
        other.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(5), G_WORLD)]))
        assert store.value(A, P) == Literal(1)          # one consistent view within the decision
    with store.reading():
        assert store.value(A, P) == Literal(5)          # the next decision sees it
    assert store.reloads == loaded + 1
    # a conditional write built on what another client changed meanwhile is refused by the server, not the copy
    with store.reading():
        other.apply(ChangeSet(remove=[(A, P, Literal(5), G_WORLD)], add=[(A, P, Literal(6), G_WORLD)]))
        with pytest.raises(StoreConflict) as err:
            store.apply(ChangeSet(remove=[(A, P, Literal(5), G_WORLD)], add=[(A, P, Literal(7), G_WORLD)],
                                  expect=[(A, P, Literal(5), G_WORLD)]))
        assert '"6"^^<http://www.w3.org/2001/XMLSchema#integer>' in str(err.value), str(err.value)
    assert store.value(A, P) == Literal(6) and other.value(A, P) == Literal(6)
    assert store.reloads == loaded + 2                  # the other client's second write, seen


def test_writes_of_two_clients_in_turn_keep_both_copies_exact(sparql_store):
    """Each client's write is its own version; after each of the other's writes a client loads its copy again,
    after its own it does not; the two copies always answer as the server does."""
    first, second = _mirror(sparql_store), _mirror(sparql_store)
    plain = sparql_store()
    for i in range(6):
        writer, reader = (first, second) if i % 2 == 0 else (second, first)
        loads = (writer.reloads, reader.reloads)
        writer.apply(ChangeSet(remove=[(A, P, Literal(i - 1), G_WORLD), (B, P, Literal(i - 1), G_LOG)],
                               add=[(A, P, Literal(i), G_WORLD), (B, P, Literal(i), G_LOG)]))
        truth = sorted(plain.quads())
        assert sorted(first.quads()) == truth and sorted(second.quads()) == truth
        if i:
            assert (writer.reloads, reader.reloads) == (loads[0], loads[1] + 1), i
    assert first.value(A, P) == Literal(5) and second.value(B, P) == Literal(5)


def test_a_write_of_another_system_is_seen_when_it_replaces_the_marker_and_not_before_a_reload(sparql_store,
                                                                                             oxigraph_server):
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    graph = "<%s>" % G_WORLD
    # an MES that writes PEMKRE's world graph without the version update: the copy does not know
    _raw_update(oxigraph_server, "DELETE DATA { GRAPH %s { <%s> <%s> 1 } } ; INSERT DATA { GRAPH %s { <%s> <%s> 2 } }"
                % (graph, A, P, graph, A, P))
    assert store.value(A, P) == Literal(1)
    store.reload()
    assert store.value(A, P) == Literal(2)
    # with the version update in the same request, as the README asks of other writers, it is seen at once
    _raw_update(oxigraph_server, "DELETE DATA { GRAPH %s { <%s> <%s> 2 } } ; INSERT DATA { GRAPH %s { <%s> <%s> 3 } }"
                " ;\n%s" % (graph, A, P, graph, A, P, SparqlStore.version_update(VERSION_PREFIX + str(uuid.uuid4()))))
    assert store.value(A, P) == Literal(3)


def test_two_versions_at_once_or_a_missing_link_make_the_copy_load_again(sparql_store, oxigraph_server):
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    loaded = store.reloads
    # two writers that replaced the same version at the same moment (snapshot isolation): two markers
    from locem_bridge.pemkre.sparql_store import G_CLAIMS, P_VERSION, VERSION_MARKER
    _raw_update(oxigraph_server, "INSERT DATA { GRAPH <%s> { <%s> <%s> <%s1> } }" % (G_CLAIMS, VERSION_MARKER,
                                                                                   P_VERSION, VERSION_PREFIX))
    assert store.value(A, P) == Literal(1) and store.reloads == loaded + 1
    store.value(A, P)
    assert store.reloads == loaded + 1                  # the copy holds both versions now: current
    store.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)]))
    assert store.value(A, P) == Literal(2)              # its write replaced both, as its copy knew
    assert store.reloads == loaded + 1
    _raw_update(oxigraph_server, "INSERT DATA { GRAPH <%s> { <%s> <%s> <%s2> } }" % (G_CLAIMS, VERSION_MARKER,
                                                                                   P_VERSION, VERSION_PREFIX))
    store.apply(ChangeSet(remove=[(A, P, Literal(2), G_WORLD)], add=[(A, P, Literal(3), G_WORLD)]))
    assert store.value(A, P) == Literal(3)              # its write replaced two it did not know: loaded again
    assert store.reloads == loaded + 2
    # another writer between two writes of this client (its own chain has a stranger in it)
    other = sparql_store()
    store.apply(ChangeSet(add=[(B, P, Literal(1), G_WORLD)]))
    other.apply(ChangeSet(add=[(B, P, Literal(9), G_LOG)]))
    store.apply(ChangeSet(add=[(B, P, Literal(2), G_WORLD)]))
    assert sorted(store.objects(B, P)) == [Literal(1), Literal(2), Literal(9)]
    assert store.reloads == loaded + 3


def test_a_write_whose_answer_was_lost_is_in_the_copy_when_applied_and_the_copy_loads_again_when_unknown(
        sparql_store):
    store = _mirror(sparql_store, retry=QUICK)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    post = store.update_endpoint.post
    send = [True]

    def lost(*args, **kwargs):   # the answer never comes back; the server got it or not
        if send[0]:
            post(*args, **kwargs)
        raise StoreUnavailable("SPARQL update endpoint x: connection lost; whether it was applied is unknown",
                               "x", "connection lost", applied=None)
    store.update_endpoint.post = lost
    loaded = store.reloads
    store.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)]))  # token found
    assert store.value(A, P) == Literal(2) and store.reloads == loaded   # applied: in the copy, no load
    send[0] = False
    with pytest.raises(StoreUnavailable) as err:
        store.apply(ChangeSet(remove=[(A, P, Literal(2), G_WORLD)], add=[(A, P, Literal(3), G_WORLD)]))
    assert err.value.applied is None
    store.update_endpoint.post = post
    assert store.value(A, P) == Literal(2) and store.reloads == loaded + 1   # unknown: the server's truth loaded


def test_a_copy_that_keeps_changing_while_it_loads_is_not_ready_naming_the_endpoint(sparql_store, oxigraph_server):
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    load = store._load_graph

    def busy_writer(copy, graph):   # another writer replaces the marker while each graph is read
        load(copy, graph)
        _raw_update(oxigraph_server, SparqlStore.version_update(VERSION_PREFIX + str(uuid.uuid4())))
    store._load_graph = busy_writer
    with pytest.raises(StoreUnavailable) as err:
        store.reload()
    msg = str(err.value)
    assert "\n" not in msg and oxigraph_server.query_url in msg and "changed while it was being loaded" in msg, msg
    assert err.value.code == "NOT_READY"
    store._load_graph = load
    assert store.value(A, P) == Literal(1)              # the next read loads it (the writer has stopped)


def test_blank_nodes_answer_as_blank_nodes_from_the_copy_and_after_loading_it(sparql_store):
    from locem_bridge.pemkre.store import G_ONTOLOGY

    store = _mirror(sparql_store)
    g = G_ONTOLOGY
    node = BNode("r1")
    store.replace_graph(g, [(A, P, node), (node, P, Literal(3))])
    q = store.prepare("SELECT ?r ?v WHERE { ex:a ex:p ?r . ?r ex:p ?v }", "r", {"ex": EX})
    assert store.select(q) == [{"r": node, "v": Literal(3)}]
    assert store.select(q, {"r": node}) == [{"r": node, "v": Literal(3)}]
    assert store.value(node, P, (g,)) == Literal(3)
    store.reload()
    assert store.select(q) == [{"r": node, "v": Literal(3)}] and store.value(A, P, (g,)) == node
    fresh = _mirror(sparql_store)                   # a second client: loads it from the server
    assert fresh.select(fresh.prepare(q.text, "r", {"ex": EX})) == [{"r": node, "v": Literal(3)}]


def test_the_server_away_is_not_ready_and_the_copy_is_not_used_to_answer(sparql_store, oxigraph_server):
    store = _mirror(sparql_store, retry=QUICK)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    oxigraph_server.kill()
    try:
        with pytest.raises(StoreUnavailable) as err:
            store.value(A, P)                           # the copy may be stale: without the marker, no answer
        assert err.value.code == "NOT_READY" and oxigraph_server.base_url in str(err.value)
        with pytest.raises(StoreUnavailable):
            with store.reading():
                pass
    finally:
        oxigraph_server.start()
    assert store.value(A, P) == Literal(1)


def test_the_factory_opens_the_copy_by_default_and_the_plain_store_on_request(oxigraph_server):
    from locem_bridge.pemkre.store_factory import open_store

    urls = dict(query_url=oxigraph_server.query_url, update_url=oxigraph_server.update_url)
    oxigraph_server.start()
    default, plain = open_store("sparql", "", **urls), open_store("sparql", "", mirror=False, **urls)
    try:
        assert isinstance(default, MirroredSparqlStore)
        assert isinstance(plain, SparqlStore) and not isinstance(plain, MirroredSparqlStore)
    finally:
        default.close()
        plain.close()


def test_a_write_that_changed_nothing_keeps_the_copy(sparql_store):
    """A conflict with no other writer about, and a write refused before it was sent, leave the server as it was:
    the copy stays current (no load) and the next decision's reads cost the one marker request."""
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    assert store.value(A, P) == Literal(1)
    loaded = store.reloads
    with pytest.raises(StoreConflict):
        store.apply(ChangeSet(remove=[(A, P, Literal(9), G_WORLD)], add=[(A, P, Literal(10), G_WORLD)],
                              expect=[(A, P, Literal(9), G_WORLD)]))
    with pytest.raises(StoreError, match="blank nodes"):
        store.apply(ChangeSet(add=[(BNode(), P, Literal(3), G_WORLD)]))
    sent = _count_requests(store)
    with store.reading():
        assert store.value(A, P) == Literal(1) and store.count() == 1
    assert store.reloads == loaded and sent == {"query": 1, "update": 0}


def test_a_graph_replaced_in_several_requests_and_a_new_graph_of_another_client(sparql_store):
    from locem_bridge.pemkre.store import G_ONTOLOGY
    from locem_bridge.pemkre.vocab import GRAPHS

    store, other = _mirror(sparql_store), sparql_store()
    store.chunk_triples = 3
    assert store.count() == 0                       # the copy loaded (empty)
    loaded = store.reloads
    store.replace_graph(G_ONTOLOGY, [(URIRef(EX + "c%d" % i), P, Literal(i)) for i in range(10)])
    assert store.count(G_ONTOLOGY) == 10 and store.reloads == loaded      # four versions, all its own
    extra = URIRef(str(GRAPHS) + "extra")
    other.apply(ChangeSet(add=[(A, P, Literal(7), extra)]))
    assert store.value(A, P) == Literal(7) and store.count(extra) == 1   # found, loaded with the copy
    assert store.reloads == loaded + 1


def test_dropping_pemkre_graphs_empties_the_copy_too(sparql_store):
    store = _mirror(sparql_store)
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD), (B, P, Literal(2), G_LOG)]))
    assert store.count() == 2
    store.drop_pemkre_graphs()
    assert store.count() == 0 and store.value(A, P) is None
    store.apply(ChangeSet(add=[(A, P, Literal(3), G_WORLD)]))
    assert store.value(A, P) == Literal(3) and store.count() == 1


def test_version_links_do_not_pile_up_on_the_server(sparql_store):
    from locem_bridge.pemkre.sparql_store import G_CLAIMS, P_VERSION_AFTER

    store, other = _mirror(sparql_store), _mirror(sparql_store)
    for i in range(20):
        store.apply(ChangeSet(remove=[(A, P, Literal(i - 1), G_WORLD)], add=[(A, P, Literal(i), G_WORLD)]))
        with store.reading():
            store.value(A, P)
        other.value(A, P)
    links = list(other.quads(None, P_VERSION_AFTER, None, (G_CLAIMS,)))
    assert len(links) <= 2, links        # the links of the last checked version(s), deleted by the next write
    store.close()
    assert list(other.quads(None, P_VERSION_AFTER, None, (G_CLAIMS,))) == []


def test_a_copy_found_stale_soon_after_a_load_reads_from_the_server_for_a_while(sparql_store):
    """Loading the copy takes at most about RELOAD_SHARE of the time: stale again soon after a load, the store
    answers from the server (right answers, the first-member index steps aside) until the time is up."""
    from locem_bridge.pemkre.first_member import FirstMember, Unanswerable
    from rdflib import RDF

    store, other = sparql_store(mirror=True), sparql_store()
    now = [1000.0]
    store.clock = lambda: now[0]
    store.apply(ChangeSet(add=[(A, RDF.type, B, G_WORLD), (A, P, Literal(1), G_WORLD)]))
    index = FirstMember(store, B, P)
    assert index.first() == A                       # loaded at t=1000 (the clock stands: took 0 s)
    loaded = store.reloads
    store._no_load_before = now[0] + 5.0            # as after a load of 0.5 s with the share of 0.1
    other.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)]))
    with store.reading():
        assert store.value(A, P) == Literal(2)      # from the server
        with pytest.raises(Unanswerable, match="reads from the server"):
            index.first()
    assert store.reloads == loaded
    now[0] += 5.0
    assert store.value(A, P) == Literal(2) and store.reloads == loaded + 1
    assert index.first() == A


def test_beside_a_server_that_is_not_oxigraph_the_copy_is_off_and_reads_go_to_the_server(oxigraph_server):
    """The copy keeps literals in Oxigraph's canonical form: beside another server (its Server header says so)
    the store reads from the server as the plain store does, and says why."""
    from test_sparql_store import FakeServer

    def relay(h, body):
        req = urllib.request.Request(oxigraph_server.query_url, data=body, headers={
            "Content-Type": "application/x-www-form-urlencoded", "Accept": h.headers.get("Accept", "*/*")})
        with urllib.request.urlopen(req, timeout=10) as resp:
            media, data = resp.headers.get("Content-Type", ""), resp.read()
        h.send_response(200)
        h.send_header("Content-Type", media)
        h.send_header("Server", "Apache Jena Fuseki (4.10.0)")
        h.send_header("Content-Length", str(len(data)))
        h.end_headers()
        h.wfile.write(data)

    oxigraph_server.start()
    proxy = FakeServer(relay)
    store = MirroredSparqlStore(proxy.url, oxigraph_server.update_url)
    try:
        assert "Fuseki" in store.copy_off and not store.sole_writer
        store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
        before = proxy.requests
        assert store.value(A, P) == Literal(1) and proxy.requests == before + 1    # asked the server
        assert store.reloads == 0
    finally:
        store.close()
        proxy.close()
