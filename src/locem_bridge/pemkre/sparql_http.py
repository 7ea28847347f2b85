"""One HTTP endpoint of a SPARQL 1.1 server (the query or the update URL), as the SPARQL 1.1 Protocol uses it.

Why not ``urllib.request``: it opens a new connection for every request. PEMKRE asks the store dozens of small
questions per decision, so reads keep one HTTP/1.1 connection alive (``http.client``, standard library) and
reconnect when the server has closed it. Writes open a fresh connection each time: a kept-alive connection the
server closed while idle fails only once the request is on its way, and a write must never be guessed to have
failed when it may have arrived (see :meth:`Endpoint.post`).

Every failure becomes one line naming the endpoint (the URL without credentials) and what is wrong:
:class:`~locem_bridge.pemkre.errors.StoreUnavailable` when the server cannot be reached (refused, unknown host,
timeout, connection lost), :class:`HttpStatusError` (a :class:`~locem_bridge.pemkre.errors.StoreError`) for an
HTTP error answer, with the server's own message. Reads are retried with bounded exponential backoff
(:class:`RetryPolicy`) on transient failures: unreachable, HTTP 502/503/504.
"""
import base64
import html
import http.client
import re
import socket
import ssl
import threading
import time
from dataclasses import dataclass
from typing import Callable, Dict, List, Optional, Tuple
from urllib.parse import unquote, urlencode, urlsplit

from .errors import StoreError, StoreUnavailable

#: HTTP statuses that say "try again later" (a proxy without its backend, a server starting or overloaded).
TRANSIENT_STATUSES = (502, 503, 504)
_MESSAGE_CHARS = 300


@dataclass(frozen=True)
class RetryPolicy:
    """How often and how patiently a transient failure is retried: ``attempts`` tries in all, waiting
    ``first_delay_s`` after the first failure and doubling up to ``max_delay_s`` between later ones."""

    attempts: int = 4
    first_delay_s: float = 0.2
    max_delay_s: float = 2.0

    def delays(self) -> List[float]:
        """The waits between the attempts (``attempts - 1`` of them)."""
        out, d = [], self.first_delay_s
        for _ in range(max(0, self.attempts - 1)):
            out.append(min(d, self.max_delay_s))
            d *= 2
        return out


@dataclass
class Answer:
    """An HTTP answer: status, the media type of its body (lower case, without parameters) and the body."""

    status: int
    reason: str
    media_type: str
    body: bytes
    location: str = ""
    server: str = ""        # the Server header (e.g. "Oxigraph/0.5.13")

    def text(self) -> str:
        return self.body.decode("utf-8", errors="replace")


class HttpStatusError(StoreError):
    """The server answered with an HTTP error status; ``status`` holds it, the message the server's own words."""

    def __init__(self, message: str, status: int) -> None:
        super().__init__(message)
        self.status = status


class _NotSent(Exception):
    """The request did not leave this machine (no connection could be made): safe to try again."""

    def __init__(self, reason: str) -> None:
        super().__init__(reason)
        self.reason = reason


class _Lost(Exception):
    """The request may have reached the server, but no complete answer came back."""

    def __init__(self, reason: str, timed_out: bool) -> None:
        super().__init__(reason)
        self.reason = reason
        self.timed_out = timed_out


def summarize(answer: Answer) -> str:
    """The server's message in an error answer, as one short line (an HTML page reduced to its text)."""
    text = answer.text()
    if answer.media_type == "text/html" or text.lstrip().startswith("<"):
        text = re.sub(r"(?is)<(script|style)\b.*?</\1>", " ", text)
        text = html.unescape(re.sub(r"<[^>]*>", " ", text))
    text = " ".join(text.split())
    if len(text) > _MESSAGE_CHARS:
        text = text[:_MESSAGE_CHARS] + "..."
    return text or "(no message)"


class Endpoint:
    """One SPARQL protocol URL; ``role`` (``query`` / ``update``) names it in messages. Thread-safe: requests on
    the kept-alive connection are serialized."""

    def __init__(self, url: str, role: str, timeout_s: float = 10.0, retry: RetryPolicy = RetryPolicy(),
                 sleep: Callable[[float], None] = time.sleep) -> None:
        self.role = role
        if not isinstance(url, str) or not url.strip():
            raise StoreError("SPARQL %s endpoint: no URL given (e.g. http://127.0.0.1:7878/%s)" % (role, role))
        parts = urlsplit(url.strip())
        if parts.scheme not in ("http", "https"):
            self.name = "SPARQL %s endpoint %s" % (role, re.sub(r"//[^/@]*@", "//", url.strip()))
            raise StoreError("%s: not an http:// or https:// URL (%s)" % (
                self.name, "scheme %r" % parts.scheme if parts.scheme else "no scheme"))
        shown = _without_credentials(parts)
        self.name = "SPARQL %s endpoint %s" % (role, shown)
        try:
            port = parts.port
        except ValueError:
            raise StoreError("%s: the port is not a number" % self.name) from None
        if not parts.hostname:
            raise StoreError("%s: the URL names no host" % self.name)
        if timeout_s <= 0:
            raise StoreError("%s: the timeout must be positive, got %r s" % (self.name, timeout_s))
        self.url = shown
        self.https = parts.scheme == "https"
        self.host = parts.hostname
        self.port = port or (443 if self.https else 80)
        self.path = (parts.path or "/") + ("?" + parts.query if parts.query else "")
        self.timeout_s = float(timeout_s)
        self.retry = retry
        self._sleep = sleep
        self._headers: Dict[str, str] = {"User-Agent": "locem_bridge-pemkre"}
        if parts.username is not None:
            cred = "%s:%s" % (unquote(parts.username), unquote(parts.password or ""))
            self._headers["Authorization"] = "Basic " + base64.b64encode(cred.encode("utf-8")).decode("ascii")
        self._conn: Optional[http.client.HTTPConnection] = None
        self._lock = threading.Lock()

    # ---------------------------------------------------------------- public
    def post(self, form: List[Tuple[str, str]], accept: str, write: bool = False,
             retry: Optional[RetryPolicy] = None) -> Answer:
        """POST ``form`` (``application/x-www-form-urlencoded``, as the protocol allows for query and update).

        A read is retried on transient failures (bounded by :attr:`retry`). A write is retried only while no
        connection could be made (nothing was sent); once sent, a lost answer raises
        :class:`~locem_bridge.pemkre.errors.StoreUnavailable` with ``applied=None`` and is never resent here.
        An HTTP error answer raises :class:`HttpStatusError`; other answers are returned as they are. ``retry``
        replaces :attr:`retry` for this request.
        """
        body = urlencode(form).encode("ascii")
        headers = dict(self._headers)
        headers["Content-Type"] = "application/x-www-form-urlencoded"
        headers["Accept"] = accept
        delays = (retry or self.retry).delays()
        started = time.monotonic()
        attempt = 0
        while True:
            attempt += 1
            try:
                answer = self._exchange(body, headers, fresh=write)
            except _NotSent as exc:
                if attempt <= len(delays):
                    self._sleep(delays[attempt - 1])
                    continue
                raise self._unavailable(exc.reason, attempt, started, applied=False) from None
            except _Lost as exc:
                if write:
                    raise StoreUnavailable("%s: %s after the write was sent; whether it was applied is unknown"
                                           % (self.name, exc.reason), self.url, exc.reason, applied=None,
                                           timed_out=exc.timed_out) from None
                if attempt <= len(delays):
                    self._sleep(delays[attempt - 1])
                    continue
                raise self._unavailable(exc.reason, attempt, started, applied=False) from None
            if answer.status in TRANSIENT_STATUSES and not write and attempt <= len(delays):
                self._sleep(delays[attempt - 1])
                continue
            if write and answer.status in (502, 504):
                # a gateway in front of the server failed or gave up: the write may have reached the server
                raise StoreUnavailable("%s: HTTP %d %s after the write was sent (a gateway); whether it was applied "
                                       "is unknown" % (self.name, answer.status, answer.reason), self.url,
                                       "HTTP %d" % answer.status, applied=None, timed_out=True)
            if answer.status >= 300:
                raise self.status_error(answer)
            return answer

    def status_error(self, answer: Answer, what: str = "") -> HttpStatusError:
        """The one-line error for an HTTP error answer (``what``: e.g. ``query X`` it was about)."""
        if 300 <= answer.status < 400:
            detail = "redirected to %s; use that URL" % (answer.location or "another URL")
        else:
            detail = summarize(answer)
        return HttpStatusError("%s%s: HTTP %d %s: %s" % (self.name, " (%s)" % what if what else "", answer.status,
                                                         answer.reason, detail), answer.status)

    def close(self) -> None:
        with self._lock:
            self._drop()

    # ---------------------------------------------------------------- internals
    def _unavailable(self, reason: str, attempts: int, started: float, applied: Optional[bool]) -> StoreUnavailable:
        tries = " (%d attempts over %.1f s)" % (attempts, time.monotonic() - started) if attempts > 1 else ""
        return StoreUnavailable("%s: %s%s" % (self.name, reason, tries), self.url, reason, applied=applied)

    def _connect(self) -> http.client.HTTPConnection:
        if self.https:
            conn: http.client.HTTPConnection = http.client.HTTPSConnection(
                self.host, self.port, timeout=self.timeout_s, context=ssl.create_default_context())
        else:
            conn = http.client.HTTPConnection(self.host, self.port, timeout=self.timeout_s)
        try:
            conn.connect()
        except socket.gaierror as exc:
            conn.close()
            raise _NotSent("unknown host %r (%s)" % (self.host, exc.strerror or exc)) from None
        except ConnectionRefusedError:
            conn.close()
            raise _NotSent("connection refused (is the SPARQL server running on %s:%d?)" % (self.host, self.port)) \
                from None
        except socket.timeout:
            conn.close()
            raise _NotSent("no connection within %g s" % self.timeout_s) from None
        except ssl.SSLError as exc:
            conn.close()
            raise _NotSent("TLS handshake failed: %s" % exc) from None
        except OSError as exc:
            conn.close()
            raise _NotSent("cannot connect: %s" % (exc.strerror or exc)) from None
        if conn.sock is not None:
            conn.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        return conn

    def _drop(self) -> None:
        if self._conn is not None:
            try:
                self._conn.close()
            finally:
                self._conn = None

    def _exchange(self, body: bytes, headers: Dict[str, str], fresh: bool) -> Answer:
        """One request and its answer. ``fresh``: on a connection of its own, closed afterwards."""
        with self._lock:
            if fresh:
                conn = self._connect()
                try:
                    return self._send(conn, body, headers, reused=False)
                finally:
                    conn.close()
            reused = self._conn is not None
            if self._conn is None:
                self._conn = self._connect()
            try:
                answer = self._send(self._conn, body, headers, reused=reused)
            except _Lost as exc:
                self._drop()
                if reused and not exc.timed_out:
                    # the server closed the idle connection: a read is simply asked again on a new one
                    self._conn = self._connect()
                    return self._send(self._conn, body, headers, reused=False)
                raise
            return answer

    def _send(self, conn: http.client.HTTPConnection, body: bytes, headers: Dict[str, str], reused: bool) -> Answer:
        try:
            conn.request("POST", self.path, body=body, headers=headers)
            resp = conn.getresponse()
            data = resp.read()
        except socket.timeout:
            conn.close()
            raise _Lost("no answer within %g s" % self.timeout_s, timed_out=True) from None
        except (http.client.HTTPException, OSError) as exc:
            conn.close()
            what = type(exc).__name__ if not str(exc) else "%s: %s" % (type(exc).__name__, exc)
            raise _Lost("the connection was lost before an answer came (%s)" % what, timed_out=False) from None
        if resp.will_close:
            conn.close()
            if conn is self._conn:
                self._conn = None
        media = (resp.getheader("Content-Type") or "").split(";")[0].strip().lower()
        return Answer(resp.status, resp.reason or "", media, data, resp.getheader("Location") or "",
                      resp.getheader("Server") or "")


def _without_credentials(parts) -> str:
    """The URL as it may be printed: user and password left out."""
    netloc = parts.netloc.rsplit("@", 1)[-1]
    return "%s://%s%s%s" % (parts.scheme, netloc, parts.path, "?" + parts.query if parts.query else "")
