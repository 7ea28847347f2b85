"""LOCEM core: ONE generic command-string interface, ROS-free.

A command string ``NAME arg1 arg2 ... key=value ...`` travels through four stages:

1. :mod:`.grammar` splits it into a name, positional and keyword tokens (or rejects it);
2. :mod:`.registry` binds the tokens to the command's declared, typed arguments (SI units, ranges);
3. :mod:`.dispatcher` applies the resource policy (one running command per resource, ``STOP`` pre-empts
   everything, every command has a deadline) and runs the handler in its own thread;
4. the handler drives a device through a bridge and returns a JSON-able result.

The ROS adapters in :mod:`locem_bridge.ros` expose the dispatcher as a service, an action, a procedure
queue (:mod:`.procedures`), a subscriber and a publisher.
"""

from ..common.locem_codes import Code
from .errors import (
    Aborted,
    Busy,
    CommandTimeout,
    HardwareError,
    InvalidArgument,
    InvalidCommand,
    LocemError,
    NotReady,
)
from .response import Response

__all__ = [
    "Aborted",
    "Busy",
    "Code",
    "CommandTimeout",
    "HardwareError",
    "InvalidArgument",
    "InvalidCommand",
    "LocemError",
    "NotReady",
    "Response",
]
