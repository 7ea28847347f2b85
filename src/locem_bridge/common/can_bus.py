"""Open the python-can bus of ``robot.base.drives.can``, the one way for the base bridge and the simulated drives.

``interface`` is one of :data:`CAN_INTERFACES`:

* ``socketcan``      a Linux CAN device (hardware or ``vcan``); its ``bitrate`` is passed on (set with ``ip link``)
* ``virtual``        python-can's in-process bus (one process: tests, a simulator and its master in one program)
* ``udp_multicast``  python-can's bus over UDP multicast on loopback (the simulated worksite across processes)

``socketcan`` and ``virtual`` buses behave like a CAN controller: a sender does not receive its own frames.
``udp_multicast`` hands every socket in the group every datagram, its own included; :func:`open_bus` wraps it in a
filter that drops those echoes (each sent frame is expected back once within ``window`` s, as a real controller
would never show it), otherwise canopen's RPDO maps would take the echo of an older command as new data.

python-can is imported inside the functions, so importing this module costs nothing. Errors are
:class:`CanInterfaceError` (the file names an interface that is not allowed) and :class:`CanOpenError` (the bus
named cannot be opened); each layer turns them into its own error type.
"""
import collections
import threading
import time
from typing import Any, Deque, Dict, Mapping, Optional, Tuple

CAN_INTERFACES = ("virtual", "udp_multicast", "socketcan")
"""The interfaces a robot file may name for ``robot.base.drives.can.interface``."""

SHARED_INTERFACES = ("udp_multicast", "socketcan")
"""The interfaces whose bus another process can open too (``virtual`` lives inside one process)."""

CAN_KEY = "robot.base.drives.can"


class CanBusError(Exception):
    """The CAN bus of a robot file cannot be used; the message names the bus and what is allowed."""


class CanInterfaceError(CanBusError, ValueError):
    """``interface`` is not one of :data:`CAN_INTERFACES`."""

    def __init__(self, interface: Any, key: str = CAN_KEY) -> None:
        self.interface, self.key, self.allowed = interface, key + ".interface", CAN_INTERFACES
        self.problem = "%r is not a CAN interface this package opens" % (interface,)
        super().__init__("%s: %s (allowed: %s)" % (self.key, self.problem, ", ".join(CAN_INTERFACES)))


class CanOpenError(CanBusError, OSError):
    """python-can could not open the bus named (no such device, port taken, ...)."""


def bus_name(can_cfg: Mapping[str, Any]) -> str:
    """``udp_multicast 239.74.163.2:43114``, ``socketcan can0``: the bus as a person names it in a message."""
    port = (":%s" % can_cfg["port"]) if can_cfg.get("interface") == "udp_multicast" and "port" in can_cfg else ""
    return "%s %s%s" % (can_cfg.get("interface"), can_cfg.get("channel"), port)


def bus_kwargs(can_cfg: Mapping[str, Any], key: str = CAN_KEY) -> Dict[str, Any]:
    """The ``can.Bus`` keyword arguments for ``can_cfg`` (interface, channel, optional port / bitrate).

    Raises :class:`CanInterfaceError` for an interface outside :data:`CAN_INTERFACES`.
    """
    interface = can_cfg.get("interface")
    if interface not in CAN_INTERFACES:
        raise CanInterfaceError(interface, key)
    kwargs: Dict[str, Any] = {"interface": interface, "channel": can_cfg.get("channel")}
    if interface == "udp_multicast":
        kwargs["fd"] = False
        if "port" in can_cfg:
            kwargs["port"] = int(can_cfg["port"])
    elif interface == "virtual":
        kwargs["receive_own_messages"] = False
    elif "bitrate" in can_cfg:
        kwargs["bitrate"] = int(can_cfg["bitrate"])
    return kwargs


def open_bus(can_cfg: Mapping[str, Any], key: str = CAN_KEY) -> Any:
    """The ``can.BusABC`` named by ``can_cfg``, as a CAN controller shows it: without the sender's own frames.

    Raises :class:`CanInterfaceError` (interface not allowed) or :class:`CanOpenError` (the bus cannot be opened;
    the message names the bus and python-can's reason).
    """
    import can

    kwargs = bus_kwargs(can_cfg, key)
    try:
        bus = can.Bus(**kwargs)
    except Exception as exc:
        reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise CanOpenError("CAN bus %s cannot be opened: %s" % (bus_name(can_cfg), reason))
    return own_echo_filter()(bus) if kwargs["interface"] == "udp_multicast" else bus


_Key = Tuple[int, bytes, bool, bool]
_FILTER_CLASS: Dict[str, Any] = {}


def own_echo_filter() -> Any:
    """The class ``OwnEchoFilterBus(inner, window=1.0)``: a ``can.BusABC`` around ``inner`` that drops the frames
    ``inner`` hands back to their own sender.

    Each sent frame is expected back once: a received frame equal (id, data, flags) to a pending sent one is
    dropped and that entry consumed; entries expire after ``window`` seconds (an echo that never came). Built on
    first use, so this module does not import python-can.
    """
    if "cls" in _FILTER_CLASS:
        return _FILTER_CLASS["cls"]
    import can

    def frame_key(msg: Any) -> _Key:
        return (msg.arbitration_id, bytes(msg.data), bool(msg.is_extended_id), bool(msg.is_remote_frame))

    class OwnEchoFilterBus(can.BusABC):
        """A bus that drops the frames ``inner`` hands back to their own sender (see :func:`own_echo_filter`)."""

        def __init__(self, inner: Any, window: float = 1.0) -> None:
            self._inner = inner
            self._window = float(window)
            self._pending: Deque[Tuple[float, _Key]] = collections.deque()
            self._guard = threading.Lock()
            self.channel_info = "echo-filtered %s" % (getattr(inner, "channel_info", ""),)
            super().__init__(channel=getattr(inner, "channel", None))

        def send(self, msg: Any, timeout: Optional[float] = None) -> None:
            now = time.monotonic()
            with self._guard:
                while self._pending and now - self._pending[0][0] >= self._window:
                    self._pending.popleft()
                self._pending.append((now, frame_key(msg)))
            self._inner.send(msg, timeout)

        def _recv_internal(self, timeout: Optional[float]) -> Any:
            deadline = None if timeout is None else time.monotonic() + timeout
            while True:
                remaining = None if deadline is None else max(0.0, deadline - time.monotonic())
                msg = self._inner.recv(remaining)
                if msg is None:
                    return None, False
                key = frame_key(msg)
                with self._guard:
                    for i, (_, pending) in enumerate(self._pending):
                        if pending == key:         # our own frame coming back: drop it
                            del self._pending[i]
                            break
                    else:
                        return msg, False
                if deadline is not None and time.monotonic() >= deadline:
                    return None, False

        def shutdown(self) -> None:
            super().shutdown()
            self._inner.shutdown()

    _FILTER_CLASS["cls"] = OwnEchoFilterBus
    return OwnEchoFilterBus
