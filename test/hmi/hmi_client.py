"""A tiny HTTP client over http.client for the HMI tests (real sockets, raw control over headers and bodies)."""
import http.client
import json
from typing import Any, Dict, Optional
from urllib.parse import urlsplit


class Reply:
    def __init__(self, status: int, headers: Dict[str, str], body: bytes) -> None:
        self.status = status
        self.headers = headers
        self.body = body

    @property
    def json(self) -> Any:
        return json.loads(self.body.decode("utf-8"))

    @property
    def error(self) -> Dict[str, Any]:
        return self.json["error"]

    def __repr__(self) -> str:
        return "Reply(%d, %r)" % (self.status, self.body[:200])


def request(url: str, method: str, path: str, body: Any = None, raw: Optional[bytes] = None,
            headers: Optional[Dict[str, str]] = None, timeout: float = 10.0) -> Reply:
    """``body`` is sent as JSON with the JSON content type; ``raw`` is sent as given (headers as given)."""
    parts = urlsplit(url)
    conn = http.client.HTTPConnection(parts.hostname, parts.port, timeout=timeout)
    hdrs = dict(headers or {})
    data = raw
    if body is not None:
        data = json.dumps(body).encode("utf-8")
        hdrs.setdefault("Content-Type", "application/json")
    try:
        conn.request(method, path, body=data, headers=hdrs)
        resp = conn.getresponse()
        return Reply(resp.status, {k.lower(): v for k, v in resp.getheaders()}, resp.read())
    finally:
        conn.close()


def get(url: str, path: str, **kw: Any) -> Reply:
    return request(url, "GET", path, **kw)


def post(url: str, path: str, body: Any = None, **kw: Any) -> Reply:
    return request(url, "POST", path, body=body, **kw)


def state(url: str) -> Dict[str, Any]:
    r = get(url, "/api/state")
    assert r.status == 200, r
    return r.json


def wait_state(url: str, predicate: Any, timeout: float = 5.0) -> Dict[str, Any]:
    """Poll /api/state until ``predicate(doc)`` holds (bounded); returns the doc or fails with the last one."""
    import time
    end = time.monotonic() + timeout
    doc: Dict[str, Any] = {}
    while time.monotonic() < end:
        doc = state(url)
        if predicate(doc):
            return doc
        time.sleep(0.02)
    raise AssertionError("state never satisfied the condition; last: %r" % (doc,))


def serving(url: str) -> bool:
    r = get(url, "/api/state")
    return r.status == 200 and "snapshot" in r.json

