"""A real SPARQL 1.1 server for tests: ``oxigraph serve`` (PyPI package ``oxigraph``) on a free loopback port.

``OxigraphServer(location)`` starts nothing; :meth:`~OxigraphServer.start` runs the server on a free port of
127.0.0.1 with its data in ``location`` and returns once it answers a query; :meth:`~OxigraphServer.kill` ends it
at once (``SIGKILL``, as a power loss would), :meth:`~OxigraphServer.stop` politely; :meth:`~OxigraphServer.start`
again serves the same data on the same port, so clients can reconnect. Used as a context manager it is killed at
the end. The binary is found next to the running interpreter (the venv's ``bin/``) or on ``PATH``.
"""
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
from typing import List, Optional


def oxigraph_binary() -> str:
    """Path of the ``oxigraph`` CLI; RuntimeError saying how to install it when missing."""
    here = os.path.join(os.path.dirname(sys.executable), "oxigraph")
    if os.access(here, os.X_OK):
        return here
    found = shutil.which("oxigraph")
    if found:
        return found
    raise RuntimeError("the oxigraph server binary is not installed (pip install 'oxigraph>=0.5,<0.6'; "
                       "tools/setup.sh does it from requirements.txt)")


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port nobody listens on right now (the kernel's choice)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


class OxigraphServer:
    """One ``oxigraph serve`` process; see the module docstring. ``extra`` are further CLI options
    (e.g. ``["--union-default-graph"]``)."""

    def __init__(self, location: str, host: str = "127.0.0.1", port: Optional[int] = None,
                 extra: Optional[List[str]] = None, start_timeout_s: float = 20.0) -> None:
        self.location = location
        self.host = host
        self.port = port
        self.extra = list(extra or [])
        self.start_timeout_s = start_timeout_s
        self.proc: Optional[subprocess.Popen] = None
        self._log_path = os.path.join(os.path.dirname(os.path.abspath(location)),
                                      os.path.basename(location.rstrip("/")) + ".server.log")

    @property
    def base_url(self) -> str:
        return "http://%s:%d" % (self.host, self.port or 0)

    @property
    def query_url(self) -> str:
        return self.base_url + "/query"

    @property
    def update_url(self) -> str:
        return self.base_url + "/update"

    def start(self) -> "OxigraphServer":
        """Start (or start again) and wait until the server answers ``ASK {}``; RuntimeError with its log if not."""
        if self.proc is not None and self.proc.poll() is None:
            return self
        tries = 3 if self.port is None else 1
        for attempt in range(tries):
            if self.port is None or attempt > 0:
                self.port = free_port(self.host)
            os.makedirs(self.location, exist_ok=True)
            log = open(self._log_path, "ab")
            try:
                self.proc = subprocess.Popen(
                    [oxigraph_binary(), "serve", "--location", self.location, "--bind",
                     "%s:%d" % (self.host, self.port)] + self.extra,
                    stdout=log, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
            finally:
                log.close()
            if self._wait_ready():
                return self
            self.kill()
        raise RuntimeError("oxigraph serve did not answer on %s within %g s; its log:\n%s"
                           % (self.base_url, self.start_timeout_s, self.log()[-2000:]))

    def _wait_ready(self) -> bool:
        deadline = time.monotonic() + self.start_timeout_s
        body = urllib.parse.urlencode({"query": "ASK {}"}).encode("ascii")
        while time.monotonic() < deadline:
            if self.proc is None or self.proc.poll() is not None:
                return False  # it died (e.g. the port was taken after all)
            try:
                req = urllib.request.Request(self.query_url, data=body,
                                             headers={"Accept": "application/sparql-results+json"})
                with urllib.request.urlopen(req, timeout=1.0) as resp:
                    if resp.status == 200:
                        return True
            except (urllib.error.URLError, OSError):
                pass
            time.sleep(0.05)
        return False

    def kill(self) -> None:
        """End the server at once (SIGKILL) and reap it."""
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.send_signal(signal.SIGKILL)
            self.proc.wait(timeout=10)
            self.proc = None

    def stop(self) -> None:
        """End the server politely (SIGTERM, then SIGKILL after 5 s)."""
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.terminate()
                try:
                    self.proc.wait(timeout=5)
                except subprocess.TimeoutExpired:
                    pass
            self.kill()

    def log(self) -> str:
        try:
            with open(self._log_path, "r", encoding="utf-8", errors="replace") as fh:
                return fh.read()
        except OSError:
            return ""

    def __enter__(self) -> "OxigraphServer":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.kill()


def clear_server(server: OxigraphServer) -> None:
    """Empty every graph of ``server`` (``DROP ALL``)."""
    body = urllib.parse.urlencode({"update": "DROP ALL"}).encode("ascii")
    with urllib.request.urlopen(urllib.request.Request(server.update_url, data=body), timeout=10):
        pass
