"""BT.CPP 4 XML loader: every node kind and port form, and every load-time error with file, line and name."""
import os

import pytest
from py_trees.common import Status

from hicem_fakes import Scripted, Typed, build, library, tree_xml
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.errors import TreeLoadError
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.registry import default_registry
from locem_bridge.hicem.xml_loader import TreeLibrary


def load_error(text, filename="bad.xml"):
    with pytest.raises(TreeLoadError) as ei:
        library(text, filename=filename)
    return ei.value


def test_every_control_and_decorator_kind_loads_in_compact_and_explicit_form():
    body = """<Sequence>
  <SequenceWithMemory><AlwaysSuccess/></SequenceWithMemory>
  <Control ID="Fallback" name="fb"><AlwaysFailure/><AlwaysSuccess/></Control>
  <ReactiveSequence><AlwaysSuccess/></ReactiveSequence>
  <ReactiveFallback><AlwaysSuccess/></ReactiveFallback>
  <Parallel success_count="1" failure_count="1"><AlwaysSuccess/><AlwaysSuccess/></Parallel>
  <Inverter><AlwaysFailure/></Inverter>
  <Decorator ID="ForceSuccess"><AlwaysFailure/></Decorator>
  <Inverter><ForceFailure><AlwaysSuccess/></ForceFailure></Inverter>
  <RetryUntilSuccessful num_attempts="2"><AlwaysSuccess/></RetryUntilSuccessful>
  <Repeat num_cycles="2"><AlwaysSuccess/></Repeat>
  <Timeout msec="1000"><AlwaysSuccess/></Timeout>
  <Action ID="SetBlackboard" output_key="k" value="v"/>
  <Condition ID="CheckEqual" a="{k}" b="v"/>
  <SubTree ID="Other"/>
  <Sleep msec="0"/>
</Sequence>"""
    t, _ = build(body, extra='<BehaviorTree ID="Other"><AlwaysSuccess/></BehaviorTree>')
    assert t.tick() == Status.SUCCESS
    names = [n.name for n in t.root.iterate()]
    assert "fb" in names and "Other" in names


def test_multiple_trees_main_tree_and_include(tmp_path):
    (tmp_path / "shared.xml").write_text('<root BTCPP_format="4"><BehaviorTree ID="Shared">'
                                         '<AlwaysSuccess/></BehaviorTree></root>')
    (tmp_path / "main.xml").write_text('<root BTCPP_format="4" main_tree_to_execute="Main">'
                                       '<include path="shared.xml"/>'
                                       '<BehaviorTree ID="Main"><SubTree ID="Shared"/></BehaviorTree>'
                                       '<BehaviorTree ID="Spare"><AlwaysFailure/></BehaviorTree></root>')
    lib = TreeLibrary()
    lib.load_file(str(tmp_path / "main.xml"))
    assert lib.tree_ids() == ["Main", "Shared", "Spare"]
    assert lib.main_trees[str(tmp_path / "main.xml")] == "Main"
    assert lib.build("Main").tick() == Status.SUCCESS


def test_port_forms_literal_default_blackboard_and_root_reference():
    lib = library(tree_xml('<Sequence><Typed name="top" f="2.5" fl="[1, 2]" s="{who}" out="{o}"/>'
                           '<SubTree ID="S"/></Sequence>',
                           extra='<BehaviorTree ID="S"><Typed name="inner" i="{@cfg.count}" s="{@name}"/>'
                                 '</BehaviorTree>'))
    bb = Blackboard()
    bb.update({"cfg.count": 3, "name": "n1", "who": "operator"})
    t = lib.build("T", NodeContext(), bb)
    assert t.tick() == Status.SUCCESS
    nodes = {n.name: n for n in t.root.iterate()}
    # top level: literals converted by the declared types, {who} read from the blackboard, every other port at
    # its declared default (i's default is the root reference {@cfg.count})
    assert bb.get("seen") == {"f": 2.5, "i": 3, "b": False, "fl": [1.0, 2.0], "j": {}, "s": "operator",
                              "mode": "fast"}
    assert bb.get("o") == 2.5  # output port written through its {o} pointer
    # inside the subtree (its own isolated scope): {@cfg.count} and {@name} resolve at the root blackboard
    inner_scope = nodes["inner"].ports.blackboard
    assert inner_scope is not bb and not inner_scope.has("name")  # the plain key is not visible in there
    assert inner_scope.get("seen") == {"f": 1.5, "i": 3, "b": False, "fl": [0.0, 0.0], "j": {}, "s": "n1",
                                       "mode": "fast"}
    # the root values are read at tick time, not copied at build time
    bb.update({"cfg.count": 7, "name": "n2", "who": "lead"})
    assert t.tick() == Status.SUCCESS
    assert inner_scope.get("seen")["i"] == 7 and inner_scope.get("seen")["s"] == "n2"
    assert bb.get("seen")["i"] == 7 and bb.get("seen")["s"] == "lead"


def test_plain_key_inside_an_isolated_subtree_is_not_the_root_entry():
    lib = library(tree_xml('<SubTree ID="S"/>', extra='<BehaviorTree ID="S"><Typed s="{name}"/></BehaviorTree>'))
    bb = Blackboard()
    bb.update({"cfg.count": 3, "name": "n1"})
    ctx = NodeContext()
    t = lib.build("T", ctx, bb)
    assert t.tick() == Status.FAILURE  # without '@' the subtree's own (empty) scope is read
    assert "blackboard key 'name', which is not set" in ctx.last_failure()[1]


def test_real_trees_directory_loads_every_action_type():
    here = os.path.dirname(os.path.abspath(__file__))
    lib = TreeLibrary()
    lib.load_directory(os.path.join(here, "..", "..", "trees"))
    for at in ("SCAN", "GET_TOOL", "VALIDATE_TAPE_LINE", "TAPE_LINE", "MANUAL_TAPING", "SPRAY_AREA",
               "SAND_AREA", "GO_HOME"):
        assert lib.has_tree(at), at
        assert lib.trees[at].main, at


# ------------------------------------------------------------------------------------------ load errors --
def test_xml_syntax_error_has_line():
    e = load_error('<root BTCPP_format="4">\n<BehaviorTree ID="T">\n<Sequence>\n</BehaviorTree></root>')
    assert e.file == "bad.xml" and e.line == 4 and "syntax" in str(e)


@pytest.mark.parametrize("attr", ['', 'BTCPP_format="3"'])
def test_only_format_4(attr):
    e = load_error('<root %s>\n<BehaviorTree ID="T"><AlwaysSuccess/></BehaviorTree></root>' % attr)
    assert e.line == 1 and "BTCPP_format" in str(e)


def test_unknown_node_type_names_file_line_and_node_with_suggestion():
    e = load_error(tree_xml("<Sequence>\n  <AlwaysSucess/>\n</Sequence>"))
    assert (e.file, e.line, e.name) == ("bad.xml", 4, "AlwaysSucess")
    assert "unknown node type" in str(e) and "AlwaysSuccess" in str(e)
    assert str(e).startswith("bad.xml: line 4 'AlwaysSucess': unknown node type 'AlwaysSucess'")


def test_unknown_explicit_action_id():
    e = load_error(tree_xml('<Action ID="NoSuchThing"/>'))
    assert e.line == 3 and e.name == "NoSuchThing"


def test_unknown_port_lists_the_allowed_ones():
    e = load_error(tree_xml('<Sequence>\n<Timeout msec="5" sec="1"><AlwaysSuccess/></Timeout></Sequence>'))
    assert (e.file, e.line, e.name) == ("bad.xml", 4, "Timeout")
    assert str(e).startswith("bad.xml: line 4 'Timeout': ") and "unknown port 'sec'" in str(e) and "msec" in str(e)


def test_scripting_attributes_are_rejected():
    e = load_error(tree_xml('<AlwaysSuccess _skipIf="x == 1"/>'))
    assert "_skipIf" in str(e) and "not supported" in str(e)


@pytest.mark.parametrize("body,port,why", [
    ('<RetryUntilSuccessful num_attempts="three"><AlwaysSuccess/></RetryUntilSuccessful>', "num_attempts", "int"),
    ('<Timeout msec="1.5"><AlwaysSuccess/></Timeout>', "msec", "int"),
    ('<Typed f="fast"/>', "f", "float"),
    ('<Typed f="nan"/>', "f", "float"),
    ('<Typed b="yes"/>', "b", "bool"),
    ('<Typed fl="1;x"/>', "fl", "float_list"),
    ('<Typed j="{not json"/>', "j", "json"),
    ('<Typed mode="loud"/>', "mode", "allowed: fast, slow"),
])
def test_port_of_the_wrong_type(body, port, why):
    e = load_error(tree_xml(body))
    assert e.line == 3 and "port '%s'" % port in str(e) and why in str(e)


def test_missing_required_port():
    e = load_error(tree_xml('<Sequence>\n<Scripted script="S"/></Sequence>'))
    assert e.line == 4 and "missing required port 'id'" in str(e)


def test_output_port_must_be_a_blackboard_pointer():
    e = load_error(tree_xml('<Writer value="3"/>'))
    assert "output port 'value'" in str(e) and "{key}" in str(e)


def test_missing_subtree():
    e = load_error(tree_xml('<Sequence>\n<SubTree ID="Nowhere"/></Sequence>'))
    assert (e.line, e.name) == (4, "Nowhere") and "not defined" in str(e)


def test_recursive_subtree():
    e = load_error(tree_xml('<SubTree ID="A"/>', extra='<BehaviorTree ID="A">\n<SubTree ID="T"/></BehaviorTree>'))
    assert "recursion" in str(e)


def test_subtree_port_that_the_subtree_does_not_use():
    e = load_error(tree_xml('<SubTree ID="A" speed="{s}"/>',
                            extra='<BehaviorTree ID="A"><SetBlackboard output_key="{x}" value="1"/></BehaviorTree>'))
    assert e.line == 3 and "has no port 'speed'" in str(e) and "x" in str(e)


def test_main_tree_must_exist():
    e = load_error('<root BTCPP_format="4" main_tree_to_execute="Main">\n'
                   '<BehaviorTree ID="T"><AlwaysSuccess/></BehaviorTree></root>')
    assert e.name == "Main" and e.line == 1


def test_duplicate_tree_id():
    e = load_error('<root BTCPP_format="4">\n<BehaviorTree ID="T"><AlwaysSuccess/></BehaviorTree>\n'
                   '<BehaviorTree ID="T"><AlwaysSuccess/></BehaviorTree></root>')
    assert e.line == 3 and "defined twice" in str(e)


@pytest.mark.parametrize("body,msg", [
    ("<Sequence/>", "at least 1"),
    ("<Inverter><AlwaysSuccess/><AlwaysSuccess/></Inverter>", "exactly 1"),
    ("<AlwaysSuccess><AlwaysSuccess/></AlwaysSuccess>", "exactly 0"),
    ('<Parallel success_count="3"><AlwaysSuccess/><AlwaysSuccess/></Parallel>', "success_count"),
    ('<Repeat num_cycles="0"><AlwaysSuccess/></Repeat>', "-1 (forever) or at least 1"),
    ('<RetryUntilSuccessful num_attempts="-5"><AlwaysSuccess/></RetryUntilSuccessful>', "at least 1"),
    ('<Timeout msec="-1"><AlwaysSuccess/></Timeout>', ">= 0 ms"),
])
def test_child_count_and_parallel_thresholds(body, msg):
    e = load_error(tree_xml(body))
    assert e.line == 3 and msg in str(e)


def test_blackboard_key_used_with_incompatible_types():
    e = load_error(tree_xml('<Sequence>\n<Writer value="{v}"/>\n<ReaderList value="{v}"/></Sequence>'))
    assert e.line == 5 and "blackboard key 'v'" in str(e) and "line 4" in str(e)


def test_bad_autoremap_and_unexpected_root_child():
    e = load_error(tree_xml('<SubTree ID="A" _autoremap="maybe"/>',
                            extra='<BehaviorTree ID="A"><AlwaysSuccess/></BehaviorTree>'))
    assert "_autoremap" in str(e)
    e = load_error('<root BTCPP_format="4"><Tree ID="T"/></root>')
    assert "unexpected element <Tree>" in str(e)


def test_missing_file_and_missing_include(tmp_path):
    with pytest.raises(TreeLoadError) as ei:
        TreeLibrary().load_file(str(tmp_path / "none.xml"))
    assert "cannot read" in str(ei.value)
    p = tmp_path / "a.xml"
    p.write_text('<root BTCPP_format="4">\n<include path="gone.xml"/></root>')
    with pytest.raises(TreeLoadError) as ei:
        TreeLibrary().load_file(str(p))
    assert ei.value.line == 2 and "gone.xml" in str(ei.value)


def test_load_errors_leave_no_half_built_tree_in_use():
    lib = TreeLibrary(default_registry(extra=[Scripted, Typed]))
    lib.load_string(tree_xml("<AlwaysSuccess/>", tree_id="Good"), "good.xml")
    with pytest.raises(TreeLoadError):
        lib.load_string(tree_xml("<Bogus/>", tree_id="Bad"), "bad.xml")
    assert lib.build("Good").tick() == Status.SUCCESS
    with pytest.raises(KeyError):
        lib.build("Bad")
