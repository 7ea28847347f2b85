"""Fake leaves for tree-semantics tests (test code): a scripted leaf that records ticks and halts."""
from typing import List, Optional, Tuple

from py_trees.common import Status

from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.node_base import Leaf, NodeContext
from locem_bridge.hicem.ports import ANY, FLOAT, INT, JSON, STRING, STRING_LIST, BOOL, FLOAT_LIST, input_port, output_port
from locem_bridge.hicem.registry import default_registry
from locem_bridge.hicem.xml_loader import TreeLibrary

_CODES = {"S": Status.SUCCESS, "F": Status.FAILURE, "R": Status.RUNNING}


class Scripted(Leaf):
    """Returns the statuses of ``script`` (S/F/R separated by ';') one per tick, the last one forever."""
    DESCRIPTION = "test leaf"
    PORTS = (input_port("script", STRING_LIST, "S", "", "statuses"),
             input_port("id", STRING, None, "", "label"))

    def initialise(self) -> None:
        super().initialise()

    def on_tick(self) -> Status:
        events = self.ctx.events  # type: ignore[attr-defined]
        label = self.get("id")
        n = sum(1 for e in events if e == ("tick", label))
        script = self.get("script")
        events.append(("tick", label))
        return _CODES[script[min(n, len(script) - 1)]]

    def on_halt(self) -> None:
        self.ctx.events.append(("halt", self.get("id")))  # type: ignore[attr-defined]


class Typed(Leaf):
    """Leaf with one port of each type; copies its inputs to the blackboard entry 'seen'."""
    DESCRIPTION = "test leaf with typed ports"
    PORTS = (input_port("f", FLOAT, "1.5", "m", ""), input_port("i", INT, "{@cfg.count}", "", ""),
             input_port("b", BOOL, "false", "", ""), input_port("fl", FLOAT_LIST, "0;0", "m", ""),
             input_port("j", JSON, "{}", "", ""), input_port("s", STRING, "x", "", ""),
             input_port("mode", STRING, "fast", "", "", choices=("fast", "slow")),
             output_port("out", ANY, None, "", ""))

    def on_tick(self) -> Status:
        vals = {p: self.get(p) for p in ("f", "i", "b", "fl", "j", "s", "mode")}
        self.ports.blackboard.set("seen", vals)
        self.set("out", vals["f"])
        return Status.SUCCESS


class Writer(Leaf):
    DESCRIPTION = "writes a float to an output port"
    PORTS = (output_port("value", FLOAT, None, "m", ""),)

    def on_tick(self) -> Status:
        self.set("value", 2.0)
        return Status.SUCCESS


class ReaderList(Leaf):
    DESCRIPTION = "reads a float list"
    PORTS = (input_port("value", FLOAT_LIST, None, "m", ""),)

    def on_tick(self) -> Status:
        self.get("value")
        return Status.SUCCESS


def library(*texts: str, filename: str = "test.xml") -> TreeLibrary:
    lib = TreeLibrary(default_registry(extra=[Scripted, Typed, Writer, ReaderList]))
    for i, t in enumerate(texts):
        lib.load_string(t, filename if len(texts) == 1 else "test%d.xml" % i, link=False)
    lib.link()
    return lib


def tree_xml(body: str, tree_id: str = "T", extra: str = "") -> str:
    return ('<root BTCPP_format="4" main_tree_to_execute="%s">\n<BehaviorTree ID="%s">\n%s\n</BehaviorTree>\n%s'
            '</root>' % (tree_id, tree_id, body, extra))


def build(body: str, extra: str = "", clock=None, cfg: Optional[dict] = None):
    lib = library(tree_xml(body, extra=extra))
    ctx = NodeContext(clock=clock) if clock else NodeContext()
    ctx.events = []  # type: ignore[attr-defined]
    bb = Blackboard()
    for k, v in (cfg or {}).items():
        bb.set(k, v)
    return lib.build("T", ctx, bb), ctx


def ticks(events: List[Tuple[str, str]]) -> List[str]:
    return [e[1] for e in events if e[0] == "tick"]


def halts(events: List[Tuple[str, str]]) -> List[str]:
    return [e[1] for e in events if e[0] == "halt"]
