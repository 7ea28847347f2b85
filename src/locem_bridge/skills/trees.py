"""Composite skills from the action trees: their declarations, and what is derived from the trees themselves.

A tree file declares the skill its main tree is, Groot2 / BehaviorTree.CPP 4 style, in its ``<TreeNodesModel>``::

    <TreeNodesModel>
      <SubTree ID="GET_TOOL">
        <input_port name="param_tool" type="std::string">the tool to mount</input_port>
        <MetadataFields>
          <Metadata capability="plb:cap_GetTool"/>
          <Metadata summary="make the requested tool the mounted one"/>
        </MetadataFields>
      </SubTree>
    </TreeNodesModel>

A ``SubTree`` entry with a ``capability`` metadata field makes the tree of that ID (defined in the same file) a
composite skill realizing that capability (a prefixed name of ``ontologies/``). Its ``input_port`` elements are
the PEMKRE task parameters the tree reads (``param_<name>``): ``type`` (``std::string``, ``double``, ``int``,
``bool``), optional ``unit`` (a unit of :mod:`.units`) and ``default`` (then the parameter is optional); the text
is the description. Entries without ``capability`` (Groot2 writes them for plain subtrees) are not skills, and a
tree without a declaration is not a skill (``BASIC_SKILL``, which runs basic skills, has none).

Derived, never written: the LOCEM commands the tree sends (first word of every ``command`` template of the tree
and its subtrees), and whether it waits for the operator (a ``WaitForOperator`` node).
"""
import os
import re
from xml.etree import ElementTree
from dataclasses import dataclass, field
from typing import Dict, List, Optional, Sequence, Set, Tuple

from ..common.config_errors import ConfigError
from ..hicem.xml_loader import XmlElement, parse_xml
from .errors import SkillModelError
from .units import UNITS

#: port type (BT.CPP / Groot2 spelling) -> XSD local name
PORT_TYPES: Dict[str, str] = {"std::string": "string", "string": "string", "double": "double", "float": "double",
                              "int": "integer", "unsigned": "integer", "bool": "boolean"}
PARAM_PREFIX = "param_"
_PARAM_REF = re.compile(r"\{(param_[A-Za-z0-9_]+)")
_COMMAND_WORD = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
EXCLUDED_FILES = ("node_catalogue.xml",)


@dataclass
class PortDeclaration:
    name: str                 # without param_
    datatype: str
    unit: str = ""
    default: Optional[str] = None
    doc: str = ""


@dataclass
class TreeSkill:
    """One composite skill as read from its tree file (before it is checked against a robot)."""

    tree_id: str
    file: str
    line: int
    capability: str = ""              # as written (prefixed name), "" when none
    summary: str = ""
    ports: List[PortDeclaration] = field(default_factory=list)
    commands: Tuple[str, ...] = ()    # LOCEM command names, in first-use order
    operator: bool = False
    reads: Tuple[str, ...] = ()       # param_* keys read by the tree and its subtrees


@dataclass
class TreeFile:
    path: str
    root: XmlElement
    trees: Dict[str, XmlElement]
    port_texts: Dict[Tuple[str, str], str]


def tree_files(tree_dirs: Sequence[str]) -> List[str]:
    """Every ``*.xml`` of the folders (not the generated node catalogue), in folder order, sorted within each."""
    out: List[str] = []
    for d in tree_dirs:
        if not os.path.isdir(d):
            raise SkillModelError("is not a folder of behavior trees", file=d)
        for name in sorted(os.listdir(d)):
            if name.endswith(".xml") and name not in EXCLUDED_FILES:
                out.append(os.path.abspath(os.path.join(d, name)))
    return out


def _parse(path: str) -> TreeFile:
    try:
        with open(path, "r", encoding="utf-8") as handle:
            text = handle.read()
    except (OSError, UnicodeDecodeError) as exc:
        raise SkillModelError("cannot be read: %s" % exc, file=path)
    try:
        root = parse_xml(text, path)
    except ConfigError as exc:
        raise SkillModelError(exc.problem, file=path, key=exc.key)
    trees = {el.attrs.get("ID", ""): el for el in root.children if el.tag == "BehaviorTree"}
    return TreeFile(path, root, trees, _port_texts(path))


def read_tree_skills(tree_dirs: Sequence[str]) -> List[TreeSkill]:
    """The composite skills of the tree folders, with their derived commands and operator flag.

    Raises :class:`SkillModelError` (``FILE: KEY: PROBLEM``) for a tree ID defined in two files, a declaration
    for a tree the file does not define, a port that is not a ``param_*`` port, of an unknown type or unit, a
    declared parameter the tree never reads or a read one it does not declare."""
    files: Dict[str, TreeFile] = {}
    queue = list(tree_files(tree_dirs))
    while queue:                                     # the folders' files and whatever they include
        path = queue.pop(0)
        if path in files:
            continue
        tf = _parse(path)
        files[path] = tf
        for el in tf.root.children:
            if el.tag == "include" and el.attrs.get("path"):
                inc = el.attrs["path"]
                inc = inc if os.path.isabs(inc) else os.path.join(os.path.dirname(path), inc)
                if os.path.isfile(inc):
                    queue.append(os.path.abspath(inc))
    where: Dict[str, Tuple[str, XmlElement]] = {}
    for path, tf in files.items():
        for tid, el in tf.trees.items():
            if tid in where and where[tid][0] != path:
                raise SkillModelError("tree ID %s is defined twice (also in %s): skill names must be unique"
                                      % (tid, where[tid][0]), file=path, key="line %d BehaviorTree[%s]" % (el.line, tid))
            where[tid] = (path, el)
    skills: List[TreeSkill] = []
    for path in sorted(files):
        tf = files[path]
        declared: Dict[str, TreeSkill] = {}
        for model in (el for el in tf.root.children if el.tag == "TreeNodesModel"):
            for entry in (el for el in model.children if el.tag == "SubTree"):
                skill = _declaration(tf, entry)
                if skill is not None:
                    if skill.tree_id in declared:
                        raise SkillModelError("the skill is declared twice in this file", file=path,
                                              key="line %d TreeNodesModel.SubTree[%s]" % (entry.line, skill.tree_id))
                    declared[skill.tree_id] = skill
        for skill in declared.values():
            _derive(skill, where)
            _check_ports(skill)
            skills.append(skill)
    names = [s.tree_id for s in skills]
    for s in skills:
        if names.count(s.tree_id) > 1:
            other = [o.file for o in skills if o.tree_id == s.tree_id and o is not s][0]
            raise SkillModelError("skill %s is declared twice (also in %s)" % (s.tree_id, other), file=s.file,
                                  key="TreeNodesModel.SubTree[%s]" % s.tree_id)
    return skills


def _key(entry: XmlElement, tree_id: str, rest: str = "") -> str:
    return "line %d TreeNodesModel.SubTree[%s]%s" % (entry.line, tree_id, rest)


def _declaration(tf: TreeFile, entry: XmlElement) -> Optional[TreeSkill]:
    tree_id = entry.attrs.get("ID", "")
    meta: Dict[str, str] = {}
    for fields in (el for el in entry.children if el.tag == "MetadataFields"):
        for m in (el for el in fields.children if el.tag == "Metadata"):
            meta.update(m.attrs)
    if "capability" not in meta:
        return None                                  # a plain subtree's port model (Groot2), not a skill
    if tree_id not in tf.trees:
        raise SkillModelError("declares a skill for tree %r, which this file does not define" % tree_id,
                              file=tf.path, key=_key(entry, tree_id), allowed=sorted(tf.trees))
    skill = TreeSkill(tree_id, tf.path, tf.trees[tree_id].line, capability=meta["capability"].strip(),
                      summary=meta.get("summary", "").strip())
    for port in entry.children:
        if port.tag in ("output_port", "inout_port"):
            raise SkillModelError("a skill's inputs are PEMKRE task parameters; %s is not allowed" % port.tag,
                                  file=tf.path, key=_key(entry, tree_id, ".%s" % port.tag), allowed="input_port")
        if port.tag != "input_port":
            continue
        pname = port.attrs.get("name", "")
        pkey = _key(entry, tree_id, ".input_port[%s]" % pname)
        if not pname.startswith(PARAM_PREFIX) or len(pname) == len(PARAM_PREFIX):
            raise SkillModelError("a skill's input ports are the PEMKRE task parameters it reads, named "
                                  "param_<name>", file=tf.path, key=pkey)
        ptype = port.attrs.get("type", "std::string")
        if ptype not in PORT_TYPES:
            raise SkillModelError("type %r is not a parameter type" % ptype, file=tf.path, key=pkey + ".type",
                                  allowed=sorted(PORT_TYPES))
        unit = port.attrs.get("unit", "")
        if unit not in UNITS:
            raise SkillModelError("%r is not a known unit" % unit, file=tf.path, key=pkey + ".unit",
                                  allowed=sorted(u for u in UNITS if u))
        text = tf.port_texts.get((tree_id, pname), "")
        skill.ports.append(PortDeclaration(pname[len(PARAM_PREFIX):], PORT_TYPES[ptype], unit,
                                           port.attrs.get("default"), text))
    names = [p.name for p in skill.ports]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise SkillModelError("parameter param_%s is declared twice" % dup[0], file=tf.path, key=_key(entry, tree_id))
    return skill


def _port_texts(path: str) -> Dict[Tuple[str, str], str]:
    """(tree ID, port name) -> the description text of each declared port (the line-keeping parser drops text)."""
    out: Dict[Tuple[str, str], str] = {}
    for entry in ElementTree.parse(path).getroot().iter("SubTree"):
        for port in entry.findall("input_port"):
            out[(entry.get("ID", ""), port.get("name", ""))] = " ".join((port.text or "").split())
    return out


def _derive(skill: TreeSkill, where: Dict[str, Tuple[str, XmlElement]]) -> None:
    commands: List[str] = []
    reads: List[str] = []
    operator = False
    seen: Set[str] = set()
    stack = [skill.tree_id]
    while stack:
        tid = stack.pop(0)
        if tid in seen or tid not in where:
            continue
        seen.add(tid)
        todo = [where[tid][1]]
        while todo:
            el = todo.pop(0)
            todo.extend(el.children)
            if el.tag == "WaitForOperator":
                operator = True
            if el.tag == "SubTree" and el.attrs.get("ID"):
                stack.append(el.attrs["ID"])
            for attr, value in el.attrs.items():
                for key in _PARAM_REF.findall(value):
                    if key not in reads:
                        reads.append(key)
                if attr == "command":
                    words = value.split()
                    if words and _COMMAND_WORD.match(words[0]) and words[0].upper() not in commands:
                        commands.append(words[0].upper())
    skill.commands = tuple(commands)
    skill.operator = operator
    skill.reads = tuple(reads)


def _check_ports(skill: TreeSkill) -> None:
    declared = [PARAM_PREFIX + p.name for p in skill.ports]
    for name in declared:
        if name not in skill.reads:
            raise SkillModelError("declares input port %s, which the tree and its subtrees never read" % name,
                                  file=skill.file, key="TreeNodesModel.SubTree[%s].input_port[%s]"
                                  % (skill.tree_id, name), allowed=", ".join(skill.reads) or "no param_* port")
    for name in skill.reads:
        if name not in declared:
            raise SkillModelError("the tree reads {%s} but its skill declaration has no input port %s"
                                  % (name, name), file=skill.file, key="TreeNodesModel.SubTree[%s]" % skill.tree_id,
                                  allowed=", ".join(declared) or "no param_* port")
