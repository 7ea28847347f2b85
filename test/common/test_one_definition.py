"""One definition per contract: a meaning that crosses layers is written in its module under ``common/`` and
nowhere else (issue 16). Every module of the package is parsed; a second copy anywhere fails, naming the file
and line.

To guard another contract, add a row to ``CONTRACTS``: where it lives, the names that define it, and the string
values that, found together in one collection literal or one class body, are a copy of it.
"""
import ast
import os
from typing import FrozenSet, Iterator, List, NamedTuple, Tuple

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PACKAGE = os.path.join(REPO, "src", "locem_bridge")


class Contract(NamedTuple):
    what: str
    home: str                         # path under src/locem_bridge/, the one module allowed to define it
    names: FrozenSet[str]             # assigned or class names that define it
    values: FrozenSet[str] = frozenset()   # string values that define it, when ...
    min_values: int = 0               # ... at least this many appear in one literal collection or class body


CONTRACTS = [
    Contract("LOCEM answer codes", "common/locem_codes.py", frozenset({"LOCEM_CODES", "Code"}),
             frozenset({"OK", "INVALID_COMMAND", "INVALID_ARGUMENT", "BUSY", "TIMEOUT", "HARDWARE_ERROR",
                        "ABORTED", "NOT_READY"}), 4),
    Contract("task statuses", "common/task_status.py", frozenset({"TASK_STATUSES"}),
             frozenset({"in_progress", "succeeded", "failed"}), 3),
    Contract("next-action record", "common/next_action.py",
             frozenset({"NextAction", "parse_parameters", "parameters_from_ntriples"})),
    Contract("health levels and the grading of a device's health", "common/health.py",
             frozenset({"LEVELS", "LEVEL_NAMES", "DIAG_LEVELS", "grade", "health_level", "HEALTH_OK", "HEALTH_WARN",
                        "HEALTH_ERROR"}),
             frozenset({"OK", "WARN", "ERROR", "STALE"}), 3),
    Contract("angle and rotation helpers", "common/geometry.py",
             frozenset({"wrap_angle", "rotvec_to_matrix", "matrix_to_rotvec", "rpy_to_matrix", "rotvec_to_quat",
                        "quat_to_rotvec", "matrix_to_quat", "rotation_z_along", "pose_to_matrix", "matrix_to_pose",
                        "angle_between"})),
    Contract("wheeled base kinematics (mecanum, differential)", "common/base_kinematics.py",
             frozenset({"WHEEL_KEYS", "WHEEL_ORDER", "MecanumKinematics", "DifferentialKinematics",
                        "kinematics_for"}),
             frozenset({"front_left", "front_right", "rear_left", "rear_right"}), 4),
    Contract("opening the base's CAN bus", "common/can_bus.py",
             frozenset({"CAN_INTERFACES", "SHARED_INTERFACES", "open_bus", "bus_kwargs", "OwnEchoFilterBus"}),
             frozenset({"virtual", "udp_multicast", "socketcan"}), 3),
]


def modules() -> Iterator[Tuple[str, ast.AST]]:
    for folder, dirs, files in os.walk(PACKAGE):
        dirs[:] = [d for d in dirs if d != "__pycache__"]
        for name in sorted(files):
            if name.endswith(".py"):
                path = os.path.join(folder, name)
                with open(path, encoding="utf-8") as handle:
                    yield os.path.relpath(path, PACKAGE).replace(os.sep, "/"), ast.parse(handle.read(), path)


def _strings(nodes) -> List[str]:
    return [n.value for n in nodes if isinstance(n, ast.Constant) and isinstance(n.value, str)]


def definitions(tree: ast.AST, contract: Contract) -> List[Tuple[int, str]]:
    """(line, what) for every place ``tree`` defines ``contract``."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.ClassDef, ast.FunctionDef)) and node.name in contract.names:
            found.append((node.lineno, "defines %s" % node.name))
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            for t in [e for t in targets for e in (t.elts if isinstance(t, ast.Tuple) else [t])]:
                if isinstance(t, ast.Name) and t.id in contract.names:
                    found.append((node.lineno, "assigns %s" % t.id))
        if not contract.min_values:
            continue
        if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
            held = set(_strings(node.elts)) & contract.values
        elif isinstance(node, ast.Dict):
            held = set(_strings([k for k in node.keys if k is not None])) & contract.values
            held = max(held, set(_strings(node.values)) & contract.values, key=len)
        elif isinstance(node, ast.ClassDef):
            held = set(_strings([s.value for s in node.body if isinstance(s, (ast.Assign, ast.AnnAssign))
                                 and s.value is not None])) & contract.values
        else:
            continue
        if len(held) >= contract.min_values:
            found.append((node.lineno, "writes %s" % ", ".join(sorted(held))))
    return found


TREES = dict(modules())


@pytest.mark.parametrize("contract", CONTRACTS, ids=[c.what for c in CONTRACTS])
def test_defined_once_in_common(contract):
    assert contract.home.startswith("common/")
    assert definitions(TREES[contract.home], contract), \
        "%s: %s no longer defines it (move the row with it)" % (contract.what, contract.home)
    copies = ["src/locem_bridge/%s:%d %s" % (path, line, what) for path, tree in sorted(TREES.items())
              if path != contract.home for line, what in definitions(tree, contract)]
    assert not copies, "%s are defined in %s; import them from there instead of:\n  %s" % (
        contract.what, contract.home, "\n  ".join(copies))


def test_a_copy_is_found():
    """The check itself: each way of copying a contract is caught."""
    copy = ast.parse("LOCEM_CODES = ('OK', 'BUSY')\n"
                     "KNOWN = {'OK': 1, 'BUSY': 2, 'TIMEOUT': 3, 'ABORTED': 4}\n"
                     "class Answer:\n    GOOD = 'OK'\n    BAD = 'INVALID_COMMAND'\n    LATE = 'TIMEOUT'\n"
                     "    BUSY = 'BUSY'\n"
                     "def report(s):\n    return s in ['in_progress', 'succeeded', 'failed']\n"
                     "class NextAction:\n    pass\n"
                     "NAMES = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}\n"
                     "def grade(record):\n    return 0\n"
                     "HEALTH_OK, HEALTH_ERROR = 0, 2\n")
    by_what = {c.what: c for c in CONTRACTS}
    codes, statuses, record, health = (by_what[w] for w in ("LOCEM answer codes", "task statuses",
                                                            "next-action record",
                                                            "health levels and the grading of a device's health"))
    assert sorted({line for line, _ in definitions(copy, codes)}) == [1, 2, 3]
    assert sorted({line for line, _ in definitions(copy, statuses)}) == [9]
    assert sorted({line for line, _ in definitions(copy, record)}) == [10]
    assert sorted({line for line, _ in definitions(copy, health)}) == [12, 13, 15]
    assert definitions(ast.parse("ok = code in (Code.OK, Code.BUSY)\nLAST = ('succeeded', 'failed')\n"),
                       codes) == []
