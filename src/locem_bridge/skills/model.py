"""The resource model of one robot as typed records, and its RDF view (``ontologies/skill.ttl`` vocabulary).

Built by :func:`locem_bridge.skills.build.build_resource_model`; never edited by hand. Instance IRIs live under
``https://locem-bridge.example.org/robot/<robot name>/`` so several robots can share one store:

============================  ===========================================================================
``robot``                     the robot (``ppr:Robot``)
``device_<name>``             a device (``sk:Arm``, ``sk:MobileBase``, ``sk:Compressor``, ``sk:Scanner``, ...)
``frame_<name>``              a frame of the mount chain or a tool's TCP (``sk:Frame``)
``<tool name>``               a tool (its ``ppr:Tool`` class from the robot file's ``kind``); the local name is
                              the tool name, the symbol HICEM and LOCEM use (``taping_tool``)
``skill_<NAME>``              a basic skill (LOCEM command ``NAME``)
``skill_tree_<ID>``           a composite skill (action tree ``ID``)
``<skill>_param_<name>``      a skill parameter
``interface_<name>``          a skill interface (``/locem/command`` service, ``/locem/command_action`` action)
============================  ===========================================================================
"""
import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

from rdflib import Graph, Literal, Namespace, URIRef
from rdflib.namespace import OWL, RDF, RDFS, XSD

from ..pemkre.vocab import BASE, PLB, PPR, PROC, SK
from .units import qudt_iri

ROBOT_BASE = BASE + "robot/"
SKILL_ONTOLOGY = "https://locem-bridge.example.org/ont/skill"
PPR_ONTOLOGY = "https://locem-bridge.example.org/ont/ppr"
BASIC = "basic"
COMPOSITE = "composite"

#: device kind -> its sk: class local name
DEVICE_CLASSES: Dict[str, str] = {"arm": "Arm", "base": "MobileBase", "lift": "Lift", "compressor": "Compressor",
                                  "tool_changer": "ToolChanger", "scanner": "Scanner"}
#: robot.base.kind -> the sk:BaseKinematics individual
KINEMATICS: Dict[str, str] = {"mecanum": "Mecanum", "differential": "DifferentialDrive"}
#: the LOCEM interfaces a basic skill is reachable through (Interface value -> class, endpoint)
INTERFACES: Dict[str, Tuple[str, str]] = {"service": ("RosServiceInterface", "/locem/command"),
                                          "action": ("RosActionInterface", "/locem/command_action")}
_XSD = {"double": XSD.double, "integer": XSD.integer, "boolean": XSD.boolean, "string": XSD.string}


@dataclass(frozen=True)
class SkillParameter:
    """One input of a skill. ``datatype`` is an XSD local name (double, integer, boolean, string); ``unit`` the
    LOCEM unit ("" = unitless); ``choices`` the allowed values of a choice; ``default`` None when required."""

    name: str
    datatype: str
    unit: str = ""
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    default: Any = None
    choices: Tuple[str, ...] = ()
    required: bool = True
    keyword_only: bool = False
    doc: str = ""


@dataclass(frozen=True)
class Skill:
    """A basic skill (``kind`` = ``basic``: a LOCEM command) or a composite one (``composite``: an action tree).

    ``capability`` is the full IRI of the capability it realizes ("" when none); ``devices`` the device names it
    uses; ``invokes`` (composite) the LOCEM commands its tree sends; ``offered`` False when the robot cannot run it,
    ``reason`` says why; ``interfaces`` the LOCEM interfaces that carry a basic skill; ``source`` the tree file or
    the module declaring the command."""

    name: str
    kind: str
    summary: str = ""
    capability: str = ""
    parameters: Tuple[SkillParameter, ...] = ()
    devices: Tuple[str, ...] = ()
    invokes: Tuple[str, ...] = ()
    involves_operator: bool = False
    offered: bool = True
    reason: str = ""
    interfaces: Tuple[str, ...] = ()
    source: str = ""

    @property
    def local_name(self) -> str:
        return ("skill_%s" if self.kind == BASIC else "skill_tree_%s") % self.name


@dataclass(frozen=True)
class Device:
    """A device of the robot (a section of the robot file; also its LOCEM resource name)."""

    name: str
    kind: str                   # a key of DEVICE_CLASSES
    protocol: str = ""
    model: str = ""
    mounted_on: str = ""        # local name of the frame or device it is fixed to ("" for the base)
    xyz: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: Tuple[float, float, float] = (0.0, 0.0, 0.0)
    reach: Optional[float] = None          # arms, m
    kinematics: str = ""                   # bases: a key of KINEMATICS


@dataclass(frozen=True)
class Frame:
    """A frame of the mount chain (base footprint, pedestal, flange) or a tool centre point."""

    name: str
    mounted_on: str             # local name of the parent (frame_..., device_...)
    xyz: Optional[Tuple[float, float, float]] = None      # None: the offset varies (the flange moves with the arm)
    rpy: Optional[Tuple[float, float, float]] = None


@dataclass(frozen=True)
class Tool:
    """A tool of the robot; ``tool_class`` is the full IRI of its ``ppr:Tool`` sub-class (from the file's
    ``kind``); ``tcp`` its TCP frame (mounted on the flange); ``length`` flange to TCP, m."""

    name: str
    kind: str
    tool_class: str
    tcp: Frame
    length: float
    mass: float


@dataclass
class ResourceModel:
    """Everything the robot offers, generated from the robot file, its LOCEM registry and the action trees."""

    robot_name: str
    namespace: str
    robot_file: str
    kinematics: str
    devices: List[Device] = field(default_factory=list)
    frames: List[Frame] = field(default_factory=list)
    tools: List[Tool] = field(default_factory=list)
    basic_skills: List[Skill] = field(default_factory=list)
    composite_skills: List[Skill] = field(default_factory=list)
    tree_dirs: List[str] = field(default_factory=list)
    #: IRIs of further ontologies the exported model imports (those declaring the capabilities it names)
    imports: List[str] = field(default_factory=list)

    # -- lookups ---------------------------------------------------------------------------------------
    @property
    def base_iri(self) -> str:
        return ROBOT_BASE + self.robot_name + "/"

    @property
    def robot_iri(self) -> URIRef:
        return URIRef(self.base_iri + "robot")

    def iri(self, local: str) -> URIRef:
        return URIRef(self.base_iri + local)

    def skills(self) -> List[Skill]:
        return list(self.basic_skills) + list(self.composite_skills)

    def offered_skills(self) -> List[Skill]:
        return [s for s in self.skills() if s.offered]

    def skill(self, name: str, kind: str = "") -> Skill:
        """The skill named ``name`` (a command name or tree ID; ``kind`` picks one when both exist)."""
        found = [s for s in self.skills() if s.name == name and (not kind or s.kind == kind)]
        if not found:
            raise KeyError("no %sskill named %s" % (kind + " " if kind else "", name))
        if len(found) > 1:
            raise KeyError("%s is both a basic and a composite skill; pass kind=" % name)
        return found[0]

    def device(self, name: str) -> Device:
        for d in self.devices:
            if d.name == name:
                return d
        raise KeyError("no device named %s" % name)

    def tool(self, name: str) -> Tool:
        for t in self.tools:
            if t.name == name:
                return t
        raise KeyError("no tool named %s" % name)

    def capabilities(self) -> List[str]:
        """The capabilities the offered skills realize (IRIs, sorted)."""
        return sorted({s.capability for s in self.offered_skills() if s.capability})

    # -- RDF view --------------------------------------------------------------------------------------
    def to_graph(self, header: bool = True) -> Graph:
        """The model as RDF (no blank nodes). ``header``: an ``owl:Ontology`` for the robot that imports
        ``skill.ttl``, ``ppr.ttl`` and the ontologies declaring its capabilities by IRI (what Protégé needs;
        harmless in a store)."""
        g = Graph()
        g.bind("sk", Namespace(str(SK)))
        g.bind("ppr", Namespace(str(PPR)))
        g.bind("plb", Namespace(str(PLB)))
        g.bind("owl", OWL)
        g.bind("xsd", XSD)
        g.bind("unit", Namespace("http://qudt.org/vocab/unit/"))
        g.bind(self.robot_name.replace("-", "_") if self.robot_name[:1].isalpha() else "robot",
               Namespace(self.base_iri))
        robot = self.robot_iri
        if header:
            onto = URIRef(ROBOT_BASE + self.robot_name)
            g.add((onto, RDF.type, OWL.Ontology))
            g.add((onto, RDFS.label, Literal("Resource model of %s (generated)" % self.robot_name, lang="en")))
            g.add((onto, OWL.imports, URIRef(SKILL_ONTOLOGY)))
            g.add((onto, OWL.imports, URIRef(PPR_ONTOLOGY)))
            for extra in self.imports:
                g.add((onto, OWL.imports, URIRef(extra)))
        g.add((robot, RDF.type, PPR.Robot))
        g.add((robot, RDF.type, OWL.NamedIndividual))
        g.add((robot, RDFS.label, Literal(self.robot_name)))
        if self.namespace:
            g.add((robot, SK.rosNamespace, Literal(self.namespace)))
        if self.robot_file:
            g.add((robot, SK.sourceFile, Literal(self.robot_file)))
        for d in self.devices:
            node = self.iri("device_" + d.name)
            g.add((robot, SK.hasDevice, node))
            g.add((node, RDF.type, SK[DEVICE_CLASSES[d.kind]]))
            g.add((node, RDF.type, OWL.NamedIndividual))
            g.add((node, SK.deviceName, Literal(d.name)))
            if d.protocol:
                g.add((node, SK.protocol, Literal(d.protocol)))
            if d.model:
                g.add((node, SK.model, Literal(d.model)))
            if d.reach is not None:
                g.add((node, SK.reach, Literal(float(d.reach), datatype=XSD.double)))
            if d.kinematics:
                g.add((node, SK.kinematics, SK[KINEMATICS[d.kinematics]]))
            if d.mounted_on:
                g.add((node, SK.mountedOn, self.iri(d.mounted_on)))
                _offset(g, node, d.xyz, d.rpy)
        for f in self.frames:
            self._frame(g, f)
        for t in self.tools:
            node = self.iri(t.name)
            g.add((robot, SK.hasTool, node))
            g.add((node, RDF.type, URIRef(t.tool_class)))
            g.add((node, RDF.type, OWL.NamedIndividual))
            g.add((node, SK.toolName, Literal(t.name)))
            g.add((node, SK.toolLength, Literal(float(t.length), datatype=XSD.double)))
            g.add((node, SK.mass, Literal(float(t.mass), datatype=XSD.double)))
            g.add((node, SK.mountedOn, self.iri(t.tcp.mounted_on)))
            g.add((node, SK.hasTcp, self.iri("frame_" + t.tcp.name)))
            self._frame(g, t.tcp)
        for name, (cls, endpoint) in sorted(INTERFACES.items()):
            node = self.iri("interface_" + name)
            g.add((node, RDF.type, SK[cls]))
            g.add((node, RDF.type, OWL.NamedIndividual))
            g.add((node, SK.endpoint, Literal(endpoint)))
        for s in self.skills():
            self._skill(g, s)
        return g

    def seed_graph(self) -> Graph:
        """The robot's identity as a PEMKRE world seed (``proc:isWorldSeed``): the robot and its tools with their
        classes, under the same IRIs as :meth:`to_graph`. What a PEMKRE without a resource model binds the robot
        and tool parameters to; loading this robot's model on top adds to the same individuals."""
        g = Graph()
        g.bind("ppr", Namespace(str(PPR)))
        g.bind("sk", Namespace(str(SK)))
        g.bind("owl", OWL)
        g.bind("proc", Namespace(str(PROC)))
        g.bind(self.robot_name.replace("-", "_") if self.robot_name[:1].isalpha() else "robot",
               Namespace(self.base_iri))
        onto = URIRef(ROBOT_BASE + self.robot_name + "/seed")
        g.add((onto, RDF.type, OWL.Ontology))
        g.add((onto, RDFS.label, Literal("%s and its tools as world seed (generated from %s)"
                                         % (self.robot_name, os.path.basename(self.robot_file)), lang="en")))
        g.add((onto, PROC.isWorldSeed, Literal(True)))
        g.add((onto, OWL.imports, URIRef(PPR_ONTOLOGY)))
        g.add((onto, OWL.imports, URIRef(SKILL_ONTOLOGY)))
        robot = self.robot_iri
        g.add((robot, RDF.type, PPR.Robot))
        g.add((robot, RDF.type, OWL.NamedIndividual))
        g.add((robot, RDFS.label, Literal(self.robot_name)))
        for t in self.tools:
            node = self.iri(t.name)
            g.add((robot, SK.hasTool, node))
            g.add((node, RDF.type, URIRef(t.tool_class)))
            g.add((node, RDF.type, OWL.NamedIndividual))
            g.add((node, SK.toolName, Literal(t.name)))
        return g

    def _frame(self, g: Graph, f: Frame) -> None:
        node = self.iri("frame_" + f.name)
        g.add((self.robot_iri, SK.hasFrame, node))
        g.add((node, RDF.type, SK.Frame))
        g.add((node, RDF.type, OWL.NamedIndividual))
        g.add((node, SK.frameName, Literal(f.name)))
        g.add((node, SK.mountedOn, self.iri(f.mounted_on)))
        _offset(g, node, f.xyz, f.rpy)

    def _skill(self, g: Graph, s: Skill) -> None:
        node = self.iri(s.local_name)
        robot = self.robot_iri
        g.add((node, RDF.type, SK.BasicSkill if s.kind == BASIC else SK.CompositeSkill))
        g.add((node, RDF.type, OWL.NamedIndividual))
        g.add((node, SK.skillName, Literal(s.name)))
        g.add((node, SK.involvesOperator, Literal(bool(s.involves_operator))))
        g.add((node, SK.hasStateMachine, SK.ProgramStateMachine))
        if s.summary:
            g.add((node, SK.summary, Literal(s.summary)))
        if s.source:
            g.add((node, SK.sourceFile, Literal(s.source)))
        if s.offered:
            g.add((robot, SK.providesSkill, node))
        else:
            g.add((node, SK.notOfferedBy, robot))
            g.add((node, SK.notOfferedReason, Literal(s.reason)))
        if s.capability:
            cap = URIRef(s.capability)
            g.add((node, SK.realizesCapability, cap))
            g.add((cap, SK.isRealizedBySkill, node))
            if s.offered:
                g.add((robot, SK.providesCapability, cap))
        for d in s.devices:
            g.add((node, SK.usesDevice, self.iri("device_" + d)))
        for name in s.invokes:
            g.add((node, SK.invokesSkill, self.iri("skill_" + name)))
        for i in s.interfaces:
            g.add((node, SK.hasSkillInterface, self.iri("interface_" + i)))
        for index, p in enumerate(s.parameters):
            pn = self.iri("%s_param_%s" % (s.local_name, p.name))
            g.add((node, SK.hasParameter, pn))
            g.add((pn, RDF.type, SK.SkillParameter))
            g.add((pn, RDF.type, OWL.NamedIndividual))
            g.add((pn, SK.parameterName, Literal(p.name)))
            g.add((pn, SK.parameterIndex, Literal(index)))
            g.add((pn, SK.datatype, _XSD[p.datatype]))
            g.add((pn, SK.isRequired, Literal(bool(p.required))))
            if p.keyword_only:
                g.add((pn, SK.keywordOnly, Literal(True)))
            if p.doc:
                g.add((pn, RDFS.comment, Literal(p.doc)))
            unit = qudt_iri(p.unit)
            if unit:
                g.add((pn, SK.unit, URIRef(unit)))
            if p.minimum is not None:
                g.add((pn, SK.minValue, _literal(p.minimum, p.datatype)))
            if p.maximum is not None:
                g.add((pn, SK.maxValue, _literal(p.maximum, p.datatype)))
            if not p.required and p.default is not None:
                g.add((pn, SK.defaultValue, _literal(p.default, p.datatype)))
            for c in p.choices:
                g.add((pn, SK.allowedValue, Literal(c)))


def _literal(value: Any, datatype: str) -> Literal:
    if datatype == "double":
        return Literal(float(value), datatype=XSD.double)
    if datatype == "integer":
        return Literal(int(value), datatype=XSD.integer)
    if datatype == "boolean":
        return Literal(bool(value))
    return Literal(str(value))


def _offset(g: Graph, node: URIRef, xyz: Optional[Sequence[float]], rpy: Optional[Sequence[float]]) -> None:
    if xyz is not None:
        g.add((node, SK.offsetXyz, Literal(" ".join(_num(v) for v in xyz))))
    if rpy is not None:
        g.add((node, SK.offsetRpy, Literal(" ".join(_num(v) for v in rpy))))


def _num(v: float) -> str:
    text = "%.6f" % float(v)
    text = text.rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
