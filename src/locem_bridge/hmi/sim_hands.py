"""The simulated operator's hands: what an operator physically does at the worksite before answering a prompt.

On the real site the operator mounts the tool, or tapes a joint by hand, and then answers ``done``. In the
simulated worksite those acts are the simulator's operations (``sim_worksite``'s ``~remove_tool``,
``~mount_tool``, ``~manual_taping`` services), so whoever answers for the operator -- a person on the web page
or the automatic operator -- must perform them first, or the simulated world would not know the tool is on the
arm (no tape, spray or sanding recorded) or that a joint was taped by hand (the report would show it open).

:func:`hand_actions` is the pure part: for a prompt and its answer, the simulator operations to run, in order,
as ``(operation, args)`` pairs. The ROS adapter runs them (``locem_bridge.ros.operator_hmi``).
"""
import re
from typing import Any, Dict, Iterable, List, Tuple

from .errors import HmiError

TOOLS = ("taping_tool", "spray_gun", "sander")          # docs/contracts.md
_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]*")


class HandsError(HmiError):
    """The prompt does not say which tool or joint the operator's hands must handle."""


def _words(prompt: Dict[str, Any]) -> List[str]:
    words = _WORD.findall(prompt.get("text") or "")
    words += [v for v in (prompt.get("context") or {}).values() if isinstance(v, str)]
    return words


def hand_actions(prompt: Dict[str, Any], answer: str, joints: Iterable[str] = ()) -> List[Tuple[str, Dict[str, Any]]]:
    """Simulator operations for answering ``prompt`` with ``answer``.

    ``mount_tool`` + ``done``: remove the current tool, mount the one named in the prompt. ``manual_taping`` or
    ``finish_interrupted`` + ``done``: mark the joint named in the prompt as taped by hand (``joints`` lists the
    site's joint ids; without it, a word containing ``_joint_`` is taken). Anything else: nothing.
    Raises :class:`HandsError` when the prompt does not name the tool/joint.
    """
    kind = prompt.get("kind", "")
    if answer != "done":
        return []
    words = _words(prompt)
    if kind == "mount_tool":
        tools = [w for w in words if w in TOOLS]
        if not tools:
            raise HandsError("prompt %s asks to mount a tool but names none of %s: %r" % (
                prompt.get("id", "?"), ", ".join(TOOLS), prompt.get("text", "")))
        return [("remove_tool", {}), ("mount_tool", {"name": tools[0]})]
    if kind in ("manual_taping", "finish_interrupted"):
        known = set(joints)
        found = [w for w in words if (w in known if known else "_joint_" in w)]
        if not found:
            raise HandsError("prompt %s asks to tape a joint by hand but names no known joint: %r" % (
                prompt.get("id", "?"), prompt.get("text", "")))
        return [("manual_taping", {"joint": found[0]})]
    return []
