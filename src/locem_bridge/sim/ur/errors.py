"""Exception hierarchy of the UR controller stand-in.

Every error raised by :mod:`locem_bridge.sim.ur` derives from :class:`UrStandInError`, so callers can catch the
whole subpackage with one ``except`` clause and still tell the cases apart. Bad input from network clients is never
raised: it is answered as a real controller would and recorded in ``UrControllerStandIn.refused``.
"""


class UrStandInError(Exception):
    """Base class of every error raised by the UR controller stand-in."""


class ConfigurationError(UrStandInError):
    """A constructor argument is invalid (bad address, unknown model, non-positive time scale ...)."""


class KinematicsError(UrStandInError):
    """Forward or inverse kinematics failed (e.g. no inverse kinematics solution for a pose)."""


class ScriptRuntimeError(UrStandInError):
    """The emulated control script hit a runtime error (the real controller halts the program: runtime STOPPED)."""


class ListenError(UrStandInError, OSError):
    """A port of the stand-in cannot be bound; the message names the address, the port and why (one line).
    Also an OSError, as the socket error it replaces."""
