"""House rules a machine can check: the core is ROS-free, every Python file is Python 3.8 syntax, and the trees,
the executive and its parameters hold no robot facts."""
import ast
import os
import re

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


# Robot facts (tool names, standoffs, reach, widths, height bands, segment lengths) come from the robot file
# (config/robots/*.yaml), derived by locem_bridge/robot_facts.py and read by the trees as {@robot...}: the trees,
# the executive and the HICEM parameters hold none, so the same trees run on every robot.
FACT_WORDS = {"standoff", "reach", "width", "flange"}              # a key with one of these as a _-separated word
FACT_KEYS = {"tools", "z_range", "z_band", "segment_length", "lane_spacing", "line_length"}
_YAML_KEY = re.compile(r"^\s*(?:-\s*)?([A-Za-z_][A-Za-z0-9_]*)\s*:")
_CFG_REF = re.compile(r"\bcfg((?:\.[A-Za-z_][A-Za-z0-9_]*)+)")


def _fact_key(key):
    return key in FACT_KEYS or bool(FACT_WORDS & set(key.lower().split("_")))


def robot_fact_findings(text, kind, tool_names):
    """(line, what) for every robot fact in a file's text: a tool name of the robot (anywhere, comments too), a
    robot-fact key (``kind`` yaml: a mapping key; trees and code: a ``cfg.<section>.<key>`` reference)."""
    names = re.compile(r"\b(%s)\b" % "|".join(re.escape(n) for n in tool_names))
    found = []
    for number, line in enumerate(text.splitlines(), 1):
        for match in names.finditer(line):
            found.append((number, "tool name '%s'" % match.group(1)))
        keys = []
        if kind == "yaml":
            m = _YAML_KEY.match(line.split("#", 1)[0])
            keys = [m.group(1)] if m else []
        for ref in _CFG_REF.finditer(line):
            keys += [k for k in ref.group(1).split(".") if k]
        found += [(number, "robot-fact key '%s'" % k) for k in keys if _fact_key(k)]
    return found


def _fact_files():
    for name in sorted(os.listdir(os.path.join(REPO, "trees"))):
        if name.endswith(".xml"):
            yield os.path.join(REPO, "trees", name), "xml"
    for path in python_files("src/locem_bridge/hicem"):
        yield path, "py"
    folder = os.path.join(REPO, "config", "hicem")
    for name in sorted(os.listdir(folder)):
        if name.endswith((".yaml", ".yml")):
            yield os.path.join(folder, name), "yaml"


def test_trees_hicem_and_its_parameters_hold_no_robot_facts():
    from locem_bridge.robot_file import load_robot
    tools = list(load_robot()["robot"]["tools"])
    offenders = []
    for path, kind in _fact_files():
        with open(path, encoding="utf-8") as handle:
            offenders += ["%s:%d: %s (robot facts come from the robot file: {@robot...}, locem_bridge/robot_facts.py)"
                          % (os.path.relpath(path, REPO), line, what)
                          for line, what in robot_fact_findings(handle.read(), kind, tools)]
    assert not offenders, "robot facts in trees, hicem/ or config/hicem:\n" + "\n".join(offenders)


def test_the_robot_fact_rule_detects_a_violation():
    tools = ["taping_tool", "spray_gun"]
    yaml_text = ("spray:\n  base_standoff: 1.3   # gun\n  section_run_in: 0.02\n  tools: [a]\n"
                 "area_work:\n  unreachable_codes: [X]\n  tool_change_location: home\n  # the spray_gun's fan\n")
    assert robot_fact_findings(yaml_text, "yaml", tools) == [
        (2, "robot-fact key 'base_standoff'"), (4, "robot-fact key 'tools'"), (8, "tool name 'spray_gun'")]
    xml_text = ('<A section_width="{@robot.work.spray.section_width}" s="{@cfg.spray.speed}"/>\n'
                '<B w="{@cfg.sand.lane_spacing}" t="{@cfg.tools}"/>\n<!-- param_tool: taping_tool -->\n')
    assert robot_fact_findings(xml_text, "xml", tools) == [
        (2, "robot-fact key 'lane_spacing'"), (2, "robot-fact key 'tools'"), (3, "tool name 'taping_tool'")]
    assert robot_fact_findings('X = input_port("standoff", F, "{@cfg.taping.z_range}")\n', "py", tools) == [
        (1, "robot-fact key 'z_range'")]
