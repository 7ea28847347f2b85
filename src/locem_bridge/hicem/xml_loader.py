"""Loader for BehaviorTree.CPP format 4 XML → py_trees trees with BT.CPP semantics (with :mod:`.controls` and the
node library :mod:`.nodes`, the paper's Behavior Tree Engine of the HHLC).

Two phases:

1. **load** (:meth:`TreeLibrary.load_file`, :meth:`load_string`, :meth:`load_directory`): parse each file
   (``<root BTCPP_format="4" main_tree_to_execute=...>``, any number of ``<BehaviorTree ID=...>``, ``<include
   path=.../>``, ``<TreeNodesModel>`` ignored), resolve every node type against the :class:`NodeRegistry`
   (compact ``<Sequence>`` and explicit ``<Action ID="X">`` forms), check every attribute against the node's
   declared ports, convert literal port values by the declared type, then link: every ``<SubTree ID>``
   must exist, must not recurse, and its remapped ports must be keys the subtree uses; a blackboard key used by
   ports of incompatible types within one tree is rejected. Every problem raises :class:`TreeLoadError` naming
   file, line and the node/port/tree. Loading never touches a device.
2. **build** (:meth:`TreeLibrary.build`): instantiate fresh py_trees nodes for one tree ID, bound to a new
   :class:`Blackboard` scope and a :class:`NodeContext`. Cheap; done once per high-level action.
"""
import glob
import os
import xml.parsers.expat
from typing import Any, Dict, List, Optional, Set, Tuple

import py_trees

from .blackboard import Blackboard
from .controls import SubTree
from .errors import TreeLoadError
from .node_base import NodeContext
from .ports import OUTPUT, Binding, Literal, PortBinding, Ref, blackboard_key, template_keys
from .registry import NodeRegistry, default_registry

_EXPLICIT_TAGS = ("Action", "Condition", "Control", "Decorator", "SubTree")
_RESERVED = ("name", "_description")
_SUBTREE_RESERVED = ("ID", "name", "_autoremap", "_description")


class XmlElement:
    """Minimal element with the 1-based source line (xml.etree keeps no line numbers)."""
    __slots__ = ("tag", "attrs", "children", "line")

    def __init__(self, tag: str, attrs: Dict[str, str], line: int) -> None:
        self.tag = tag
        self.attrs = attrs
        self.children: List["XmlElement"] = []
        self.line = line


def parse_xml(text: str, filename: str) -> XmlElement:
    parser = xml.parsers.expat.ParserCreate()
    parser.ordered_attributes = False
    stack: List[XmlElement] = []
    root: List[XmlElement] = []

    def start(tag: str, attrs: Dict[str, str]) -> None:
        el = XmlElement(tag, dict(attrs), parser.CurrentLineNumber)
        if stack:
            stack[-1].children.append(el)
        else:
            root.append(el)
        stack.append(el)

    def end(tag: str) -> None:
        stack.pop()

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(text.encode("utf-8") if isinstance(text, str) else text, True)
    except xml.parsers.expat.ExpatError as exc:
        raise TreeLoadError("XML syntax error: %s" % xml.parsers.expat.ErrorString(exc.code),
                            filename, exc.lineno, "")
    return root[0]


class NodeTemplate:
    """A validated node, ready to be instantiated any number of times."""
    __slots__ = ("cls", "name", "type_id", "bindings", "children", "file", "line", "subtree", "remap",
                 "sub_literals", "autoremap")

    def __init__(self, cls: Any, name: str, type_id: str, bindings: Dict[str, Binding], file: str,
                 line: int) -> None:
        self.cls = cls
        self.name = name
        self.type_id = type_id
        self.bindings = bindings
        self.children: List["NodeTemplate"] = []
        self.file = file
        self.line = line
        self.subtree: Optional[str] = None
        self.remap: Dict[str, str] = {}
        self.sub_literals: Dict[str, str] = {}
        self.autoremap = False

    def walk(self):
        yield self
        for c in self.children:
            for n in c.walk():
                yield n


class TreeTemplate:
    __slots__ = ("id", "root", "file", "line", "main")

    def __init__(self, tree_id: str, root: NodeTemplate, file: str, line: int) -> None:
        self.id = tree_id
        self.root = root
        self.file = file
        self.line = line
        self.main = False


class BuiltTree:
    """One instantiated tree: the py_trees ``BehaviourTree``, its root blackboard scope and context."""

    def __init__(self, tree_id: str, tree: py_trees.trees.BehaviourTree, blackboard: Blackboard,
                 ctx: NodeContext) -> None:
        self.id = tree_id
        self.tree = tree
        self.root = tree.root
        self.blackboard = blackboard
        self.ctx = ctx

    def tick(self) -> py_trees.common.Status:
        self.tree.tick()
        return self.root.status

    def halt(self) -> None:
        """Halt every running node (their terminate cancels LOCEM commands and operator prompts)."""
        if self.root.status != py_trees.common.Status.INVALID:
            self.root.stop(py_trees.common.Status.INVALID)

    def tip_name(self) -> str:
        tip = self.root.tip()
        return tip.name if tip is not None else ""

    def running_path(self) -> List[str]:
        path = []
        node = self.root
        while node is not None and node.status == py_trees.common.Status.RUNNING:
            path.append(node.name)
            nxt = None
            for c in node.children:
                if c.status == py_trees.common.Status.RUNNING:
                    nxt = c
                    break
            node = nxt
        return path


def _compatible(a: str, b: str) -> bool:
    loose = ("any", "str", "json")
    return a == b or a in loose or b in loose or {a, b} == {"int", "float"}


class TreeLibrary:
    """All trees known to the executive, by BehaviorTree ID (the high-level action type for action trees)."""

    def __init__(self, registry: Optional[NodeRegistry] = None) -> None:
        self.registry = registry or default_registry()
        self.trees: Dict[str, TreeTemplate] = {}
        self.files: List[str] = []
        self.main_trees: Dict[str, str] = {}  # file -> main tree id

    # -- loading --------------------------------------------------------------------------------------------
    def load_file(self, path: str, link: bool = True) -> List[str]:
        path = os.path.abspath(path)
        if path in self.files:
            return []
        try:
            with open(path, "r", encoding="utf-8") as f:
                text = f.read()
        except OSError as exc:
            raise TreeLoadError("cannot read tree file: %s" % exc.strerror, path, 0, "")
        return self.load_string(text, path, link=link)

    def load_files(self, paths: List[str]) -> List[str]:
        """Load several files, then link; on any error nothing of them stays loaded."""
        snap = self._snapshot()
        try:
            ids: List[str] = []
            for p in paths:
                ids += self.load_file(p, link=False)
            self.link()
        except TreeLoadError:
            self._restore(snap)
            raise
        return ids

    def _snapshot(self) -> tuple:
        return dict(self.trees), list(self.files), dict(self.main_trees)

    def _restore(self, snap: tuple) -> None:
        self.trees, self.files, self.main_trees = dict(snap[0]), list(snap[1]), dict(snap[2])

    def load_directory(self, directory: str, exclude: Tuple[str, ...] = ("node_catalogue.xml",)) -> List[str]:
        paths = sorted(p for p in glob.glob(os.path.join(directory, "*.xml"))
                       if os.path.basename(p) not in exclude)
        if not paths:
            raise TreeLoadError("no tree files (*.xml) in directory", directory, 0, "")
        return self.load_files(paths)

    def load_directories(self, directories: List[str], exclude: Tuple[str, ...] = ("node_catalogue.xml",)) -> List[str]:
        """Load the trees of several folders as one set (the package's ``trees/`` and an integrator's folders):
        a tree may use a subtree of another folder (e.g. the shipped ``GuardedCommand``) without including it; a
        BehaviorTree ID defined in two files is refused naming both; a folder that does not exist or holds no
        ``*.xml`` is refused naming it; on any error nothing of them stays loaded."""
        from ..common.config_errors import ConfigError
        from ..common.folders import folder_files
        paths: List[str] = []
        for directory in directories:
            try:
                found = folder_files([directory], ".xml", "trees folder", exclude)
            except ConfigError as exc:        # a missing folder, as the trees' own error type
                raise TreeLoadError(exc.problem, exc.file, 0, "") from None
            if not found:
                raise TreeLoadError("no tree files (*.xml) in directory", os.path.abspath(directory), 0, "")
            paths += [p for p in found if p not in paths]
        return self.load_files(paths)

    def load_string(self, text: str, filename: str = "<string>", link: bool = True) -> List[str]:
        """Load one document; with ``link`` (default) an error leaves the library as it was before."""
        if not link:
            return self._load_string(text, filename, link)
        snap = self._snapshot()
        try:
            return self._load_string(text, filename, link)
        except TreeLoadError:
            self._restore(snap)
            raise

    def _load_string(self, text: str, filename: str, link: bool) -> List[str]:
        root = parse_xml(text, filename)
        if root.tag != "root":
            raise TreeLoadError("the document element must be <root>, found <%s>" % root.tag, filename,
                                root.line, root.tag)
        fmt = root.attrs.get("BTCPP_format")
        if fmt != "4":
            raise TreeLoadError("BTCPP_format=%r is not supported; only BTCPP_format=\"4\" is" % fmt,
                                filename, root.line, "root")
        self.files.append(filename)
        new_ids: List[str] = []
        for el in root.children:
            if el.tag == "BehaviorTree":
                new_ids.append(self._compile_tree(el, filename))
            elif el.tag == "include":
                inc = el.attrs.get("path")
                if not inc:
                    raise TreeLoadError("<include> needs a path attribute", filename, el.line, "include")
                base = os.path.dirname(filename) if os.path.isabs(filename) else os.getcwd()
                inc_path = inc if os.path.isabs(inc) else os.path.join(base, inc)
                if not os.path.exists(inc_path):
                    raise TreeLoadError("included file %s does not exist" % inc_path, filename, el.line, inc)
                new_ids += self.load_file(inc_path, link=False)
            elif el.tag == "TreeNodesModel":
                continue
            else:
                raise TreeLoadError("unexpected element <%s> under <root>; allowed: BehaviorTree, include, "
                                    "TreeNodesModel" % el.tag, filename, el.line, el.tag)
        main = root.attrs.get("main_tree_to_execute")
        if main is not None:
            if main not in self.trees:
                raise TreeLoadError("main_tree_to_execute names '%s', which is not a BehaviorTree ID here "
                                    "(defined: %s)" % (main, ", ".join(sorted(self.trees)) or "none"),
                                    filename, root.line, main)
            self.trees[main].main = True
            self.main_trees[filename] = main
        if link:
            self.link()
        return new_ids

    def _compile_tree(self, el: XmlElement, filename: str) -> str:
        tid = el.attrs.get("ID")
        if not tid:
            raise TreeLoadError("<BehaviorTree> without an ID attribute", filename, el.line, "BehaviorTree")
        if tid in self.trees:
            other = self.trees[tid]
            raise TreeLoadError("BehaviorTree ID '%s' is defined twice (also in %s:%d)" % (
                tid, other.file, other.line), filename, el.line, tid)
        if len(el.children) != 1:
            raise TreeLoadError("a BehaviorTree must have exactly one root node, found %d" % len(el.children),
                                filename, el.line, tid)
        root = self._compile_node(el.children[0], filename)
        self._check_key_types(root, tid)
        self.trees[tid] = TreeTemplate(tid, root, filename, el.line)
        return tid

    def _compile_node(self, el: XmlElement, filename: str) -> NodeTemplate:
        attrs = dict(el.attrs)
        if el.tag in _EXPLICIT_TAGS:
            type_id = attrs.get("ID")
            if not type_id:
                raise TreeLoadError("<%s> needs an ID attribute" % el.tag, filename, el.line, el.tag)
            if el.tag != "SubTree":
                attrs.pop("ID")
        else:
            type_id = el.tag
        if el.tag == "SubTree":
            return self._compile_subtree(el, attrs, filename)
        cls = self.registry.get(type_id)
        if cls is None:
            raise TreeLoadError("unknown node type '%s'; %ssee trees/node_catalogue.xml for the custom nodes"
                                % (type_id, self.registry.suggest(type_id)), filename, el.line, type_id)
        name = attrs.pop("name", type_id)
        attrs.pop("_description", None)
        n_children = len(el.children)
        if n_children < cls.MIN_CHILDREN or (cls.MAX_CHILDREN is not None and n_children > cls.MAX_CHILDREN):
            want = ("exactly %d" % cls.MIN_CHILDREN if cls.MAX_CHILDREN == cls.MIN_CHILDREN
                    else "at least %d" % cls.MIN_CHILDREN)
            raise TreeLoadError("%s '%s' must have %s child node(s), has %d" % (
                cls.KIND, type_id, want, n_children), filename, el.line, name)
        specs = cls.port_specs()
        bindings: Dict[str, Binding] = {}
        literals: Dict[str, Any] = {}
        for attr, text in attrs.items():
            spec = specs.get(attr)
            if spec is None:
                allowed = ", ".join(sorted(specs)) or "none"
                extra = " (BT.CPP scripting attributes are not supported)" if attr.startswith("_") else ""
                raise TreeLoadError("unknown port '%s' for node type '%s'%s; its ports: %s" % (
                    attr, type_id, extra, allowed), filename, el.line, name)
            key = blackboard_key(text)
            if key is not None:
                bindings[attr] = Ref(key)
                continue
            if spec.direction == OUTPUT:
                raise TreeLoadError("output port '%s' must name a blackboard entry as {key}, got '%s'" % (
                    attr, text), filename, el.line, name)
            try:
                value = spec.convert_literal(text)
            except ValueError as exc:
                raise TreeLoadError("port '%s' (type %s%s): %s" % (
                    attr, spec.type.name, (", unit %s" % spec.unit) if spec.unit else "", exc),
                    filename, el.line, name)
            bindings[attr] = Literal(value, text)
            literals[attr] = value
        for pname, spec in specs.items():
            if pname in bindings:
                continue
            if spec.default is not None:
                key = blackboard_key(spec.default)
                if key is not None:
                    bindings[pname] = Ref(key)
                elif spec.direction != OUTPUT:
                    bindings[pname] = Literal(spec.convert_literal(spec.default), spec.default)
                    literals[pname] = bindings[pname].value  # type: ignore[union-attr]
            elif spec.required:
                raise TreeLoadError("missing required port '%s' (type %s%s) of node type '%s'" % (
                    pname, spec.type.name, (", unit %s" % spec.unit) if spec.unit else "", type_id),
                    filename, el.line, name)
        problem = cls.validate_literals(literals) if literals else None
        if problem is None and type_id == "Parallel":
            s, f = cls.required_counts(n_children, literals.get("success_count", -1),
                                       literals.get("failure_count", 1))
            if not (0 < s <= n_children and 0 < f <= n_children):
                problem = ("success_count/failure_count must select between 1 and %d children (got %d/%d)"
                           % (n_children, s, f))
        if problem:
            raise TreeLoadError(problem, filename, el.line, name)
        tmpl = NodeTemplate(cls, name, type_id, bindings, filename, el.line)
        tmpl.children = [self._compile_node(c, filename) for c in el.children]
        return tmpl

    def _compile_subtree(self, el: XmlElement, attrs: Dict[str, str], filename: str) -> NodeTemplate:
        sub_id = attrs["ID"]
        name = attrs.get("name", sub_id)
        if el.children:
            raise TreeLoadError("<SubTree> takes no child elements", filename, el.line, name)
        tmpl = NodeTemplate(SubTree, name, "SubTree", {}, filename, el.line)
        tmpl.subtree = sub_id
        auto = attrs.get("_autoremap", "false").strip().lower()
        if auto not in ("true", "false", "1", "0"):
            raise TreeLoadError("_autoremap must be true or false, got '%s'" % auto, filename, el.line, name)
        tmpl.autoremap = auto in ("true", "1")
        for k, v in attrs.items():
            if k in _SUBTREE_RESERVED:
                continue
            if k.startswith("_"):
                raise TreeLoadError("unsupported SubTree attribute '%s'; allowed: ID, name, _autoremap and "
                                    "port remappings" % k, filename, el.line, name)
            key = k if v.strip() == "{=}" else blackboard_key(v)  # "{=}": same key name in the parent (BT.CPP 4)
            if key is not None:
                tmpl.remap[k] = key
            else:
                tmpl.sub_literals[k] = v
        return tmpl

    def _check_key_types(self, root: NodeTemplate, tree_id: str) -> None:
        seen: Dict[str, Tuple[str, str, int]] = {}
        for n in root.walk():
            specs = n.cls.port_specs() if n.subtree is None else {}
            for pname, b in n.bindings.items():
                if not isinstance(b, Ref) or b.key.startswith("@") or b.key.startswith("cfg."):
                    continue
                t = specs[pname].type.name
                if b.key in seen and not _compatible(seen[b.key][0], t):
                    other = seen[b.key]
                    raise TreeLoadError(
                        "blackboard key '%s' is used as %s by port '%s' here and as %s by '%s' (line %d)" % (
                            b.key, t, pname, other[0], other[1], other[2]), n.file, n.line, n.name)
                if t not in ("any", "str", "json"):
                    seen.setdefault(b.key, (t, n.name, n.line))

    def link(self) -> None:
        """Check SubTree references across everything loaded so far (existence, recursion, port names)."""
        used: Dict[str, Set[str]] = {}

        def keys_of(tid: str, stack: Tuple[str, ...]) -> Set[str]:
            if tid in used:
                return used[tid]
            tt = self.trees[tid]
            keys: Set[str] = set()
            for n in tt.root.walk():
                if n.subtree is not None:
                    if n.subtree not in self.trees:
                        raise TreeLoadError("SubTree '%s' is not defined; defined trees: %s" % (
                            n.subtree, ", ".join(sorted(self.trees))), n.file, n.line, n.subtree)
                    if n.subtree in stack or n.subtree == tid:
                        raise TreeLoadError("SubTree '%s' includes itself (recursion: %s)" % (
                            n.subtree, " -> ".join(stack + (tid, n.subtree))), n.file, n.line, n.subtree)
                    inner = keys_of(n.subtree, stack + (tid,))
                    for port in list(n.remap) + list(n.sub_literals):
                        if port not in inner:
                            raise TreeLoadError(
                                "SubTree '%s' has no port '%s'; the keys it uses: %s" % (
                                    n.subtree, port, ", ".join(sorted(inner)) or "none"), n.file, n.line, n.name)
                    keys.update(n.remap.values())
                    if n.autoremap:
                        keys.update(k for k in inner if not k.startswith("_") and k not in n.remap
                                    and k not in n.sub_literals)
                else:
                    for b in n.bindings.values():
                        if isinstance(b, Ref):
                            ks = [b.key]
                        elif isinstance(b.value, str):
                            ks = template_keys(b.value)
                        else:
                            ks = []
                        for k in ks:
                            if not k.startswith("@"):
                                parts = k.split(".")  # a dotted key may be entry + fields: all prefixes
                                keys.update(".".join(parts[:i]) for i in range(1, len(parts) + 1))
            used[tid] = keys
            return keys

        for tid in list(self.trees):
            keys_of(tid, ())

    # -- building -------------------------------------------------------------------------------------------
    def tree_ids(self) -> List[str]:
        return sorted(self.trees)

    def has_tree(self, tree_id: str) -> bool:
        return tree_id in self.trees

    def build(self, tree_id: str, ctx: Optional[NodeContext] = None,
              blackboard: Optional[Blackboard] = None) -> BuiltTree:
        if tree_id not in self.trees:
            raise KeyError("no BehaviorTree with ID '%s'; loaded: %s" % (tree_id, ", ".join(self.tree_ids())))
        ctx = ctx or NodeContext()
        bb = blackboard if blackboard is not None else Blackboard()
        root = self._instantiate(self.trees[tree_id].root, bb, ctx)
        return BuiltTree(tree_id, py_trees.trees.BehaviourTree(root), bb, ctx)

    def _instantiate(self, t: NodeTemplate, bb: Blackboard, ctx: NodeContext) -> py_trees.behaviour.Behaviour:
        if t.subtree is not None:
            sub_bb = Blackboard(parent=bb, remap=t.remap, autoremap=t.autoremap)
            for k, v in t.sub_literals.items():
                sub_bb.set_local(k, v)
            child = self._instantiate(self.trees[t.subtree].root, sub_bb, ctx)
            node = SubTree(t.name, [child], PortBinding(t.name, {}, {}, bb), ctx)
        else:
            binding = PortBinding(t.name, t.cls.port_specs(), t.bindings, bb)
            if t.children:
                node = t.cls(t.name, [self._instantiate(c, bb, ctx) for c in t.children], binding, ctx)
            elif t.cls.MIN_CHILDREN > 0:
                node = t.cls(t.name, [], binding, ctx)
            else:
                node = t.cls(t.name, binding, ctx)
        node.source = (t.file, t.line)  # type: ignore[attr-defined]
        return node

    def count_nodes(self, tree_id: str) -> int:
        def count(t: NodeTemplate) -> int:
            if t.subtree is not None:
                return 1 + count(self.trees[t.subtree].root)
            return 1 + sum(count(c) for c in t.children)
        return count(self.trees[tree_id].root)
