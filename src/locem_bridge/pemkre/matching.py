"""Capability matching: which skill of this robot realizes each task of a process, and why the others do not.

Lifecycle: :class:`MatchingQueries` prepares the catalogue queries once on the store (with the vocabulary
prefixes as ``initNs``); :meth:`SkillCatalog.read` runs them over the store -- the ontologies (task types with
``sk:requiresCapability``, task templates) and the robot's resource model (skills with
``sk:realizesCapability``, ``sk:usesDevice``, ``sk:invokesSkill``, ``sk:involvesOperator``, parameters with
ranges and choices; the robot with ``sk:providesSkill``, ``sk:hasDevice``, ``sk:hasTool``) -- and indexes them
in plain Python; :func:`match_process` then matches every task node of one abstract process without touching
the store again, except for the task parameters a check needs, which the caller evaluates (``bind``).

For every task node whose task type requires a capability, the candidates are the skills that realize it (those
this robot offers and those no robot offers: the model keeps a tree the robot cannot run, so the reason can be
told), the skills of this robot named like the action type that realize something else, and the task templates
that expand the task type. A candidate is rejected with a reason: it does not realize the capability; it is not
offered by this robot (and which command it needs is missing); it uses a device the robot does not have; a
parameter value the task binds is outside the skill's range or choices; the tool the task binds is absent from
the robot; it needs the operator while an automatic realization exists; or a better one was chosen. Ranking:
a single skill without the operator, then a template expansion (every step matched to a skill of this robot),
then a skill involving the operator. A task type without a required capability is not matched (its tree is its
action type, as before matching existed).

ROS-free and typed; read-only. The engine (:mod:`locem_bridge.pemkre.engine`) calls it at ``start_process`` and
when it issues a task.
"""
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Set, Tuple

from rdflib import Literal, Namespace, URIRef
from rdflib.term import Node

from ..common.next_action import BASIC, COMPOSITE
from .ontology import AbstractProcess, FlowNode, Parameter
from .store import PreparedQuery, TripleStore
from .terms import local_name
from .vocab import BASE, PREFIXES, SK

#: ``Realization.kind``: one skill realizes the task.
SKILL = "skill"
#: ``Realization.kind``: a task template expands the task into subtasks, each realized by a skill.
TEMPLATE = "template"

#: The predicates of a subtask's arguments (execution log, next action): the local name is the argument name.
ARG = Namespace(BASE + "skill-argument/")

_ARG_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_PLACEHOLDER_RE = re.compile(r"^\{([A-Za-z_][A-Za-z0-9_]*)\}$")

_QUERIES: Dict[str, str] = {
    "skills": """
SELECT ?skill ?kind ?name ?op ?why WHERE {
  VALUES ?kind { sk:BasicSkill sk:CompositeSkill }
  ?skill a ?kind .
  OPTIONAL { ?skill sk:skillName ?name }
  OPTIONAL { ?skill sk:involvesOperator ?op }
  OPTIONAL { ?skill sk:notOfferedReason ?why }
}""",
    "realizes": """
SELECT DISTINCT ?skill ?cap WHERE { { ?skill sk:realizesCapability ?cap } UNION { ?cap sk:isRealizedBySkill ?skill } }""",
    "robots": """
SELECT ?robot ?p ?o WHERE {
  ?robot a ppr:Robot .
  OPTIONAL { VALUES ?p { sk:providesSkill sk:hasDevice sk:hasTool } ?robot ?p ?o }
}""",
    "skill_links": """
SELECT ?skill ?p ?o WHERE { VALUES ?p { sk:usesDevice sk:invokesSkill sk:notOfferedBy } ?skill ?p ?o }""",
    "parameters": """
SELECT ?skill ?name ?min ?max ?allowed ?default ?required WHERE {
  ?skill sk:hasParameter ?prm . ?prm sk:parameterName ?name .
  OPTIONAL { ?prm sk:minValue ?min }
  OPTIONAL { ?prm sk:maxValue ?max }
  OPTIONAL { ?prm sk:allowedValue ?allowed }
  OPTIONAL { ?prm sk:defaultValue ?default }
  OPTIONAL { ?prm sk:isRequired ?required }
}""",
    "tool_names": """
SELECT ?tool ?name WHERE { ?tool sk:toolName ?name }""",
    "templates": """
SELECT ?tmpl ?type ?step ?idx ?cap ?arg WHERE {
  ?tmpl sk:expandsTaskType ?type ; sk:hasStep ?step .
  ?step sk:stepIndex ?idx ; sk:requiresCapability ?cap .
  OPTIONAL { ?step sk:stepArgument ?arg }
}""",
    "required": """
SELECT ?type ?cap WHERE { ?type sk:requiresCapability ?cap ; proc:actionType ?at }""",
    "tool_properties": """
SELECT DISTINCT ?p WHERE { ?p rdfs:range ?c . ?c rdfs:subClassOf* ppr:Tool }""",
}


class MatchingQueries:
    """The catalogue queries, prepared once on ``store`` (values are never spliced into their text)."""

    def __init__(self, store: TripleStore) -> None:
        prefixes = {k: str(v) for k, v in PREFIXES.items()}
        prefixes.setdefault("sk", str(SK))
        self.store = store
        self.queries: Dict[str, PreparedQuery] = {
            name: store.prepare(text, "matching query %r" % name, prefixes) for name, text in _QUERIES.items()}

    def rows(self, name: str) -> List[Dict[str, Node]]:
        return self.store.select(self.queries[name])


# ===================================================================== the catalogue (plain Python indexes)
@dataclass
class SkillParameter:
    name: str
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    allowed: List[str] = field(default_factory=list)
    default: Optional[str] = None
    required: bool = False


@dataclass
class SkillInfo:
    iri: URIRef
    name: str
    kind: str                                   # basic | composite
    capabilities: Set[URIRef] = field(default_factory=set)
    involves_operator: bool = False
    devices: Set[URIRef] = field(default_factory=set)
    invokes: List[URIRef] = field(default_factory=list)
    parameters: Dict[str, SkillParameter] = field(default_factory=dict)
    not_offered_reason: str = ""                # what the resource model says (sk:notOfferedReason)


@dataclass
class RobotInfo:
    iri: URIRef
    skills: Set[URIRef] = field(default_factory=set)
    devices: Set[URIRef] = field(default_factory=set)
    tools: Set[URIRef] = field(default_factory=set)


@dataclass
class TemplateStep:
    index: int
    capability: URIRef
    arguments: List[Tuple[str, str]] = field(default_factory=list)   # (argument name, value text)
    problem: str = ""                                                # a malformed argument


@dataclass
class TemplateInfo:
    iri: URIRef
    task_type: URIRef
    steps: List[TemplateStep] = field(default_factory=list)


def _num(term: Optional[Node]) -> Optional[float]:
    if isinstance(term, Literal):
        try:
            return float(term.toPython())
        except (TypeError, ValueError):
            return None
    return None


def _flag(term: Optional[Node]) -> bool:
    return isinstance(term, Literal) and term.toPython() is True


def _param_name(name: str) -> str:
    """A tree's input port ``param_tool`` and a command argument ``tool`` both take the task parameter ``tool``."""
    return name[len("param_"):] if name.startswith("param_") else name


@dataclass
class SkillCatalog:
    """Every skill, robot and template the store knows, indexed for matching (see the module docstring)."""

    skills: Dict[URIRef, SkillInfo] = field(default_factory=dict)
    robots: Dict[URIRef, RobotInfo] = field(default_factory=dict)
    templates: Dict[URIRef, List[TemplateInfo]] = field(default_factory=dict)   # by task type
    required: Dict[URIRef, URIRef] = field(default_factory=dict)               # task type -> capability
    tool_names: Dict[URIRef, Set[str]] = field(default_factory=dict)
    tool_properties: Set[URIRef] = field(default_factory=set)
    realized_by: Dict[URIRef, List[URIRef]] = field(default_factory=dict)      # capability -> skills
    offered_by: Dict[URIRef, Set[URIRef]] = field(default_factory=dict)        # skill -> robots
    described_for: Dict[URIRef, Set[URIRef]] = field(default_factory=dict)     # skill -> robots not offering it

    @classmethod
    def read(cls, q: MatchingQueries) -> "SkillCatalog":
        cat = cls()
        for row in q.rows("skills"):
            s = row["skill"]
            if not isinstance(s, URIRef) or s in cat.skills:
                continue
            name = row.get("name")
            cat.skills[s] = SkillInfo(s, str(name) if name is not None else re.sub(r"^skill_", "", local_name(s)),
                                      BASIC if row["kind"] == SK.BasicSkill else COMPOSITE,
                                      involves_operator=_flag(row.get("op")),
                                      not_offered_reason=str(row.get("why") or ""))
        for row in q.rows("realizes"):
            info = cat.skills.get(row["skill"])  # type: ignore[arg-type]
            cap = row["cap"]
            if info is not None and isinstance(cap, URIRef):
                info.capabilities.add(cap)
                cat.realized_by.setdefault(cap, []).append(info.iri)
        for row in q.rows("robots"):
            r = row["robot"]
            if not isinstance(r, URIRef):
                continue
            robot = cat.robots.setdefault(r, RobotInfo(r))
            p, o = row.get("p"), row.get("o")
            if p == SK.providesSkill:
                robot.skills.add(o)  # type: ignore[arg-type]
                cat.offered_by.setdefault(o, set()).add(r)  # type: ignore[arg-type]
            elif p == SK.hasDevice:
                robot.devices.add(o)  # type: ignore[arg-type]
            elif p == SK.hasTool:
                robot.tools.add(o)  # type: ignore[arg-type]
        for row in q.rows("skill_links"):
            info = cat.skills.get(row["skill"])  # type: ignore[arg-type]
            if info is None:
                continue
            if row["p"] == SK.usesDevice:
                info.devices.add(row["o"])  # type: ignore[arg-type]
            elif row["p"] == SK.notOfferedBy:
                cat.described_for.setdefault(info.iri, set()).add(row["o"])  # type: ignore[arg-type]
            elif row["o"] not in info.invokes:
                info.invokes.append(row["o"])  # type: ignore[arg-type]
        for row in q.rows("parameters"):
            info = cat.skills.get(row["skill"])  # type: ignore[arg-type]
            if info is None:
                continue
            name = _param_name(str(row["name"]))
            prm = info.parameters.get(name)
            if prm is None:
                prm = info.parameters[name] = SkillParameter(name, _num(row.get("min")), _num(row.get("max")),
                                                             default=None if row.get("default") is None
                                                             else str(row["default"]),
                                                             required=_flag(row.get("required")))
            allowed = row.get("allowed")
            if allowed is not None:
                text = local_name(allowed) if isinstance(allowed, URIRef) else str(allowed)
                if text not in prm.allowed:
                    prm.allowed.append(text)
        for row in q.rows("tool_names"):
            cat.tool_names.setdefault(row["tool"], set()).add(str(row["name"]))  # type: ignore[arg-type]
        steps: Dict[Tuple[URIRef, URIRef], Dict[Node, TemplateStep]] = {}
        for row in q.rows("templates"):
            key = (row["tmpl"], row["type"])
            by_step = steps.setdefault(key, {})  # type: ignore[arg-type]
            st = by_step.get(row["step"])
            if st is None:
                idx = _num(row.get("idx"))
                st = by_step[row["step"]] = TemplateStep(int(idx) if idx is not None else 0, row["cap"])  # type: ignore
            arg = row.get("arg")
            if arg is not None:
                m = _ARG_RE.match(str(arg))
                if m is None:
                    st.problem = "argument %r is not name=value or name={parameter}" % str(arg)
                elif (m.group(1), m.group(2)) not in st.arguments:
                    st.arguments.append((m.group(1), m.group(2)))
        for (tmpl, tt), by_step in sorted(steps.items()):
            ordered = sorted(by_step.values(), key=lambda s: s.index)
            for st in ordered:
                st.arguments.sort()
            cat.templates.setdefault(tt, []).append(TemplateInfo(tmpl, tt, ordered))
        for row in q.rows("required"):
            cat.required[row["type"]] = row["cap"]  # type: ignore[index]
        cat.tool_properties = {row["p"] for row in q.rows("tool_properties")}  # type: ignore[misc]
        return cat

    def default_robot(self) -> Optional[URIRef]:
        """The robot matching is for when none is named: the first by IRI offering skills (else the first)."""
        offering = [r for r, info in self.robots.items() if info.skills]
        return min(offering) if offering else (min(self.robots) if self.robots else None)


# ===================================================================== the answer
@dataclass
class Rejection:
    """A candidate that does not realize the task here, and why."""

    candidate: str          # the skill's or template's IRI
    name: str               # the skill name (command or tree ID) or the template's local name
    kind: str               # basic | composite | template
    reason: str

    def to_dict(self) -> Dict[str, str]:
        return {"candidate": self.candidate, "name": self.name, "kind": self.kind, "reason": self.reason}


@dataclass
class StepMatch:
    """One template step and the skill that realizes it."""

    index: int
    capability: str
    skill: str
    name: str
    skill_kind: str
    arguments: List[Tuple[str, str]] = field(default_factory=list)   # (argument name, value text or {parameter})
    involves_operator: bool = False

    def to_dict(self) -> Dict[str, Any]:
        return {"index": self.index, "capability": self.capability, "skill": self.skill, "name": self.name,
                "skill_kind": self.skill_kind, "arguments": ["%s=%s" % a for a in self.arguments],
                "involves_operator": self.involves_operator}


@dataclass
class Realization:
    """The chosen way to run a task: one skill (``kind`` skill) or a template's steps (``kind`` template)."""

    kind: str
    skill: str = ""                 # skill: the skill IRI
    name: str = ""                  # skill: the command name or tree ID; template: the template's local name
    skill_kind: str = ""            # skill: basic | composite
    template: str = ""              # template: its IRI
    steps: List[StepMatch] = field(default_factory=list)
    involves_operator: bool = False

    def to_dict(self) -> Dict[str, Any]:
        d: Dict[str, Any] = {"kind": self.kind, "name": self.name, "involves_operator": self.involves_operator}
        if self.kind == SKILL:
            d.update(skill=self.skill, skill_kind=self.skill_kind)
        else:
            d.update(template=self.template, steps=[s.to_dict() for s in self.steps])
        return d


@dataclass
class NodeMatch:
    """The match of one task node: its required capability, the chosen realization, the rejected candidates."""

    node: str
    task_type: str
    action_type: str
    capability: str = ""            # "" = the task type requires none (not matched: its tree is the action type)
    realization: Optional[Realization] = None
    rejected: List[Rejection] = field(default_factory=list)
    problem: str = ""               # why nothing realizes it (when realization is None and a capability is required)

    @property
    def ok(self) -> bool:
        return not self.capability or self.realization is not None

    def to_dict(self) -> Dict[str, Any]:
        return {"node": self.node, "task_type": self.task_type, "action_type": self.action_type,
                "capability": self.capability, "ok": self.ok,
                "realization": self.realization.to_dict() if self.realization else None,
                "rejected": [r.to_dict() for r in self.rejected], "problem": self.problem}


@dataclass
class ProcessMatch:
    """Every task node of one abstract process matched against one robot's skills."""

    process: str
    robot: str
    nodes: List[NodeMatch] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return all(n.ok for n in self.nodes)

    def node(self, iri: str) -> NodeMatch:
        for n in self.nodes:
            if n.node == str(iri):
                return n
        raise KeyError(iri)

    def problems(self) -> List[str]:
        """One line per task node nothing realizes: the node, its task type and capability, and why."""
        return ["task node <%s> (%s, requires %s): %s" % (n.node, n.action_type, n.capability, n.problem)
                for n in self.nodes if not n.ok]

    def to_dict(self) -> Dict[str, Any]:
        return {"process": self.process, "robot": self.robot, "ok": self.ok,
                "nodes": [n.to_dict() for n in self.nodes]}


# ===================================================================== matching
Bind = Callable[[FlowNode, Parameter], Optional[Node]]


def short(iri: Node) -> str:
    """``sk:cap_MoveArm`` for an IRI in a known namespace, else the IRI."""
    text = str(iri)
    best = ""
    for pfx, ns in _SHORT_PREFIXES:
        if text.startswith(ns) and len(ns) > len(best):
            best, name = ns, "%s:%s" % (pfx, text[len(ns):])
    return name if best else "<%s>" % text


_SHORT_PREFIXES: List[Tuple[str, str]] = sorted(
    [(k, str(v)) for k, v in PREFIXES.items() if k not in ("rdf", "rdfs", "owl", "xsd")] + [("sk", str(SK))])


def _value_names(value: Node, cat: SkillCatalog) -> List[str]:
    if isinstance(value, URIRef):
        return [local_name(value)] + sorted(cat.tool_names.get(value, ()))
    return [str(value)]


def check_value(prm: SkillParameter, value: Node, cat: SkillCatalog, what: str = "") -> str:
    """Why ``value`` does not fit the skill parameter ``prm`` ("" when it fits)."""
    label = what or "parameter %r" % prm.name
    if prm.allowed:
        names = _value_names(value, cat)
        if not any(n in prm.allowed for n in names):
            return "%s value %r is not among the allowed values: %s" % (label, names[0], ", ".join(prm.allowed))
    if prm.minimum is not None or prm.maximum is not None:
        x = _num(value) if isinstance(value, Literal) else None
        if x is None:
            return "%s value %r is not a number (range %s..%s)" % (label, str(value), prm.minimum, prm.maximum)
        if (prm.minimum is not None and x < prm.minimum) or (prm.maximum is not None and x > prm.maximum):
            return "%s value %g is outside the range %s..%s" % (
                label, x, "" if prm.minimum is None else "%g" % prm.minimum,
                "" if prm.maximum is None else "%g" % prm.maximum)
    return ""


class _NodeContext:
    """The task parameters of one node, evaluated on demand and once (``bind`` runs a binding query)."""

    def __init__(self, node: FlowNode, bind: Bind) -> None:
        self.node = node
        self._bind = bind
        self._values: Dict[str, Optional[Node]] = {}
        self.by_name = {p.name: p for p in node.parameters}

    def value(self, name: str) -> Optional[Node]:
        if name not in self._values:
            prm = self.by_name.get(name)
            self._values[name] = self._bind(self.node, prm) if prm is not None else None
        return self._values[name]


class Matcher:
    """Matches processes against one catalogue for one robot (see :func:`match_process`)."""

    def __init__(self, cat: SkillCatalog, robot: Optional[URIRef] = None) -> None:
        self.cat = cat
        self.robot_iri = robot if robot is not None else cat.default_robot()
        self.robot = cat.robots.get(self.robot_iri) if self.robot_iri is not None else None

    # ---------------------------------------------------------------- one skill
    def _not_offered(self, s: SkillInfo) -> str:
        """Why this robot cannot run ``s`` ("" when it can)."""
        robot = self.robot
        assert robot is not None
        missing = [b for b in s.invokes if b not in robot.skills]
        if missing:
            names = [self.cat.skills[b].name if b in self.cat.skills else re.sub(r"^skill_", "", local_name(b))
                     for b in missing]
            return "uses %s, not offered by this robot" % ", ".join(names)
        if s.iri not in robot.skills:
            return s.not_offered_reason or "not offered by this robot"
        absent = sorted(d for d in s.devices if d not in robot.devices)
        if absent:
            return "uses device %s, which this robot does not have" % ", ".join(local_name(d) for d in absent)
        return ""

    def _skill_problem(self, s: SkillInfo, ctx: _NodeContext) -> str:
        """Why ``s`` cannot realize the task of ``ctx`` on this robot ("" when it can)."""
        why = self._not_offered(s)
        if why:
            return why
        for name, prm in sorted(s.parameters.items()):
            if not (prm.allowed or prm.minimum is not None or prm.maximum is not None):
                continue
            if name not in ctx.by_name:
                continue
            value = ctx.value(name)
            if value is not None:
                why = check_value(prm, value, self.cat)
                if why:
                    return why
        return ""

    def _step_problem(self, s: SkillInfo, step: TemplateStep, ctx: _NodeContext) -> str:
        why = self._not_offered(s)
        if why:
            return why
        given = set()
        for arg, text in step.arguments:
            given.add(arg)
            prm = s.parameters.get(arg)
            if prm is None:
                if s.parameters:
                    return "has no parameter %r (it has %s)" % (arg, ", ".join(sorted(s.parameters)))
                continue
            m = _PLACEHOLDER_RE.match(text)
            value: Optional[Node] = Literal(text)
            if m is not None:
                value = ctx.value(m.group(1))
            if value is not None:
                why = check_value(prm, value, self.cat, "argument %s=%s" % (arg, text))
                if why:
                    return why
        for name, prm in sorted(s.parameters.items()):
            if prm.required and prm.default is None and name not in given:
                return "parameter %r is required and the step does not give it" % name
        return ""

    # ---------------------------------------------------------------- one node
    def _tool_problem(self, ctx: _NodeContext) -> str:
        """The tool the task binds must be one of this robot's tools."""
        robot = self.robot
        assert robot is not None
        for prm in ctx.node.parameters:
            if prm.prop not in self.cat.tool_properties:
                continue
            value = ctx.value(prm.name)
            tools = ", ".join(sorted(n for t in robot.tools for n in _value_names(t, self.cat)[:1])) or "none"
            if value is None:
                if prm.required:
                    return "tool absent: parameter %r binds no tool (<%s> finds none); this robot's tools: %s" % (
                        prm.name, prm.iri, tools)
                continue
            if value in robot.tools:
                continue
            names = set(_value_names(value, self.cat))
            if any(names & set(_value_names(t, self.cat)) for t in robot.tools):
                continue
            return "tool absent: parameter %r binds %s, which is not among this robot's tools (%s)" % (
                prm.name, local_name(value), tools)
        return ""

    def _step(self, step: TemplateStep, ctx: _NodeContext) -> Tuple[Optional[StepMatch], str]:
        if step.problem:
            return None, step.problem
        for arg, text in step.arguments:
            m = _PLACEHOLDER_RE.match(text)
            if m is not None and m.group(1) not in ctx.by_name:
                return None, "argument %s=%s: the task has no parameter %r (it has %s)" % (
                    arg, text, m.group(1), ", ".join(sorted(ctx.by_name)) or "none")
        reasons = []
        fits: List[SkillInfo] = []
        for iri in self.cat.realized_by.get(step.capability, []):
            s = self.cat.skills[iri]
            if self._foreign(s):
                continue
            why = self._step_problem(s, step, ctx)
            if why:
                reasons.append("%s: %s" % (s.name, why))
            else:
                fits.append(s)
        if not fits:
            return None, "no skill of this robot realizes %s%s" % (
                short(step.capability), " (%s)" % "; ".join(reasons) if reasons else "")
        fits.sort(key=lambda s: (s.involves_operator, s.kind != BASIC, s.name, str(s.iri)))
        s = fits[0]
        return StepMatch(step.index, str(step.capability), str(s.iri), s.name, s.kind, list(step.arguments),
                         s.involves_operator), ""

    def _foreign(self, s: SkillInfo) -> bool:
        """A skill of another robot's model (offered by it, or described for it): not a candidate here."""
        robot = self.robot
        assert robot is not None
        if s.iri in robot.skills:
            return False
        owners = self.cat.offered_by.get(s.iri, set()) | self.cat.described_for.get(s.iri, set())
        return bool(owners) and robot.iri not in owners

    def match_node(self, node: FlowNode, bind: Bind) -> NodeMatch:
        tt = node.task_type
        assert tt is not None
        cap = self.cat.required.get(tt.iri)
        nm = NodeMatch(str(node.iri), str(tt.iri), tt.action_type, str(cap) if cap is not None else "")
        if cap is None:
            return nm
        if self.robot is None:
            nm.problem = ("no robot in the resource model" if self.robot_iri is None
                          else "robot <%s> is not in the resource model" % self.robot_iri)
            return nm
        ctx = _NodeContext(node, bind)
        why = self._tool_problem(ctx)
        if why:
            nm.problem = why
            return nm
        cap_name = short(cap)
        auto: List[SkillInfo] = []
        operator: List[SkillInfo] = []
        realizing = self.cat.realized_by.get(cap, [])
        for iri in realizing:
            s = self.cat.skills[iri]
            if self._foreign(s):
                continue
            why = self._skill_problem(s, ctx)
            if why:
                nm.rejected.append(Rejection(str(s.iri), s.name, s.kind, why))
            else:
                (operator if s.involves_operator else auto).append(s)
        for iri in sorted(self.robot.skills):     # named like the action type, but realizing something else
            s = self.cat.skills.get(iri)
            if s is not None and s.name == tt.action_type and cap not in s.capabilities:
                nm.rejected.append(Rejection(str(s.iri), s.name, s.kind, "does not realize %s (it realizes %s)" % (
                    cap_name, ", ".join(sorted(short(c) for c in s.capabilities)) or "nothing")))
        templates: List[Realization] = []
        for tmpl in self.cat.templates.get(tt.iri, []):
            steps: List[StepMatch] = []
            failed = ""
            for step in tmpl.steps:
                sm, why = self._step(step, ctx)
                if sm is None:
                    failed = "step %d: %s" % (step.index, why)
                    break
                steps.append(sm)
            if failed or not steps:
                nm.rejected.append(Rejection(str(tmpl.iri), local_name(tmpl.iri), TEMPLATE,
                                             failed or "the template has no steps"))
            else:
                templates.append(Realization(TEMPLATE, name=local_name(tmpl.iri), template=str(tmpl.iri),
                                             steps=steps, involves_operator=any(s.involves_operator for s in steps)))

        def rank(s: SkillInfo) -> Tuple[bool, bool, str, str]:
            # the tree named like the action type first (what ran before matching), then trees, then by name
            return (s.name != tt.action_type, s.kind != COMPOSITE, s.name, str(s.iri))

        auto.sort(key=rank)
        operator.sort(key=rank)
        auto_templates = [t for t in templates if not t.involves_operator]
        op_templates = [t for t in templates if t.involves_operator]
        chosen: Optional[Realization] = None
        if auto:
            s = auto[0]
            chosen = Realization(SKILL, str(s.iri), s.name, s.kind)
        elif auto_templates:
            chosen = auto_templates[0]
        elif operator:
            s = operator[0]
            chosen = Realization(SKILL, str(s.iri), s.name, s.kind, involves_operator=True)
        elif op_templates:
            chosen = op_templates[0]
        if chosen is None:
            nm.problem = ("no skill of this robot realizes %s and no task template expands %s" % (
                cap_name, short(tt.iri)) if not nm.rejected else
                "no candidate fits: " + "; ".join("%s: %s" % (r.name, r.reason) for r in nm.rejected))
            return nm
        nm.realization = chosen
        label = chosen.name if chosen.kind == SKILL else "template %s" % chosen.name
        for s in auto + operator:
            if chosen.kind == SKILL and str(s.iri) == chosen.skill:
                continue
            if s.involves_operator and not chosen.involves_operator:
                reason = "needs the operator; an automatic realization exists (%s)" % label
            else:
                reason = "ranked below %s" % label
            nm.rejected.append(Rejection(str(s.iri), s.name, s.kind, reason))
        for t in templates:
            if t is chosen:
                continue
            if t.involves_operator and not chosen.involves_operator:
                reason = "needs the operator; an automatic realization exists (%s)" % label
            elif chosen.kind == SKILL and not chosen.involves_operator:
                reason = "a single skill realizes the task (%s)" % label
            else:
                reason = "ranked below %s" % label
            nm.rejected.append(Rejection(t.template, t.name, TEMPLATE, reason))
        return nm

    def match(self, process: AbstractProcess, bind: Bind) -> ProcessMatch:
        pm = ProcessMatch(str(process.iri), str(self.robot_iri) if self.robot_iri is not None else "")
        for iri in sorted(process.nodes):
            node = process.nodes[iri]
            if node.kind == "task":
                pm.nodes.append(self.match_node(node, bind))
        return pm


def match_process(cat: SkillCatalog, process: AbstractProcess, bind: Bind,
                  robot: Optional[URIRef] = None) -> ProcessMatch:
    """Match every task node of ``process`` against the skills ``robot`` (default: the catalogue's first robot)
    offers; ``bind(node, parameter)`` evaluates a task parameter's binding query (None: no value yet)."""
    return Matcher(cat, robot).match(process, bind)

