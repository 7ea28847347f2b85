"""Helpers for the PEMKRE tests: SCAN results in the contracts.md shape, a HICEM-like runner, store snapshots."""
import json
import os
import sys
from typing import Callable, Dict, List, Optional, Tuple

_SRC = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))), "src")
if _SRC not in sys.path:
    sys.path.insert(0, _SRC)

from locem_bridge.pemkre import OxigraphStore, ProcessEngine  # noqa: E402
from locem_bridge.pemkre.store import TripleStore  # noqa: E402

DATA = os.path.join(os.path.dirname(os.path.abspath(__file__)), "data")


class FakeClock:
    """Deterministic time: every reading advances by ``step`` seconds."""

    def __init__(self, start: float = 1_800_000_000.0, step: float = 1.5) -> None:
        self.t = start
        self.step = step

    def __call__(self) -> float:
        self.t += self.step
        return self.t


def scan_result(walls: int = 1, joints_per_wall: int = 2, areas_per_wall: int = 1, prefix: str = "wall") -> Dict:
    """A SCAN result (docs/contracts.md) with ids wall_1, wall_1_joint_1, wall_1_area_1, ..."""
    out: Dict = {"stamp": 12.5, "walls": [], "joints": [], "areas": []}
    for w in range(1, walls + 1):
        wid = "%s_%d" % (prefix, w)
        y = 3.0 * w
        out["walls"].append({"id": wid, "p0": [0.0, y], "p1": [4.8, y], "height": 2.5, "thickness": 0.0125,
                             "normal": [0.0, -1.0, 0.0]})
        for j in range(1, joints_per_wall + 1):
            out["joints"].append({"id": "%s_joint_%d" % (wid, j), "wall": wid, "kind": "vertical",
                                  "start": [1.2 * j, y, 0.0], "end": [1.2 * j, y, 2.5], "width": 0.05})
        for a in range(1, areas_per_wall + 1):
            out["areas"].append({"id": "%s_area_%d" % (wid, a), "wall": wid, "origin": [0.0, y, 0.0],
                                 "u": [1.0, 0.0, 0.0], "width": 4.8, "height": 2.5})
    return out


def quads_snapshot(store: TripleStore) -> List[Tuple]:
    """Every quad of the store, sorted: equal snapshots mean nothing was written."""
    return sorted((str(s), str(p), o.n3() if hasattr(o, "n3") else str(o), str(g))
                  for s, p, o, g in store.quads())


Decide = Callable[[object], Tuple[str, str]]


def run_process(engine: ProcessEngine, decide: Optional[Decide] = None, limit: int = 200) -> List[Tuple[str, Dict]]:
    """Drive ``next_action`` / ``set_task_status`` like HICEM until the process ends or fails.

    ``decide(action)`` returns (status, detail) for each action; default: succeeded with an empty detail.
    Returns [(action_type, params)] and, as the last item, ("ENDED"|"FAILED", {"message": ...}).
    """
    seen: List[Tuple[str, Dict]] = []
    for _ in range(limit):
        a = engine.next_action()
        if a.status != "action":
            seen.append((a.status.upper(), {"message": a.message}))
            return seen
        seen.append((a.action_type, a.params()))
        engine.set_task_status(a.task, "in_progress")
        status, detail = decide(a) if decide else ("succeeded", "")
        engine.set_task_status(a.task, status, detail)
    raise AssertionError("process did not end within %d actions: %s" % (limit, seen[-5:]))




def json_dumps(d: Dict) -> str:
    return json.dumps(d)
