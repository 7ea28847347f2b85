"""The HMI server's JSON API over real loopback sockets, against the scripted HICEM test double.

What a user cares about: the operator can start a process, see it, answer prompts and stop; pictures and KPIs
are served; every bad request gets a clear 4xx naming what was wrong and what is allowed; and the server keeps
serving afterwards.
"""
import json
import logging
import os
import socket
import struct
import threading
import time

import pytest

from hicem_double import PROCESSES, TAPING, ScriptedHicemDouble
from hmi_client import get, post, request, serving, state, wait_state
from locem_bridge.hmi import BackendRefused, BackendUnavailable, HmiServer, ServerStartError
from locem_bridge.hmi.server import STATIC_DIR

PNG = b"\x89PNG\r\n\x1a\n"


def test_page_and_static_files_are_local(server):
    page = get(server.url, "/")
    assert page.status == 200 and page.headers["content-type"].startswith("text/html")
    html = page.body.decode("utf-8")
    assert "STOP" in html and server.title in html and "{{TITLE}}" not in html
    for ref in ("/static/app.js", "/static/style.css"):
        assert ref in html
        r = get(server.url, ref)
        assert r.status == 200 and len(r.body) > 500
    for name in os.listdir(STATIC_DIR):       # no CDN, no remote font: nothing leaves the machine
        text = open(os.path.join(STATIC_DIR, name), encoding="utf-8").read()
        for remote in ('src="http', "src='http", 'href="http', "href='http", "url(http", "//cdn", "@import"):
            assert remote not in text, "%s refers to a remote resource (%s)" % (name, remote)
    missing = get(server.url, "/static/../server.py")
    assert missing.status == 404
    assert get(server.url, "/static/nothing.js").error["code"] == "not_found"


def test_a_run_through_the_api(server, double):
    doc = state(server.url)
    assert [p["iri"] for p in doc["processes"]] == [p["iri"] for p in PROCESSES]
    assert doc["snapshot"]["phase"] == "idle" and doc["prompts"] == [] and doc["kpis"] == {}
    v0 = doc["version"]

    r = post(server.url, "/api/processes/start", {"iri": TAPING})
    assert r.status == 200 and r.json["started"] == TAPING
    assert r.json["result"] == {"specific_process": "urn:test:run-1"}
    assert ("start_process", TAPING) in double.calls
    doc = wait_state(server.url, lambda d: d["prompts"])
    assert doc["version"] > v0
    snap = doc["snapshot"]
    assert (snap["process"], snap["phase"], snap["tree"], snap["node"]) == (TAPING, "running", "GET_TOOL", "ask_mount")
    assert snap["health"]["status"] == "ok" and snap["progress"]["total"] == 3
    (mount,) = doc["prompts"]
    assert mount["kind"] == "mount_tool" and mount["choices"] == ["done"]
    assert any("started Taping" in e["text"] for e in doc["events"])

    assert post(server.url, "/api/prompts/%s/reply" % mount["id"], {"answer": "done"}).status == 200
    doc = wait_state(server.url, lambda d: d["prompts"] and d["prompts"][0]["kind"] == "validate_line")
    line = doc["prompts"][0]
    assert line["context"]["line"] == "wall_1_joint_1" and line["choices"] == ["valid", "invalid"]
    assert post(server.url, "/api/prompts/%s/reply" % line["id"], {"answer": "invalid"}).status == 200
    assert ("reply", line["id"], "invalid") in double.calls
    assert double.joint_state["wall_1_joint_1"] == "manual"

    # answering the same prompt again: it is no longer open -> 409 naming the open prompt
    again = post(server.url, "/api/prompts/%s/reply" % line["id"], {"answer": "valid"})
    assert again.status == 409 and again.error["code"] == "prompt_not_open"
    open_now = double.desk.open_prompts()[0].id
    assert line["id"] in again.error["message"] and open_now in again.error["message"]
    assert double.joint_state["wall_1_joint_1"] == "manual"          # the late answer changed nothing

    assert post(server.url, "/api/stop", {}).status == 200
    assert double.calls[-1] == ("stop",)
    doc = wait_state(server.url, lambda d: d["snapshot"]["phase"] == "stopped" and d["kpis"])
    assert doc["prompts"] == []
    (proc,) = doc["kpis"]["processes"]
    assert proc["operatorInterventions"] == 2 and proc["manualFallbacks"] == 1 and proc["status"] == "stopped"
    assert {row["actionType"] for row in doc["kpis"]["task_types"]} == {"GET_TOOL", "VALIDATE_TAPE_LINE",
                                                                       "MANUAL_TAPING"}
    assert get(server.url, "/api/kpis").json["kpis"] == doc["kpis"]


def test_stop_needs_no_body_and_is_always_accepted(server, double):
    assert request(server.url, "POST", "/api/stop").status == 200          # no body at all
    assert request(server.url, "POST", "/api/stop", raw=b"", headers={"Content-Type": "application/json"}).status == 200
    assert double.calls == [("stop",), ("stop",)]


def test_wall_pictures_are_pngs_that_change_with_the_work(server, double):
    walls = {w["id"]: w for w in state(server.url)["walls"]}
    assert sorted(walls) == ["wall_1", "wall_2"]
    first = get(server.url, walls["wall_1"]["url"])
    assert first.status == 200 and first.headers["content-type"] == "image/png" and first.body.startswith(PNG)
    post(server.url, "/api/processes/start", {"iri": TAPING})
    post(server.url, "/api/prompts/%s/reply" % double.prompts()[0]["id"], {"answer": "done"})
    post(server.url, "/api/prompts/%s/reply" % double.prompts()[0]["id"], {"answer": "valid"})
    doc = wait_state(server.url, lambda d: {w["id"]: w for w in d["walls"]}["wall_1"]["version"] !=
                     walls["wall_1"]["version"])
    now = {w["id"]: w for w in doc["walls"]}
    assert now["wall_2"]["version"] == walls["wall_2"]["version"]            # untouched wall: same token
    second = get(server.url, now["wall_1"]["url"])
    assert second.body.startswith(PNG) and second.body != first.body

    unknown = get(server.url, "/api/walls/wall_9.png")
    assert unknown.status == 404 and unknown.error["code"] == "unknown_wall"
    assert "wall_1" in unknown.error["message"] and "wall_2" in unknown.error["message"]
    assert serving(server.url)


class PathPictures(ScriptedHicemDouble):
    """The double, but with pictures given as file paths (as the worksite writes them)."""

    def __init__(self, folder):
        super().__init__()
        self.folder = folder

    def wall_pictures(self):
        return {"wall_1": os.path.join(self.folder, "wall_1.png"), "wall_2": os.path.join(self.folder, "wall_2.png")}


def test_pictures_given_as_paths(tmp_path):
    backend = PathPictures(str(tmp_path))
    with HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, picture_period_s=0.05,
                   shutdown_poll_s=0.05) as srv:
        walls = {w["id"]: w for w in state(srv.url)["walls"]}
        assert walls["wall_1"]["url"] == ""                                   # not written yet
        r = get(srv.url, "/api/walls/wall_1.png")
        assert r.status == 404 and r.error["code"] == "picture_not_ready"
        png = ScriptedHicemDouble().wall_pictures()["wall_1"]
        (tmp_path / "wall_1.png").write_bytes(png)
        (tmp_path / "wall_2.png").write_bytes(b"GIF89a not a png")
        doc = wait_state(srv.url, lambda d: {w["id"]: w for w in d["walls"]}["wall_1"]["url"])
        url = {w["id"]: w for w in doc["walls"]}["wall_1"]["url"]
        assert get(srv.url, url).body == png
        bad = get(srv.url, "/api/walls/wall_2.png")
        assert bad.status == 502 and bad.error["code"] == "bad_picture" and "wall_2" in bad.error["message"]
        (tmp_path / "wall_2.png").write_bytes(png[:len(png) // 2])           # caught while being written
        half = get(srv.url, "/api/walls/wall_2.png")
        assert half.status == 404 and half.error["code"] == "picture_not_ready"
        assert "incomplete" in half.error["message"]
        assert serving(srv.url)


@pytest.mark.parametrize("path, body, raw, headers, status, code, words", [
    ("/api/processes/start", None, b"{not json", {"Content-Type": "application/json"}, 400, "malformed_json",
     ["not valid JSON"]),
    ("/api/processes/start", ["iri"], None, None, 400, "bad_body", ["JSON object", "list"]),
    ("/api/processes/start", {}, None, None, 400, "missing_field", ["'iri'"]),
    ("/api/processes/start", {"iri": 7}, None, None, 400, "missing_field", ["'iri'", "7"]),
    ("/api/processes/start", {"iri": TAPING, "speed": 2}, None, None, 400, "unknown_field", ["speed", "iri"]),
    ("/api/processes/start", None, b'{"iri": "x"}', {"Content-Type": "text/plain"}, 415,
     "unsupported_media_type", ["application/json", "text/plain"]),
    ("/api/processes/start", None, b"x" * (65 * 1024), {"Content-Type": "application/json"}, 413,
     "body_too_large", ["65536"]),
    ("/api/processes/start", None, b"", {"Content-Type": "application/json"}, 400, "missing_body", ["iri"]),
    ("/api/processes/start", {"iri": "urn:nope"}, None, None, 404, "unknown_process", ["urn:nope", TAPING]),
    ("/api/prompts/abc123/reply", {"answer": "valid"}, None, None, 409, "prompt_not_open", ["abc123", "none"]),
    ("/api/prompts/abc123/reply", {"answer": ""}, None, None, 400, "missing_field", ["'answer'"]),
    ("/api/prompts/abc123/reply", None, b"\xff\xfe", {"Content-Type": "application/json"}, 400, "malformed_json",
     ["not valid JSON"]),
])
def test_bad_posts_get_clear_errors(server, double, path, body, raw, headers, status, code, words):
    r = request(server.url, "POST", path, body=body, raw=raw, headers=headers)
    assert r.status == status, r
    err = r.error
    assert err["status"] == status and err["code"] == code
    for w in words:
        assert w in err["message"], (w, err["message"])
    assert not [c for c in double.calls if c[0] != "stop"]                  # nothing reached the backend
    assert serving(server.url)


def test_a_post_without_content_length(server, double):
    with socket.create_connection(("127.0.0.1", server.port), timeout=5) as sock:
        sock.sendall(b"POST /api/processes/start HTTP/1.0\r\nHost: 127.0.0.1\r\n"
                     b"Content-Type: application/json\r\n\r\n")
        answer = sock.makefile("rb").read()
    assert answer.startswith(b"HTTP/1.0 411 ") and b"Content-Length" in answer
    assert double.calls == [] and serving(server.url)


def test_unknown_endpoints_and_methods(server):
    r = get(server.url, "/api/nothing")
    assert r.status == 404 and r.error["code"] == "not_found"
    assert "GET /api/state" in r.error["message"] and "POST /api/stop" in r.error["message"]
    r = get(server.url, "/api/stop")
    assert r.status == 405 and r.headers["allow"] == "POST" and "allowed: POST" in r.error["message"]
    r = post(server.url, "/api/state", {})
    assert r.status == 405 and r.headers["allow"] == "GET"
    r = request(server.url, "DELETE", "/api/state")
    assert r.status == 405 and r.error["code"] == "method_not_allowed" and "DELETE" in r.error["message"]
    r = request(server.url, "BREW", "/api/state")
    assert r.status == 501 and "BREW" in r.json["error"]["message"]
    assert get(server.url, "/api").json["endpoints"][0] == {"method": "GET", "path": "/", "what": "the operator page"}
    head = request(server.url, "HEAD", "/api/events")
    assert head.status == 200 and head.body == b"" and head.headers["content-type"].startswith("text/event-stream")
    assert serving(server.url)


def test_answer_not_among_choices(server, double):
    post(server.url, "/api/processes/start", {"iri": TAPING})
    pid = double.prompts()[0]["id"]
    r = post(server.url, "/api/prompts/%s/reply" % pid, {"answer": "yes"})
    assert r.status == 400 and r.error["code"] == "answer_not_allowed"
    assert "'yes'" in r.error["message"] and "allowed: done" in r.error["message"]
    assert double.desk.get(pid).state == "open"


def test_backend_refusals_become_409_with_the_backends_reason(server, double):
    assert post(server.url, "/api/processes/start", {"iri": TAPING}).status == 200
    r = post(server.url, "/api/processes/start", {"iri": TAPING})
    assert r.status == 409 and r.error["code"] == "refused" and "still running" in r.error["message"]
    doc = wait_state(server.url, lambda d: any(e["level"] == "error" for e in d["events"]))
    assert "still running" in doc["events"][-1]["text"]


def test_cross_site_posts_are_refused(server, double):
    r = post(server.url, "/api/stop", {}, headers={"Origin": "http://evil.example"})
    assert r.status == 403 and r.error["code"] == "forbidden_origin" and "evil.example" in r.error["message"]
    assert double.calls == []
    same = "http://127.0.0.1:%d" % server.port
    assert post(server.url, "/api/stop", {}, headers={"Origin": same}).status == 200
    assert double.calls == [("stop",)]


def test_dns_rebinding_host_is_refused(server):
    r = get(server.url, "/api/state", headers={"Host": "evil.example:%d" % server.port})
    assert r.status == 403 and r.error["code"] == "forbidden_host" and "evil.example" in r.error["message"]
    assert get(server.url, "/api/state", headers={"Host": "localhost:%d" % server.port}).status == 200
    assert get(server.url, "/api/state", headers={"Host": "[::1]:%d" % server.port}).status == 200


def test_a_distinct_loopback_address_is_served(double):
    try:
        srv = HmiServer(double, "127.0.0.37", 0, shutdown_poll_s=0.05).start()
    except OSError as err:   # pragma: no cover - a host without the whole 127/8 on lo
        pytest.skip("cannot bind 127.0.0.37: %s" % err)
    try:
        assert srv.url.startswith("http://127.0.0.37:") and serving(srv.url)
    finally:
        srv.close()


def test_silent_clients_are_dropped(double):
    with HmiServer(double, "127.0.0.1", 0, request_timeout_s=0.3, shutdown_poll_s=0.05) as srv:
        idle = [socket.create_connection(("127.0.0.1", srv.port), timeout=5) for _ in range(5)]
        half = socket.create_connection(("127.0.0.1", srv.port), timeout=5)
        half.sendall(b"GET /api/state HTTP/1.1\r\nHost: 127.0.0.1\r\n")        # never finishes its headers
        t0 = time.monotonic()
        for sock in idle + [half]:
            assert sock.recv(1024) == b""                  # closed by the server, no answer
            sock.close()
        assert time.monotonic() - t0 < 4.0
        assert serving(srv.url)


def test_a_port_in_use_is_a_clear_error(server, double):
    with pytest.raises(ServerStartError) as info:
        HmiServer(double, "127.0.0.1", server.port).start()
    assert str(server.port) in str(info.value) and "another port" in str(info.value)
    assert serving(server.url)


def test_ipv6_loopback(double):
    try:
        srv = HmiServer(double, "::1", 0, shutdown_poll_s=0.05).start()
    except ServerStartError as err:   # pragma: no cover - a host without IPv6 loopback
        pytest.skip(str(err))
    try:
        assert srv.url.startswith("http://[::1]:")
        conn_reply = get(srv.url, "/api/state")
        assert conn_reply.status == 200 and conn_reply.json["snapshot"]["phase"] == "idle"
    finally:
        srv.close()


def _read_events(sock_file, count, timeout):
    """Read ``count`` SSE 'state' events (bounded by the socket timeout); returns their decoded data."""
    events, data = [], []
    end = time.monotonic() + timeout
    while len(events) < count and time.monotonic() < end:
        line = sock_file.readline().decode("utf-8")
        if not line:
            break
        line = line.rstrip("\n")
        if line.startswith("data: "):
            data.append(line[6:])
        elif line == "" and data:
            events.append(json.loads("\n".join(data)))
            data = []
    return events


def test_server_sent_events_push_changes(server, double):
    sock = socket.create_connection(("127.0.0.1", server.port), timeout=5)
    try:
        sock.sendall(b"GET /api/events HTTP/1.1\r\nHost: 127.0.0.1\r\nAccept: text/event-stream\r\n\r\n")
        f = sock.makefile("rb")
        status = f.readline()
        assert b" 200 " in status
        headers = []
        while True:
            line = f.readline()
            if line in (b"\r\n", b"\n", b""):
                break
            headers.append(line.lower())
        assert any(h.startswith(b"content-type: text/event-stream") for h in headers)
        (first,) = _read_events(f, 1, 5)
        assert first["snapshot"]["phase"] == "idle"
        post(server.url, "/api/processes/start", {"iri": TAPING})
        pushed = []
        while not pushed or not pushed[-1]["prompts"]:
            more = _read_events(f, 1, 5)
            assert more, "no event pushed after the start"
            pushed += more
        assert pushed[-1]["version"] > first["version"]
        assert pushed[-1]["snapshot"]["phase"] == "running" and pushed[-1]["prompts"][0]["kind"] == "mount_tool"
    finally:
        sock.close()


def _open_stream(port):
    sock = socket.create_connection(("127.0.0.1", port), timeout=5)
    sock.sendall(b"GET /api/events HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
    return sock, sock.makefile("rb").readline()


def test_event_streams_are_limited_and_slots_come_back(double):
    with HmiServer(double, "127.0.0.1", 0, max_streams=2, heartbeat_s=0.1, shutdown_poll_s=0.05) as srv:
        streams = []
        for _ in range(2):
            sock, status = _open_stream(srv.port)
            assert b" 200 " in status
            streams.append(sock)
        third = get(srv.url, "/api/events")
        assert third.status == 503 and third.error["code"] == "too_many_streams" and "2" in third.error["message"]
        streams.pop().close()                    # the tab is closed: the next heartbeat write frees the slot
        end = time.monotonic() + 5
        status = b""
        while time.monotonic() < end:
            sock, status = _open_stream(srv.port)
            if b" 200 " in status:
                streams.append(sock)
                break
            sock.close()
            time.sleep(0.05)
        assert b" 200 " in status
        for sock in streams:
            sock.close()
        assert serving(srv.url)


def test_nothing_is_pushed_while_nothing_changes(server, double):
    v = state(server.url)["version"]
    time.sleep(0.4)                                  # 8 poll periods
    assert state(server.url)["version"] == v
    renders = double.render_count
    time.sleep(0.3)                                  # pictures polled 3 more times: not re-rendered, same token
    assert double.render_count == renders


class FlakyBackend(ScriptedHicemDouble):
    """The double with a broken snapshot() and an unreachable stop()."""

    def snapshot(self):
        raise RuntimeError("state topic lost")

    def stop(self):
        raise BackendUnavailable("/hicem/stop did not answer within 2 s")

    def kpis(self):
        raise BackendUnavailable("/pemkre/query is down")


def test_backend_failures_are_shown_and_the_server_keeps_serving():
    with HmiServer(FlakyBackend(), "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05) as srv:
        doc = state(srv.url)
        assert "snapshot(): RuntimeError: state topic lost" in doc["backend_error"]
        assert "kpis(): /pemkre/query is down" in doc["backend_error"]
        assert doc["snapshot"]["health"]["status"] == "unknown"
        r = post(srv.url, "/api/stop", {})
        assert r.status == 503 and r.error["code"] == "backend_unavailable" and "/hicem/stop" in r.error["message"]
        assert post(srv.url, "/api/processes/start", {"iri": TAPING}).status == 200
        assert serving(srv.url)


class StuckKpis(ScriptedHicemDouble):
    """The double whose kpis() hangs (a PEMKRE query that does not answer) until the test releases it."""

    def __init__(self):
        super().__init__()
        self.release = threading.Event()
        self.stuck = threading.Event()

    def kpis(self):
        if self.calls:                       # the first poll (at start) passes; later ones hang
            self.stuck.set()
            self.release.wait(20)
        return {}


def test_stop_does_not_wait_for_a_stuck_backend_poll():
    backend = StuckKpis()
    with HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, kpi_period_s=0.05, shutdown_poll_s=0.05) as srv:
        try:
            assert post(srv.url, "/api/processes/start", {"iri": TAPING}).status == 200
            assert backend.stuck.wait(10)                          # the hub thread is now stuck in kpis()
            r = post(srv.url, "/api/stop", {}, timeout=5)          # answered although the poll is stuck
            assert r.status == 200 and backend.calls[-1] == ("stop",)
            assert get(srv.url, "/api/state", timeout=5).status == 200
        finally:
            backend.release.set()
        doc = wait_state(srv.url, lambda d: d["snapshot"]["phase"] == "stopped")
        assert any(e["text"] == "STOP pressed" for e in doc["events"])


class RacyBackend(ScriptedHicemDouble):
    """Lists a prompt as open, then refuses the reply (it was closed in between, as happens with a human and the
    automatic operator answering at once), or crashes on reply."""

    def __init__(self, crash=False):
        super().__init__()
        self.crash = crash

    def prompts(self):
        return [{"id": "p1", "kind": "validate_line", "text": "Is joint wall_1_joint_1 valid?",
                 "choices": ["valid", "invalid"]}]

    def reply(self, prompt_id, answer):
        self.calls.append(("reply", prompt_id, answer))
        if self.crash:
            raise KeyError("p1")
        raise BackendRefused("prompt 'p1' is already answered; open prompts: none")


@pytest.mark.parametrize("crash, status, code, words", [
    (False, 409, "refused", "already answered"), (True, 502, "backend_error", "KeyError"),
])
def test_reply_races_and_backend_bugs(crash, status, code, words):
    backend = RacyBackend(crash)
    with HmiServer(backend, "127.0.0.1", 0, shutdown_poll_s=0.05) as srv:
        r = post(srv.url, "/api/prompts/p1/reply", {"answer": "valid"})
        assert r.status == status and r.error["code"] == code and words in r.error["message"]
        assert backend.calls == [("reply", "p1", "valid")]
        assert serving(srv.url)


def test_many_bad_requests_at_once_then_good_ones(server, double):
    def hammer(i):
        for j in range(10):
            kind = (i + j) % 4
            if kind == 0:
                request(server.url, "POST", "/api/stop", raw=b"[", headers={"Content-Type": "application/json"})
            elif kind == 1:
                get(server.url, "/api/walls/%d.png" % j)
            elif kind == 2:
                post(server.url, "/api/prompts/x%d/reply" % j, {"answer": "valid"})
            else:
                raw = socket.create_connection(("127.0.0.1", server.port), timeout=5)
                raw.sendall(b"\x00\x01garbage\r\n\r\n")
                raw.recv(1024)
                raw.close()
    threads = [threading.Thread(target=hammer, args=(i,)) for i in range(6)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(30)
    assert not any(t.is_alive() for t in threads)
    assert post(server.url, "/api/processes/start", {"iri": TAPING}).status == 200
    assert wait_state(server.url, lambda d: d["snapshot"]["phase"] == "running")
    stops = sum(1 for i in range(6) for j in range(10) if (i + j) % 4 == 0)
    assert double.calls == [("stop",)] * stops + [("start_process", TAPING)]   # a broken STOP body still stops


def test_stop_is_carried_out_whatever_its_body_holds(server, double):
    r = post(server.url, "/api/stop", {"reason": "smoke", "force": True})
    assert r.status == 200 and r.json == {"ok": True, "ignored": ["force", "reason"]}
    assert request(server.url, "POST", "/api/stop", raw=b"{broken",
                   headers={"Content-Type": "application/json"}).status == 200
    assert request(server.url, "POST", "/api/stop", raw=b"stop now",
                   headers={"Content-Type": "text/plain"}).status == 200
    assert request(server.url, "POST", "/api/stop", raw=b"x" * (65 * 1024),
                   headers={"Content-Type": "application/json"}).status == 200
    assert double.calls == [("stop",)] * 4
    # every other endpoint still refuses what it does not know, naming it
    post(server.url, "/api/processes/start", {"iri": TAPING})
    pid = double.prompts()[0]["id"]
    r = post(server.url, "/api/prompts/%s/reply" % pid, {"answer": "done", "note": "x", "by": "me"})
    assert r.status == 400 and r.error["code"] == "unknown_field"
    assert "by, note" in r.error["message"] and "allowed: answer" in r.error["message"]
    assert double.desk.get(pid).state == "open" and serving(server.url)


def _short_post(port, path, announced, sent):
    sock = socket.create_connection(("127.0.0.1", port), timeout=20)
    sock.sendall(b"POST %s HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\nContent-Length: %d\r\n\r\n"
                 % (path.encode(), announced) + sent)
    return sock


def test_a_short_body_is_a_400_within_seconds_and_others_are_served_meanwhile(server, double):
    t0 = time.monotonic()
    sock = _short_post(server.port, "/api/processes/start", 100, b'{"iri": ')
    # while that client keeps the server waiting for the rest of its body, everyone else is served at once
    for _ in range(3):
        t1 = time.monotonic()
        assert serving(server.url) and time.monotonic() - t1 < 1.0
    answer = sock.makefile("rb").read()
    elapsed = time.monotonic() - t0
    sock.close()
    assert answer.startswith(b"HTTP/1.0 400 "), answer[:200]
    body = json.loads(answer.split(b"\r\n\r\n", 1)[1])
    assert body["error"]["code"] == "incomplete_body" and "8 of the 100 bytes" in body["error"]["message"]
    assert server.body_timeout_s - 0.5 < elapsed < server.body_timeout_s + 2.0 < 10.0
    assert double.calls == []
    # a client that hangs up half-way is answered at once, not after the timeout
    sock = _short_post(server.port, "/api/processes/start", 100, b'{"iri": ')
    sock.shutdown(socket.SHUT_WR)
    t0 = time.monotonic()
    answer = sock.makefile("rb").read()
    sock.close()
    assert b" 400 " in answer.split(b"\r\n", 1)[0] and b"connection ended after 8 of the 100" in answer
    assert time.monotonic() - t0 < 1.0 and double.calls == []


def test_a_short_stop_body_still_stops(server, double):
    sock = _short_post(server.port, "/api/stop", 100, b'{"why": ')
    answer = sock.makefile("rb").read()
    sock.close()
    assert answer.startswith(b"HTTP/1.0 200 ") and double.calls == [("stop",)]


def _reset(sock):
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    sock.close()


def test_clients_hanging_up_are_one_quiet_line(caplog, double):
    caplog.set_level(logging.INFO, logger="locem_bridge.hmi")
    with HmiServer(double, "127.0.0.1", 0, heartbeat_s=0.1, body_timeout_s=0.5, shutdown_poll_s=0.05) as srv:
        requests = [b"GET /static/app.js HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
                    b"GET /api/events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n",
                    b"POST /api/processes/start HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                    b"Content-Length: 50\r\n\r\n{\"i",
                    b"POST /api/stop HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                    b"Content-Length: 50\r\n\r\n{\"i",
                    b"GET /api/sta"]
        for req in requests:
            for how in ("close", "reset", "reset later"):
                sock = socket.create_connection(("127.0.0.1", srv.port), timeout=5)
                sock.sendall(req)
                if how == "reset later":
                    time.sleep(0.7)
                _reset(sock) if how.startswith("reset") else sock.close()
                time.sleep(0.1)
        time.sleep(0.5)
        assert serving(srv.url)
    records = [r for r in caplog.records if r.name.startswith("locem_bridge.hmi")]
    assert not [r for r in records if r.exc_info or r.levelno >= logging.WARNING], [
        r.getMessage() for r in records if r.exc_info or r.levelno >= logging.WARNING]
    hung = [r.getMessage() for r in records if "hung up" in r.getMessage()]
    assert hung and all("\n" not in m for m in hung)


def test_other_sites_pages_cannot_read_or_hold_streams(server, double):
    evil = {"Origin": "http://evil.example"}
    for path in ("/api/events", "/api/state"):
        r = get(server.url, path, headers=evil)
        assert r.status == 403 and r.error["code"] == "forbidden_origin" and "evil.example" in r.error["message"]
    # an <img>/<script> load from another page carries no Origin, but the browser marks it cross-site
    for site in ("cross-site", "same-site"):
        r = get(server.url, "/api/events", headers={"Sec-Fetch-Site": site, "Sec-Fetch-Mode": "no-cors"})
        assert r.status == 403 and site in r.error["message"]
    # the page itself and a typed-in address keep working
    assert get(server.url, "/", headers={"Sec-Fetch-Site": "cross-site", "Sec-Fetch-Mode": "navigate"}).status == 200
    assert get(server.url, "/api/state", headers={"Sec-Fetch-Site": "same-origin",
                                                  "Origin": "http://127.0.0.1:%d" % server.port}).status == 200
    assert get(server.url, "/api/state", headers={"Sec-Fetch-Site": "none"}).status == 200


def _stream_from(port, source):
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.settimeout(5)
    sock.bind((source, 0))
    sock.connect(("127.0.0.1", port))
    sock.sendall(b"GET /api/events HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n")
    f = sock.makefile("rb")
    status = f.readline()
    rest = f.read() if b" 200 " not in status else b""
    return sock, status, rest


def test_one_client_cannot_take_every_stream_slot(double):
    with HmiServer(double, "127.0.0.1", 0, max_streams=4, max_streams_per_client=2, heartbeat_s=0.1,
                   shutdown_poll_s=0.05) as srv:
        held = []
        for _ in range(2):
            sock, status, _ = _stream_from(srv.port, "127.0.0.1")
            assert b" 200 " in status
            held.append(sock)
        sock, status, rest = _stream_from(srv.port, "127.0.0.1")
        sock.close()
        assert b" 503 " in status and b"per client" in rest and b"127.0.0.1" in rest
        for source in ("127.0.0.2", "127.0.0.3"):     # other clients still get theirs
            sock, status, _ = _stream_from(srv.port, source)
            assert b" 200 " in status, status
            held.append(sock)
        for sock in held:
            sock.close()
        assert serving(srv.url)


# ------------------------------------------------------------------------------------- skill matching --
def test_the_skill_matching_of_a_process_per_task(server, double):
    from urllib.parse import quote
    r = get(server.url, "/api/match?process=" + quote(TAPING, safe=""))
    assert r.status == 200, r
    view = r.json["match"]
    assert view["process"] == TAPING and view["ok"] is True and view["robot_name"] == "diffdrive_ur5e"
    scan, get_tool = view["tasks"]
    assert (scan["action_type"], scan["capability"], scan["chosen"]["name"], scan["chosen"]["kind"]) == (
        "SCAN", "cap_ScanWalls", "SCAN", "composite")
    assert get_tool["chosen"]["kind"] == "template" and get_tool["chosen"]["name"] == "tmpl_getToolAutomatically"
    assert [(s["index"], s["name"], s["kind"], s["arguments"], s["capability"]) for s in get_tool["chosen"]["steps"]] == [
        (1, "WALL_READY", "basic", "", "cap_ArmToWallReady"),
        (2, "CHANGE_TOOL", "basic", "tool={tool}", "cap_ChangeToolAutomatically")]
    assert get_tool["rejected"] == [{"name": "GET_TOOL", "kind": "composite",
                                     "reason": "uses MOUNT_TOOL, not offered by this robot"}]
    assert ("match_process", TAPING) in double.calls


def test_an_unmatchable_process_shows_why_and_refusals_and_bad_requests_are_clear(server, double):
    from urllib.parse import quote
    sanding = PROCESSES[2]["iri"]
    (task,) = get(server.url, "/api/match?process=" + quote(sanding, safe="")).json["match"]["tasks"]
    assert task["ok"] is False and task["chosen"] is None and "cap_SandArea" in task["problem"]
    assert task["rejected"][0]["reason"] == "tool absent: sander"
    r = get(server.url, "/api/match?process=" + quote(PROCESSES[1]["iri"], safe=""))      # PEMKRE refuses
    assert r.status == 409 and r.error["code"] == "refused" and "no resource model" in r.error["message"]
    r = get(server.url, "/api/match")
    assert r.status == 400 and r.error["code"] == "missing_field" and "process" in r.error["message"]
    r = get(server.url, "/api/match?process=urn%3Anope")
    assert r.status == 404 and r.error["code"] == "unknown_process" and TAPING in r.error["message"]
    r = get(server.url, "/api/match?proc=x")
    assert r.status == 400 and r.error["code"] == "unknown_field" and "allowed: process" in r.error["message"]
    assert post(server.url, "/api/match", {}).status == 405
    assert not any(c[0] == "match_process" and c[1] == "urn:nope" for c in double.calls)
    assert serving(server.url)


def test_a_backend_without_matching_and_a_malformed_match_are_named():
    class NoMatching(ScriptedHicemDouble):
        match_process = None

    class Broken(ScriptedHicemDouble):
        def match_process(self, iri):
            return {"process": iri, "nodes": [{"node": "", "realization": None}]}

    from urllib.parse import quote
    for backend, status, code, words in ((NoMatching(), 404, "no_matching", "does not offer skill matching"),
                                         (Broken(), 502, "bad_match", "'node'")):
        with HmiServer(backend, "127.0.0.1", 0, poll_period_s=0.05, shutdown_poll_s=0.05) as srv:
            r = get(srv.url, "/api/match?process=" + quote(TAPING, safe=""))
            assert (r.status, r.error["code"]) == (status, code) and words in r.error["message"], r
