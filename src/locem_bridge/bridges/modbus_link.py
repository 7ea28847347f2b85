"""One Modbus TCP link of a device backend: the pymodbus sync client and one bounded, retried request.

The compressor and the tool changer (and any further Modbus device) talk through a :class:`ModbusLink`: it makes
the pymodbus client the same on both supported pymodbus lines (the unit keyword is ``device_id`` on 3.7+ and
``slave`` before; reconnect delays where the client has them), keeps one request at a time on the client
(:attr:`lock`, which the backend may also hold around a read-modify-write of its own state), and turns pymodbus's
failures into the bridges' errors: no answer after ``attempts`` tries is :class:`~.errors.LinkDown` naming the
device, its address and the last error; an exception response is :class:`~.errors.DeviceFault`.
"""
import inspect
import logging
import threading
from typing import Any, Callable, Dict, Optional

from .errors import DeviceFault, LinkDown

#: ``call(client, unit_kwargs)`` makes one pymodbus request, e.g. ``lambda c, kw: c.write_coil(0, True, **kw)``.
Request = Callable[[Any, Dict[str, Any]], Any]


class ModbusLink:
    """The client of one device (``device``: its name in errors and health, e.g. ``compressor``)."""

    def __init__(self, device: str, host: str, port: int, device_id: int, timeout: float) -> None:
        self.device = device
        self.host = host
        self.port = port
        self.device_id = device_id
        self.timeout = timeout
        self.lock = threading.Lock()
        self._client: Optional[Any] = None
        self._unit_kw = "device_id"

    @property
    def is_open(self) -> bool:
        return self._client is not None

    def open(self) -> None:
        """Create the client (it connects on the first request and again after a failed one)."""
        from pymodbus.client import ModbusTcpClient

        # pymodbus logs every failed attempt at ERROR level; the backends report link state themselves (health,
        # one warning per loss), so the node's log stays readable while a device is unplugged
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
        params = inspect.signature(ModbusTcpClient.read_input_registers).parameters
        self._unit_kw = "device_id" if "device_id" in params else "slave"
        kwargs: Dict[str, Any] = {"port": self.port, "timeout": self.timeout, "retries": 0}
        if "reconnect_delay" in inspect.signature(ModbusTcpClient.__init__).parameters:
            kwargs.update(reconnect_delay=0.1, reconnect_delay_max=1.0)
        self._client = ModbusTcpClient(self.host, **kwargs)

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None

    def request(self, call: Request, attempts: int = 2) -> Any:
        """One request, tried up to ``attempts`` times (the client reconnects between tries)."""
        from pymodbus.exceptions import ModbusException

        client = self._client
        if client is None:
            raise LinkDown("%s backend is not started" % self.device, device=self.device)
        error, name = "", self.device.replace("_", " ")
        for _ in range(attempts):
            with self.lock:
                try:
                    reply = call(client, {self._unit_kw: self.device_id})
                except (ModbusException, OSError) as exc:
                    error = "%s: %s" % (type(exc).__name__, exc)
                    try:
                        client.close()             # the next attempt reconnects
                    except Exception:  # noqa: BLE001 - a half-open socket may fail to close; the retry reopens
                        pass
                    continue
            if reply.isError():
                code = getattr(reply, "exception_code", None)
                if code is None:
                    error = "no valid answer (%s)" % (reply,)
                    continue
                raise DeviceFault("%s refused the request (Modbus exception %s)" % (name, code), device=self.device)
            return reply
        raise LinkDown("%s %s:%d does not answer (%d attempts, %.0f ms timeout each): %s"
                       % (name, self.host, self.port, attempts, self.timeout * 1000, error), device=self.device)
