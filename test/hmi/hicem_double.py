"""TEST DOUBLE of the HICEM side for the HMI tests: ``ScriptedHicemDouble`` implements ``HmiBackend`` in process.

It is not the executive. It plays a fixed, deterministic script of the taping process so tests can click through
a run: start -> GET_TOOL asks "mount_tool" -> VALIDATE_TAPE_LINE asks "validate_line" for each joint in turn
(valid -> taped, invalid -> manual) -> ended, or STOP at any time (prompts withdrawn, phase "stopped"). Prompts
are managed by HICEM's real ``OperatorDesk`` so open/answered/cancelled semantics are the executive's own. Every
call the HMI makes is recorded in ``calls`` so tests can assert on what the backend received. Wall pictures are
rendered with Pillow (joints: red open, green taped, blue manual), re-rendered only when a wall changes.
"""
import io
import threading
from typing import Any, Dict, List, Optional, Tuple

from PIL import Image, ImageDraw

from locem_bridge.hicem.errors import OperatorError
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hmi.errors import BackendRefused

PLB = "https://locem-bridge.example.org/ont/plasterboard#"
TAPING = PLB + "TapingProcess"
PROCESSES = [
    {"iri": TAPING, "name": "Taping", "description": "taping of plasterboard joint lines"},
    {"iri": PLB + "SprayingProcess", "name": "Spraying", "description": "spraying compound on wall areas"},
    {"iri": PLB + "SandingProcess", "name": "Sanding", "description": "sanding the sprayed areas"},
]
# wall id -> joints as (joint id, x position along the wall in m); walls are 4.8 m x 2.5 m
WALLS: Dict[str, List[Tuple[str, float]]] = {
    "wall_1": [("wall_1_joint_1", 1.2), ("wall_1_joint_2", 2.4)],
    "wall_2": [("wall_2_joint_1", 1.2)],
}
SK = "https://locem-bridge.example.org/ont/skill#"
ROBOT = "https://locem-bridge.example.org/robot/diffdrive_ur5e/"
# the skill matching PEMKRE answers (ProcessMatch.to_dict()) for the taping and sanding processes on a robot with a
# tool changer and no sander; spraying is refused as PEMKRE refuses without a resource model
MATCHES: Dict[str, Dict[str, Any]] = {
    TAPING: {"process": TAPING, "robot": ROBOT + "robot", "ok": True, "nodes": [
        {"node": PLB + "t_scan", "task_type": PLB + "ScanTask", "action_type": "SCAN",
         "capability": PLB + "cap_ScanWalls", "ok": True, "problem": "", "rejected": [],
         "realization": {"kind": "skill", "name": "SCAN", "skill": ROBOT + "skill_SCAN", "skill_kind": "composite",
                         "involves_operator": False}},
        {"node": PLB + "t_getTool", "task_type": PLB + "GetToolTask", "action_type": "GET_TOOL",
         "capability": PLB + "cap_GetTool", "ok": True, "problem": "",
         "rejected": [{"candidate": ROBOT + "skill_GET_TOOL", "name": "GET_TOOL", "kind": "composite",
                       "reason": "uses MOUNT_TOOL, not offered by this robot"}],
         "realization": {"kind": "template", "name": "tmpl_getToolAutomatically", "involves_operator": False,
                         "template": PLB + "tmpl_getToolAutomatically", "steps": [
                             {"index": 1, "capability": SK + "cap_ArmToWallReady", "skill": ROBOT + "skill_WALL_READY",
                              "name": "WALL_READY", "skill_kind": "basic", "arguments": [], "involves_operator": False},
                             {"index": 2, "capability": SK + "cap_ChangeToolAutomatically",
                              "skill": ROBOT + "skill_CHANGE_TOOL", "name": "CHANGE_TOOL", "skill_kind": "basic",
                              "arguments": ["tool={tool}"], "involves_operator": False}]}}]},
    PLB + "SandingProcess": {"process": PLB + "SandingProcess", "robot": ROBOT + "robot", "ok": False, "nodes": [
        {"node": PLB + "s_sand", "task_type": PLB + "SandAreaTask", "action_type": "SAND_AREA",
         "capability": PLB + "cap_SandArea", "ok": False, "realization": None,
         "problem": "no skill of this robot realizes plb:cap_SandArea",
         "rejected": [{"candidate": ROBOT + "skill_SAND_AREA", "name": "SAND_AREA", "kind": "composite",
                       "reason": "tool absent: sander"}]}]},
}
COLORS = {"open": (210, 40, 40), "taped": (30, 160, 60), "manual": (40, 90, 220)}   # as sim.outcome draws them


class ScriptedHicemDouble:
    """Scripted, thread-safe test double of HICEM + PEMKRE KPIs (see the module docstring)."""

    def __init__(self, walls: Optional[Dict[str, List[Tuple[str, float]]]] = None) -> None:
        self.walls = walls or WALLS
        self.joints = [j for w in sorted(self.walls) for j, _x in self.walls[w]]
        self.desk = OperatorDesk()
        self.calls: List[Tuple[Any, ...]] = []
        self.joint_state: Dict[str, str] = {j: "open" for j in self.joints}
        self._lock = threading.RLock()
        self._state: Dict[str, Any] = {"process": "", "phase": "idle", "action": "", "tree": "", "node": "",
                                       "detail": ""}
        self._step = -1                       # -1 mount tool, 0..n-1 validating joint i
        self._tasks: List[Dict[str, Any]] = []
        self._renders: Dict[str, Tuple[Tuple[str, ...], bytes]] = {}
        self.render_count = 0
        # knob: prompts still reported after they closed, as a lagging prompt topic would (tests the refusal path)
        self.lagging_prompts: List[Dict[str, Any]] = []

    # -- HmiBackend -----------------------------------------------------------------------------------------
    def list_processes(self) -> List[Dict[str, Any]]:
        return [dict(p) for p in PROCESSES]

    def start_process(self, iri: str) -> Any:
        with self._lock:
            self.calls.append(("start_process", iri))
            if self._state["phase"] == "running":
                raise BackendRefused("process %s is still running; stop it first" % self._state["process"])
            if iri != TAPING:
                raise BackendRefused("this test double only scripts %s" % TAPING)
            self.desk.cancel_all()
            self._tasks = []
            self._state.update(process=iri, phase="running", detail="")
            self._step = -1
            self._set_action("GET_TOOL taping_tool", "GET_TOOL", "ask_mount")
            self.desk.open("mount_tool", "Mount the taping_tool on the arm, then answer done.", ("done",),
                           {"tool": "taping_tool"})
            return {"specific_process": "urn:test:run-1"}

    def stop(self) -> None:
        with self._lock:
            self.calls.append(("stop",))
            self.desk.cancel_all()
            if self._state["phase"] == "running":
                self._state.update(phase="stopped", detail="stop requested by the operator")
                self._set_action("", "", "")

    def snapshot(self) -> Dict[str, Any]:
        with self._lock:
            done = sum(1 for s in self.joint_state.values() if s != "open")
            snap = dict(self._state)
            snap["health"] = {"status": "ok", "detail": "all modules alive"}
            snap["progress"] = {"done": done, "total": len(self.joints),
                                "text": "joint %d of %d" % (min(done + 1, len(self.joints)), len(self.joints))
                                if self._state["phase"] == "running" else "%d of %d joints done" % (
                                    done, len(self.joints))}
            return snap

    def prompts(self) -> List[Dict[str, Any]]:
        return [p.as_dict() for p in self.desk.open_prompts()] + [dict(p) for p in self.lagging_prompts]

    def reply(self, prompt_id: str, answer: str) -> None:
        with self._lock:
            self.calls.append(("reply", prompt_id, answer))
            try:
                prompt = self.desk.reply(prompt_id, answer)
            except OperatorError as err:
                raise BackendRefused(str(err))
            if prompt.kind == "mount_tool":
                self._tasks.append({"type": "GET_TOOL", "status": "succeeded", "operator": True})
            elif prompt.kind == "validate_line":
                joint = prompt.context["line"]
                self.joint_state[joint] = "taped" if answer == "valid" else "manual"
                self._tasks.append({"type": "VALIDATE_TAPE_LINE", "status": "succeeded", "operator": True})
                self._tasks.append({"type": "TAPE_LINE" if answer == "valid" else "MANUAL_TAPING",
                                    "status": "succeeded", "operator": False})
            self._advance()

    def kpis(self) -> Dict[str, List[Dict[str, Any]]]:
        with self._lock:
            if self._state["phase"] not in ("stopped", "ended"):
                return {}
            by_type: Dict[str, Dict[str, Any]] = {}
            for t in self._tasks:
                row = by_type.setdefault(t["type"], {"actionType": t["type"], "count": 0, "succeeded": 0})
                row["count"] += 1
                row["succeeded"] += t["status"] == "succeeded"
            manual = sum(1 for s in self.joint_state.values() if s == "manual")
            return {"processes": [{"process": "urn:test:run-1", "abstractProcess": self._state["process"],
                                   "status": self._state["phase"], "count": len(self._tasks),
                                   "succeeded": sum(1 for t in self._tasks if t["status"] == "succeeded"),
                                   "operatorInterventions": self.desk.interventions, "manualFallbacks": manual,
                                   "successRate": 1.0 if self._tasks else 0.0}],
                    "task_types": [by_type[k] for k in sorted(by_type)]}

    def match_process(self, iri: str) -> Dict[str, Any]:
        with self._lock:
            self.calls.append(("match_process", iri))
        if iri not in MATCHES:
            raise BackendRefused("PEMKRE match refused: no resource model is loaded, so nothing is matched")
        return MATCHES[iri]

    def wall_pictures(self) -> Dict[str, bytes]:
        with self._lock:
            out = {}
            for wall, joints in sorted(self.walls.items()):
                key = tuple(self.joint_state[j] for j, _x in joints)
                cached = self._renders.get(wall)
                if cached is None or cached[0] != key:
                    cached = (key, self._render(joints))
                    self._renders[wall] = cached
                out[wall] = cached[1]
            return out

    # -- script ---------------------------------------------------------------------------------------------
    def _set_action(self, action: str, tree: str, node: str) -> None:
        self._state.update(action=action, tree=tree, node=node)

    def _advance(self) -> None:
        self._step += 1
        if self._step < len(self.joints):
            joint = self.joints[self._step]
            self._set_action("VALIDATE_TAPE_LINE %s" % joint, "VALIDATE_TAPE_LINE", "ask_valid")
            self.desk.open("validate_line", "Is joint %s well placed for taping from here? Answer valid or "
                           "invalid." % joint, ("valid", "invalid"), {"line": joint})
        else:
            self._state.update(phase="ended", detail="all joints handled")
            self._set_action("", "", "")

    def _render(self, joints: List[Tuple[str, float]]) -> bytes:
        self.render_count += 1
        scale = 100                                    # px per m
        img = Image.new("RGB", (int(4.8 * scale), int(2.5 * scale)), (235, 235, 228))
        draw = ImageDraw.Draw(img)
        draw.rectangle([0, 0, img.width - 1, img.height - 1], outline=(90, 90, 90), width=2)
        for joint, x in joints:
            px = int(x * scale)
            draw.rectangle([px - 3, 4, px + 3, img.height - 5], fill=COLORS[self.joint_state[joint]])
        buf = io.BytesIO()
        img.save(buf, "PNG")
        return buf.getvalue()
