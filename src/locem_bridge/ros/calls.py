"""A blocking ROS call bounded in time: the adapters' one way to call a peer that may be gone or shutting down.

:func:`timed` runs ``fn()`` in a helper thread and waits at most ``timeout`` s. It returns what ``fn`` returned;
when ``fn`` raises, or has not returned in time (the helper thread is left to end by itself), it raises
``error`` (default :class:`CallFailed`) with a message naming ``what`` and why: ``"<what>: no answer within
2.0 s"`` or ``"<what>: <the exception>"``.
"""
import threading
from typing import Any, Callable, Dict, Type


class CallFailed(Exception):
    """A ROS call failed or did not answer in time (message: what and why)."""


def timed(fn: Callable[[], Any], timeout: float, what: str, error: Type[Exception] = CallFailed) -> Any:
    """``fn()`` within ``timeout`` s (see the module docstring)."""
    box: Dict[str, Any] = {}

    def run() -> None:
        try:
            box["value"] = fn()
        except Exception as err:  # noqa: BLE001 - reported to the caller below
            box["error"] = err

    worker = threading.Thread(target=run, name="ros-timed-call", daemon=True)
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        raise error("%s: no answer within %.1f s" % (what, timeout))
    if "error" in box:
        raise error("%s: %s" % (what, box["error"]))
    return box.get("value")
