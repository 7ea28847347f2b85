"""Exception hierarchy of the operator HMI.

Every error raised by :mod:`locem_bridge.hmi` derives from :class:`HmiError`. Backends (the HICEM side seen
through :class:`locem_bridge.hmi.backend.HmiBackend`) raise :class:`BackendRefused` when they decline a request
on purpose (a reply to a prompt that is no longer open, a start while a process runs) and
:class:`BackendUnavailable` when they cannot be reached; the HTTP server turns the first into ``409 Conflict``
and the second into ``503 Service Unavailable``, each with the backend's message, and keeps serving.
:class:`RequestError` carries an HTTP status for everything the server itself rejects (bad JSON, unknown
endpoint, unknown prompt id, ...).
"""
from typing import Optional


class HmiError(Exception):
    """Base class of every HMI error."""


class BackendRefused(HmiError):
    """The backend declined the request on purpose; the message says why and, where it can, what is allowed."""


class BackendUnavailable(HmiError):
    """The backend cannot answer now (a service is down, a call timed out)."""


class RequestError(HmiError):
    """A request the HTTP server rejects: ``status`` is the HTTP status, ``code`` a short machine-readable word."""

    def __init__(self, status: int, code: str, message: str, allow: Optional[str] = None) -> None:
        super().__init__(message)
        self.status = int(status)
        self.code = code
        self.message = message
        self.allow = allow


class ServerStartError(HmiError):
    """The HTTP server cannot bind its address (port in use, address not on this machine)."""


class AutoOperatorConfigError(HmiError):
    """The automatic operator's configuration is malformed; the message names the key and what is allowed."""
