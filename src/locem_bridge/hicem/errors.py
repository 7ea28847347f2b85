"""Exception hierarchy of the HICEM executive.

Every error raised by :mod:`locem_bridge.hicem` derives from :class:`HicemError`, so an adapter can catch the
whole family in one place. Each subclass names one kind of failure; messages always say what was wrong and,
where there is a closed set, what is allowed.
"""
from typing import List, Optional

from ..common.config_errors import ConfigError as _ConfigFileError


class HicemError(Exception):
    """Base class of every HICEM error."""


class TreeLoadError(HicemError, _ConfigFileError):
    """A behavior-tree XML file cannot be turned into a tree (raised at load time, never while ticking).

    Carries ``file``, ``line`` (1-based, 0 when unknown) and ``name`` (the node, port or tree at fault) so an
    integrator can jump straight to the spot in Groot2 or an editor; prints as one line
    ``FILE: line N <element>: PROBLEM`` (:class:`locem_bridge.common.config_errors.ConfigError`).
    """

    def __init__(self, message: str, file: str = "<string>", line: int = 0, name: str = "") -> None:
        where = " ".join(p for p in ("line %d" % line if line else "", "'%s'" % name if name else "") if p)
        _ConfigFileError.__init__(self, message, file=file, key=where)
        self.line = line
        self.name = name
        self.reason = message


class PortError(HicemError):
    """A port value is missing or of the wrong type while a node runs (blackboard-fed ports)."""


class NodeDeclarationError(HicemError):
    """A node class declares itself wrongly (duplicate name, bad port spec). A programming error."""


class DataStoreError(HicemError):
    """The data store (HDM/HDICT) rejected an operation: bad collection, non-JSON value, closed database."""


class ScanFormatError(DataStoreError):
    """A SCAN result does not follow docs/contracts.md; the message names the offending field."""


class HealthError(HicemError):
    """Bad input to the health monitor (unknown module, unknown level)."""


class OperatorError(HicemError):
    """Operator interaction failed: reply to a prompt that is not open, or an answer that is not allowed."""


class LocemCallError(HicemError):
    """HICEM's call to LOCEM went wrong: a command could not be sent or its reply was not understood (LOCEM's own
    refusals are :class:`locem_bridge.locem.errors.LocemError`, carried back as a reply code)."""

    def __init__(self, message: str, code: Optional[str] = None) -> None:
        self.code = code
        super().__init__(message)


class PemkreCallError(HicemError):
    """HICEM's call to PEMKRE went wrong: PEMKRE refused it or answered something HICEM cannot use (bad
    next-action shape, unknown status). PEMKRE's own errors are :class:`locem_bridge.pemkre.errors.PemkreError`."""


class ControllerError(HicemError):
    """The high-level controller was asked to do something its state does not allow."""


class SkillMethodRefused(ControllerError):
    """A skill method (Suspend, Resume, Halt, Reset) on HICEM's action that its state does not allow; nothing
    changed. The text is the state machine's refusal (the state and the methods it allows) or says that no action
    runs; ``method``, ``state`` (the skill state, "" when no action ran yet) and ``allowed`` (the methods HICEM
    accepts now) carry the same in fields."""

    def __init__(self, message: str, method: str = "", state: str = "", allowed: Optional[List[str]] = None) -> None:
        super().__init__(message)
        self.method = method
        self.state = state
        self.allowed = list(allowed or [])


class ConfigError(HicemError, _ConfigFileError):
    """The HICEM parameter file is missing a key or has a value of the wrong type (one line: FILE: KEY: PROBLEM)."""
