"""One exception hierarchy for LOCEM: every error carries the :class:`~.codes.Code` it maps to.

Handlers and bridges raise these; the dispatcher turns them into responses. Anything else escaping a handler
is a bug and is reported as ``HARDWARE_ERROR`` with the exception text, never swallowed silently.
"""

from typing import Optional

from ..common.locem_codes import Code


class LocemError(Exception):
    """Base class. ``argument`` names the offending argument when there is one."""

    code = Code.HARDWARE_ERROR

    def __init__(self, message: str, argument: Optional[str] = None) -> None:
        super().__init__(message)
        self.message = message
        self.argument = argument


class InvalidCommand(LocemError):
    code = Code.INVALID_COMMAND


class InvalidArgument(LocemError):
    code = Code.INVALID_ARGUMENT


class Busy(LocemError):
    code = Code.BUSY


class CommandTimeout(LocemError):
    code = Code.TIMEOUT


class HardwareError(LocemError):
    code = Code.HARDWARE_ERROR


class Aborted(LocemError):
    code = Code.ABORTED


class NotReady(LocemError):
    code = Code.NOT_READY


class SuspendRequest(BaseException):
    """Raised by a context's ``check()`` / ``sleep()`` when the command is suspended and its handler asked to be
    unwound to its resume point (:meth:`~locem_bridge.locem.execution.CommandContext.unwinding`). Not a
    :class:`LocemError` (the command has not ended) and not an ``Exception`` (no ``except Exception`` in a device
    layer may swallow it): the device layers stop their motion on the way out, as for a cancel."""
