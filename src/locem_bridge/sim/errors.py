"""Exception hierarchy of the simulated worksite (one base class, specific subclasses)."""

from ..common.config_errors import ConfigError


class SimError(Exception):
    """Base class of every error raised by :mod:`locem_bridge.sim`."""


class SimConfigError(SimError, ConfigError):
    """A site or robot configuration file is missing, malformed or out of range.

    Prints as one line ``FILE: KEY: PROBLEM (allowed: ...)`` naming the key path (e.g.
    ``site.walls[1].height``), what was found and what is allowed (:class:`~locem_bridge.common.config_errors.ConfigError`).
    """


class SimStateError(SimError):
    """An operation is not allowed in the current state (e.g. mounting a tool while one is mounted)."""


class DeviceStandInError(SimError):
    """A device stand-in (Modbus compressor, CAN drives) could not start or was used wrongly."""
