"""What only a remote store can get wrong, against a real ``oxigraph serve`` and tiny fake servers: bad endpoints
(wrong scheme, nothing listening, an HTML page, HTTP 500, no answer) each give one line naming the endpoint; a
query the server refuses; the server killed and restarted (reads reconnect, the data is still there); a write
whose answer is lost (the claim token tells whether it was applied); the engine on the server."""
import http.server
import re
import threading
import time
import urllib.parse
import urllib.request

import pytest
from oxigraph_server import OxigraphServer, free_port
from pemkre_testkit import FakeClock, json_dumps, run_process, scan_result
from rdflib import Literal, URIRef

from locem_bridge.pemkre import PLB, PPR, ProcessEngine
from locem_bridge.pemkre.errors import QueryError, StoreConflict, StoreError, StoreUnavailable, TaskStateError
from locem_bridge.pemkre.sparql_http import Endpoint, RetryPolicy
from locem_bridge.pemkre.sparql_store import SparqlStore
from locem_bridge.pemkre.store import G_LOG, G_WORLD, ChangeSet
from locem_bridge.pemkre.vocab import SITE

EX = "https://ex.example/"
A, P = URIRef(EX + "a"), URIRef(EX + "p")
QUICK = RetryPolicy(attempts=2, first_delay_s=0.01, max_delay_s=0.01)


class FakeServer:
    """An HTTP server on a free loopback port whose every POST is answered by ``handle(handler, body)``."""

    def __init__(self, handle):
        outer = self

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_POST(self):
                body = self.rfile.read(int(self.headers.get("Content-Length") or 0))
                outer.requests += 1
                handle(self, body)

            def log_message(self, *args):
                pass

        self.requests = 0
        self.httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.httpd.daemon_threads = True
        self.url = "http://127.0.0.1:%d/sparql" % self.httpd.server_address[1]
        self.thread = threading.Thread(target=self.httpd.serve_forever, args=(0.05,), daemon=True)
        self.thread.start()

    def close(self):
        self.httpd.shutdown()
        self.httpd.server_close()


@pytest.fixture
def fake_server():
    servers = []

    def make(handle):
        s = FakeServer(handle)
        servers.append(s)
        return s

    yield make
    for s in servers:
        s.close()


def _reply(handler, status, media, text):
    data = text.encode("utf-8")
    handler.send_response(status)
    handler.send_header("Content-Type", media)
    handler.send_header("Content-Length", str(len(data)))
    handler.end_headers()
    handler.wfile.write(data)


def _one_line(exc):
    msg = str(exc)
    assert "\n" not in msg, msg
    return msg


# ------------------------------------------------------------------------------------------------ bad endpoints
def test_a_url_that_is_not_http_is_refused_naming_it():
    with pytest.raises(StoreError) as err:
        SparqlStore("ftp://127.0.0.1/query", "http://127.0.0.1:1/update")
    assert _one_line(err.value) == "SPARQL query endpoint ftp://127.0.0.1/query: not an http:// or https:// URL " \
                                   "(scheme 'ftp')"
    with pytest.raises(StoreError, match=r"^SPARQL update endpoint 127.0.0.1:7878/update: not an http:// or "
                                         r"https:// URL \(no scheme\)$"):
        SparqlStore("http://127.0.0.1:1/query", "127.0.0.1:7878/update")
    with pytest.raises(StoreError, match="SPARQL query endpoint http://:7878/query: the URL names no host"):
        SparqlStore("http://:7878/query", "http://127.0.0.1:1/update")


def test_nothing_listening_is_one_line_naming_the_endpoint_after_the_retries():
    port = free_port()
    started = time.monotonic()
    with pytest.raises(StoreUnavailable) as err:
        SparqlStore("http://127.0.0.1:%d/query" % port, "http://127.0.0.1:%d/update" % port, retry=QUICK)
    msg = _one_line(err.value)
    assert msg.startswith("SPARQL query endpoint http://127.0.0.1:%d/query: connection refused (is the SPARQL "
                          "server running on 127.0.0.1:%d?) (2 attempts over " % (port, port)), msg
    assert err.value.endpoint == "http://127.0.0.1:%d/query" % port and err.value.applied is False
    assert time.monotonic() - started < 5


def test_a_server_answering_an_html_page_is_named_as_such(fake_server):
    page = "<!DOCTYPE html><html><head><title>Welcome to nginx!</title></head><body><h1>Welcome</h1></body></html>"
    srv = fake_server(lambda h, body: _reply(h, 200, "text/html; charset=utf-8", page))
    with pytest.raises(StoreError) as err:
        SparqlStore(srv.url, srv.url, retry=QUICK)
    assert _one_line(err.value) == (
        "SPARQL query endpoint %s answered the check at opening with an HTML page ('Welcome to nginx!'), not "
        "SPARQL results JSON: is this the query URL of a SPARQL 1.1 server?" % srv.url)


def test_http_500_gives_the_servers_message_in_one_line(fake_server):
    srv = fake_server(lambda h, body: _reply(h, 500, "text/plain", "boom:\n  the database\n  is on fire"))
    with pytest.raises(StoreError) as err:
        SparqlStore(srv.url, srv.url, retry=QUICK)
    assert _one_line(err.value) == "SPARQL query endpoint %s: HTTP 500 Internal Server Error: boom: the database " \
                                   "is on fire" % srv.url
    assert srv.requests == 1  # a 500 is not retried (502/503/504 are)


def test_503_is_retried_then_reported(fake_server):
    srv = fake_server(lambda h, body: _reply(h, 503, "text/html", "<html><body><p>Service  Unavailable</p></body>"
                                                                   "</html>"))
    with pytest.raises(StoreError, match=r"HTTP 503 Service Unavailable: Service Unavailable$"):
        SparqlStore(srv.url, srv.url, retry=QUICK)
    assert srv.requests == 2


def test_a_server_that_does_not_answer_times_out(fake_server):
    srv = fake_server(lambda h, body: time.sleep(2))
    with pytest.raises(StoreUnavailable) as err:
        SparqlStore(srv.url, srv.url, timeout_s=0.2, retry=QUICK)
    assert "SPARQL query endpoint %s: no answer within 0.2 s (2 attempts over" % srv.url in _one_line(err.value)


def test_update_and_query_urls_of_different_datasets_are_refused(oxigraph_server, fake_server):
    oxigraph_server.start()
    sink = fake_server(lambda h, body: _reply(h, 204, "text/plain", ""))  # accepts every write, keeps nothing
    with pytest.raises(StoreError) as err:
        SparqlStore(oxigraph_server.query_url, sink.url)
    assert _one_line(err.value) == ("SPARQL update endpoint %s accepted a write that SPARQL query endpoint %s does "
                                    "not show: do both URLs name the same dataset?"
                                    % (sink.url, oxigraph_server.query_url))


def test_a_query_the_server_refuses_is_a_query_error_naming_query_and_endpoint(sparql_store, oxigraph_server):
    s = sparql_store()
    q = s.prepare("SELECT ?o WHERE { ?s ?p ?o } GROUP BY ?s", "grouped", {})  # rdflib lets it pass, SPARQL not
    with pytest.raises(QueryError) as err:
        s.select(q)
    msg = _one_line(err.value)
    assert msg.startswith("query grouped failed on the server: SPARQL query endpoint %s: HTTP 400 Bad Request: "
                          % oxigraph_server.query_url), msg
    assert err.value.query_iri == "grouped"


# ------------------------------------------------------------------------------------------------ the server away
def test_reads_reconnect_after_a_server_restart_and_the_data_is_still_there(tmp_path):
    with OxigraphServer(str(tmp_path / "data")) as server:
        s = SparqlStore(server.query_url, server.update_url, retry=QUICK)
        s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
        assert s.value(A, P) == Literal(1)  # the kept-alive connection is open now
        server.kill()
        with pytest.raises(StoreUnavailable) as err:
            s.value(A, P)
        assert _one_line(err.value).startswith("SPARQL query endpoint %s: connection refused" % server.query_url)
        with pytest.raises(StoreUnavailable) as err:
            s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
        assert err.value.applied is False and "update endpoint" in str(err.value)
        server.start()  # same port, same data folder
        assert s.objects(A, P) == [Literal(1)]
        s.apply(ChangeSet(add=[(A, P, Literal(3), G_WORLD)]))
        s.close()
        again = SparqlStore(server.query_url, server.update_url)
        assert sorted(again.objects(A, P)) == [Literal(1), Literal(3)]
        again.close()


def _proxy(target, mode):
    """A write endpoint in front of ``target``: ``mode[0]`` "forward" passes a write and its answer, "lose" passes
    the write and drops the answer (closes the connection), "drop" drops the write."""

    def handle(h, body):
        if mode[0] in ("forward", "lose"):
            req = urllib.request.Request(target, data=body,
                                         headers={"Content-Type": "application/x-www-form-urlencoded"})
            with urllib.request.urlopen(req, timeout=10) as resp:
                status = resp.status
            if mode[0] == "forward":
                _reply(h, status, "text/plain", "")
                return
        h.close_connection = True  # no answer at all

    return handle


def test_a_write_whose_answer_is_lost_is_known_applied_or_not_through_its_token(sparql_store, oxigraph_server,
                                                                                 fake_server):
    mode = ["forward"]
    proxy = fake_server(_proxy(oxigraph_server.update_url, mode))
    s = SparqlStore(oxigraph_server.query_url, proxy.url, retry=QUICK)
    mode[0] = "lose"
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))  # written; only the answer was lost: no error
    assert s.objects(A, P) == [Literal(1)]
    mode[0] = "drop"
    clock = [1000.0]
    s.clock = lambda: clock[0]
    with pytest.raises(StoreUnavailable) as err:
        s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
    msg = _one_line(err.value)
    # sent, and the connection lost: the server may still have it on its way (a proxy's queue), so it is not
    # "nothing was written" until its token shows or the claim ttl has passed
    assert err.value.applied is None and msg.startswith("SPARQL update endpoint %s: the connection was lost "
                                                        "before an answer came" % proxy.url), msg
    assert "does not have it yet, but it may still apply it" in msg, msg
    assert s.objects(A, P) == [Literal(1)]
    mode[0] = "forward"
    with pytest.raises(StoreUnavailable) as err:        # no write builds on it meanwhile
        s.apply(ChangeSet(add=[(A, P, Literal(3), G_WORLD)]))
    assert err.value.applied is False and "an earlier write's fate is unknown" in str(err.value)
    assert s.was_applied(s.unknown_writes[0]) is None
    for drop in (lambda: s.replace_graph(G_WORLD, [(A, P, Literal(4))]), s.drop_pemkre_graphs):
        with pytest.raises(StoreUnavailable, match="an earlier write's fate is unknown"):
            drop()                                      # the late write could land after it
    assert s.objects(A, P) == [Literal(1)]
    clock[0] += s.claim_ttl_s + 1.0
    assert s.unknown_writes and s.was_applied(s.unknown_writes[0]) is False and not s.unknown_writes
    s.apply(ChangeSet(add=[(A, P, Literal(3), G_WORLD)]))
    assert sorted(s.objects(A, P)) == [Literal(1), Literal(3)]
    with pytest.raises(StoreError, match="'<x> . } ; DROP ALL #' is not a write token"):
        s.was_applied("<x> . } ; DROP ALL #")
    s.close()


def test_a_lost_answer_while_the_server_cannot_be_asked_leaves_the_token_for_later(tmp_path, fake_server):
    with OxigraphServer(str(tmp_path / "data")) as server:
        mode = ["forward"]

        def handle(h, body):
            _proxy(server.update_url, mode)(h, body)
            if mode[0] == "lose":
                server.kill()  # the server dies right after writing: nobody can say yet

        proxy = fake_server(handle)
        s = SparqlStore(server.query_url, proxy.url, retry=QUICK)
        mode[0] = "lose"
        with pytest.raises(StoreUnavailable) as err:
            s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
        assert err.value.applied is None and err.value.token in s.unknown_writes
        assert "was_applied(" in _one_line(err.value)
        server.start()
        assert s.was_applied(err.value.token) and s.unknown_writes == []
        assert s.objects(A, P) == [Literal(1)]
        s.close()


def test_a_write_that_times_out_is_not_called_unwritten_while_the_server_may_still_apply_it(sparql_store,
                                                                                            oxigraph_server,
                                                                                            fake_server):
    mode = ["forward"]
    forwarded, release = threading.Event(), threading.Event()

    def slow(h, body):
        if mode[0] == "slow":
            release.wait(30)  # held until the client has given up and asked for the token
        try:
            _proxy(oxigraph_server.update_url, ["forward"])(h, body)
        except OSError:
            pass  # the client is gone: its answer cannot be delivered
        finally:
            forwarded.set()

    s = SparqlStore(oxigraph_server.query_url, fake_server(slow).url, timeout_s=0.3, retry=QUICK)
    s.query_endpoint = Endpoint(oxigraph_server.query_url, "query", 10.0, QUICK)  # reads are not what is timed
    mode[0] = "slow"
    forwarded.clear()
    try:
        with pytest.raises(StoreUnavailable) as err:
            s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    finally:
        release.set()  # now the write arrives, after the client gave up
    msg = _one_line(err.value)
    assert err.value.applied is None and err.value.timed_out, msg
    assert "no answer within 0.3 s after the write was sent; asked again, the server does not have it yet, but it " \
           "may still apply it" in msg
    assert forwarded.wait(10)
    assert s.was_applied(err.value.token) and s.objects(A, P) == [Literal(1)]
    s.close()


# ------------------------------------------------------------------------------------------------ options
def test_a_server_serving_the_union_as_default_graph_needs_no_dataset(tmp_path):
    with OxigraphServer(str(tmp_path / "data"), extra=["--union-default-graph"]) as server:
        s = SparqlStore(server.query_url, server.update_url, union_default_graph=True)
        s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD), (A, URIRef(EX + "q"), Literal(2), URIRef(EX + "g"))]))
        q = s.prepare("SELECT ?x ?y WHERE { ex:a ex:p ?x ; ex:q ?y }", "union", {"ex": EX})
        assert s.select(q) == [{"x": Literal(1), "y": Literal(2)}]
        # a big change is not staged there (the staging graphs would be part of every query): one request
        s.max_update_bytes = 1000
        sent = _counting(s)
        s.apply(ChangeSet(add=[(URIRef(EX + "j%d" % i), P, Literal(i), G_WORLD) for i in range(100)]))
        assert len(sent) == 1 and "urn:pemkre:staging" not in sent[0]
        assert s.count(G_WORLD) == 101
        s.close()


# ------------------------------------------------------------------------------------------------ the engine
#: the engine's tests run on both ways PEMKRE reads a server: every read a request, or from its copy (the default)
MIRROR_OR_NOT = pytest.mark.parametrize("mirror", [False, True], ids=["plain", "mirror"])

def _decide(action):
    if action.action_type == "SCAN":
        return "succeeded", json_dumps(scan_result(joints_per_wall=2))
    return "succeeded", ""


@MIRROR_OR_NOT
def test_the_engine_runs_a_process_on_the_server_as_on_the_embedded_store(mirror, sparql_store, make_engine):
    embedded = make_engine()
    embedded.start_process(str(PLB.TapingProcess), {"validateLines": False})
    expected = run_process(embedded, _decide)
    remote = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    remote.start_process(str(PLB.TapingProcess), {"validateLines": False})
    assert run_process(remote, _decide) == expected
    assert remote.store.value(SITE.wall_1_joint_2, PPR.tapingStatus) == PPR.processed
    assert remote.check_consistency(full_inference=True) == []


@MIRROR_OR_NOT
def test_two_engines_on_one_server_racing_on_one_task_status_exactly_one_wins(mirror, sparql_store):
    first = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    first.start_process(str(PLB.TapingProcess), {"validateLines": False})
    task = first.next_action().task
    first.set_task_status(task, "in_progress")
    # a second PEMKRE client: finds the running process
    second = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    outcome = {}
    start = threading.Barrier(2)

    def report(name, engine, status):
        start.wait()
        try:
            engine.set_task_status(task, status, request_id="")
            outcome[name] = ("won", status)
        except (StoreConflict, TaskStateError) as exc:
            outcome[name] = ("lost", exc)

    threads = [threading.Thread(target=report, args=(n, e, st))
               for n, e, st in (("first", first, "succeeded"), ("second", second, "failed"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert sorted(v[0] for v in outcome.values()) == ["lost", "won"], outcome
    loser = [v[1] for v in outcome.values() if v[0] == "lost"][0]
    # both reports are final: whichever comes second, even one after the other, finds the task no longer running
    assert "another writer" in str(loser) or "not running" in str(loser), loser
    winner_status = [v[1] for v in outcome.values() if v[0] == "won"][0]
    status = first.store.objects(URIRef(task), URIRef("https://locem-bridge.example.org/ont/process#status"))
    assert len(status) == 1 and str(status[0]).endswith(winner_status), (status, winner_status)


@MIRROR_OR_NOT
def test_an_engine_restarted_on_the_server_runs_the_process_as_on_the_embedded_store(mirror, sparql_store, make_engine):
    """The schema and ontology graphs share blank nodes (restrictions), written by separate requests: reloaded
    from the server, they must still be the same nodes (skolemised), or the restarted engine reasons wrongly."""
    embedded = make_engine()
    embedded.start_process(str(PLB.TapingProcess), {"validateLines": False})
    expected = run_process(embedded, _decide)
    first = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    first.start_process(str(PLB.TapingProcess), {"validateLines": False})
    scan = first.next_action()
    first.set_task_status(scan.task, "in_progress")
    first.set_task_status(scan.task, *_decide(scan))
    first.store.close()
    restarted = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    assert [(scan.action_type, scan.params())] + run_process(restarted, _decide) == expected
    assert restarted.store.value(SITE.wall_1_joint_2, PPR.tapingStatus) == PPR.processed


@MIRROR_OR_NOT
def test_while_the_server_is_away_the_engine_answers_not_ready_naming_it_and_loses_nothing(mirror, sparql_store,
                                                                                          oxigraph_server, make_engine):
    """The server killed (SIGKILL) in the middle of a process: every call of the engine fails with code NOT_READY
    in one line naming the endpoint and the reason, and changes nothing; the server back, the same calls (a status
    report with its request id) are applied once and the process runs on to the end it has on the embedded store."""
    embedded = make_engine()
    embedded.start_process(str(PLB.TapingProcess), {"validateLines": False})
    expected = run_process(embedded, _decide)
    engine = ProcessEngine(sparql_store(mirror=mirror, retry=QUICK), clock=FakeClock())
    engine.start_process(str(PLB.TapingProcess), {"validateLines": False}, request_id="start-1")
    scan = engine.next_action()
    engine.set_task_status(scan.task, "in_progress", request_id="r-1")
    oxigraph_server.kill()
    try:
        calls = [lambda: engine.next_action(),
                 lambda: engine.set_task_status(scan.task, *_decide(scan), request_id="r-2"),
                 lambda: engine.start_process(str(PLB.TapingProcess), {"validateLines": False}, request_id="start-1",
                                              abort_running=True)]
        for call in calls:
            with pytest.raises(StoreUnavailable) as err:
                call()
            msg = _one_line(err.value)
            assert err.value.code == "NOT_READY", msg
            assert oxigraph_server.base_url in msg and err.value.endpoint and err.value.reason, msg
    finally:
        oxigraph_server.start()
    assert engine.next_action().task == scan.task                  # still the SCAN, still in progress
    engine.set_task_status(scan.task, *_decide(scan), request_id="r-2")
    again = engine.set_task_status(scan.task, *_decide(scan), request_id="r-2")
    assert again.repeated
    # the start sent again with its request id (HICEM's retry) answers the same process, which runs on
    assert engine.start_process(str(PLB.TapingProcess), {"validateLines": False}, request_id="start-1",
                                abort_running=True) == engine.current_process()
    assert [(scan.action_type, scan.params())] + run_process(engine, _decide) == expected


@MIRROR_OR_NOT
def test_blank_nodes_shared_by_the_ontology_and_schema_graphs_stay_shared_on_the_server(mirror, sparql_store, make_engine):
    from rdflib import BNode

    from locem_bridge.pemkre.store import G_ONTOLOGY, G_SCHEMA_INFERRED

    def shared(store):
        nodes = [{t for q in store.quads(None, None, None, (g,)) for t in (q[0], q[2]) if isinstance(t, BNode)}
                 for g in (G_ONTOLOGY, G_SCHEMA_INFERRED)]
        return len(nodes[0] & nodes[1])

    expected = shared(make_engine().store)
    assert expected > 0
    remote = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    assert shared(remote.store) == expected
    assert shared(sparql_store(mirror=mirror)) == expected  # a second client reading them


@MIRROR_OR_NOT
def test_two_clients_starting_on_an_empty_server_write_the_same_blank_node_labels(mirror, sparql_store):
    """Two clients (two processes: no shared closure cache) starting at once: one's ontology graph and the other's
    inferred schema graph may end up together on the server; with canonical labels they still share their nodes."""
    from rdflib import BNode

    import locem_bridge.pemkre.engine as engine_module
    from locem_bridge.pemkre import RdflibStore
    from locem_bridge.pemkre.store import G_ONTOLOGY, G_SCHEMA_INFERRED

    def graph(store, g):  # the triples around blank nodes
        return {q[:3] for q in store.quads(None, None, None, (g,)) if any(isinstance(t, BNode) for t in q[:3])}

    engine_module._CLOSURE_CACHE.clear()  # the first process
    remote = ProcessEngine(sparql_store(mirror=mirror), clock=FakeClock())
    engine_module._CLOSURE_CACHE.clear()  # the second process loads the same files
    other = ProcessEngine(RdflibStore(), clock=FakeClock())
    for g in (G_ONTOLOGY, G_SCHEMA_INFERRED):
        mine, theirs = graph(remote.store, g), graph(other.store, g)
        assert mine and mine == theirs, g  # the same triples, blank node labels included


def test_a_conditional_write_that_failed_after_its_claim_can_be_retried_at_once(sparql_store, oxigraph_server,
                                                                                 fake_server):
    mode = ["forward"]
    forward = _proxy(oxigraph_server.update_url, mode)
    fail_final, claimed = [True], [False]

    def handle(h, body):
        text = urllib.parse.parse_qs(body.decode("utf-8")).get("update", [""])[0]
        if "NOW()" in text:                             # the claim request
            claimed[0] = True
        elif fail_final[0] and claimed[0]:              # the final write, after the claim
            fail_final[0] = False
            _reply(h, 500, "text/plain", "injected failure")
            return
        forward(h, body)

    proxy = fake_server(handle)
    s = SparqlStore(oxigraph_server.query_url, proxy.url, retry=QUICK, claim_attempts=2)
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    change = ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)],
                       expect=[(A, P, Literal(1), G_WORLD)])
    with pytest.raises(StoreError):
        s.apply(change)
    assert not fail_final[0]
    started = time.monotonic()
    s.apply(change)  # not blocked by its own dead claim
    assert time.monotonic() - started < 5
    assert s.objects(A, P) == [Literal(2)]
    s.close()


def test_a_claim_ttl_shorter_than_twice_the_longest_read_and_write_path_is_refused(sparql_store):
    from locem_bridge.pemkre.errors import InvalidParameterError

    with pytest.raises(InvalidParameterError, match="claim_ttl_s 30.0 s is too short"):
        sparql_store(timeout_s=10.0, claim_ttl_s=30.0)
    s = sparql_store()
    assert s.claim_ttl_s > 2 * s.claim_path_s


def test_dead_claims_are_deleted_by_the_next_claim_request_and_an_unreadable_clock_is_not_forever(sparql_store):
    from locem_bridge.pemkre.sparql_store import G_CLAIMS, P_CLAIM_AT, P_CLAIM_ON

    s = sparql_store(retry=QUICK, timeout_s=2.0)
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    dead = URIRef("urn:uuid:00000000-0000-0000-0000-000000000001")
    old = Literal("2000-01-01T00:00:00Z", datatype=URIRef("http://www.w3.org/2001/XMLSchema#dateTime"))
    s.apply(ChangeSet(add=[(dead, P_CLAIM_ON, URIRef("urn:pemkre-claim:x"), G_CLAIMS),
                           (dead, P_CLAIM_AT, old, G_CLAIMS)]))
    assert len(list(s.quads(dead, None, None, (G_CLAIMS,)))) == 2
    s.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)],
                      expect=[(A, P, Literal(1), G_WORLD)]))
    assert list(s.quads(dead, None, None, (G_CLAIMS,))) == []
    # a claim whose time cannot be read: counted by this client's clock, dead after the ttl
    clock = [100.0]
    s.clock = lambda: clock[0]  # the store's own clock, not the global time.monotonic
    s._select_doc = lambda *a, **k: {"head": {"vars": ["t", "at", "now"]}, "results": {"bindings": [
        {"t": {"type": "uri", "value": "urn:uuid:r"}, "at": {"type": "literal", "value": "garbage"},
         "now": {"type": "literal", "value": "garbage"}}]}}
    assert [c.token for c in s._live_claims(URIRef("urn:pemkre-claim:x"))] == ["urn:uuid:r"]
    clock[0] += s.claim_ttl_s + 1
    assert s._live_claims(URIRef("urn:pemkre-claim:x")) == []


def test_a_write_after_one_whose_fate_is_unknown_waits_until_it_shows_or_the_claim_ttl_has_passed(sparql_store,
                                                                                                   oxigraph_server):
    s = sparql_store(retry=QUICK, timeout_s=2.0)
    clock = [1000.0]
    s.clock = lambda: clock[0]
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    lost = "urn:uuid:00000000-0000-0000-0000-0000000000aa"
    s._note_unknown(lost, s.clock(), timed_out=False)  # as after a write whose answer was lost, server not asked
    oxigraph_server.kill()
    try:
        with pytest.raises(StoreUnavailable) as err:
            s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
        msg = _one_line(err.value)
        assert "earlier write's fate is unknown" in msg and s.update_endpoint.name in msg, msg
        assert s.unknown_writes == [lost]
    finally:
        oxigraph_server.start()
    # the server answers, but not having the token yet proves nothing: the write may still arrive
    clock[0] += 5
    with pytest.raises(StoreUnavailable) as err:
        s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
    msg = _one_line(err.value)
    assert err.value.applied is False and "sent 5.0 s ago" in msg and "may still apply it" in msg, msg
    assert s.was_applied(lost) is None and s.unknown_writes == [lost]
    clock[0] += s.claim_ttl_s  # the claim ttl has passed since it was sent: it will not be applied any more
    s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
    assert s.unknown_writes == [] and sorted(s.objects(A, P)) == [Literal(1), Literal(2)]


def test_a_write_that_arrives_after_its_token_was_first_missed_is_found_and_holds_back_later_writes(
        sparql_store, oxigraph_server, fake_server):
    mode = ["forward"]
    forwarded, release = threading.Event(), threading.Event()

    def slow(h, body):
        held = mode[0] == "slow"
        if held:
            release.wait(30)  # held until the test releases it: a write on its way for a long time
        try:
            _proxy(oxigraph_server.update_url, ["forward"])(h, body)
        except OSError:
            pass  # the client is gone
        finally:
            if held:
                forwarded.set()

    s = SparqlStore(oxigraph_server.query_url, fake_server(slow).url, timeout_s=0.3, retry=QUICK)
    s.query_endpoint = Endpoint(oxigraph_server.query_url, "query", 10.0, QUICK)
    clock = [1000.0]
    s.clock = lambda: clock[0]
    mode[0] = "slow"
    try:
        with pytest.raises(StoreUnavailable) as err:
            s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
        token = err.value.token
        assert err.value.applied is None and s.unknown_writes == [token]
        mode[0] = "forward"
        assert s.was_applied(token) is None and s.unknown_writes == [token]  # not there yet: still unknown
        with pytest.raises(StoreUnavailable, match="earlier write's fate is unknown"):
            s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))  # nothing builds on it while it may arrive
        assert s.objects(A, P) == []
    finally:
        release.set()
    assert forwarded.wait(10)  # the old write lands now
    assert s.was_applied(token) is True and s.unknown_writes == []
    s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
    assert sorted(s.objects(A, P)) == [Literal(1), Literal(2)]
    s.close()


def test_a_conditional_write_of_unknown_fate_keeps_its_claim_so_no_other_writer_builds_on_the_old_state(
        sparql_store, oxigraph_server, fake_server):
    from locem_bridge.pemkre.sparql_store import G_CLAIMS, P_CLAIM_ON

    hold = [False]
    forwarded, release = threading.Event(), threading.Event()

    def handle(h, body):
        text = urllib.parse.parse_qs(body.decode("utf-8")).get("update", [""])[0]
        held = hold[0] and "INSERT {" in text and "NOW()" not in text  # the final write, after the claim
        if held:
            release.wait(30)
        try:
            _proxy(oxigraph_server.update_url, ["forward"])(h, body)
        except OSError:
            pass
        finally:
            if held:
                forwarded.set()

    s = SparqlStore(oxigraph_server.query_url, fake_server(handle).url, timeout_s=0.3, retry=QUICK)
    s.query_endpoint = Endpoint(oxigraph_server.query_url, "query", 10.0, QUICK)
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    change = ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)],
                       expect=[(A, P, Literal(1), G_WORLD)])
    rival = ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(3), G_WORLD)],
                      expect=[(A, P, Literal(1), G_WORLD)])
    key = SparqlStore.claim_key(change.expect)
    other = sparql_store(retry=QUICK, claim_attempts=2)
    hold[0] = True
    try:
        with pytest.raises(StoreUnavailable) as err:
            s.apply(change)
        assert err.value.applied is None and err.value.token in s.unknown_writes, str(err.value)
        assert len(list(other.quads(None, P_CLAIM_ON, key, (G_CLAIMS,)))) == 1  # the claim was not withdrawn
        with pytest.raises(StoreUnavailable) as err2:
            other.apply(rival)  # would win on the old state (and be undone by the late write) without the claim
        msg = _one_line(err2.value)
        assert "claimed by another writer (%s, claimed " % s.client in msg and "nothing was written" in msg, msg
    finally:
        release.set()
    assert forwarded.wait(10)
    assert s.was_applied(err.value.token) is True
    assert other.objects(A, P) == [Literal(2)]
    assert list(other.quads(None, P_CLAIM_ON, key, (G_CLAIMS,))) == []  # the write deleted its claim
    with pytest.raises(StoreConflict):
        other.apply(rival)
    s.close()


def test_a_claim_left_by_a_dead_client_makes_the_store_unavailable_naming_its_age_not_a_conflict(sparql_store,
                                                                                                oxigraph_server):
    from locem_bridge.pemkre.sparql_store import G_CLAIMS, P_CLAIM_AT, P_CLAIM_ON, P_WRITE_CLAIM

    s = sparql_store(retry=QUICK, claim_attempts=3)
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    change = ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)],
                       expect=[(A, P, Literal(1), G_WORLD)])
    ghost = "<urn:uuid:00000000-0000-0000-0000-0000000000dd>"
    update = ("INSERT { GRAPH <%s> { %s <%s> \"ghost host pid 1\" ; <%s> <%s> ; <%s> ?now } } WHERE { BIND(NOW() AS "
              "?now) }" % (G_CLAIMS, ghost, P_WRITE_CLAIM, P_CLAIM_ON, SparqlStore.claim_key(change.expect),
                           P_CLAIM_AT))
    body = urllib.parse.urlencode({"update": update}).encode("ascii")
    urllib.request.urlopen(urllib.request.Request(oxigraph_server.update_url, data=body), timeout=10).close()
    with pytest.raises(StoreUnavailable) as err:
        s.apply(change)
    msg = _one_line(err.value)
    assert not isinstance(err.value, StoreConflict) and err.value.applied is False
    assert re.search(r"is claimed by another writer \(ghost host pid 1, claimed \d+ s ago\) through 3 attempts; "
                     r"nothing was written; .*claim_ttl_s", msg), msg
    assert s.objects(A, P) == [Literal(1)]


def test_a_conditional_write_answered_but_whose_token_cannot_be_read_back_is_unknown_not_unapplied(sparql_store):
    s = sparql_store(retry=QUICK)
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    real, asked = s._token_stored, []

    def failing_once(token):
        if not asked:
            asked.append(token)
            raise StoreUnavailable("SPARQL query endpoint x: connection refused", "x", "connection refused")
        return real(token)

    s._token_stored = failing_once
    with pytest.raises(StoreUnavailable) as err:
        s.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)],
                          expect=[(A, P, Literal(1), G_WORLD)]))
    msg = _one_line(err.value)
    assert err.value.applied is None and err.value.token == asked[0] and s.unknown_writes == asked, msg
    assert "reading its token back failed" in msg, msg
    assert s.was_applied(asked[0]) is True and s.unknown_writes == []
    assert s.objects(A, P) == [Literal(2)]
    # a write the server answered whose token is not there did not apply (its condition failed): settled at once
    s._note_unknown("urn:uuid:00000000-0000-0000-0000-0000000000ee", s.clock(), timed_out=False, answered=True)
    assert s.was_applied("urn:uuid:00000000-0000-0000-0000-0000000000ee") is False and s.unknown_writes == []


def test_reads_without_a_graph_never_see_another_systems_graphs(sparql_store, oxigraph_server):
    s = sparql_store()
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))
    foreign = URIRef(EX + "mes/orders")
    body = urllib.parse.urlencode({"update": "INSERT DATA { GRAPH <%s> { <%s> <%s> 9 . <%s> <%s> <%s> } }" % (
        foreign, A, P, A, URIRef("http://www.w3.org/1999/02/22-rdf-syntax-ns#type"), URIRef(EX + "Order"))})
    urllib.request.urlopen(urllib.request.Request(oxigraph_server.update_url, data=body.encode("ascii")),
                           timeout=10).close()
    assert s.objects(A, P) == [Literal(1)]
    assert all(q[3] != foreign for q in s.quads())
    assert s.count() == 1
    assert foreign not in [g.identifier for g in s.snapshot().graphs()]
    assert s.objects(A, P, (foreign,)) == [Literal(9)]  # named, it is read


@pytest.mark.parametrize("status", [502, 504])
def test_a_gateway_error_on_a_write_is_a_lost_answer_settled_by_the_token(sparql_store, oxigraph_server,
                                                                           fake_server, status):
    mode = ["forward"]

    def handle(h, body):
        if mode[0] == "forward":
            _proxy(oxigraph_server.update_url, ["forward"])(h, body)
        elif mode[0] == "applied":
            req = urllib.request.Request(oxigraph_server.update_url, data=body,
                                         headers={"Content-Type": "application/x-www-form-urlencoded"})
            urllib.request.urlopen(req, timeout=10).close()
            _reply(h, status, "text/plain", "gateway")
        else:
            _reply(h, status, "text/plain", "gateway")

    proxy = fake_server(handle)
    s = SparqlStore(oxigraph_server.query_url, proxy.url, retry=QUICK)
    mode[0] = "applied"
    s.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD)]))  # written; the gateway's error hid the answer
    assert s.objects(A, P) == [Literal(1)]
    mode[0] = "not applied"
    with pytest.raises(StoreUnavailable) as err:
        s.apply(ChangeSet(add=[(A, P, Literal(2), G_WORLD)]))
    assert err.value.applied is None and err.value.token in s.unknown_writes, str(err.value)
    # not there: but a gateway's error may come while the write is still on its way, so it stays unknown
    assert s.was_applied(err.value.token) is None and err.value.token in s.unknown_writes
    s.clock = lambda: time.monotonic() + s.claim_ttl_s  # until the claim ttl has passed since it was sent
    assert s.was_applied(err.value.token) is False and s.unknown_writes == []
    s.close()


def test_only_pemkre_graphs_found_on_the_server_join_the_default_graph(sparql_store, oxigraph_server):
    from locem_bridge.pemkre.vocab import GRAPHS

    writer = sparql_store()
    foreign, ours = URIRef(EX + "other-system"), URIRef(str(GRAPHS) + "extra")
    writer.replace_graph(foreign, [(A, P, Literal(1))])
    writer.replace_graph(ours, [(A, P, Literal(2))])
    reader = sparql_store()  # finds both graphs on the server
    q = reader.prepare("SELECT ?x WHERE { ex:a ex:p ?x }", "p", {"ex": EX})
    assert reader.select(q) == [{"x": Literal(2)}]
    assert foreign not in reader.refresh_graphs() and ours in reader.refresh_graphs()


def test_within_one_decision_each_subject_costs_one_round_trip_and_writes_and_other_clients_are_seen(sparql_store):
    """``reading()`` (the engine wraps each decision in it): look-ups by subject are answered from one fetch of the
    subject's quads; this client's own write is seen at once (the written subjects are fetched again), another
    client's write at the next decision; outside a decision every look-up asks the server."""
    store, other = sparql_store(), sparql_store()
    b, q = URIRef(EX + "b"), URIRef(EX + "q")
    store.apply(ChangeSet(add=[(A, P, Literal(1), G_WORLD), (A, q, b, G_WORLD), (b, P, Literal(5), G_WORLD)]))
    posts = []
    send = store.query_endpoint.post

    def counted(*args, **kwargs):
        posts.append(args[0])
        return send(*args, **kwargs)
    store.query_endpoint.post = counted
    with store.reading():
        store.prefetch([A, b])
        assert len(posts) == 1                                   # both subjects in one request
        assert store.value(A, P) == Literal(1) and store.value(A, q) == b and store.value(b, P) == Literal(5)
        assert store.objects(A, P, (G_WORLD,)) == [Literal(1)] and store.value(A, P, (G_LOG,)) is None
        assert len(posts) == 1
        other.apply(ChangeSet(remove=[(b, P, Literal(5), G_WORLD)], add=[(b, P, Literal(6), G_WORLD)]))
        store.apply(ChangeSet(remove=[(A, P, Literal(1), G_WORLD)], add=[(A, P, Literal(2), G_WORLD)]))
        assert store.value(A, P) == Literal(2)                   # its own write: A fetched again
        assert store.value(b, P) == Literal(5)                   # another client's: within this decision, not yet
        fetched = len(posts)
        with store.reading():                                    # nested: the same decision
            assert store.value(A, q) == b and len(posts) == fetched
    assert store.value(b, P) == Literal(6)                       # the next decision sees it
    assert store.value(b, P) == Literal(6) and len(posts) == fetched + 2   # outside a decision: a request each


# ------------------------------------------------------------------------------------------------ staged changes
def _staging_graphs(server):
    """The staging graphs and staging records on the server (asked directly, outside any PEMKRE client)."""
    text = ('SELECT DISTINCT ?g WHERE { { GRAPH ?g { ?s ?p ?o } FILTER(STRSTARTS(STR(?g), "urn:pemkre:staging:")) }'
            ' UNION { GRAPH <urn:pemkre:staging> { ?g ?p ?o } } }')
    req = urllib.request.Request(server.query_url, data=urllib.parse.urlencode({"query": text}).encode("ascii"),
                                 headers={"Accept": "application/sparql-results+json"})
    with urllib.request.urlopen(req, timeout=10) as answer:
        import json
        return sorted(b["g"]["value"] for b in json.load(answer)["results"]["bindings"])


_RECORD = r"urn:pemkre:staging:[0-9a-f-]{36}"


def _big_change(n, old, tag="line"):
    """``n`` additions over two graphs and the removal of the quads ``old``."""
    from locem_bridge.pemkre.store import G_ABOX_INFERRED
    add = [(URIRef(EX + "joint_%d" % i), P, Literal("%s %d of a long scan" % (tag, i)),
            G_WORLD if i % 3 else G_ABOX_INFERRED) for i in range(n)]
    return ChangeSet(remove=list(old), add=add)


def _counting(store, on_update=None):
    """Wrap ``store``'s update endpoint: returns the list of update texts sent (``on_update(n)`` before the n-th)."""
    sent = []
    send = store.update_endpoint.post

    def post(params, *args, **kwargs):
        sent.append(params[0][1])
        if on_update is not None:
            on_update(len(sent))
        return send(params, *args, **kwargs)
    store.update_endpoint.post = post
    return sent


@pytest.mark.parametrize("mirror", [False, True], ids=["plain", "copy"])
def test_a_change_longer_than_one_request_is_staged_and_shows_all_at_once(mirror, sparql_store, oxigraph_server):
    """A change over ``max_update_bytes`` (by default 16 MiB of text, a world scan of about 4,500 features;
    ``oxigraph serve`` refuses bodies over 128 MiB) is written in parts into staging graphs no PEMKRE query sees,
    then applied by one request: a reader never sees part of it, through look-ups or queries; a quad both removed
    and added stays; afterwards no staging graph or record is left."""
    with pytest.raises(Exception) as err:
        sparql_store(max_update_bytes=10)
    assert "max_update_bytes 10 is too small" in _one_line(err.value) and "1000 or more" in str(err.value)
    store, reader = sparql_store(mirror=mirror, max_update_bytes=2000), sparql_store()
    old = [(URIRef(EX + "old_%d" % i), P, Literal(i), G_WORLD) for i in range(40)]
    both = (A, P, Literal("removed and added again"), G_WORLD)
    store.apply(ChangeSet(add=old + [(A, P, Literal("kept"), G_WORLD), both]))
    change = _big_change(300, old + [both])
    change.add.append(both)
    counting = reader.prepare("SELECT (COUNT(*) AS ?n) WHERE { ?s ?p ?o }", "count", {})
    seen = []

    def look(n):
        reader.refresh_graphs()
        seen.append((reader.count(G_WORLD), len(reader.objects(URIRef(EX + "joint_1"), P)),
                     int(reader.select(counting)[0]["n"])))
    sent = _counting(store, look)
    with store.reading():
        store.apply(change)
    # 341 quads of about 100 bytes in parts of at most 2,000 bytes: the record, 20+ parts, the final request
    assert len(sent) >= 20 and sent[0].startswith("INSERT { GRAPH <urn:pemkre:staging>"), len(sent)
    assert all(len(t.encode("utf-8")) <= 2000 + 600 for t in sent[1:-1]), max(len(t) for t in sent)
    assert set(seen) == {(42, 0, 42)}, "a reader saw part of the change: %r" % sorted(set(seen))
    expected = {(A, P, Literal("kept"), G_WORLD), both} | set(change.add)
    assert set(reader.quads()) == expected
    assert _staging_graphs(oxigraph_server) == []
    if mirror:
        reloads = store.reloads
        with store.reading():
            assert set(store.quads()) == expected  # the copy followed the change without loading itself again
        assert store.reloads == reloads
    other = sparql_store(mirror=True)  # another client's copy sees it from its next decision on
    with other.reading():
        assert other.count() == len(expected)


def test_a_staged_change_cut_off_by_a_dead_server_changes_nothing_and_its_parts_are_dropped_once_expired(
        sparql_store, oxigraph_server):
    """The server dies while a change is being staged: NOT_READY with ``applied=False``, PEMKRE's graphs as before
    after the restart; the parts it left are dropped by the next staged change once the record has expired (the
    server's clock, this client's claim ttl after its last part)."""
    quick = dict(timeout_s=1.0, retry=RetryPolicy(attempts=1), claim_ttl_s=4.5, max_update_bytes=2000)
    store = sparql_store(**quick)
    old = [(URIRef(EX + "old_%d" % i), P, Literal(i), G_WORLD) for i in range(40)]
    store.apply(ChangeSet(add=old))
    _counting(store, lambda n: oxigraph_server.kill() if n == 6 else None)
    with pytest.raises(StoreUnavailable) as err:
        store.apply(_big_change(300, old))
    assert err.value.applied is False, str(err.value)
    assert "nothing of it was applied (it was being staged: 4 parts stored)" in _one_line(err.value)
    assert store.update_endpoint.name in str(err.value)
    oxigraph_server.start()
    reader = sparql_store()
    assert set(reader.quads()) == set(old)
    left = _staging_graphs(oxigraph_server)
    assert any(re.fullmatch(_RECORD, g) for g in left), left
    assert any(re.fullmatch(_RECORD + r":add:\d+", g) for g in left), left
    other = sparql_store(**quick)
    other.apply(_big_change(100, [], "fresh"))  # the record has not expired yet: a live client may be staging
    assert _staging_graphs(oxigraph_server) == left
    time.sleep(5.5)  # expired now (4 s after its last part)
    other.apply(_big_change(100, [], "later"))
    assert _staging_graphs(oxigraph_server) == []
    assert reader.count(G_WORLD) == 40 + 2 * len([i for i in range(100) if i % 3])  # the two later changes


def test_a_staged_change_whose_part_fails_drops_its_parts_at_once_and_keeps_its_record_until_it_expires(
        sparql_store, oxigraph_server):
    """A part that fails while the server still answers (here: its connection lost): the parts are dropped at
    once, PEMKRE's graphs are as before; the record stays (a part whose answer was lost may still land) until it
    expires. A sweep that cannot be done does not hold a change back."""
    store = sparql_store(max_update_bytes=2000)
    store.apply(ChangeSet(add=[(A, P, Literal("kept"), G_WORLD)]))

    def lose(n):
        if n == 5:
            raise StoreUnavailable("SPARQL update endpoint %s: connection lost" % oxigraph_server.update_url,
                                   store.update_endpoint.name, "connection lost", applied=None)
    sent = _counting(store, lose)
    with pytest.raises(StoreUnavailable) as err:
        store.apply(_big_change(200, []))
    assert err.value.applied is False and "nothing of it was applied (it was being staged: 3 parts stored)" in \
        _one_line(err.value)
    assert sent[-1].startswith("DROP SILENT GRAPH <urn:pemkre:staging:"), sent[-1][:80]
    left = _staging_graphs(oxigraph_server)
    assert len(left) == 1 and re.fullmatch(_RECORD, left[0]), left  # the record only
    assert set(sparql_store().quads()) == {(A, P, Literal("kept"), G_WORLD)}
    other = sparql_store(max_update_bytes=2000)
    ask = other.query_endpoint.post

    def no_sweep(params, *args, **kwargs):
        if "urn:pemkre:staging" in params[0][1] and params[0][1].startswith("SELECT"):
            raise StoreError("%s: HTTP 500: sweep refused" % other.query_endpoint.name)
        return ask(params, *args, **kwargs)
    other.query_endpoint.post = no_sweep
    other.apply(_big_change(30, [], "other"))  # the sweep failed: logged, the change is applied all the same
    assert len(list(sparql_store().quads())) == 31
    assert _staging_graphs(oxigraph_server) == left  # the record is young: its client may still be staging


def test_a_live_stage_is_not_swept_and_a_stage_found_dead_is_not_applied_in_part(sparql_store, oxigraph_server):
    """Two clients staging at once: a client with a short claim ttl does not sweep the stage of one with a long
    ttl (each record says how long it lives, renewed by every part). A client that stalls between two parts longer
    than its own ttl finds its stage dropped by another client: its change is NOT_READY ``applied=False`` and none
    of it is on the server, never a part."""
    short = dict(timeout_s=1.0, retry=RetryPolicy(attempts=1), claim_ttl_s=4.5, max_update_bytes=2000)
    slow = sparql_store(max_update_bytes=2000)  # the default ttl: about 196 s
    sweeper = sparql_store(**short)

    def meanwhile(n):
        if n == 4:
            time.sleep(5.5)  # longer than the sweeper's ttl, far shorter than slow's
            sweeper.apply(_big_change(60, [], "sweeper"))
    _counting(slow, meanwhile)
    slow.apply(_big_change(300, [], "slow"))
    reader = sparql_store()
    literals = [str(q[2]) for q in reader.quads()]
    assert len([x for x in literals if x.startswith("slow ")]) == 300  # all of slow's change
    assert len([x for x in literals if x.startswith("sweeper ")]) == 60
    assert _staging_graphs(oxigraph_server) == []

    stalled = sparql_store(**short)

    def stall(n):
        if n == 4:
            time.sleep(5.5)  # stalled past its own ttl: its record expires
            sweeper.apply(_big_change(60, [], "sweeper again"))
    sent = _counting(stalled, stall)
    before = set(reader.quads())
    with pytest.raises(StoreUnavailable) as err:
        stalled.apply(_big_change(300, [], "stalled"))
    assert err.value.applied is False and "staged parts were dropped as unfinished" in _one_line(err.value)
    assert len(sent) > 15  # it went on staging, then its final request found the record gone
    after = set(reader.quads())
    assert not any("stalled" in str(q[2]) for q in after), "part of the dead stage was applied"
    assert after - before == {q for q in _big_change(60, [], "sweeper again").add}
    assert _staging_graphs(oxigraph_server) == []


def test_a_staged_change_whose_final_request_is_refused_drops_its_parts_and_the_copy_stays(sparql_store,
                                                                                           oxigraph_server):
    """The server refuses the final request (an HTTP error: nothing written): the change is refused in one line,
    its staged parts and record are dropped at once, and the copy of a MirroredSparqlStore stays as it was without
    loading itself again."""
    from locem_bridge.pemkre.sparql_http import HttpStatusError

    store = sparql_store(mirror=True, max_update_bytes=2000)
    store.apply(ChangeSet(add=[(A, P, Literal("kept"), G_WORLD)]))
    with store.reading():
        assert store.objects(A, P) == [Literal("kept")]  # the copy is loaded
    reloads = store.reloads

    def refuse(n):
        text = sent[-1]
        if text.count("DROP SILENT GRAPH") and "INSERT { GRAPH" in text and "WHERE { GRAPH <urn:pemkre:staging>" in \
                text and not text.startswith("DROP"):
            raise HttpStatusError("%s: HTTP 400: refused by the test" % store.update_endpoint.name, 400)
    sent = _counting(store, refuse)
    with pytest.raises(StoreError) as err:
        store.apply(_big_change(200, []))
    assert "(applying its" in _one_line(err.value) and "was refused (nothing was written)" in str(err.value)
    assert sent[-1].startswith("DROP SILENT GRAPH <urn:pemkre:staging:") and "DELETE WHERE" in sent[-1]
    assert _staging_graphs(oxigraph_server) == []
    assert set(sparql_store().quads()) == {(A, P, Literal("kept"), G_WORLD)}
    with store.reading():
        assert set(store.quads()) == {(A, P, Literal("kept"), G_WORLD)}
    assert store.reloads == reloads
