"""The Groot2 node catalogue matches the code; the shipped trees are documented, load, and use only data."""
import ast
import difflib
import os
import re
import xml.etree.ElementTree as ET

from locem_bridge.hicem.ports import PORT_TYPES
from locem_bridge.hicem.registry import catalogue_xml, default_registry
from locem_bridge.hicem.xml_loader import TreeLibrary

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..")
TREES = os.path.join(ROOT, "trees")
CATALOGUE = os.path.join(TREES, "node_catalogue.xml")
ACTION_TYPES = ("SCAN", "GET_TOOL", "VALIDATE_TAPE_LINE", "TAPE_LINE", "MANUAL_TAPING", "SPRAY_AREA",
                "SAND_AREA", "GO_HOME", "RECOVER")


def test_catalogue_file_is_what_the_code_declares():
    generated = catalogue_xml(default_registry())
    on_disk = open(CATALOGUE, encoding="utf-8").read()
    diff = "".join(difflib.unified_diff(on_disk.splitlines(True), generated.splitlines(True), "on disk", "code"))
    assert not diff, ("trees/node_catalogue.xml is out of date; regenerate with "
                      "`python -m locem_bridge.hicem.registry trees/node_catalogue.xml`:\n" + diff)


def test_catalogue_lists_every_custom_node_and_port_with_type_default_unit():
    root = ET.parse(CATALOGUE).getroot()
    assert root.tag == "root" and root.get("BTCPP_format") == "4"
    model = root.find("TreeNodesModel")
    by_id = {el.get("ID"): el for el in model}
    reg = default_registry()
    assert set(by_id) == {c.node_id() for c in reg.custom_nodes()}
    xml_types = {t.xml_type for t in PORT_TYPES.values()}
    for cls in reg.custom_nodes():
        el = by_id[cls.node_id()]
        assert el.tag == cls.KIND
        ports = {p.get("name"): p for p in el}
        assert set(ports) == {p.name for p in cls.PORTS}, cls.node_id()
        for spec in cls.PORTS:
            p = ports[spec.name]
            assert p.tag == {"input": "input_port", "output": "output_port", "inout": "inout_port"}[spec.direction]
            assert p.get("type") == spec.type.xml_type and p.get("type") in xml_types
            assert p.get("default") == spec.default
            assert p.get("unit") == (spec.unit or "-")
    for must in ("CheckHealth", "SendLocemCommand", "ReadDataStore", "WriteDataStore", "WaitForOperator", "Log",
                 "GetTapingPosition", "GetTapePath", "GetAreaRaster", "TagIdNameToObjectId", "LoopList"):
        assert must in by_id


def test_each_action_type_has_a_documented_tree_file_that_loads():
    lib = TreeLibrary()
    lib.load_directory(TREES)
    for at in ACTION_TYPES:
        path = os.path.join(TREES, at + ".xml")
        text = open(path, encoding="utf-8").read()
        header = re.search(r"<!--(.*?)-->", text, re.S)
        assert header and header.group(1).strip().startswith(at + ":"), at
        assert lib.main_trees[os.path.abspath(path)] == at


def test_trees_take_numbers_from_data_only():
    # no numeric literal in any tree attribute: numbers come from {@cfg.*}, the PEMKRE parameters or the store
    for name in os.listdir(TREES):
        if not name.endswith(".xml") or name == "node_catalogue.xml":
            continue
        for el in ET.parse(os.path.join(TREES, name)).getroot().iter():
            for k, v in el.attrib.items():
                if k == "BTCPP_format":
                    continue
                words = re.sub(r"\{[^}]*\}", "", v).replace("=", " ").split()
                nums = [w for w in words if re.fullmatch(r"[-+]?\d+(\.\d*)?", w)]
                assert not nums, "%s: <%s %s=%r> has a hard-coded number" % (name, el.tag, k, v)


def test_hicem_core_never_imports_ros():
    pkg = os.path.join(ROOT, "src", "locem_bridge", "hicem")
    banned = {"rospy", "actionlib", "roslib", "rosgraph", "std_msgs", "diagnostic_msgs", "locem_bridge.msg",
              "locem_bridge.srv"}
    for name in os.listdir(pkg):
        if name.endswith(".py"):
            tree = ast.parse(open(os.path.join(pkg, name), encoding="utf-8").read())
            for node in ast.walk(tree):
                mods = []
                if isinstance(node, ast.Import):
                    mods = [a.name for a in node.names]
                elif isinstance(node, ast.ImportFrom) and node.module:
                    mods = [node.module]
                for m in mods:
                    assert not any(m == b or m.startswith(b + ".") for b in banned), (name, m)
