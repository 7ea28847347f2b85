"""The CAN bus of a CANopen device backend (the base's drives, the lift), opened with the bridges' errors.

:func:`locem_bridge.common.can_bus.open_bus` is the one opener (the simulator's drives use it too); here its
errors become the bridges' own: a bad ``can`` section is :class:`~.errors.BridgeConfigError` naming the key and
what is allowed, a bus that cannot be opened (no such interface, no permission) :class:`~.errors.LinkDown`.
"""
from typing import Any, Mapping

from .errors import BridgeConfigError, LinkDown


def open_device_bus(can_cfg: Mapping[str, Any], device: str) -> Any:
    """The python-can bus ``can_cfg`` describes, for the backend of ``device`` (named in every error)."""
    from locem_bridge.common.can_bus import CanInterfaceError, CanOpenError, open_bus
    try:
        return open_bus(can_cfg)
    except CanInterfaceError as error:
        raise BridgeConfigError(error.problem, key=error.key, allowed=error.allowed, device=device)
    except CanOpenError as error:
        raise LinkDown(str(error), device=device)
