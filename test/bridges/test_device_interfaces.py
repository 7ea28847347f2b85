"""The device interfaces are the whole contract between the command sets and the backends: every backend of the
name -> backend table implements its interface completely (abstract methods, annotated attributes, the optional
groups it declares), and the command modules use nothing but the interfaces (no concrete backend imported, no
method or attribute the interface does not declare, no ``hasattr`` probing). A second arm backend thus learns
the contract from ``bridges/interfaces.py`` alone."""
import ast
import inspect
import os
import typing

import pytest
import yaml

from locem_bridge.bridges import backends
from locem_bridge.bridges.commands_arm import ArmCommands
from locem_bridge.bridges.config import load_robot_config
from locem_bridge.bridges.errors import NotSupported
from locem_bridge.bridges.interfaces import INTERFACES, Arm
from locem_bridge.bridges.robot import build_robot
from locem_bridge.common.locem_codes import Code

from bridge_rigs import ROBOT_YAML, SHORT_WALL, TOOL_CHANGER_RACK

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BRIDGES = os.path.join(REPO, "src", "locem_bridge", "bridges")
COMMAND_MODULES = sorted(n for n in os.listdir(BRIDGES) if n.startswith("commands_") and n.endswith(".py"))
#: the modules of the concrete backends (the table's targets) and what only they use
CONCRETE = {target.partition(":")[0] for table in backends.BACKENDS.values() for target in table.values()} | {
    "locem_bridge.bridges.ur_worker"}
#: how the command modules name a device handle -> its interface
HANDLES = {"arm": "arm", "_arm": "arm", "base": "base", "compressor": "compressor", "comp": "compressor",
           "scanner": "scanner", "lift": "lift", "changer": "tool_changer"}


def _all_backends():
    return [(kind, name, backends.backend_class(kind, name))
            for kind, table in sorted(backends.BACKENDS.items()) for name in sorted(table)]


def _public_methods(iface):
    return {n: f for n, f in inspect.getmembers(iface, inspect.isfunction) if not n.startswith("_")}


def _instance_attributes(iface):
    """Attributes the interface annotates for its backends to set (ClassVar ones are the interface's own)."""
    out = set()
    for klass in iface.__mro__:
        if klass is object:
            continue
        for name, hint in typing.get_type_hints(klass).items():
            if getattr(hint, "__origin__", None) is not typing.ClassVar:
                out.add(name)
    return out


def _declared(iface, name):
    return hasattr(iface, name) or name in _instance_attributes(iface)


@pytest.mark.parametrize("kind,name,cls", _all_backends(), ids=lambda v: v if isinstance(v, str) else "")
def test_every_backend_implements_its_interface_completely(kind, name, cls):
    iface = INTERFACES[kind]
    assert issubclass(cls, iface), "%s backend %s is no %s" % (kind, name, iface.__name__)
    assert not cls.__abstractmethods__, "%s leaves abstract: %s" % (cls.__name__, sorted(cls.__abstractmethods__))
    optional = getattr(iface, "OPTIONAL", {})
    declared = getattr(cls, "capabilities", frozenset())
    assert declared <= set(optional), "%s declares unknown capabilities %s" % (cls.__name__, declared - set(optional))
    for group in declared:
        for method in optional[group]:
            assert getattr(cls, method) is not getattr(iface, method), \
                "%s declares '%s' but does not implement %s" % (cls.__name__, group, method)
    for method, spec in _public_methods(iface).items():
        mine = inspect.signature(getattr(cls, method)).parameters
        theirs = inspect.signature(spec).parameters
        assert list(mine)[:len(theirs)] == list(theirs), \
            "%s.%s%s does not take the interface's parameters %s" % (cls.__name__, method, list(mine), list(theirs))
        extra = [p for p in list(mine.values())[len(theirs):] if p.default is inspect.Parameter.empty
                 and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)]
        assert not extra, "%s.%s needs more than the interface passes: %s" % (cls.__name__, method, extra)


def test_built_backends_set_every_attribute_their_interface_annotates(robot):
    second = build_robot(load_robot_config(os.path.join(REPO, "config", "robots", "diffdrive_ur5e.yaml")),
                         site=SHORT_WALL)                 # the robot with a lift
    with open(TOOL_CHANGER_RACK) as handle:             # the shipped robot plus a tool changer: every kind
        robot = load_robot_config(ROBOT_YAML, yaml.safe_load(handle))
    built = build_robot(robot, site=SHORT_WALL)          # built, never started: no device is contacted
    assert sorted(set(built.backends) | set(second.backends)) == sorted(INTERFACES)
    assert "lift" not in built.backends                  # the shipped robot has no lift section
    for kind, backend in list(built.backends.items()) + list(second.backends.items()):
        missing = [a for a in sorted(_instance_attributes(INTERFACES[kind])) if not hasattr(backend, a)]
        assert not missing, "%s backend %s lacks %s" % (kind, type(backend).__name__, missing)
    second.close()
    arm = built.get("arm")
    assert arm.supports(Arm.PATH) and arm.supports(Arm.FORCE)
    with pytest.raises(ValueError, match="arm has no optional capability 'teleport'; known: force, path"):
        arm.supports("teleport")
    built.close()


def test_a_command_needing_a_capability_the_arm_lacks_is_refused_before_anything_moves(robot):
    ur = backends.backend_class("arm", "ur_rtde")

    class PathlessArm(ur):
        capabilities = frozenset({Arm.FORCE})

    arm = PathlessArm(robot["arm"])                   # never started: any device call would fail NOT_READY
    with pytest.raises(NotSupported, match=r"this robot's arm \(PathlessArm\) has no path capability") as caught:
        ArmCommands(arm).move_path(None, "0.5:0.2:0.4:0:3.14:0", 0.25, 1.2, 0.0)
    assert caught.value.code == Code.INVALID_COMMAND


# -- the command modules use the interfaces only (ast) ---------------------------------------------------------
def _module_of(node, package="locem_bridge.bridges"):
    base = node.module or ""
    if node.level:
        parts = package.split(".")
        parts = parts[:len(parts) - (node.level - 1)] if node.level > 1 else parts
        base = ".".join(parts + ([node.module] if node.module else []))
    return base


def _handle_kind(node):
    """The device kind an expression names: ``arm``, ``self.arm``, ``self._need("arm")``; else None."""
    if isinstance(node, ast.Name):
        return HANDLES.get(node.id)
    if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "self":
        return HANDLES.get(node.attr)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "_need" and \
            node.args and isinstance(node.args[0], ast.Constant):
        return HANDLES.get(node.args[0].value)
    return None


def contract_breaches(source, filename="<module>"):
    """What a command module does past the interfaces: imports of a concrete backend, attributes a device
    handle's interface does not declare, ``hasattr`` / ``getattr`` on a handle."""
    tree = ast.parse(source, filename)
    out = []
    for node in ast.walk(tree):
        modules = []
        if isinstance(node, ast.Import):
            modules = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = _module_of(node)
            modules = [base] + [base + "." + a.name for a in node.names]
        elif isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant) and \
                getattr(node.func, "attr", getattr(node.func, "id", "")) in ("import_module", "__import__"):
            modules = [node.args[0].value]
        hit = [m for m in modules if m in CONCRETE]
        if hit:
            out.append("%s:%d imports the concrete backend %s" % (filename, node.lineno, hit[0]))
        if isinstance(node, ast.Attribute):
            kind = _handle_kind(node.value)
            if kind and not _declared(INTERFACES[kind], node.attr):
                out.append("%s:%d uses %s.%s, which %s does not declare"
                           % (filename, node.lineno, kind, node.attr, INTERFACES[kind].__name__))
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") in ("hasattr", "getattr") and node.args \
                and _handle_kind(node.args[0]):
            out.append("%s:%d probes the %s with %s (ask supports())"
                       % (filename, node.lineno, _handle_kind(node.args[0]), node.func.id))
    return out


def test_the_command_modules_use_the_device_interfaces_only():
    assert len(COMMAND_MODULES) >= 4, COMMAND_MODULES
    breaches = []
    for name in COMMAND_MODULES:
        path = os.path.join(BRIDGES, name)
        breaches += contract_breaches(open(path, encoding="utf-8").read(), os.path.relpath(path, REPO))
    assert not breaches, "command modules past the device interfaces:\n" + "\n".join(breaches)


def test_the_contract_check_detects_each_breach():
    source = ("from .ur_arm import UrRtdeArm\nimport locem_bridge.bridges.cia402_base\n"
              "def f(self, arm, comp):\n"
              "    arm.move_linear(None, [0] * 6, 0.1, 1.0)\n"          # declared: fine
              "    arm.safety_latched\n"                                 # UR-only
              "    self._need('compressor').reset_fault()\n"             # Modbus-only
              "    self.base.loop_rate()\n"                              # CiA 402-only
              "    return hasattr(arm, 'force_mode_start')\n")
    found = contract_breaches(source)
    assert len(found) == 6, found
    assert any("imports the concrete backend locem_bridge.bridges.ur_arm" in f for f in found)
    assert any("imports the concrete backend locem_bridge.bridges.cia402_base" in f for f in found)
    assert any("arm.safety_latched, which Arm does not declare" in f for f in found)
    assert any("compressor.reset_fault, which Compressor does not declare" in f for f in found)
    assert any("base.loop_rate, which Base does not declare" in f for f in found)
    assert any("probes the arm with hasattr" in f for f in found)


# -- an arm without the path group: the wall commands work lane by lane ------------------------------------------
@pytest.mark.slow
def test_sand_area_with_an_arm_without_the_path_group_runs_lane_by_lane(robot, core, monkeypatch):
    """The raster's one blended path is an optional group: a backend that does not declare it (here the real UR
    backend, declaring force only) gets straight moves lane by lane, and the area is still sanded completely."""
    pytest.importorskip("rtde_control")
    from locem_bridge.bridges import robot as robot_module
    from bridge_rigs import WorksiteRig

    ur = backends.backend_class("arm", "ur_rtde")

    class LaneByLaneArm(ur):
        capabilities = frozenset({Arm.FORCE})

        def move_path(self, *args, **kwargs):
            raise AssertionError("move_path called on an arm that does not declare the path group")

    real = robot_module.backend_class
    monkeypatch.setattr(robot_module, "backend_class",
                        lambda kind, name: LaneByLaneArm if kind == "arm" else real(kind, name))
    rig = WorksiteRig(robot)
    built = build_robot(rig.robot, site=rig.site_path, initial_pose=tuple(rig.world.base_pose()))
    try:
        built.start()
        for command_set in built.command_sets:
            core.install(command_set)
        for kind in ("arm", "compressor", "base"):
            assert built.get(kind).wait_ready(20.0), (kind, built.get(kind).health())
        assert not built.get("arm").supports(Arm.PATH)
        rig.world.mount_tool("sander")
        assert core.dispatcher.execute("MOUNT_TOOL sander").success
        assert core.dispatcher.execute("GOTO 2.4 2.6 1.5708").success
        r = core.dispatcher.execute("SAND_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 0 -1 0 spacing=0.1 speed=0.15")
        assert r.success, r.message
        assert r.result["lanes"] == 7 and r.result["contact"] == "position"
        m = rig.world.outcome.maps["wall_1"]
        cells = m.sanded[(m.tc >= 0.9) & (m.tc <= 1.5)][:, (m.sc >= 0.2) & (m.sc <= 1.0)]
        assert cells.mean() >= 0.98, cells.mean()
        assert rig.nothing_running(), rig.running()
    finally:
        built.close()
        rig.close()
