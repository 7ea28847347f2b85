"""Name → node-class table used by the XML loader, and the Groot2 node catalogue generated from it.

The node classes come from the node modules the HICEM parameters list under ``hhlc.node_modules`` (default
:data:`DEFAULT_NODE_MODULES`, the shipped library in :mod:`locem_bridge.hicem.nodes`): each is a Python module
importable by its dotted name that lists its node classes in ``LIBRARY``. An integrator adds nodes of their own
by adding their module to that list (on the Python path, e.g. in a package of their own), without editing this
package; a name that cannot be imported is a :class:`~.errors.ConfigError` naming the key and the module.

The catalogue (``trees/node_catalogue.xml``, BT.CPP 4 ``TreeNodesModel`` that Groot2 imports) is produced by
:func:`catalogue_xml` from the node classes' own ``PORTS`` declarations, never written by hand; regenerate it
with ``python -m locem_bridge.hicem.registry trees/node_catalogue.xml``.
"""
import difflib
import importlib
import sys
from typing import Dict, Iterable, List, Optional, Sequence, Type
from xml.sax.saxutils import escape, quoteattr

from .controls import BUILTIN_NODES, EXTRA_CONTROL_NODES
from .errors import ConfigError, NodeDeclarationError
from .node_base import Ported


class NodeRegistry:
    """Maps XML node IDs to classes. ``builtin`` nodes are BT.CPP's own (not written to the catalogue)."""

    def __init__(self) -> None:
        self._nodes: Dict[str, Type[Ported]] = {}
        self._builtin: set = set()

    def register(self, cls: Type[Ported], builtin: bool = False) -> Type[Ported]:
        nid = cls.node_id()
        if nid in self._nodes and self._nodes[nid] is not cls:
            raise NodeDeclarationError("node ID '%s' registered twice (%s and %s)" % (
                nid, self._nodes[nid].__name__, cls.__name__))
        names = [p.name for p in cls.PORTS]
        if len(set(names)) != len(names):
            raise NodeDeclarationError("node '%s' declares a port twice: %s" % (nid, names))
        if "name" in names or "ID" in names:
            raise NodeDeclarationError("node '%s': 'name' and 'ID' are reserved attribute names" % nid)
        self._nodes[nid] = cls
        if builtin:
            self._builtin.add(nid)
        return cls

    def get(self, node_id: str) -> Optional[Type[Ported]]:
        return self._nodes.get(node_id)

    def names(self) -> List[str]:
        return sorted(self._nodes)

    def suggest(self, node_id: str) -> str:
        close = difflib.get_close_matches(node_id, self._nodes.keys(), n=3)
        return ("did you mean %s? " % " or ".join("'%s'" % c for c in close)) if close else ""

    def custom_nodes(self) -> List[Type[Ported]]:
        return [self._nodes[n] for n in sorted(self._nodes) if n not in self._builtin]


NODE_MODULES_KEY = "hhlc.node_modules"
DEFAULT_NODE_MODULES = ("locem_bridge.hicem.nodes.generic", "locem_bridge.hicem.nodes.plasterboard",
                        "locem_bridge.hicem.nodes.area_work")


def node_classes(modules: Sequence[str] = DEFAULT_NODE_MODULES) -> List[Type[Ported]]:
    """The node classes of ``modules`` (dotted module names), each module's ``LIBRARY`` in order. A name that is
    not a string, cannot be imported, or names a module without a ``LIBRARY`` of node classes raises
    :class:`ConfigError` naming ``hhlc.node_modules[i]`` and the module."""
    classes: List[Type[Ported]] = []
    for i, name in enumerate(modules):
        key = "%s[%d]" % (NODE_MODULES_KEY, i)
        if not isinstance(name, str) or not name.strip():
            raise ConfigError("%r is not a module name" % (name,), key=key,
                              allowed="dotted Python module names, e.g. locem_bridge.hicem.nodes.generic")
        try:
            module = importlib.import_module(name.strip())
        except Exception as exc:        # not found, or the module itself fails while importing (its own problem)
            raise ConfigError("cannot import node module '%s': %s" % (name, " ".join(str(exc).split())
                                                                       or type(exc).__name__), key=key)
        library = getattr(module, "LIBRARY", None)
        if not isinstance(library, (list, tuple)) or not all(
                isinstance(c, type) and issubclass(c, Ported) for c in library):
            raise ConfigError("node module '%s' has no LIBRARY tuple of node classes (subclasses of "
                              "locem_bridge.hicem.node_base.Leaf)" % name, key=key)
        classes.extend(library)
    return classes


def default_registry(extra: Iterable[Type[Ported]] = (),
                     modules: Sequence[str] = DEFAULT_NODE_MODULES) -> NodeRegistry:
    """BT.CPP built-ins + HICEM's own controls + the node modules' classes (:func:`node_classes`) + ``extra``.
    A node ID two modules both declare raises :class:`ConfigError` naming ``hhlc.node_modules``."""
    reg = NodeRegistry()
    for cls in BUILTIN_NODES:
        reg.register(cls, builtin=True)
    for cls in EXTRA_CONTROL_NODES:
        reg.register(cls)
    for cls in node_classes(modules):
        try:
            reg.register(cls)
        except NodeDeclarationError as exc:
            raise ConfigError("%s (in %s)" % (exc, cls.__module__), key=NODE_MODULES_KEY)
    for cls in extra:
        reg.register(cls)
    return reg


def catalogue_xml(registry: NodeRegistry) -> str:
    """The Groot2 TreeNodesModel for every custom node: each port with type, default, unit and description."""
    tag_of = {"input": "input_port", "output": "output_port", "inout": "inout_port"}
    out = ['<?xml version="1.0" encoding="UTF-8"?>',
           "<!-- GENERATED from the node declarations in src/locem_bridge/hicem (do not edit by hand):",
           "     python -m locem_bridge.hicem.registry trees/node_catalogue.xml",
           "     Ports: type (BT.CPP spelling), default (a literal or a {blackboard_key}), unit (SI). -->",
           '<root BTCPP_format="4">', "  <TreeNodesModel>"]
    for cls in registry.custom_nodes():
        desc = " ".join(cls.DESCRIPTION.split())
        if desc:
            out.append("    <!-- %s: %s -->" % (cls.node_id(), desc.replace("--", "-")))
        out.append("    <%s ID=%s>" % (cls.KIND, quoteattr(cls.node_id())))
        for p in cls.PORTS:
            attrs = "name=%s type=%s" % (quoteattr(p.name), quoteattr(p.type.xml_type))
            if p.default is not None:
                attrs += " default=%s" % quoteattr(p.default)
            attrs += " unit=%s" % quoteattr(p.unit or "-")
            text = p.description
            if p.choices:
                text += " (one of: %s)" % ", ".join(p.choices)
            if p.unit:
                text = "[%s] %s" % (p.unit, text)
            out.append("      <%s %s>%s</%s>" % (tag_of[p.direction], attrs, escape(text), tag_of[p.direction]))
        out.append("    </%s>" % cls.KIND)
    out += ["  </TreeNodesModel>", "</root>", ""]
    return "\n".join(out)


def main(argv: Optional[List[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    text = catalogue_xml(default_registry())
    if argv:
        with open(argv[0], "w", encoding="utf-8") as f:
            f.write(text)
    else:
        sys.stdout.write(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
