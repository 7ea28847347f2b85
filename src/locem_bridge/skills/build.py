"""Generate a robot's resource model from its only sources: the robot file, its LOCEM command registry and the
action trees.

* **Devices, frames, tools** from the robot file (loaded by :func:`locem_bridge.robot_file.load_robot`, the one
  loader): base (kinematics), pedestal, arm (model, reach, mount), lift and tool changer when present, compressor,
  scanner; each tool with its TCP frame on the flange, its length and its ``ppr:Tool`` class (``kind``).
* **Basic skills**: the commands the robot's LOCEM registers, built as ``locem_node`` builds them
  (:func:`locem_bridge.bridges.robot.build_robot` with the same ``devices``; nothing is started or connected) plus
  the system commands. Arguments become parameters (XSD type, QUDT unit, range, choices, default), resources the
  devices, ``CommandSpec.capability`` the capability.
* **Composite skills**: the declared action trees (:mod:`.trees`), offered only when this robot's LOCEM registers
  every command they send; otherwise kept with the reason.

Any inconsistency raises :class:`~.errors.SkillModelError` as ``FILE: KEY: PROBLEM`` and no model is returned.
"""
import inspect
import math
import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

import numpy as np
from rdflib import Graph, URIRef
from rdflib.namespace import OWL, RDF, RDFS

from ..common.config_errors import ConfigError
from ..common.geometry import rotvec_to_matrix
from ..bridges.robot import ALL_DEVICES
from ..common.paths import shipped_dir
from ..pemkre.vocab import PLB, PPR, SK
from .errors import SkillModelError
from .model import BASIC, COMPOSITE, DEVICE_CLASSES, KINEMATICS, PPR_ONTOLOGY, SKILL_ONTOLOGY, Device, Frame, \
    ResourceModel, Skill, SkillParameter, Tool
from .trees import read_tree_skills
from .units import UNITS

#: resources a command may occupy that are not devices of their own (the tool on the flange)
NON_DEVICE_RESOURCES = ("tool",)
_DATATYPE = {"float": "double", "int": "integer", "bool": "boolean", "enum": "string", "name": "string",
             "command": "string"}


def default_tree_dirs() -> List[str]:
    return [shipped_dir("trees")]


def build_resource_model(robot_file: str, tree_dirs: Sequence[str] = (), overrides: Optional[Mapping[str, Any]] = None,
                         devices: Sequence[str] = ALL_DEVICES,
                         ontology_files: Optional[Sequence[str]] = None) -> ResourceModel:
    """The resource model of the robot described by ``robot_file`` (``overrides`` deep-merged into its ``robot``
    section, as for ``locem_node``'s ``~robot_overrides``), with the composite skills of ``tree_dirs`` (default:
    the shipped ``trees/``). ``devices`` limits the LOCEM bridges as ``locem_node``'s ``~devices`` does;
    ``ontology_files`` (default: the shipped ``ontologies/*.ttl``) declare the capabilities and tool classes the
    model may name. Raises :class:`SkillModelError` naming file, key and problem; nothing is returned then."""
    from ..bridges.config import load_robot_config

    try:
        robot = load_robot_config(robot_file, overrides)
    except ConfigError as exc:
        raise exc.recast(SkillModelError)
    path = str(robot["_path"])
    onto = _Ontologies(ontology_files)
    model = ResourceModel(robot_name=str(robot["name"]), namespace=str(robot.get("namespace", "")),
                          robot_file=path, kinematics=str(robot["base"]["kind"]),
                          tree_dirs=[os.path.abspath(d) for d in (tree_dirs or default_tree_dirs())])
    _hardware(model, robot, devices, onto, path)
    specs, served, modules = _registry(robot, devices)
    known_devices = {d.name for d in model.devices}
    for spec in specs:
        model.basic_skills.append(_basic_skill(spec, served, known_devices, modules.get(spec.name, ""), onto, path))
    by_name = {s.name: s for s in model.basic_skills}
    for tree in read_tree_skills(model.tree_dirs):
        key = "TreeNodesModel.SubTree[%s]" % tree.tree_id
        capability = onto.capability(tree.capability, tree.file, key + ".capability") if tree.capability else ""
        missing = [c for c in tree.commands if c not in by_name or not by_name[c].offered]
        used: List[str] = []
        for c in tree.commands:
            if c in by_name:
                used.extend(d for d in by_name[c].devices if d not in used)
        reason = ""
        if missing:
            reason = "invokes %s, which this robot's LOCEM does not %s" % (
                ", ".join(missing), "register" if len(missing) > 1 or missing[0] not in by_name else "serve")
        params = tuple(SkillParameter(p.name, p.datatype, unit=p.unit, default=p.default,
                                      required=p.default is None, doc=p.doc) for p in tree.ports)
        model.composite_skills.append(Skill(
            name=tree.tree_id, kind=COMPOSITE, summary=tree.summary, capability=capability, parameters=params,
            devices=tuple(sorted(used)), invokes=tuple(c for c in tree.commands if c in by_name),
            involves_operator=tree.operator, offered=not missing, reason=reason, source=tree.file))
    # the exported file imports the ontologies that declare the capabilities it names (Protégé shows them typed)
    model.imports = sorted({onto.defined_in[s.capability] for s in model.skills()
                            if s.capability in onto.defined_in} - {SKILL_ONTOLOGY, PPR_ONTOLOGY})
    return model


# ===================================================================== ontologies: capabilities, tool classes
class _Ontologies:
    def __init__(self, files: Optional[Sequence[str]]) -> None:
        if files is None:
            from ..pemkre.ontology import default_ontology_files
            files = default_ontology_files()
        self.graph = Graph()
        self.prefixes: Dict[str, str] = {"sk": str(SK), "plb": str(PLB), "ppr": str(PPR)}
        self.defined_in: Dict[str, str] = {}        # capability IRI -> IRI of the ontology that declares it
        for f in files:
            g = Graph()
            try:
                g.parse(f, format="turtle")
            except Exception as exc:  # rdflib raises several types for syntax errors
                raise SkillModelError("Turtle cannot be read: %s" % str(exc).splitlines()[0][:200], file=f)
            for pfx, ns in g.namespaces():
                if pfx and pfx not in self.prefixes:
                    self.prefixes[pfx] = str(ns)
            self.graph += g
            header = next(iter(g.subjects(RDF.type, OWL.Ontology)), None)
            for c in g.subjects(RDF.type, SK.Capability):
                if header is not None:
                    self.defined_in.setdefault(str(c), str(header))
        self.capabilities = {str(c) for c in self.graph.subjects(RDF.type, SK.Capability)}

    def _names(self) -> List[str]:
        out = []
        for iri in sorted(self.capabilities):
            for pfx, ns in sorted(self.prefixes.items()):
                if iri.startswith(ns) and pfx in ("sk", "plb"):
                    out.append("%s:%s" % (pfx, iri[len(ns):]))
                    break
        return out

    def capability(self, name: str, file: str, key: str) -> str:
        """The IRI of a capability named ``sk:cap_X`` / ``plb:cap_X`` / a bare local name (sk, then plb) / an IRI."""
        candidates: List[str] = []
        if name.startswith(("http://", "https://")):
            candidates = [name]
        elif ":" in name:
            pfx, local = name.split(":", 1)
            if pfx in self.prefixes:
                candidates = [self.prefixes[pfx] + local]
        else:
            candidates = [str(SK) + name, str(PLB) + name]
        for iri in candidates:
            if iri in self.capabilities:
                return iri
        raise SkillModelError("%r is not a capability declared in the ontologies (an sk:Capability individual)"
                              % name, file=file, key=key, allowed=self._names())

    def tool_class(self, kind: str, file: str, key: str) -> str:
        """``kind`` (snake_case, e.g. spray_gun) -> the ppr:Tool sub-class of that name (ppr:SprayGun)."""
        tools = self._tool_classes()
        wanted = str(PPR) + "".join(w[:1].upper() + w[1:] for w in kind.split("_"))
        if wanted not in tools:
            raise SkillModelError("tool kind %r names no sub-class of ppr:Tool in the ontologies" % kind, file=file,
                                  key=key, allowed=sorted(_snake(c[len(str(PPR)):]) for c in tools))
        return wanted

    def _tool_classes(self) -> Set[str]:
        found: Set[str] = set()
        todo = [PPR.Tool]
        while todo:
            c = todo.pop()
            for sub in self.graph.subjects(RDFS.subClassOf, c):
                if isinstance(sub, URIRef) and str(sub) not in found:
                    found.add(str(sub))
                    todo.append(sub)
        return {c for c in found if c.startswith(str(PPR))}


def _snake(camel: str) -> str:
    return "".join("_" + ch.lower() if ch.isupper() and i else ch.lower() for i, ch in enumerate(camel))


# ===================================================================== devices, frames, tools
def _rpy(rotvec: Sequence[float]) -> Tuple[float, float, float]:
    """Roll, pitch, yaw (fixed axes x, y, z) of a rotation vector."""
    m = rotvec_to_matrix([float(v) for v in rotvec])
    pitch = math.asin(max(-1.0, min(1.0, -float(m[2, 0]))))
    if abs(float(m[2, 0])) < 1.0 - 1e-9:
        roll = math.atan2(float(m[2, 1]), float(m[2, 2]))
        yaw = math.atan2(float(m[1, 0]), float(m[0, 0]))
    else:                                       # gimbal lock: yaw carries the whole rotation about z
        roll = 0.0
        yaw = math.atan2(-float(m[0, 1]), float(m[1, 1]))
    return (roll, pitch, yaw)


def _vec3(v: Sequence[float]) -> Tuple[float, float, float]:
    return (float(v[0]), float(v[1]), float(v[2]))


def _hardware(model: ResourceModel, robot: Mapping[str, Any], devices: Sequence[str], onto: _Ontologies,
              path: str) -> None:
    base = robot["base"]
    kind = str(base["kind"])
    if kind not in KINEMATICS:
        raise SkillModelError("base kind %r has no kinematics individual in skill.ttl" % kind, file=path,
                              key="robot.base.kind", allowed=sorted(KINEMATICS))
    chassis_top = float(base["chassis"]["height"])
    model.devices.append(Device("base", "base", protocol=str(base["drives"].get("profile", "cia402")),
                                kinematics=kind))
    model.frames.append(Frame(str(base.get("frame", "base_footprint")), "device_base", (0.0, 0.0, 0.0),
                              (0.0, 0.0, 0.0)))
    footprint = "frame_" + model.frames[0].name
    ped = robot.get("pedestal")
    arm_parent, parent_xyz = footprint, (0.0, 0.0, 0.0)
    if ped:
        ped_xyz = (float(ped["xy"][0]), float(ped["xy"][1]), chassis_top)
        model.frames.append(Frame("pedestal", footprint, ped_xyz, (0.0, 0.0, 0.0)))
        arm_parent, parent_xyz = "frame_pedestal", ped_xyz
    lift = robot.get("lift")
    if isinstance(lift, Mapping) and "lift" in devices:
        # the lift's carriage rides on the pedestal column; offsets below hold with the lift at its lowest
        model.devices.append(Device("lift", "lift", protocol=str(lift.get("protocol", "cia402")),
                                    mounted_on=arm_parent, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)))
        arm_parent = "device_lift"
    arm = robot["arm"]
    model_name = str(arm.get("model", ""))
    reach = arm["reach"]                        # robot.arm.reach (checked by the robot file's loader)
    mount = arm["mount"]
    xyz = _vec3(mount["xyz"])
    if arm_parent in ("frame_pedestal", "device_lift"):
        xyz = (xyz[0] - parent_xyz[0], xyz[1] - parent_xyz[1], xyz[2] - parent_xyz[2])
    model.devices.append(Device("arm", "arm", protocol=str(arm.get("backend", "ur_rtde")), model=model_name,
                                mounted_on=arm_parent, xyz=xyz, rpy=_vec3(mount["rpy"]), reach=float(reach)))
    model.frames.append(Frame("flange", "device_arm"))
    if isinstance(robot.get("tool_changer"), Mapping) and "tool_changer" in devices:
        tc = robot["tool_changer"]
        model.devices.append(Device("tool_changer", "tool_changer", protocol=str(tc.get("protocol", "")),
                                    mounted_on="frame_flange"))
    if "compressor" in robot and "compressor" in devices:
        model.devices.append(Device("compressor", "compressor", protocol=str(robot["compressor"].get("protocol", "")),
                                    mounted_on="device_base"))
    if "scanner" in robot and "scanner" in devices:
        sc = robot["scanner"]
        model.devices.append(Device("scanner", "scanner", protocol=str(sc.get("backend", "sim")),
                                    mounted_on=footprint, xyz=_vec3(sc["mount"]["xyz"]),
                                    rpy=(0.0, 0.0, float(sc["mount"].get("yaw", 0.0)))))
    if "base" not in devices:
        model.devices = [d for d in model.devices if d.name != "base"]
    if "arm" not in devices:
        model.devices = [d for d in model.devices if d.name != "arm"]
    reserved = {"robot"}
    for name in sorted(robot.get("tools", {})):
        cfg = robot["tools"][name]
        tp = "robot.tools.%s" % name
        if name in reserved or name.startswith(("skill_", "device_", "frame_", "interface_")):
            raise SkillModelError("tool name %r clashes with the model's own names" % name, file=path, key=tp)
        tcp = cfg.get("tcp")
        if not isinstance(tcp, (list, tuple)) or len(tcp) != 6:
            raise SkillModelError("a tool needs its TCP [x, y, z, rx, ry, rz] (m, rad) from the flange", file=path,
                                  key=tp + ".tcp")
        kind = str(cfg.get("kind") or name)
        tool_class = onto.tool_class(kind, path, tp + ".kind")
        frame = Frame("tcp_" + name, "frame_flange", _vec3(tcp[:3]), _rpy(tcp[3:]))
        length = float(np.linalg.norm([float(v) for v in tcp[:3]]))
        model.tools.append(Tool(name, kind, tool_class, frame, length, float(cfg.get("mass", 0.0))))


# ===================================================================== the LOCEM registry of this robot
def _registry(robot: Mapping[str, Any], devices: Sequence[str]) -> Tuple[list, Set[str], Dict[str, str]]:
    """(declared specs in HELP order, names with a handler, name -> declaring module file), as locem_node builds
    them: the system commands, then every command set of :func:`build_robot` (nothing started)."""
    from ..bridges.robot import build_robot
    from ..locem import system_commands
    from ..locem.registry import CommandRegistry

    registry = CommandRegistry()
    served: Set[str] = set()
    modules: Dict[str, str] = {}
    for spec in system_commands.SPECS:
        if spec in system_commands.SKILL_METHODS:     # the state machine's methods, not skills
            continue
        registry.declare(spec)
        served.add(spec.name)
        modules[spec.name] = inspect.getsourcefile(system_commands) or ""
    try:
        built = build_robot(robot, devices=devices, site=None)
    except ConfigError as exc:
        raise exc.recast(SkillModelError)
    try:
        for command_set in built.command_sets:
            source = inspect.getsourcefile(type(command_set)) or ""
            for spec in command_set.specs():
                registry.declare(spec)
                modules.setdefault(spec.name, source)
            for name, handler in command_set.handlers().items():
                registry.bind(name, handler)
                served.add(name)
    finally:
        built.close()
    return registry.specs(), served, modules


def _basic_skill(spec: Any, served: Set[str], known_devices: Set[str], module: str, onto: _Ontologies,
                 robot_path: str) -> Skill:
    params: List[SkillParameter] = []
    for arg in spec.args:
        if arg.unit not in UNITS:
            raise SkillModelError("command %s argument %s: unit %r is not a known unit" % (spec.name, arg.name, arg.unit),
                                  file=module, key="%s.%s.unit" % (spec.name, arg.name),
                                  allowed=sorted(u for u in UNITS if u))
        datatype = _DATATYPE[arg.type.value]
        params.append(SkillParameter(
            arg.name, datatype, unit=arg.unit, minimum=arg.minimum, maximum=arg.maximum,
            default=None if arg.required else arg.default, choices=tuple(arg.choices), required=arg.required,
            keyword_only=arg.keyword_only, doc=arg.doc))
    used = [r for r in sorted(spec.resources) if r not in NON_DEVICE_RESOURCES]
    if spec.category in DEVICE_CLASSES and spec.category not in used and spec.category in known_devices:
        used.append(spec.category)
    for r in used:
        if r not in known_devices:
            raise SkillModelError("command %s uses device %r, which this robot does not have" % (spec.name, r),
                                  file=robot_path, key="robot.%s" % r, allowed=sorted(known_devices))
    capability = onto.capability(spec.capability, module, "%s.capability" % spec.name) if spec.capability else ""
    offered = spec.name in served
    return Skill(name=spec.name, kind=BASIC, summary=spec.summary, capability=capability, parameters=tuple(params),
                 devices=tuple(sorted(used)), offered=offered,
                 reason="" if offered else "declared but no backend of this robot serves it",
                 interfaces=tuple(sorted(i.value for i in spec.interfaces if i.value in ("service", "action"))),
                 source=module)
