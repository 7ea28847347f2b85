"""The one interface between the operator HMI and the executive it operates: :class:`HmiBackend`.

The HTTP server (:mod:`locem_bridge.hmi.server`) and the automatic operator (:mod:`locem_bridge.hmi.auto_operator`)
only ever talk to an object with these methods, injected at construction; they never import ROS. The ROS
adapter (``locem_bridge.ros.operator_hmi``) implements it over the ``/hicem/*`` and ``/pemkre/query`` interfaces;
tests implement it in process.

Contract (all methods are called from server threads, concurrently; implementations must be thread-safe and
should return quickly, reading cached state where they can):

- ``list_processes()`` -> list of ``{"iri": str, "name": str, "description": str}`` (``description`` optional).
- ``start_process(iri)`` -> ``None`` or a JSON-ready value shown to the operator; raise :class:`BackendRefused`
  when the executive declines (unknown IRI, a process already running).
- ``stop()`` -> ``None``; must always be accepted (STOP is never refused), raise only when unreachable.
- ``snapshot()`` -> ``{"process": str, "action": str, "tree": str, "node": str, "health": HEALTH,
  "progress": PROGRESS}`` plus optional ``"phase"`` (idle, running, suspending, suspended, stopping, stopped,
  ended, failed), ``"skill"`` (the skill PEMKRE matched the running task to), ``"detail"`` (free text) and the
  running action's skill state: ``"skill_state"`` (Ready, Running, Suspended, Halted; "" before any action),
  ``"allowed"`` (the skill methods accepted now, of Suspend, Resume, Halt, Reset) and ``"skill_detail"`` (the
  cause of its last transition); HEALTH is ``{"status": "ok" | "degraded" | "fault" | "unknown", "detail": str}`` (a
  plain string is accepted as the status); PROGRESS is ``{"done": int, "total": int, "text": str}`` or ``None``.
- ``prompts()`` -> the OPEN prompts: ``[{"id": str, "kind": str, "text": str, "choices": [str, ...],
  "context": {...}}]`` (``context`` optional: e.g. ``{"line": "wall_1_joint_2"}``).
- ``reply(prompt_id, answer)`` -> ``None``; raise :class:`BackendRefused` if the prompt is not open (any more) or
  the answer is not allowed.
- ``kpis()`` -> ``{table_name: [row, ...]}`` with each row a flat JSON object (e.g. PEMKRE's
  ``{"processes": [...], "task_types": [...]}``), or ``{}`` while there is nothing to show.
- ``wall_pictures()`` -> ``{wall_id: png_bytes_or_path}``: the current picture of each wall as PNG bytes or the
  path of a PNG file (read when served; a missing file means "not yet available").
- optional ``skill_method(method, cause)`` -> ``{"state": str, "allowed": [str], "message": str}``: Suspend,
  Resume, Halt or Reset (``method`` one of :data:`SKILL_METHODS`) on HICEM's running action (the page's Pause,
  Resume, Abort and Reset buttons); raise :class:`BackendRefused` naming the state and the methods it allows when
  the skill state does not allow it. A backend without it: the page says so (404) and shows no skill buttons.
- optional ``match_process(iri)`` -> PEMKRE's skill matching of an abstract process (``ProcessMatch.to_dict()``,
  JSON text or decoded; :func:`locem_bridge.hmi.pemkre_view.match_view` reads it); raise :class:`BackendRefused`
  when PEMKRE refuses (no resource model, unknown process). A backend without it: the page says so (404).
- optional ``manual_work()`` -> the planned manual work HICEM's task reports named so far in this job (parts of
  areas and joints left for a person; :meth:`locem_bridge.hmi.manual_work.ManualWorkLog.items`, fed every HICEM
  state so no report is missed between two polls). A backend without it: the page's Manual work panel stays
  empty.

Any other exception from a backend is reported to the operator as a backend failure (HTTP 502) and logged.
"""
from typing import Any, Dict, List, Optional, Protocol, Union, runtime_checkable

PictureSource = Union[bytes, str]


@runtime_checkable
class HmiBackend(Protocol):
    """What the HMI needs from the executive (see the module docstring for the exact shapes)."""

    def list_processes(self) -> List[Dict[str, Any]]: ...

    def start_process(self, iri: str) -> Any: ...

    def stop(self) -> None: ...

    def snapshot(self) -> Dict[str, Any]: ...

    def prompts(self) -> List[Dict[str, Any]]: ...

    def reply(self, prompt_id: str, answer: str) -> None: ...

    def kpis(self) -> Dict[str, List[Dict[str, Any]]]: ...

    def wall_pictures(self) -> Dict[str, PictureSource]: ...


SNAPSHOT_KEYS = ("process", "action", "tree", "node", "health", "progress")
SKILL_METHODS = ("Suspend", "Resume", "Halt", "Reset")
"""The skill methods the page offers for HICEM's action (OPC UA Part 10; Start is HICEM's own)."""
HEALTH_STATUSES = ("ok", "degraded", "fault", "unknown")


def normalize_snapshot(raw: Optional[Dict[str, Any]]) -> Dict[str, Any]:
    """A snapshot with every documented key present and HEALTH/PROGRESS in their dict forms.

    Unknown extra keys are kept (the page shows them as details). Raises ``TypeError`` when ``raw`` is not a dict.
    """
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise TypeError("snapshot() must return a dict, got %s" % type(raw).__name__)
    snap = dict(raw)
    for key in ("process", "action", "skill", "tree", "node", "phase", "detail", "skill_state", "skill_detail"):
        value = snap.get(key)
        snap[key] = "" if value is None else str(value)
    allowed = snap.get("allowed")
    snap["allowed"] = [m for m in SKILL_METHODS if isinstance(allowed, (list, tuple)) and m in allowed]
    health = snap.get("health")
    if isinstance(health, dict):
        status = str(health.get("status", "unknown"))
        health = {"status": status if status in HEALTH_STATUSES else "unknown",
                  "detail": str(health.get("detail", "") or ("" if status in HEALTH_STATUSES else status))}
    elif isinstance(health, str) and health:
        health = {"status": health if health in HEALTH_STATUSES else "unknown",
                  "detail": "" if health in HEALTH_STATUSES else health}
    else:
        health = {"status": "unknown", "detail": ""}
    snap["health"] = health
    progress = snap.get("progress")
    if isinstance(progress, dict):
        try:
            done, total = int(progress.get("done", 0)), int(progress.get("total", 0))
        except (TypeError, ValueError):
            done, total = 0, 0
        snap["progress"] = {"done": done, "total": total, "text": str(progress.get("text", "") or "")}
    else:
        snap["progress"] = None
    return snap


def normalize_prompt(raw: Dict[str, Any]) -> Dict[str, Any]:
    """One prompt in the documented shape; raises ``ValueError`` naming the missing/bad field."""
    if not isinstance(raw, dict):
        raise ValueError("a prompt must be a dict, got %s" % type(raw).__name__)
    pid = raw.get("id")
    if not isinstance(pid, str) or not pid:
        raise ValueError("a prompt needs a non-empty string 'id', got %r" % (pid,))
    choices = raw.get("choices")
    if not isinstance(choices, (list, tuple)) or not choices or not all(isinstance(c, str) for c in choices):
        raise ValueError("prompt %s needs a non-empty list of string 'choices', got %r" % (pid, choices))
    context = raw.get("context") or {}
    return {"id": pid, "kind": str(raw.get("kind", "") or ""), "text": str(raw.get("text", "") or ""),
            "choices": list(choices), "context": dict(context) if isinstance(context, dict) else {}}
