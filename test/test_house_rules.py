"""House rules a machine can check: the core is ROS-free, and every Python file is Python 3.8 syntax."""
import ast
import os

import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(REPO, "src", "locem_bridge")
ROS_MODULES = {"rospy", "actionlib", "actionlib_msgs", "rosgraph", "roslib", "rostest", "genpy", "tf2_ros",
               "roslaunch", "rosservice", "rostopic", "std_msgs", "geometry_msgs", "nav_msgs", "sensor_msgs",
               "diagnostic_msgs", "tf2_msgs"}
PEP585 = {"list", "dict", "tuple", "set", "frozenset", "type"}


def python_files(*roots):
    for root in roots:
        base = os.path.join(REPO, root)
        for folder, dirs, files in os.walk(base):
            dirs[:] = [d for d in dirs if d not in ("__pycache__", ".hypothesis")]
            for name in files:
                path = os.path.join(folder, name)
                if name.endswith(".py") or (root == "scripts" and _has_python_shebang(path)):
                    yield path


def _has_python_shebang(path):
    with open(path, "rb") as handle:
        return handle.readline().startswith(b"#!") and b"python" in open(path, "rb").readline()


def _is_ros(name):
    return name.split(".")[0] in ROS_MODULES or name in ("locem_bridge.msg", "locem_bridge.srv") or \
        name.startswith(("locem_bridge.msg.", "locem_bridge.srv."))


def ros_imports(tree, package="locem_bridge"):
    """(line, module) for every import of ROS or of the generated messages in ``tree``: plain, from-, relative
    (resolved against ``package``, the dotted package of the file) and ``importlib.import_module`` /
    ``__import__`` with a literal name."""
    for node in ast.walk(tree):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                parts = parts[:len(parts) - (node.level - 1)] if node.level > 1 else parts
                base = ".".join(parts + ([node.module] if node.module else []))
            names = [base] + [base + "." + a.name for a in node.names]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) and \
                isinstance(node.args[0].value, str):
            func = node.func
            called = func.attr if isinstance(func, ast.Attribute) else getattr(func, "id", "")
            if called in ("import_module", "__import__"):
                names = [node.args[0].value]
        for name in names:
            if _is_ros(name):
                yield node.lineno, name
                break


def _package_of(path):
    rel = os.path.relpath(os.path.dirname(path), os.path.join(REPO, "src"))
    return rel.replace(os.sep, ".")


def test_core_never_imports_ros():
    offenders = []
    for path in python_files("src/locem_bridge"):
        if os.sep + "ros" + os.sep in path[len(PACKAGE):] + os.sep and path[len(PACKAGE):].startswith(os.sep + "ros"):
            continue
        tree = ast.parse(open(path, encoding="utf-8").read(), path)
        offenders += ["%s:%d imports %s" % (os.path.relpath(path, REPO), line, name)
                      for line, name in ros_imports(tree, _package_of(path))]
    assert not offenders, "ROS imports outside src/locem_bridge/ros/:\n" + "\n".join(offenders)


def test_the_ros_rule_detects_a_violation(tmp_path):
    tree = ast.parse("import os\nfrom rospy import Time\nfrom locem_bridge.srv import Command\n"
                     "from locem_bridge import msg\nfrom .. import srv\nfrom ..msg import CommandAction\n"
                     "from . import grammar\nimport importlib\nimportlib.import_module('actionlib')\n"
                     "__import__('geometry_msgs.msg')\nimportlib.import_module('json')\n")
    found = [n for _, n in ros_imports(tree, "locem_bridge.locem")]
    assert found == ["rospy", "locem_bridge.srv", "locem_bridge.msg", "locem_bridge.srv", "locem_bridge.msg",
                     "actionlib", "geometry_msgs.msg"], found


def py38_problems(source, path):
    try:
        tree = ast.parse(source, path, feature_version=(3, 8))
    except SyntaxError as error:
        return ["%s:%s: %s" % (path, error.lineno, error.msg)]
    future = any(isinstance(n, ast.ImportFrom) and n.module == "__future__" and
                 any(a.name == "annotations" for a in n.names) for n in tree.body)
    if future:
        return []
    problems = []
    for node in ast.walk(tree):
        annotations = []
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            annotations = [a.annotation for a in node.args.args + node.args.kwonlyargs + node.args.posonlyargs]
            annotations.append(node.returns)
        elif isinstance(node, ast.AnnAssign):
            annotations = [node.annotation]
        for annotation in filter(None, annotations):
            for sub in ast.walk(annotation):
                if isinstance(sub, ast.BinOp) and isinstance(sub.op, ast.BitOr):
                    problems.append("%s:%d: 'X | Y' annotation needs Python 3.10" % (path, sub.lineno))
                if isinstance(sub, ast.Subscript) and isinstance(sub.value, ast.Name) and sub.value.id in PEP585:
                    problems.append("%s:%d: '%s[...]' annotation needs Python 3.9" % (path, sub.lineno, sub.value.id))
    return problems


def test_every_python_file_is_python_38():
    problems = []
    for path in python_files("src", "scripts", "test", "bench", "tools"):
        problems += py38_problems(open(path, encoding="utf-8").read(), os.path.relpath(path, REPO))
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("source,fragment", [
    ("match x:\n    case 1: pass\n", "Python 3.10"),
    ("def f(a: int | None): pass\n", "needs Python 3.10"),
    ("def f() -> list[int]: pass\n", "needs Python 3.9"),
])
def test_the_py38_rule_detects_newer_syntax(source, fragment):
    problems = py38_problems(source, "x.py")
    assert problems and fragment in problems[0]
