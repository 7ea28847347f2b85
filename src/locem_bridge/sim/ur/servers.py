"""The three TCP servers of the stand-in (dashboard 29999, script 30003, RTDE 30004) on one selector thread.

Lifecycle: :class:`NetLoop` is created by the controller with the listening addresses, ``start()`` binds and starts
its I/O thread (a port it cannot bind raises :class:`~.errors.ListenError` naming address, port and reason), ``close()`` closes every socket and joins the thread. Incoming bytes of every connection are handled
on the I/O thread; RTDE data packages are streamed from the controller's control thread through
:meth:`RtdeConnection.send`, which queues into a per-connection buffer flushed without blocking (a client that stops
reading for more than ``SLOW_CLIENT_BYTES`` of backlog is dropped, as a real controller drops a stalled client).
"""
import logging
import re
import selectors
import socket
import struct
import threading
from typing import Callable, Dict, List, Optional, Set, Tuple

from .errors import ListenError
from .rtde_vars import InputRecipe, OutputRecipe

LOG = logging.getLogger("locem_bridge.sim.ur")

RTDE_REQUEST_PROTOCOL_VERSION = 86   # 'V'
RTDE_GET_URCONTROL_VERSION = 118     # 'v'
RTDE_TEXT_MESSAGE = 77               # 'M'
RTDE_DATA_PACKAGE = 85               # 'U'
RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS = 79  # 'O'
RTDE_CONTROL_PACKAGE_SETUP_INPUTS = 73   # 'I'
RTDE_CONTROL_PACKAGE_START = 83      # 'S'
RTDE_CONTROL_PACKAGE_PAUSE = 80      # 'P'

SLOW_CLIENT_BYTES = 1 << 20
MAX_DASHBOARD_LINE = 4096
MAX_SCRIPT_BYTES = 4 << 20
MAX_OUTPUT_FREQUENCY = 500.0

_H = struct.Struct(">H")
_HB = struct.Struct(">HB")


def _frame(ptype: int, payload: bytes) -> bytes:
    return _HB.pack(len(payload) + 3, ptype) + payload


class Connection:
    """One accepted client socket with a non-blocking, lock-protected output buffer."""

    kind = "connection"

    def __init__(self, loop: "NetLoop", sock: socket.socket, peer: Tuple[str, int]) -> None:
        self.loop = loop
        self.sock = sock
        self.peer = peer
        self.closed = False
        self._out = bytearray()
        self._send_lock = threading.Lock()

    def send(self, data) -> bool:
        """Queue ``data`` and flush what the socket accepts now. False when the connection is (now) closed."""
        with self._send_lock:
            if self.closed:
                return False
            if self._out:
                self._out += data
                data = self._out
            try:
                n = self.sock.send(data)
            except (BlockingIOError, InterruptedError):
                n = 0
            except OSError:
                self.loop.defer_close(self, "send failed")
                return False
            if n < len(data):
                if data is self._out:
                    del self._out[:n]
                else:
                    self._out += memoryview(data)[n:]
                if len(self._out) > SLOW_CLIENT_BYTES:
                    self.loop.defer_close(self, "client does not read (%d bytes backlog)" % len(self._out))
                    return False
            elif data is self._out:
                self._out.clear()
            return True

    def on_data(self, data: bytes) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def on_close(self) -> None:
        pass


class DashboardConnection(Connection):
    kind = "dashboard"

    def __init__(self, loop: "NetLoop", sock: socket.socket, peer: Tuple[str, int]) -> None:
        super().__init__(loop, sock, peer)
        self._buf = bytearray()
        self.send(b"Connected: Universal Robots Dashboard Server\n")

    def on_data(self, data: bytes) -> None:
        self._buf += data
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                if len(self._buf) > MAX_DASHBOARD_LINE:
                    line = bytes(self._buf)
                    self._buf.clear()
                    self._answer(line)
                return
            line = bytes(self._buf[:i])
            del self._buf[:i + 1]
            if not self._answer(line):
                return

    def _answer(self, raw: bytes) -> bool:
        text = raw.decode("utf-8", errors="replace").strip("\r ")
        reply, keep = self.loop.dashboard_handler(text)
        self.send((reply + "\n").encode("utf-8", errors="replace"))
        if not keep:
            self.loop.defer_close(self, "quit")
        return keep


_STATEMENT = re.compile(r"^\s*[A-Za-z_][A-Za-z0-9_]*\s*(\(.*\)|=.*|\[.*\]\s*=.*)\s*$")
_HEADER = re.compile(r"^(def|sec)\s+[A-Za-z_][A-Za-z0-9_]*\s*\(\s*\)\s*:\s*$")


class ScriptConnection(Connection):
    """Port 30003: collects URScript text; every complete top-level program is handed to the script handler."""

    kind = "script"

    def __init__(self, loop: "NetLoop", sock: socket.socket, peer: Tuple[str, int]) -> None:
        super().__init__(loop, sock, peer)
        self._buf = bytearray()
        self._program: List[str] = []

    def on_data(self, data: bytes) -> None:
        if len(self._buf) + len(data) > MAX_SCRIPT_BYTES:
            self.loop.refuse("script port %s: more than %d bytes without a complete program; connection closed"
                             % (self.peer[0], MAX_SCRIPT_BYTES))
            self.loop.defer_close(self, "script too large")
            return
        self._buf += data
        while True:
            i = self._buf.find(b"\n")
            if i < 0:
                return
            raw = bytes(self._buf[:i])
            del self._buf[:i + 1]
            self._line(raw)

    def _line(self, raw: bytes) -> None:
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError:
            line = None
        if line is None or any((ord(c) < 32 and c not in "\t\r") for c in line):
            self.loop.refuse("script port %s: binary data is not URScript (%r...)" % (self.peer[0], raw[:40]))
            self._program = []
            return
        line = line.rstrip("\r")
        if self._program:
            self._program.append(line)
            if line.rstrip() == "end":
                text = "\n".join(self._program) + "\n"
                self._program = []
                self.loop.script_handler(text)
            return
        if not line.strip() or line.lstrip().startswith("#"):
            return
        if _HEADER.match(line):
            self._program = [line]
        elif _STATEMENT.match(line):
            self.loop.script_handler(line + "\n")
        else:
            self.loop.refuse("script port %s: syntax error in URScript line %r" % (self.peer[0], line[:80]))


class RtdeConnection(Connection):
    """One RTDE client: handshake state, its recipes, and its claims on input variables."""

    kind = "rtde"

    def __init__(self, loop: "NetLoop", sock: socket.socket, peer: Tuple[str, int]) -> None:
        super().__init__(loop, sock, peer)
        self._buf = bytearray()
        self.protocol_version = 1
        self.outputs: List[OutputRecipe] = []
        self.inputs: Dict[int, InputRecipe] = {}
        self.next_input_id = 1
        self.next_output_id = 1
        self.claims: Set[str] = set()
        self.started = False
        self._trailing_noted: Set[Tuple[int, int]] = set()

    def on_data(self, data: bytes) -> None:
        buf = self._buf
        buf += data
        while len(buf) >= 3:
            size = _H.unpack_from(buf, 0)[0]
            if size < 3:
                self.loop.refuse("RTDE %s: malformed package (size field %d < 3); connection closed"
                                 % (self.peer[0], size))
                self.loop.defer_close(self, "malformed RTDE framing")
                buf.clear()
                return
            if len(buf) < size:
                return
            ptype = buf[2]
            payload = bytes(buf[3:size])
            del buf[:size]
            self._package(ptype, payload)

    def _package(self, ptype: int, payload: bytes) -> None:
        loop = self.loop
        if ptype == RTDE_DATA_PACKAGE:
            if not payload:
                loop.refuse("RTDE %s: data package without recipe id" % self.peer[0])
                return
            rid = payload[0]
            recipe = self.inputs.get(rid)
            if recipe is None or not recipe.valid:
                loop.refuse("RTDE %s: data package for unknown or failed input recipe %d" % (self.peer[0], rid))
                return
            n = len(payload) - 1
            if n < recipe.payload_size:
                loop.refuse("RTDE %s: data package for recipe %d has %d bytes, expected %d; ignored"
                            % (self.peer[0], rid, n, recipe.payload_size))
                return
            if n > recipe.payload_size:
                # The controller reads the recipe's fields and ignores the rest. ur_rtde 1.6.5 relies on it:
                # getForwardKinematics(q, tcp_offset) sends 12 doubles with the 6-double recipe.
                self._note_trailing(rid, n, recipe.payload_size)
            loop.input_handler(recipe.decode(payload[1:1 + recipe.payload_size]))
        elif ptype == RTDE_REQUEST_PROTOCOL_VERSION:
            if len(payload) != 2:
                loop.refuse("RTDE %s: protocol version request with %d bytes" % (self.peer[0], len(payload)))
                self.send(_frame(ptype, b"\x00"))
                return
            version = _H.unpack(payload)[0]
            ok = version in (1, 2)
            if ok:
                self.protocol_version = version
            else:
                loop.refuse("RTDE %s: protocol version %d not supported (1 or 2)" % (self.peer[0], version))
            self.send(_frame(ptype, b"\x01" if ok else b"\x00"))
        elif ptype == RTDE_GET_URCONTROL_VERSION:
            self.send(_frame(ptype, struct.pack(">IIII", *loop.controller_version)))
        elif ptype == RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS:
            self._setup_outputs(payload)
        elif ptype == RTDE_CONTROL_PACKAGE_SETUP_INPUTS:
            self._setup_inputs(payload)
        elif ptype == RTDE_CONTROL_PACKAGE_START:
            ok = any(r.valid for r in self.outputs)
            if not ok:
                loop.refuse("RTDE %s: start without a valid output recipe" % self.peer[0])
            self.started = ok
            self.send(_frame(ptype, b"\x01" if ok else b"\x00"))
        elif ptype == RTDE_CONTROL_PACKAGE_PAUSE:
            self.started = False
            self.send(_frame(ptype, b"\x01"))
        elif ptype == RTDE_TEXT_MESSAGE:
            LOG.info("RTDE %s text message: %r", self.peer[0], payload[:200])
        else:
            loop.refuse("RTDE %s: unknown package type %d (%r), ignored" % (self.peer[0], ptype, chr(ptype)
                                                                           if 32 <= ptype < 127 else "?"))

    def _note_trailing(self, rid: int, n: int, expected: int) -> None:
        key = (rid, n)
        if key not in self._trailing_noted:
            self._trailing_noted.add(key)
            LOG.info("RTDE %s: data package for recipe %d has %d bytes, the recipe %d; extra bytes ignored",
                     self.peer[0], rid, n, expected)

    @staticmethod
    def _names(raw: bytes) -> List[str]:
        text = raw.decode("utf-8", errors="replace")
        return [n.strip() for n in text.split(",") if n.strip()]

    def _setup_outputs(self, payload: bytes) -> None:
        loop = self.loop
        if self.protocol_version >= 2:
            if len(payload) < 8:
                loop.refuse("RTDE %s: output setup too short (%d bytes)" % (self.peer[0], len(payload)))
                self.send(_frame(RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS, b"\x00"))
                return
            freq = struct.unpack(">d", payload[:8])[0]
            names = self._names(payload[8:])
        else:
            freq, names = 125.0, self._names(payload)
        rid = self.next_output_id
        recipe = OutputRecipe(rid, names, freq if freq > 0 else 0.0, loop.control_rate)
        LOG.debug("RTDE %s: output recipe %d at %g Hz = %s", self.peer[0], rid, freq, ",".join(names))
        bad_freq = not (0 < freq <= MAX_OUTPUT_FREQUENCY)
        if bad_freq:
            loop.refuse("RTDE %s: output frequency %r outside (0, %g] Hz" % (self.peer[0], freq,
                                                                             MAX_OUTPUT_FREQUENCY))
        if not recipe.valid:
            loop.refuse("RTDE %s: output setup NOT_FOUND for %s" % (self.peer[0], recipe.missing or "(no names)"))
        if recipe.valid and not bad_freq:
            self.next_output_id += 1
            self.outputs.append(recipe)
            reply_id = rid
        else:
            reply_id = 0
        body = bytes([reply_id]) + ",".join(recipe.types).encode()
        self.send(_frame(RTDE_CONTROL_PACKAGE_SETUP_OUTPUTS, body))

    def _setup_inputs(self, payload: bytes) -> None:
        loop = self.loop
        names = self._names(payload)
        rid = self.next_input_id
        self.next_input_id += 1          # clients number input recipes 1, 2, 3 ... whatever the answer
        in_use = loop.claimed_by_others(self, names)
        recipe = InputRecipe(rid, names, in_use)
        LOG.debug("RTDE %s: input recipe %d = %s", self.peer[0], rid, ",".join(names))
        if recipe.valid:
            self.inputs[rid] = recipe
            self.claims.update(names)
            reply_id = rid
        else:
            bad = [n + "=" + t for n, t in zip(names, recipe.types) if t in ("NOT_FOUND", "IN_USE")]
            loop.refuse("RTDE %s: input setup refused: %s" % (self.peer[0], bad or "(no names)"))
            reply_id = 0
        body = bytes([reply_id]) + ",".join(recipe.types).encode()
        self.send(_frame(RTDE_CONTROL_PACKAGE_SETUP_INPUTS, body))

    def stream(self, values: Dict[str, tuple], tick: int) -> None:
        """Send every output recipe that is due at control cycle ``tick`` (called on the control thread)."""
        for r in self.outputs:
            if tick % r.decimation == 0:
                if not self.send(r.pack(values)):
                    return


class NetLoop:
    """Selector thread serving the dashboard, script and RTDE ports of one controller address."""

    def __init__(self, address: str, ports: Dict[str, int], control_rate: float,
                 controller_version: Tuple[int, int, int, int],
                 dashboard_handler: Callable[[str], Tuple[str, bool]],
                 script_handler: Callable[[str], None],
                 input_handler: Callable[[list], None],
                 refuse: Callable[[str], None]) -> None:
        self.address = address
        self.ports = ports
        self.control_rate = control_rate
        self.controller_version = controller_version
        self.dashboard_handler = dashboard_handler
        self.script_handler = script_handler
        self.input_handler = input_handler
        self.refuse = refuse
        self.rtde_clients: List[RtdeConnection] = []
        self._conns: Dict[socket.socket, Connection] = {}
        self._listeners: Dict[socket.socket, type] = {}
        self._sel: Optional[selectors.BaseSelector] = None
        self._thread: Optional[threading.Thread] = None
        self._stop = threading.Event()
        self._to_close: List[Tuple[Connection, str]] = []
        self._close_lock = threading.Lock()
        self._wake_r: Optional[socket.socket] = None
        self._wake_w: Optional[socket.socket] = None

    def start(self) -> None:
        self._stop.clear()
        self._sel = selectors.DefaultSelector()
        kinds = {"dashboard": DashboardConnection, "script": ScriptConnection, "rtde": RtdeConnection}
        name, port = "", 0
        try:
            for name, port in self.ports.items():
                ls = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
                ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                self._listeners[ls] = kinds[name]
                ls.bind((self.address, port))
                ls.listen(8)
                ls.setblocking(False)
                self._sel.register(ls, selectors.EVENT_READ)
        except OSError as exc:
            self._close_sockets()
            raise ListenError("UR controller stand-in cannot listen on %s:%d (%s port): %s"
                              % (self.address, port, name, exc.strerror or exc)) from exc
        self._wake_r, self._wake_w = socket.socketpair()
        self._wake_r.setblocking(False)
        self._sel.register(self._wake_r, selectors.EVENT_READ)
        self._thread = threading.Thread(target=self._run, name="ur-standin-io-%s" % self.address, daemon=True)
        self._thread.start()

    def close(self) -> None:
        self._stop.set()
        if self._wake_w is not None:
            try:
                self._wake_w.send(b"x")
            except OSError:
                pass
        if self._thread is not None:
            self._thread.join(timeout=5.0)
            self._thread = None
        self._close_sockets()

    def _close_sockets(self) -> None:
        for c in list(self._conns.values()):
            self._drop(c, "controller stopped")
        for ls in list(self._listeners):
            try:
                if self._sel is not None:
                    self._sel.unregister(ls)
            except (KeyError, ValueError):
                pass
            ls.close()
        self._listeners.clear()
        for s in (self._wake_r, self._wake_w):
            if s is not None:
                s.close()
        self._wake_r = self._wake_w = None
        if self._sel is not None:
            self._sel.close()
            self._sel = None
        self.rtde_clients = []

    def claimed_by_others(self, me: RtdeConnection, names: List[str]) -> Set[str]:
        taken: Set[str] = set()
        for c in self.rtde_clients:
            if c is not me and not c.closed:
                taken |= c.claims
        return {n for n in names if n in taken}

    def defer_close(self, conn: Connection, reason: str) -> None:
        with self._close_lock:
            self._to_close.append((conn, reason))
        if threading.current_thread() is not self._thread and self._wake_w is not None:
            try:
                self._wake_w.send(b"c")
            except OSError:
                pass

    def _drop(self, conn: Connection, reason: str) -> None:
        with conn._send_lock:
            if conn.closed:
                return
            conn.closed = True
        LOG.info("UR stand-in %s: %s connection from %s closed (%s)", self.address, conn.kind, conn.peer[0],
                 reason)
        try:
            if self._sel is not None:
                self._sel.unregister(conn.sock)
        except (KeyError, ValueError):
            pass
        self._conns.pop(conn.sock, None)
        if isinstance(conn, RtdeConnection):
            self.rtde_clients = [c for c in self.rtde_clients if c is not conn]
        try:
            conn.sock.close()
        except OSError:
            pass
        conn.on_close()

    def _run(self) -> None:
        sel = self._sel
        while not self._stop.is_set():
            try:
                events = sel.select(timeout=0.5)
            except (OSError, ValueError):
                break
            for key, _mask in events:
                s = key.fileobj
                if s is self._wake_r:
                    try:
                        s.recv(4096)
                    except OSError:
                        pass
                elif s in self._listeners:
                    self._accept(s)
                else:
                    conn = self._conns.get(s)
                    if conn is None:
                        continue
                    try:
                        data = s.recv(65536)
                    except (BlockingIOError, InterruptedError):
                        continue
                    except OSError as exc:
                        self._drop(conn, str(exc))
                        continue
                    if not data:
                        self._drop(conn, "peer closed")
                        continue
                    try:
                        conn.on_data(data)
                    except Exception:   # never let one client's bytes stop the server
                        LOG.exception("UR stand-in: error handling %s data", conn.kind)
                        self.refuse("%s %s: input caused an internal error; connection closed"
                                    % (conn.kind, conn.peer[0]))
                        self._drop(conn, "internal error")
            with self._close_lock:
                pending, self._to_close = self._to_close, []
            for conn, reason in pending:
                self._drop(conn, reason)

    def _accept(self, ls: socket.socket) -> None:
        try:
            sock, peer = ls.accept()
        except (BlockingIOError, InterruptedError, OSError):
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        conn = self._listeners[ls](self, sock, peer)
        self._conns[sock] = conn
        self._sel.register(sock, selectors.EVENT_READ)
        if isinstance(conn, RtdeConnection):
            self.rtde_clients = self.rtde_clients + [conn]
        LOG.debug("UR stand-in %s: %s connection from %s", self.address, conn.kind, peer)
