"""PEMKRE's node opening a SPARQL server's store (``store_factory.open_store_waiting``, as ros/pemkre_node.py does): it waits for a server
it cannot reach, one line per attempt, and opens the store once the server answers; a server that answers wrongly
is one configuration line naming the endpoint. A real ``oxigraph serve`` and a real HTTP server answering HTML."""
import http.server
import threading

import pytest
from oxigraph_server import OxigraphServer, free_port

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.pemkre.store_factory import open_store, open_store_waiting


def _answering(status, media, body):
    """A real HTTP server on a free loopback port answering every POST with ``status``, ``media`` and ``body``
    (shut it down and close it when done)."""
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_POST(self):
            self.send_response(status)
            self.send_header("Content-Type", media)
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    httpd = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    threading.Thread(target=httpd.serve_forever, args=(0.05,), daemon=True).start()
    return httpd


def test_the_node_waits_for_a_server_that_is_not_up_yet_then_opens_its_store(tmp_path):
    port = free_port()
    server = OxigraphServer(str(tmp_path / "data"), port=port)
    waits, lines = [], []

    def sleep(seconds):                                  # the server comes up during the node's second wait
        waits.append(seconds)
        if len(waits) == 2:
            server.start()

    try:
        store = open_store_waiting(lambda: open_store("sparql", "", query_url=server.query_url,
                                                      update_url=server.update_url), "sparql",
                                   log=lines.append, first_delay_s=0.01, sleep=sleep)
        try:
            assert store.count() == 0
        finally:
            store.close()
    finally:
        server.kill()
    assert waits == [0.01, 0.02]                         # two attempts failed, the third opened the store (slices
                                                         # of at most 0.1 s)
    assert len(lines) == 2 and all(server.query_url in line and "\n" not in line for line in lines), lines


def test_a_server_answering_html_is_one_configuration_line_naming_the_endpoint():
    httpd = _answering(200, "text/html", b"<html><body>Welcome to nginx</body></html>")
    url = "http://127.0.0.1:%d/sparql" % httpd.server_address[1]
    slept = []
    try:
        with pytest.raises(ConfigError) as err:
            open_store_waiting(lambda: open_store("sparql", "", query_url=url, update_url=url), "sparql",
                               log=slept.append, sleep=slept.append)
    finally:
        httpd.shutdown()
        httpd.server_close()
    line = err.value.one_line()
    assert "\n" not in line and url in line and "html" in line.lower(), line
    assert slept == []                                   # not waited for: it will not heal by waiting


def test_a_store_kind_that_does_not_exist_is_one_configuration_line_naming_the_kinds():
    with pytest.raises(ConfigError) as err:
        open_store_waiting(lambda: open_store("postgres", "/tmp/x"), "postgres", log=print)
    assert "journal" in err.value.one_line() and "sparql" in err.value.one_line()


def test_a_gateway_answering_503_is_waited_for_and_a_stop_ends_the_wait_without_a_configuration_error():
    from locem_bridge.pemkre.errors import StoreError

    httpd = _answering(503, "text/plain", b"Service Unavailable")
    url = "http://127.0.0.1:%d/sparql" % httpd.server_address[1]
    lines = []
    try:
        with pytest.raises(StoreError) as err:            # stopped on the 3rd line: no ConfigError, nothing counted
            open_store_waiting(lambda: open_store("sparql", "", query_url=url, update_url=url), "sparql",
                               log=lines.append, stop=lambda: len(lines) >= 3, first_delay_s=0.01,
                               sleep=lambda s: None)
    finally:
        httpd.shutdown()
        httpd.server_close()
    assert not isinstance(err.value, ConfigError) and "503" in str(err.value), err.value
    assert len(lines) == 3 and all(url in line for line in lines), lines
