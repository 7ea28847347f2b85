"""The answer to one command, identical on every interface (service response, action result, procedure state)."""

import json
from dataclasses import dataclass, field
from typing import Any, Dict

from .codes import Code
from .errors import LocemError


@dataclass(frozen=True)
class Response:
    """``success`` is true exactly when ``code`` is ``OK``; ``result`` is a JSON object (``{}`` when empty)."""

    code: Code
    message: str
    result: Dict[str, Any] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return self.code is Code.OK

    @property
    def result_json(self) -> str:
        return _ENCODER.encode(self.result)

    @classmethod
    def ok(cls, message: str = "done", result: Dict[str, Any] = None) -> "Response":
        return cls(Code.OK, message, dict(result or {}))

    @classmethod
    def from_error(cls, error: LocemError, result: Dict[str, Any] = None) -> "Response":
        return cls(error.code, error.message, dict(result or {}))

    def as_dict(self) -> Dict[str, Any]:
        return {"success": self.success, "code": self.code.value, "message": self.message, "result": self.result}


def _jsonable(value: Any) -> Any:
    """Fallback for numpy scalars/arrays and other sequences in results."""
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, (set, frozenset, tuple)):
        return sorted(value) if isinstance(value, (set, frozenset)) else list(value)
    return str(value)


_ENCODER = json.JSONEncoder(sort_keys=True, separators=(",", ":"), default=_jsonable)
"""One encoder for every response (``json.dumps`` with options builds a new one per call)."""
