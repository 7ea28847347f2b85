"""Health levels and the grading of a device's health record, defined once for every layer.

Levels are those of ``diagnostic_msgs/DiagnosticStatus``: OK 0, WARN 1, ERROR 2, STALE 3 (:data:`LEVELS`,
:data:`LEVEL_NAMES`; :func:`level_of` reads a number or a name).

A device's health record (a backend's ``health()``; one entry of LOCEM's ``STATUS`` ``health`` object)::

    {"link": "up" | "down" | "connecting" | ..., "device": "ok" | "<state>", "fault": "" | "<latched fault>",
     "last_error": "", ...details}

is graded by :func:`grade`, the one rule ``/diagnostics``, HICEM's modules ``locem/<device>``, its tree nodes
and the operator page all follow:

- ERROR when the link is not ``up``, the device state starts with ``fault`` or ``safety``, or a ``fault`` is
  latched (a faulted device with its link up is ERROR, never OK);
- OK when the link is up, the device state is ``ok`` (a record without a ``device`` key counts as ``ok``) and no
  fault is latched: the device is *ready*;
- WARN otherwise (link up, device in another state, e.g. ``unknown`` or ``robot mode 5, program stopped``).

:func:`problems` names what keeps a record from OK (empty exactly when :func:`grade` is OK).
"""

from typing import Any, Dict, List

OK, WARN, ERROR, STALE = 0, 1, 2, 3
LEVELS: Dict[str, int] = {"OK": OK, "WARN": WARN, "ERROR": ERROR, "STALE": STALE}
LEVEL_NAMES: Dict[int, str] = {v: k for k, v in LEVELS.items()}


def level_of(level: Any) -> int:
    """The level ``level`` names: a name (any case) or a number 0..3 (a one-byte ``bytes`` as ROS gives it).
    ValueError naming the allowed values otherwise."""
    if isinstance(level, bytes) and len(level) == 1:
        level = level[0]
    if isinstance(level, str) and level.upper() in LEVELS:
        return LEVELS[level.upper()]
    if isinstance(level, int) and not isinstance(level, bool) and level in LEVEL_NAMES:
        return level
    raise ValueError("unknown health level %r; allowed: %s or 0..3" % (level, ", ".join(LEVELS)))


def problems(record: Dict[str, Any], links_only: bool = False) -> List[str]:
    """What keeps a device's health record from OK (``link down``, ``device fault: ...``, ``fault ...``); empty
    when it is ready. ``links_only``: only the link counts."""
    why = []
    if record.get("link") != "up":
        why.append("link %s" % record.get("link", "unknown"))
    if not links_only:
        device = record.get("device", "ok")
        if device != "ok":
            why.append("device %s" % device)
        if record.get("fault"):
            why.append("fault %s" % record.get("fault"))
    return why


def grade(record: Dict[str, Any]) -> int:
    """The level of one device health record (see the module docstring)."""
    if record.get("link") != "up" or record.get("fault"):
        return ERROR
    device = str(record.get("device", "ok"))
    if device.startswith("fault") or device.startswith("safety"):
        return ERROR
    return OK if device == "ok" else WARN
