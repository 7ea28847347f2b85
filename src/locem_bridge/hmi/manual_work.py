"""The planned manual work of a job, collected from HICEM's task reports: what the operator page's Manual work
panel lists and ``GET /api/manual`` returns. Pure, no I/O, no ROS.

HICEM plans before it touches a wall: the parts of an area or a joint the robot cannot reach are left for a
person and named in the task's detail when the task reports (HICEM's state with ``phase`` ``reporting``):

- SPRAY_AREA / SAND_AREA: ``sprayed; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, height 0..2.5 m)``
  (:func:`locem_bridge.hicem.nodes.area_work.parse_manual_work`; along = m along the wall from the area's start,
  height = m above the floor);
- TAPE_LINE: ``taped; manual work on wall_1_joint_3: part 1 (along 0..0.42 m; near a corner)``
  (:func:`locem_bridge.hicem.nodes.area_work.parse_manual_joints`; along = m from the joint's start).

:class:`ManualWorkLog` is fed every HICEM state in order (the ROS HMI from each ``/hicem/state`` message, the
in-process backend from the controller's state listener: a report is seen even when the next state follows at
once). A detail names every manual part of its feature, so the newest report of a (work, feature) replaces that
feature's parts: the same report seen twice (a state published again), a task retried or run again after
RECOVER, or resumed after a HICEM restart never lists a part twice. The log keeps every feature reported since it
was created (one job: the HMI node lives as long as the job's launch).

An entry (the API's shape): ``{"kind": "area" | "joint", "work": "spray" | "sand" | "tape", "feature": id,
"part": n (the area's section / the joint's part, from 1), "along": [a, b], "height": [c, d] | null (joints),
"reason": str ("" when the detail gives none: areas), "text": one readable line, "task": IRI, "process": IRI}``.
"""
import threading
from typing import Any, Dict, List, Mapping, Tuple

from ..hicem.nodes.area_work import AREA_WORK, parse_manual_joints, parse_manual_work, span_text
#: action type -> the work its joints' manual parts are left from
JOINT_WORK = {"TAPE_LINE": "tape"}


def manual_parts(state: Mapping[str, Any]) -> List[Dict[str, Any]]:
    """The manual parts one HICEM state reports (entries of the module docstring's shape, in the detail's order,
    a part named twice listed once); ``[]`` unless it is the report of a spray, sand or tape task naming some."""
    if str(state.get("phase", "") or "") != "reporting":
        return []
    action = str(state.get("action_type", "") or "")
    detail = str(state.get("detail", "") or "")
    common = {"task": str(state.get("task", "") or ""), "process": str(state.get("process", "") or "")}
    out: List[Dict[str, Any]] = []
    seen = set()
    if action in AREA_WORK:
        work = AREA_WORK[action]
        for p in parse_manual_work(detail):
            key = (p["area"], p["section"])
            if key in seen:
                continue
            seen.add(key)
            along, height = [float(v) for v in p["along"]], [float(v) for v in p["height"]]
            out.append(dict(common, kind="area", work=work, feature=p["area"], part=int(p["section"]), along=along,
                            height=height, reason="",
                            text="%s %s, section %d: along %s, height %s" % (work, p["area"], p["section"],
                                                                             span_text(along), span_text(height))))
    elif action in JOINT_WORK:
        work = JOINT_WORK[action]
        for p in parse_manual_joints(detail):
            key = (p["joint"], p["part"])
            if key in seen:
                continue
            seen.add(key)
            along = [float(v) for v in p["along"]]
            reason = str(p.get("reason") or "")
            out.append(dict(common, kind="joint", work=work, feature=p["joint"], part=int(p["part"]), along=along,
                            height=None, reason=reason,
                            text="%s %s, part %d: along %s%s" % (work, p["joint"], p["part"], span_text(along),
                                                                 ("; " + reason) if reason else "")))
    return out


class ManualWorkLog:
    """Every planned manual part reported so far (see the module docstring). Thread-safe: fed from a subscriber
    or listener thread, read from the HMI's hub."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        # (kind, work, feature) -> its parts as last reported; insertion order = order first reported
        self._features: Dict[Tuple[str, str, str], List[Dict[str, Any]]] = {}

    def update(self, state: Mapping[str, Any]) -> bool:
        """Feed one HICEM state; True when the list changed."""
        parts = manual_parts(state)
        if not parts:
            return False
        by_feature: Dict[Tuple[str, str, str], List[Dict[str, Any]]] = {}
        for p in parts:
            by_feature.setdefault((p["kind"], p["work"], p["feature"]), []).append(p)
        changed = False
        with self._lock:
            for key, new in by_feature.items():
                new = sorted(new, key=lambda p: p["part"])
                if self._features.get(key) != new:
                    self._features[key] = new
                    changed = True
        return changed

    def items(self) -> List[Dict[str, Any]]:
        """The parts, feature by feature in the order first reported, each feature's by part number."""
        with self._lock:
            return [dict(p, along=list(p["along"]), height=list(p["height"]) if p["height"] is not None else None)
                    for parts in self._features.values() for p in parts]

    def clear(self) -> None:
        with self._lock:
            self._features.clear()
