"""One exception hierarchy for every bridge, mapped to LOCEM result codes.

:class:`BridgeError` derives from :class:`locem_bridge.locem.errors.LocemError`, so a handler can let any bridge
error escape and the dispatcher answers with the right code:

=========================  ==================  ===========================================================
class                      LOCEM code          raised when
=========================  ==================  ===========================================================
:class:`LinkDown`          HARDWARE_ERROR      the link to a device is down or a request timed out
:class:`DeviceFault`       HARDWARE_ERROR      the device reports a fault (drive FAULT, compressor fault)
:class:`SafetyStop`        HARDWARE_ERROR      protective / emergency stop; latched until RESET_ARM
:class:`NotConnected`      NOT_READY           the backend has not connected yet (startup, reconnecting)
:class:`BridgeConfigError` NOT_READY           the robot YAML lacks or mis-states something a bridge needs
:class:`BadRequest`        INVALID_ARGUMENT    arguments are well-formed but impossible (unknown pose name,
                                               unreachable point, wrong tool)
:class:`MotionTimeout`     TIMEOUT             a motion did not end within its path-length deadline
:class:`NotSupported`      INVALID_COMMAND     the backend lacks the optional capability a command needs
                                               (:meth:`~.interfaces.Backend.supports` says so beforehand)
=========================  ==================  ===========================================================
"""

from typing import Optional

from locem_bridge.common.config_errors import Allowed, ConfigError, allowed_text
from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.errors import LocemError


class BridgeError(LocemError):
    """Base class of every bridge error; ``device`` names the backend (``arm``, ``compressor``, ``base``)."""

    code = Code.HARDWARE_ERROR

    def __init__(self, message: str, device: str = "", argument: Optional[str] = None) -> None:
        super().__init__(message, argument=argument)
        self.device = device


class LinkDown(BridgeError):
    code = Code.HARDWARE_ERROR


class DeviceFault(BridgeError):
    code = Code.HARDWARE_ERROR


class SafetyStop(DeviceFault):
    code = Code.HARDWARE_ERROR


class NotConnected(BridgeError):
    code = Code.NOT_READY


class BridgeConfigError(BridgeError, ConfigError):
    """Prints as one line ``FILE: KEY: PROBLEM (allowed: ...)`` (:class:`~locem_bridge.common.config_errors.ConfigError`)."""

    code = Code.NOT_READY

    def __init__(self, problem: str, file: str = "", key: str = "", allowed: Allowed = None,
                 device: str = "") -> None:
        BridgeError.__init__(self, problem, device=device)
        self.problem, self.file, self.key, self.allowed = problem, file, key, allowed_text(allowed)
        self.message = self.one_line()

    def in_file(self, path: str) -> "BridgeConfigError":
        ConfigError.in_file(self, path)
        self.message = self.one_line()
        return self


class BadRequest(BridgeError):
    code = Code.INVALID_ARGUMENT


class MotionTimeout(BridgeError):
    code = Code.TIMEOUT


class NotSupported(BridgeError):
    """A call into an optional capability group (:mod:`.interfaces`) the backend does not declare."""

    code = Code.INVALID_COMMAND
