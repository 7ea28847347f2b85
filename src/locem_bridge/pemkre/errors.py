"""The PEMKRE exception hierarchy: one base class, one subclass per kind of failure.

Every message names the culprit (the IRI, file, query or value) and, where there is one, what is allowed.
"""
from typing import Optional

from ..common.config_errors import ConfigError


class PemkreError(Exception):
    """Base class of every error raised by :mod:`locem_bridge.pemkre`."""

    code = "PEMKRE_ERROR"


class MalformedIriError(PemkreError, ValueError):
    """A string that should be an absolute IRI is not one (or contains characters IRIs may not hold)."""

    code = "MALFORMED_IRI"


class UnknownProcessError(PemkreError, LookupError):
    """The IRI does not name an abstract process in the loaded ontologies."""

    code = "UNKNOWN_PROCESS"


class UnknownTaskError(PemkreError, LookupError):
    """The IRI does not name a task execution of any specific process."""

    code = "UNKNOWN_TASK"


class TaskStateError(PemkreError):
    """A status report for a task that is not in a state that admits it (e.g. not running)."""

    code = "TASK_STATE"


class InvalidStatusError(PemkreError, ValueError):
    """A task status or detail outside the allowed set."""

    code = "INVALID_STATUS"


class InvalidParameterError(PemkreError, ValueError):
    """A query binding, option or term that is malformed or not allowed."""

    code = "INVALID_PARAMETER"


class UnknownQueryError(PemkreError, LookupError):
    """No predefined query of that name exists in the ontologies."""

    code = "UNKNOWN_QUERY"


class OntologyError(PemkreError, ConfigError):
    """An ontology file cannot be used (missing, syntax error, inconsistent process model).

    Prints as one line ``FILE: line N: PROBLEM`` when the file (``source``) and line are known
    (:class:`locem_bridge.common.config_errors.ConfigError`).
    """

    code = "ONTOLOGY_ERROR"

    def __init__(self, message: str, source: Optional[str] = None, line: Optional[int] = None) -> None:
        ConfigError.__init__(self, message, file=source or "", key="line %d" % line if line else "")
        self.source = source
        self.line = line


class OntologySyntaxError(OntologyError):
    """A Turtle file has a syntax error; the message names the file and, when known, the line."""

    code = "ONTOLOGY_SYNTAX"


class ProcessModelError(OntologyError):
    """An abstract process is structurally wrong (dangling transition, node without exit, ...)."""

    code = "PROCESS_MODEL"


class QueryError(PemkreError):
    """A SPARQL query stored in the ontology failed to parse or to evaluate; names the query's IRI."""

    code = "QUERY_ERROR"

    def __init__(self, message: str, query_iri: Optional[str] = None) -> None:
        super().__init__(message)
        self.query_iri = query_iri


class ConditionError(QueryError):
    """A branch condition (transition guard) failed; no transition was taken."""

    code = "CONDITION_ERROR"


class BindingError(QueryError):
    """A task parameter's binding query failed or returned no value for a required parameter."""

    code = "BINDING_ERROR"


class ReasoningBoundError(PemkreError):
    """A closure hit its time or size bound; the store keeps the last good state."""

    code = "REASONING_BOUND"


class StoreError(PemkreError):
    """The triplestore failed (I/O, lock held by another process, corrupted data; a SPARQL server that answered
    with an HTTP error or with something that is not a SPARQL answer)."""

    code = "STORE_ERROR"


class StoreUnavailable(StoreError):
    """A remote triplestore cannot be reached (connection refused, timeout, unknown host, connection lost).

    ``endpoint`` names the URL (without credentials), ``reason`` what went wrong. For a write, ``applied`` says
    what became of it: ``False`` nothing was written, ``True`` it was written (only the answer was late), ``None``
    unknown (the answer was lost and the server could not be asked, or the write is not there yet but may still
    arrive); ``token`` then names the write's claim token (see
    :meth:`~locem_bridge.pemkre.sparql_store.SparqlStore.was_applied`). A remote store also raises it while a
    write it could not settle is unknown, and while the quads of a conditional change stay claimed by another
    client (``applied=False``: nothing was written; try again later).

    Its code is ``NOT_READY``: PEMKRE cannot decide now, the same call made again later is answered (every call
    that changes something carries a request id, so one that was applied and whose answer was lost is applied once).
    """

    code = "NOT_READY"

    def __init__(self, message: str, endpoint: str = "", reason: str = "", applied: Optional[bool] = False,
                 token: str = "", timed_out: bool = False) -> None:
        super().__init__(message)
        self.endpoint = endpoint
        self.reason = reason
        self.applied = applied
        self.token = token
        #: the server did not answer in time (it may still be working on the request)
        self.timed_out = timed_out


class StoreConflict(StoreError):
    """A conditional change (:attr:`~locem_bridge.pemkre.store.ChangeSet.expect`) was not applied because a quad
    it expects was not in the store: another writer changed it first. ``quad`` is that quad; nothing was written."""

    code = "STORE_CONFLICT"

    def __init__(self, message: str, quad: object = None) -> None:
        super().__init__(message)
        self.quad = quad


class WorldUpdateError(PemkreError, ValueError):
    """A world-state update (e.g. a SCAN result) does not have the contracts.md shape."""

    code = "WORLD_UPDATE"


class UnmatchableProcessError(PemkreError):
    """A process has a task no skill of this robot realizes (``start_process`` refuses it, nothing is written).

    The message names every such task node and why no skill fits; ``match`` holds the whole
    :class:`~locem_bridge.pemkre.matching.ProcessMatch`.
    """

    code = "UNMATCHABLE_PROCESS"

    def __init__(self, message: str, match: object = None) -> None:
        super().__init__(message)
        self.match = match
