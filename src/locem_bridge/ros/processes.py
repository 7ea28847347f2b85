"""Start and stop ROS processes (a private master, nodes, launch files) for the main job and benchmarks.

Everything started here runs in its own process group and is terminated (then killed) on ``close()``, so an
interrupted run leaves no node behind.
"""

import os
import signal
import socket
import subprocess
import time
from typing import AbstractSet, Dict, List, Optional, Sequence


def free_port(avoid: AbstractSet[int] = frozenset()) -> int:
    """A TCP port free on 127.0.0.1 now and not in ``avoid`` (e.g. ports other runs have claimed)."""
    while True:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.bind(("127.0.0.1", 0))
            port = int(sock.getsockname()[1])
        if port not in avoid:
            return port


class RosProcesses:
    """A ROS master (reused when one answers at ``master_uri``, else started) and the processes started with it."""

    def __init__(self, port: Optional[int] = None, log_dir: Optional[str] = None) -> None:
        self.port = port or free_port()
        self.env: Dict[str, str] = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % self.port,
                                        ROS_IP="127.0.0.1")
        self.env.pop("ROS_HOSTNAME", None)
        self.log_dir = log_dir
        self._children: List[subprocess.Popen] = []
        self._logs: List[object] = []

    def __enter__(self) -> "RosProcesses":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def master_running(self) -> bool:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
            sock.settimeout(0.2)
            return sock.connect_ex(("127.0.0.1", self.port)) == 0

    def start_master(self, timeout: float = 20.0) -> None:
        if self.master_running():
            return
        self.spawn(["roscore", "-p", str(self.port)], "roscore")
        end = time.monotonic() + timeout
        while not self.master_running():
            if time.monotonic() > end:
                raise RuntimeError("roscore did not come up on port %d within %.0f s" % (self.port, timeout))
            time.sleep(0.1)
        self.wait_for(["rosparam", "get", "/rosdistro"], timeout)

    def spawn(self, argv: Sequence[str], name: str) -> subprocess.Popen:
        if self.log_dir:
            os.makedirs(self.log_dir, exist_ok=True)
            out = open(os.path.join(self.log_dir, name + ".log"), "w")
            self._logs.append(out)
        else:
            out = subprocess.DEVNULL  # type: ignore[assignment]
        child = subprocess.Popen(list(argv), env=self.env, stdout=out, stderr=subprocess.STDOUT,
                                 stdin=subprocess.DEVNULL, start_new_session=True)
        self._children.append(child)
        return child

    def wait_for(self, argv: Sequence[str], timeout: float) -> None:
        """Repeat a command (e.g. ``rosservice info NAME``) until it succeeds."""
        end = time.monotonic() + timeout
        while True:
            if subprocess.run(list(argv), env=self.env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL).returncode == 0:
                return
            if time.monotonic() > end:
                raise RuntimeError("timed out after %.0f s waiting for: %s" % (timeout, " ".join(argv)))
            time.sleep(0.2)

    def wait_for_service(self, name: str, timeout: float = 30.0) -> None:
        self.wait_for(["rosservice", "type", name], timeout)

    def close(self) -> None:
        for child in reversed(self._children):
            if child.poll() is None:
                try:
                    os.killpg(child.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        end = time.monotonic() + 10.0
        for child in reversed(self._children):
            try:
                child.wait(max(0.1, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                try:
                    os.killpg(child.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                child.wait(5)
        self._children.clear()
        for handle in self._logs:
            handle.close()  # type: ignore[attr-defined]
        self._logs.clear()
