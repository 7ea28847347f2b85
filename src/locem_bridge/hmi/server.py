"""The HMI's HTTP server: the page, its static files, the JSON API and the Server-Sent-Events stream.

Standard library only (``http.server.ThreadingHTTPServer``), one thread per connection, bound to 127.0.0.1 by
default. Lifecycle: ``HmiServer(backend, host, port)`` -> :meth:`HmiServer.start` (binds, starts the state hub
and the serving thread; port 0 picks a free port, see :attr:`HmiServer.url`) -> :meth:`HmiServer.close`
(stops serving, ends every event stream, joins threads). Also usable as a context manager.

Safety: while bound to a loopback address, requests whose ``Host`` header names another host are refused (403,
against DNS rebinding); requests that carry an ``Origin`` other than this server, or that the browser marks as
coming from another site's page (``Sec-Fetch-Site: cross-site`` / ``same-site``) are refused (403, against other
pages in the operator's browser posting commands or holding event streams), and POST bodies must be
``Content-Type: application/json``. Bodies are limited to 64 KiB and must arrive within ``body_timeout_s`` (a
body shorter than its ``Content-Length`` is a 400 after that, in its own thread: other clients are served
meanwhile); a client silent for ``request_timeout_s`` is dropped; event streams are limited to ``max_streams``
at once, ``max_streams_per_client`` per client address, and ``stream_lifetime_s`` each (the browser reconnects
by itself). STOP is the emergency path: it is carried out whatever its body holds (unknown fields, broken JSON,
another content type), only the Host/Origin checks apply; other endpoints refuse unknown fields with a 400
naming them. A client that hangs up is one quiet log line, not a traceback. Every rejection is a JSON error
(see the package docstring) and the server keeps serving.
"""
import json
import logging
import os
import re
import socket
import sys
import threading
import time
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Dict, List, Optional, Tuple
from urllib.parse import parse_qs, unquote, urlsplit

from .backend import SKILL_METHODS, HmiBackend
from .errors import BackendRefused, BackendUnavailable, RequestError, ServerStartError
from .hub import StateHub
from .pemkre_view import match_view

LOG = logging.getLogger("locem_bridge.hmi.server")
STATIC_DIR = os.path.join(os.path.dirname(os.path.abspath(__file__)), "static")
STATIC_TYPES = {".html": "text/html; charset=utf-8", ".js": "text/javascript; charset=utf-8",
                ".css": "text/css; charset=utf-8", ".svg": "image/svg+xml", ".png": "image/png",
                ".ico": "image/x-icon"}
MAX_BODY = 64 * 1024
HANG_UPS = (ConnectionError, socket.timeout, TimeoutError)   # a client went away or stopped sending
SAME_SITE_FETCH = ("same-origin", "none")      # Sec-Fetch-Site values of the page itself or a typed-in address
LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")
PROMPT_REPLY = re.compile(r"/api/prompts/([^/]+)/reply\Z")
WALL_PNG = re.compile(r"/api/walls/([^/]+)\.png\Z")
SKILL_METHOD = re.compile(r"/api/skill/([^/]+)\Z")
#: the page's names of the skill methods (OPC UA Part 10) it offers for HICEM's running action
SKILL_BUTTONS = {"Suspend": "Pause", "Resume": "Resume", "Halt": "Abort", "Reset": "Reset"}

ENDPOINTS = [
    ("GET", "/", "the operator page"),
    ("GET", "/api", "this list"),
    ("GET", "/api/state", "everything the page shows: snapshot, prompts, kpis, walls, processes, manual, events"),
    ("GET", "/api/events", "Server-Sent Events: 'state' events carrying /api/state on every change"),
    ("GET", "/api/processes", "processes that can be started"),
    ("POST", "/api/processes/start", "start a process: {\"iri\": str}"),
    ("POST", "/api/stop", "stop everything now: {} (always accepted)"),
    ("GET", "/api/prompts", "open operator prompts"),
    ("POST", "/api/prompts/<id>/reply", "answer a prompt: {\"answer\": str}"),
    ("GET", "/api/kpis", "KPI tables"),
    ("GET", "/api/walls", "walls with a picture"),
    ("GET", "/api/walls/<wall_id>.png", "the current picture of one wall"),
    ("GET", "/api/manual", "the planned manual work reported so far in this job: parts of areas (spray, sand) "
     "and joints (tape) left for a person, with their extent"),
    ("GET", "/api/match?process=<iri>", "how each task of a process is matched to this robot's skills: the chosen "
     "skill and the rejected candidates with reasons"),
    ("POST", "/api/skill/<method>", "suspend, resume, halt or reset HICEM's running action (Pause, Resume, Abort, "
     "Reset): {\"cause\": str} (optional)"),
]


def _known_paths() -> str:
    return ", ".join("%s %s" % (m, p) for m, p, _ in ENDPOINTS)


class _Server(ThreadingHTTPServer):
    daemon_threads = True
    block_on_close = False
    allow_reuse_address = True

    def __init__(self, addr: Tuple[str, int], app: "HmiServer") -> None:
        self.app = app
        if ":" in addr[0]:
            self.address_family = socket.AF_INET6
        super().__init__(addr, _Handler)

    def handle_error(self, request: Any, client_address: Any) -> None:  # keep serving, log once
        err = sys.exc_info()[1]
        if isinstance(err, HANG_UPS):
            LOG.info("HMI client %s hung up (%s)", client_address[0] if client_address else "?",
                     type(err).__name__)
            return
        LOG.exception("HMI request from %s failed", client_address)


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    server_version = "locem_bridge-hmi/1"
    protocol_version = "HTTP/1.0"

    # -- plumbing ------------------------------------------------------------------------------------------
    def log_message(self, fmt: str, *args: Any) -> None:
        LOG.debug("%s %s", self.address_string(), fmt % args)

    @property
    def app(self) -> "HmiServer":
        return self.server.app

    @property
    def timeout(self) -> float:  # type: ignore[override] - socket timeout while reading a request
        return self.server.app.request_timeout_s

    def _send(self, status: int, body: bytes, ctype: str, extra: Optional[Dict[str, str]] = None) -> None:
        self.send_response(status)
        self.send_header("Content-Type", ctype)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-cache")
        self.send_header("X-Content-Type-Options", "nosniff")
        for k, v in (extra or {}).items():
            self.send_header(k, v)
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, obj: Any) -> None:
        self._send(status, json.dumps(obj, default=str).encode("utf-8"), "application/json; charset=utf-8")

    def _error(self, err: RequestError) -> None:
        extra = {"Allow": err.allow} if err.allow else None
        body = {"error": {"status": err.status, "code": err.code, "message": err.message}}
        self._send(err.status, json.dumps(body).encode("utf-8"), "application/json; charset=utf-8", extra)

    def send_error(self, code: int, message: Optional[str] = None, explain: Optional[str] = None) -> None:
        """Errors raised by http.server itself (bad request line, unsupported method) as JSON too."""
        try:
            phrase = HTTPStatus(code).phrase
        except ValueError:
            phrase = "error"
        text = message or phrase
        if code == 501:
            text = "method %s is not supported; use GET or POST" % (self.command or "?")
        self.close_connection = True
        self._send(code, json.dumps({"error": {"status": code, "code": phrase.lower().replace(" ", "_"),
                                               "message": text}}).encode("utf-8"),
                   "application/json; charset=utf-8")

    def _dispatch(self, method: str) -> None:
        try:
            self._check_host()
            path = urlsplit(self.path).path
            self.app.route(self, method, path)
        except RequestError as err:
            self._answer_error(err)
        except BackendRefused as err:
            self.app.hub.note("refused: %s" % err, "error")
            self._answer_error(RequestError(409, "refused", str(err)))
        except BackendUnavailable as err:
            self.app.hub.note("backend unavailable: %s" % err, "error")
            self._answer_error(RequestError(503, "backend_unavailable", str(err)))
        except HANG_UPS as err:
            self.close_connection = True
            LOG.info("HMI client %s hung up during %s %s (%s)", self.client_address[0], method, self.path,
                     type(err).__name__)
        except Exception as err:  # noqa: BLE001 - a backend bug is reported, the server keeps serving
            LOG.exception("HMI %s %s failed", method, self.path)
            try:
                self._error(RequestError(502, "backend_error", "%s: %s" % (type(err).__name__, err)))
            except HANG_UPS:
                self.close_connection = True

    def _answer_error(self, err: RequestError) -> None:
        try:
            self._error(err)
        except HANG_UPS:
            self.close_connection = True

    def _check_host(self) -> None:
        host = (self.headers.get("Host") or "").strip()
        allowed = self.app.allowed_hosts
        if allowed is not None and _host_name(host) not in allowed:
            raise RequestError(403, "forbidden_host", "Host %r is not served here; use one of: %s" % (
                host, ", ".join(sorted(allowed))))
        origin = self.headers.get("Origin")
        if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
            raise RequestError(403, "forbidden_origin", "cross-site request from %r refused; the page must be "
                               "served by this HMI (%s)" % (origin, host))
        fetch_site = (self.headers.get("Sec-Fetch-Site") or "").strip().lower()
        if fetch_site and fetch_site not in SAME_SITE_FETCH and urlsplit(self.path).path.startswith("/api"):
            raise RequestError(403, "forbidden_origin", "request from another site's page refused (Sec-Fetch-Site: "
                               "%s); open the operator page itself (%s)" % (fetch_site, host))

    def read_body(self) -> Tuple[str, bytes]:
        """``(content type, body bytes)``; the body must arrive within ``body_timeout_s`` (400 otherwise)."""
        ctype = (self.headers.get("Content-Type") or "").split(";")[0].strip().lower()
        length_text = self.headers.get("Content-Length")
        if length_text is None:
            return ctype, b""
        try:
            length = int(length_text)
        except ValueError:
            raise RequestError(400, "bad_length", "Content-Length %r is not a number" % length_text)
        if length < 0 or length > MAX_BODY:
            raise RequestError(413, "body_too_large", "body of %d bytes; at most %d allowed" % (length, MAX_BODY))
        return ctype, self._read_exactly(length)

    def _read_exactly(self, length: int) -> bytes:
        chunks: List[bytes] = []
        got = 0
        limit = self.app.body_timeout_s
        deadline = time.monotonic() + limit
        try:
            while got < length:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise socket.timeout()
                self.connection.settimeout(left)
                chunk = self.rfile.read1(length - got)
                if not chunk:
                    break
                chunks.append(chunk)
                got += len(chunk)
        except socket.timeout:
            self.close_connection = True
            raise RequestError(400, "incomplete_body", "body incomplete: %d of the %d bytes Content-Length announced "
                               "arrived within %.1f s" % (got, length, limit))
        finally:
            try:
                self.connection.settimeout(self.timeout)
            except OSError:
                pass
        if got < length:
            self.close_connection = True
            raise RequestError(400, "incomplete_body", "body incomplete: the connection ended after %d of the %d "
                               "bytes Content-Length announced" % (got, length))
        return b"".join(chunks)

    def read_json(self, allowed: Tuple[str, ...], required: Tuple[str, ...]) -> Dict[str, Any]:
        if self.headers.get("Content-Length") is None:
            if required:
                raise RequestError(411, "length_required", "a JSON body with Content-Length is required")
            return {}
        ctype, raw = self.read_body()
        if not raw and not required:
            return {}
        if ctype != "application/json":
            raise RequestError(415, "unsupported_media_type",
                               "Content-Type must be application/json, got %r" % (ctype or "none"))
        if not raw.strip():
            if required:
                raise RequestError(400, "missing_body", "a JSON object with %s is required" % ", ".join(required))
            return {}
        try:
            body = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, ValueError) as err:
            raise RequestError(400, "malformed_json", "body is not valid JSON: %s" % err)
        if not isinstance(body, dict):
            raise RequestError(400, "bad_body", "body must be a JSON object, got %s" % type(body).__name__)
        unknown = sorted(set(body) - set(allowed))
        if unknown:
            raise RequestError(400, "unknown_field", "unknown field(s) %s; allowed: %s" % (
                ", ".join(unknown), ", ".join(allowed) or "none"))
        for key in required:
            if not isinstance(body.get(key), str) or not body[key]:
                raise RequestError(400, "missing_field", "field %r must be a non-empty string, got %r" % (
                    key, body.get(key)))
        return body

    # -- verbs ---------------------------------------------------------------------------------------------
    def do_GET(self) -> None:  # noqa: N802 - http.server naming
        self._dispatch("GET")

    def do_HEAD(self) -> None:  # noqa: N802
        self._dispatch("HEAD")

    def do_POST(self) -> None:  # noqa: N802
        self._dispatch("POST")

    def _not_allowed(self) -> None:
        self._error(RequestError(405, "method_not_allowed", "method %s is not supported; use GET or POST" %
                                 self.command, allow="GET, HEAD, POST"))

    do_PUT = do_DELETE = do_PATCH = do_OPTIONS = _not_allowed  # noqa: N815


class HmiServer:
    """The operator HMI web server over an injected :class:`~locem_bridge.hmi.backend.HmiBackend`."""

    def __init__(self, backend: HmiBackend, host: str = "127.0.0.1", port: int = 8088,
                 poll_period_s: float = 0.25, picture_period_s: float = 1.0, kpi_period_s: float = 2.0,
                 max_streams: int = 16, stream_lifetime_s: float = 300.0, heartbeat_s: float = 15.0,
                 title: str = "locem_bridge operator", shutdown_poll_s: float = 0.5,
                 request_timeout_s: float = 30.0, body_timeout_s: float = 3.0,
                 max_streams_per_client: int = 8) -> None:
        self.backend = backend
        self.host = host
        self.port = int(port)
        self.title = title
        self.shutdown_poll_s = float(shutdown_poll_s)   # serve_forever's poll: how fast close() returns
        self.request_timeout_s = float(request_timeout_s)  # a client silent this long is dropped (slow loris)
        self.body_timeout_s = float(body_timeout_s)        # a POST body must arrive within this (else 400)
        self.hub = StateHub(backend, poll_period_s=poll_period_s, picture_period_s=picture_period_s,
                            kpi_period_s=kpi_period_s)
        self.max_streams = int(max_streams)
        self.max_streams_per_client = max(1, min(int(max_streams_per_client), self.max_streams))
        self.stream_lifetime_s = float(stream_lifetime_s)
        self.heartbeat_s = float(heartbeat_s)
        self.allowed_hosts = (set(LOOPBACK_HOSTS) | {host}) if _is_loopback(host) else None
        self._streams = 0
        self._client_streams: Dict[str, int] = {}
        self._streams_lock = threading.Lock()
        self._httpd: Optional[_Server] = None
        self._thread: Optional[threading.Thread] = None
        self._static = {name: os.path.join(STATIC_DIR, name) for name in sorted(os.listdir(STATIC_DIR))
                        if os.path.splitext(name)[1] in STATIC_TYPES}

    # -- lifecycle -----------------------------------------------------------------------------------------
    def start(self) -> "HmiServer":
        if self._httpd is not None:
            return self
        try:
            self._httpd = _Server((self.host, self.port), self)
        except OSError as err:
            raise ServerStartError("cannot serve the operator HMI on %s port %d: %s (choose another port, or 0 "
                                   "for a free one)" % (self.host, self.port, err.strerror or err))
        self.port = int(self._httpd.server_address[1])
        self.hub.start()
        self._thread = threading.Thread(target=self._httpd.serve_forever, name="hmi-http", daemon=True,
                                        kwargs={"poll_interval": self.shutdown_poll_s})
        self._thread.start()
        LOG.info("operator HMI on %s", self.url)
        return self

    @property
    def url(self) -> str:
        host = "[%s]" % self.host if ":" in self.host else self.host
        return "http://%s:%d/" % (host, self.port)

    def close(self) -> None:
        self.hub.close()
        if self._httpd is not None:
            self._httpd.shutdown()
            self._httpd.server_close()
            self._httpd = None
        if self._thread is not None:
            self._thread.join(5.0)
            self._thread = None

    def __enter__(self) -> "HmiServer":
        return self.start()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def serve_until(self, stop: threading.Event) -> None:
        """Block until ``stop`` is set (for scripts); the server must be started."""
        while not stop.wait(0.5):
            pass

    # -- routing -------------------------------------------------------------------------------------------
    def route(self, h: _Handler, method: str, path: str) -> None:
        if method == "HEAD":
            method = "GET"
        if method == "GET":
            if path in ("/", "/index.html"):
                return self._static_file(h, "index.html")
            if path.startswith("/static/"):
                return self._static_file(h, path[len("/static/"):])
            if path in ("/api", "/api/"):
                return h._json(200, {"endpoints": [{"method": m, "path": p, "what": w} for m, p, w in ENDPOINTS]})
            if path == "/api/state":
                return h._json(200, self.hub.state())
            if path == "/api/events":
                return self._events(h)
            if path == "/api/processes":
                return h._json(200, {"processes": self.hub.refresh_processes()})
            if path == "/api/prompts":
                return h._json(200, {"prompts": self.hub.state().get("prompts", [])})
            if path == "/api/kpis":
                return h._json(200, {"kpis": self.hub.state().get("kpis", {})})
            if path == "/api/walls":
                return h._json(200, {"walls": self.hub.state().get("walls", [])})
            if path == "/api/manual":
                return h._json(200, {"manual": self.hub.state().get("manual", [])})
            if path == "/api/match":
                return self._match(h)
            m = WALL_PNG.match(path)
            if m:
                return self._wall(h, unquote(m.group(1)))
        elif method == "POST":
            if path == "/api/processes/start":
                return self._start(h)
            if path == "/api/stop":
                return self._stop(h)
            m = PROMPT_REPLY.match(path)
            if m:
                return self._reply(h, unquote(m.group(1)))
            m = SKILL_METHOD.match(path)
            if m:
                return self._skill(h, unquote(m.group(1)))
        if any(p.split("?")[0] == path for _m, p, _w in ENDPOINTS) or PROMPT_REPLY.match(path) or \
                WALL_PNG.match(path) or SKILL_METHOD.match(path):
            allow = ", ".join(sorted({m for m, p, _ in ENDPOINTS if p.split("?")[0] == path} or
                                     ({"POST"} if PROMPT_REPLY.match(path) or SKILL_METHOD.match(path)
                                      else {"GET"})))
            raise RequestError(405, "method_not_allowed", "%s %s is not supported; allowed: %s" % (
                method, path, allow), allow=allow)
        raise RequestError(404, "not_found", "no endpoint %s %s; endpoints: %s" % (method, path, _known_paths()))

    def _static_file(self, h: _Handler, name: str) -> None:
        full = self._static.get(name)
        if full is None:
            raise RequestError(404, "not_found", "no static file %r; files: %s" % (name, ", ".join(self._static)))
        with open(full, "rb") as fh:
            data = fh.read()
        if name == "index.html":
            data = data.replace(b"{{TITLE}}", self.title.replace("<", "&lt;").encode("utf-8"))
        h._send(200, data, STATIC_TYPES[os.path.splitext(name)[1]])

    def _wall(self, h: _Handler, wall_id: str) -> None:
        state, data, message = self.hub.picture(wall_id)
        if state == "unknown":
            raise RequestError(404, "unknown_wall", message)
        if state == "missing":
            raise RequestError(404, "picture_not_ready", message)
        if state == "bad":
            raise RequestError(502, "bad_picture", message)
        h._send(200, data or b"", "image/png")

    def _start(self, h: _Handler) -> None:
        body = h.read_json(("iri",), ("iri",))
        iri = body["iri"]
        known = self.hub.processes()
        if not any(p["iri"] == iri for p in known):
            known = self.hub.refresh_processes()
        if not any(p["iri"] == iri for p in known):
            raise RequestError(404, "unknown_process", "no process %r; processes: %s" % (
                iri, ", ".join(p["iri"] for p in known) or "none"))
        result = self.backend.start_process(iri)
        name = next((p["name"] for p in known if p["iri"] == iri), iri)
        self.hub.note("started %s" % name)
        self.hub.refresh_now()
        h._json(200, {"ok": True, "started": iri, "result": result})

    def _match(self, h: _Handler) -> None:
        query = parse_qs(urlsplit(h.path).query)
        unknown = sorted(set(query) - {"process"})
        if unknown:
            raise RequestError(400, "unknown_field", "unknown query parameter(s) %s; allowed: process" %
                               ", ".join(unknown))
        iri = (query.get("process") or [""])[0]
        if not iri:
            raise RequestError(400, "missing_field", "query parameter 'process' (an abstract process IRI) is "
                               "required: /api/match?process=<iri>")
        fn = getattr(self.backend, "match_process", None)
        if fn is None:
            raise RequestError(404, "no_matching", "this HMI's backend does not offer skill matching (it has no "
                               "match_process); the ROS HMI asks PEMKRE's <pemkre>/match service")
        known = self.hub.processes()
        if not any(p["iri"] == iri for p in known):
            known = self.hub.refresh_processes()
        if not any(p["iri"] == iri for p in known):
            raise RequestError(404, "unknown_process", "no process %r; processes: %s" % (
                iri, ", ".join(p["iri"] for p in known) or "none"))
        raw = fn(iri)
        try:
            view = match_view(raw)
        except ValueError as err:
            raise RequestError(502, "bad_match", "the backend's process match is malformed: %s" % err)
        h._json(200, {"match": view})

    def _stop(self, h: _Handler) -> None:
        # the emergency path: whatever the body holds (or fails to hold), the robot is stopped
        ignored: List[str] = []
        try:
            _ctype, raw = h.read_body()
            body = json.loads(raw.decode("utf-8")) if raw.strip() else {}
            if isinstance(body, dict):
                ignored = sorted(str(k) for k in body)
        except (RequestError, UnicodeDecodeError, ValueError):
            h.close_connection = True                 # the rest of the body (if any) is not read
        self.backend.stop()
        self.hub.note("STOP pressed", "warning")
        self.hub.refresh_now()
        h._json(200, {"ok": True, "ignored": ignored} if ignored else {"ok": True})

    def _reply(self, h: _Handler, prompt_id: str) -> None:
        body = h.read_json(("answer",), ("answer",))
        answer = body["answer"]
        open_prompts = self.backend.prompts() or []
        prompt = next((p for p in open_prompts if isinstance(p, dict) and p.get("id") == prompt_id), None)
        if prompt is None:
            ids = [str(p.get("id")) for p in open_prompts if isinstance(p, dict)]
            raise RequestError(409, "prompt_not_open", "prompt %r is not open (answered, withdrawn or never "
                               "asked); open prompts: %s" % (prompt_id, ", ".join(ids) or "none"))
        choices = list(prompt.get("choices") or [])
        if answer not in choices:
            raise RequestError(400, "answer_not_allowed", "answer %r is not allowed for prompt %r; allowed: %s" % (
                answer, prompt_id, ", ".join(choices)))
        self.backend.reply(prompt_id, answer)
        self.hub.note("answered %s: %s" % (prompt.get("kind") or prompt_id, answer))
        self.hub.refresh_now()
        h._json(200, {"ok": True, "prompt": prompt_id, "answer": answer})

    def _skill(self, h: _Handler, name: str) -> None:
        method = next((m for m in SKILL_METHODS if m.lower() == name.lower()), None)
        if method is None:
            raise RequestError(404, "unknown_skill_method", "no skill method %r; methods: %s" % (
                name, ", ".join(m.lower() for m in SKILL_METHODS)))
        body = h.read_json(("cause",), ())
        cause = body.get("cause", "")
        if not isinstance(cause, str):
            raise RequestError(400, "bad_body", "field 'cause' must be a string, got %r" % (cause,))
        fn = getattr(self.backend, "skill_method", None)
        if fn is None:
            raise RequestError(404, "no_skill_control", "this HMI's backend offers no skill methods (it has no "
                               "skill_method); the ROS HMI calls HICEM's <hicem>/%s service" % method.lower())
        button = SKILL_BUTTONS[method]
        default = "%s pressed on the operator HMI" % button
        try:
            result = fn(method, cause or default) or {}
        except BackendRefused as err:
            raise BackendRefused("%s: %s" % (button, err))
        message = str(result.get("message", "") or "")
        self.hub.note("%s pressed: %s%s" % (button, result.get("state") or "taken",
                                            " (%s)" % message if message and message != default else ""))
        self.hub.refresh_now()
        h._json(200, {"ok": True, "method": method, "state": str(result.get("state", "")),
                      "allowed": [m for m in SKILL_METHODS if m in (result.get("allowed") or [])],
                      "message": str(result.get("message", ""))})

    def _events(self, h: _Handler) -> None:
        if h.command == "HEAD":
            h._send(200, b"", "text/event-stream; charset=utf-8")
            return
        client = str(h.client_address[0])
        with self._streams_lock:
            if self._streams >= self.max_streams:
                raise RequestError(503, "too_many_streams", "at most %d event streams at once" % self.max_streams)
            if self._client_streams.get(client, 0) >= self.max_streams_per_client:
                raise RequestError(503, "too_many_streams", "at most %d event streams at once per client (%s holds "
                                   "%d); close another tab of this page" % (self.max_streams_per_client, client,
                                                                            self._client_streams[client]))
            self._streams += 1
            self._client_streams[client] = self._client_streams.get(client, 0) + 1
        try:
            h.send_response(200)
            h.send_header("Content-Type", "text/event-stream; charset=utf-8")
            h.send_header("Cache-Control", "no-cache")
            h.end_headers()
            h.wfile.write(b"retry: 2000\n\n")
            doc = self.hub.state()
            seen = -1
            end = time.monotonic() + self.stream_lifetime_s
            while not self.hub.closed and time.monotonic() < end:
                if doc is not None and doc.get("version") != seen:
                    seen = doc.get("version", seen)
                    payload = json.dumps(doc, default=str)
                    h.wfile.write(("event: state\nid: %s\ndata: %s\n\n" % (seen, payload)).encode("utf-8"))
                else:
                    h.wfile.write(b": ping\n\n")
                h.wfile.flush()
                doc = self.hub.wait_for_change(seen, min(self.heartbeat_s, max(0.0, end - time.monotonic())))
        except (BrokenPipeError, ConnectionResetError, OSError):
            pass
        finally:
            with self._streams_lock:
                self._streams -= 1
                left = self._client_streams.get(client, 1) - 1
                if left > 0:
                    self._client_streams[client] = left
                else:
                    self._client_streams.pop(client, None)


def _host_name(host: str) -> str:
    """'name' of a Host header value 'name:port', '[v6]:port' or 'name'; lower case."""
    if host.startswith("[") and "]" in host:
        return host[1:host.index("]")].lower()
    return (host.rsplit(":", 1)[0] if host.count(":") == 1 else host).lower()


def _is_loopback(host: str) -> bool:
    return host in LOOPBACK_HOSTS or host.startswith("127.")
