"""Open the python-can bus of ``robot.base.drives.can`` as a CAN master sees it.

``socketcan`` (hardware, vcan) and ``virtual`` (one process) buses behave like a CAN controller: a sender does not
receive its own frames. python-can's ``udp_multicast`` bus (the simulated worksite across processes) hands every
socket in the group every datagram, its own included; :class:`NoEchoBus` drops those echoes (each sent frame is
expected back once within ``window`` s), otherwise canopen's RPDO maps would take the echo of an older command
as new data.
"""

import collections
import threading
import time
from typing import Any, Deque, Dict, Mapping, Optional, Tuple

import can

from .errors import BridgeConfigError, LinkDown

_Key = Tuple[int, bytes, bool, bool]


def _key(msg: can.Message) -> _Key:
    return (msg.arbitration_id, bytes(msg.data), bool(msg.is_extended_id), bool(msg.is_remote_frame))


class NoEchoBus(can.BusABC):
    """Wraps a bus that echoes the sender's own frames and removes the echoes."""

    def __init__(self, inner: can.BusABC, window: float = 1.0) -> None:
        self._inner = inner
        self._window = window
        self._sent: Deque[Tuple[float, _Key]] = collections.deque()
        self._counts: Dict[_Key, int] = collections.Counter()
        self._guard = threading.Lock()
        self.channel_info = "no-echo %s" % getattr(inner, "channel_info", "")
        super().__init__(channel=getattr(inner, "channel", None))

    def _expire(self, now: float) -> None:
        while self._sent and now - self._sent[0][0] > self._window:
            _, key = self._sent.popleft()
            if self._counts.get(key, 0) > 0:
                self._counts[key] -= 1

    def send(self, msg: can.Message, timeout: Optional[float] = None) -> None:
        with self._guard:
            now = time.monotonic()
            self._expire(now)
            key = _key(msg)
            self._sent.append((now, key))
            self._counts[key] = self._counts.get(key, 0) + 1
        self._inner.send(msg, timeout)

    def _recv_internal(self, timeout: Optional[float]) -> Any:
        end = None if timeout is None else time.monotonic() + timeout
        while True:
            msg = self._inner.recv(None if end is None else max(0.0, end - time.monotonic()))
            if msg is None:
                return None, False
            key = _key(msg)
            with self._guard:
                if self._counts.get(key, 0) > 0:        # our own frame coming back: drop it
                    self._counts[key] -= 1
                    for i, (_, k) in enumerate(self._sent):
                        if k == key:
                            del self._sent[i]
                            break
                    continue
            return msg, False

    def shutdown(self) -> None:
        super().shutdown()
        self._inner.shutdown()


def open_master_bus(can_cfg: Mapping[str, Any]) -> can.BusABC:
    """The bus named by ``interface``, ``channel`` (+ ``bitrate`` for hardware, ``port`` for udp_multicast)."""
    interface = can_cfg.get("interface")
    if interface not in ("socketcan", "virtual", "udp_multicast", "pcan", "kvaser", "slcan"):
        raise BridgeConfigError("robot.base.drives.can.interface = %r; allowed: socketcan, virtual, udp_multicast, "
                                "pcan, kvaser, slcan" % (interface,))
    kwargs: Dict[str, Any] = {"interface": interface, "channel": can_cfg.get("channel")}
    if interface == "udp_multicast":
        kwargs["fd"] = False
        if "port" in can_cfg:
            kwargs["port"] = int(can_cfg["port"])
    elif interface == "virtual":
        kwargs["receive_own_messages"] = False
    elif "bitrate" in can_cfg:
        kwargs["bitrate"] = int(can_cfg["bitrate"])
    try:
        bus = can.Bus(**kwargs)
    except Exception as error:
        raise LinkDown("cannot open CAN bus %s: %s" % (kwargs, error), device="base")
    return NoEchoBus(bus) if interface == "udp_multicast" else bus
