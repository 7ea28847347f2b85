"""How HICEM's own state reads on the operator's screen: pure functions shared by every HICEM backend.

HICEM's controller publishes a state dict (``process``, ``specific_process``, ``action_type``, ``task``, ``skill``,
``tree``, ``node``, ``path``, ``phase``, ``detail``; the ROS adapter carries the same fields on ``/hicem/state``;
plus the action's skill state ``skill_state``, ``allowed`` and ``skill_detail``, which the ROS adapter follows on
``/hicem/skill_state`` instead)
and its health monitor a per-module snapshot (``{module: {"level", "message", "crucial", "fault"}}``). These
functions turn them into the HMI snapshot of :mod:`locem_bridge.hmi.backend`. No I/O, no ROS.
"""
import os
import re
from typing import Any, Dict, Mapping, Optional

from .health import health_summary

_FEATURE = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
# the work an action type does, for the progress bar (see locem_bridge.hmi.pemkre_view.work_progress)
WORK_OF_ACTION = {"VALIDATE_TAPE_LINE": "taping", "TAPE_LINE": "taping", "MANUAL_TAPING": "taping",
                  "SPRAY_AREA": "spraying", "SAND_AREA": "sanding"}


class WorkFollower:
    """Which work the running process does, from HICEM's state messages fed in order: the work of the last
    work action (:data:`WORK_OF_ACTION`) seen in this process; None after a new process starts until its first
    work action (tool change, scan, going home ... do not say)."""

    def __init__(self) -> None:
        self.process = ""
        self.work: Optional[str] = None

    def update(self, state: Mapping[str, Any]) -> Optional[str]:
        process = str(state.get("process", "") or "")
        if process != self.process:
            self.process, self.work = process, None
        work = WORK_OF_ACTION.get(str(state.get("action_type", "") or ""))
        if work is not None and process:
            self.work = work
        return self.work


def local_name(iri: str) -> str:
    """The part after the last ``#`` or ``/`` of an IRI (the whole string when there is none)."""
    text = iri or ""
    cut = max(text.rfind("#"), text.rfind("/"))
    return text[cut + 1:] if cut >= 0 and cut + 1 < len(text) else text


def action_label(action_type: str, task: str) -> str:
    """``"VALIDATE_TAPE_LINE (task_7)"`` -- the action type and the task's local name."""
    if not action_type:
        return ""
    return "%s (%s)" % (action_type, local_name(task)) if task else action_type


def snapshot_from_hicem(state: Optional[Dict[str, Any]], modules: Optional[Dict[str, Dict[str, Any]]] = None,
                        progress: Optional[Dict[str, Any]] = None,
                        health: Optional[Dict[str, str]] = None) -> Dict[str, Any]:
    """The HMI snapshot for a HICEM state dict plus health (a HEM snapshot, or an already summarized
    ``health``) and an optional progress dict."""
    st = state or {}
    return {"process": str(st.get("process", "") or ""), "phase": str(st.get("phase", "") or "idle"),
            "action": action_label(str(st.get("action_type", "") or ""), str(st.get("task", "") or "")),
            "skill": str(st.get("skill", "") or ""),
            "tree": str(st.get("tree", "") or ""), "node": str(st.get("node", "") or ""),
            "detail": str(st.get("detail", "") or ""),
            "skill_state": str(st.get("skill_state", "") or ""),
            "allowed": [str(m) for m in (st.get("allowed") or [])],
            "skill_detail": str(st.get("skill_detail", "") or ""),
            "health": health if health is not None else health_summary(modules),
            "progress": progress}


def wall_pictures_in(folder: Optional[str]) -> Dict[str, str]:
    """``{wall_id: path}`` for every ``<wall_id>.png`` in ``folder`` (the worksite's picture folder); ``{}`` when
    the folder does not exist (yet). Files whose stem is not a feature id are ignored."""
    if not folder or not os.path.isdir(folder):
        return {}
    out = {}
    for name in sorted(os.listdir(folder)):
        stem, ext = os.path.splitext(name)
        if ext.lower() == ".png" and _FEATURE.match(stem):
            out[stem] = os.path.join(folder, name)
    return out
