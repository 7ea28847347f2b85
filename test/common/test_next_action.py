"""The next-action record and its one N-Triples parameter codec (docs/contracts.md, "PEMKRE next action").

The codec is written by hand (HICEM reads parameters without an RDF library); these tests hold it to a real RDF
implementation: what it writes, pyoxigraph writes and parses the same; what pyoxigraph writes, it reads back.
"""
import ast
import os

import pyoxigraph as ox
import pytest

from locem_bridge.common.next_action import (NextAction, NextActionError, decode_parameters, encode_parameters,
                                             iri_term, literal_term)

XSD = "http://www.w3.org/2001/XMLSchema#"
TASK = "https://locem-bridge.example.org/log/taping_1_task_3"
P = "https://locem-bridge.example.org/ont/plasterboard#"
TEXTS = ["plain", 'a "quoted" word', "back\\slash", "tab\there", "two\nlines\r\n", "\x00\x01\x08\x0c\x1f\x7f",
         "é ü 日本 \u2028 😀", "it's", "", " leading and trailing "]


@pytest.mark.parametrize("text", TEXTS)
def test_a_literal_is_written_as_pyoxigraph_writes_it_and_read_back_unchanged(text):
    assert literal_term(text) == str(ox.Literal(text))
    doc = encode_parameters(TASK, [(P + "note", literal_term(text))])
    parsed = list(ox.parse(doc.encode("utf-8"), format=ox.RdfFormat.N_TRIPLES))
    assert [t.object.value for t in parsed] == [text]
    assert decode_parameters(TASK, doc) == {"note": text}


def test_typed_and_language_literals_and_iris_match_pyoxigraph():
    double = ox.NamedNode(XSD + "double")
    assert literal_term("0.2", XSD + "double") == str(ox.Literal("0.2", datatype=double))
    assert literal_term("x", XSD + "string") == str(ox.Literal("x", datatype=ox.NamedNode(XSD + "string")))
    assert literal_term("Wand", language="de-AT") == str(ox.Literal("Wand", language="de-AT"))
    assert iri_term(P + "line") == str(ox.NamedNode(P + "line"))


def test_a_document_decodes_to_the_values_trees_see():
    doc = encode_parameters(TASK, [(P + "line", iri_term("https://locem-bridge.example.org/site/wall_1_joint_1")),
                                   (P + "speed", literal_term("0.2", XSD + "double")),
                                   (P + "passes", literal_term("3", XSD + "integer")),
                                   (P + "validate", literal_term("true", XSD + "boolean")),
                                   (P + "note", literal_term("Wand", language="de"))])
    na = NextAction("action", task=TASK, action_type="TAPE_LINE", parameters=doc)
    assert na.params() == {"line": "wall_1_joint_1", "speed": 0.2, "passes": 3, "validate": True, "note": "Wand"}
    assert na.blackboard_entries()["param_line"] == "wall_1_joint_1"
    # a document pyoxigraph serialises reads the same
    ox_doc = "".join("%s %s %s .\n" % (ox.NamedNode(TASK), ox.NamedNode(P + k), v) for k, v in
                     [("speed", ox.Literal("0.2", datatype=ox.NamedNode(XSD + "double"))),
                      ("line", ox.NamedNode("https://locem-bridge.example.org/site/wall_1_joint_1"))])
    assert decode_parameters(TASK, ox_doc) == {"speed": 0.2, "line": "wall_1_joint_1"}


def test_the_record_round_trips_through_its_plain_object_form():
    na = NextAction("action", "urn:p", TASK, "TAPE_LINE", encode_parameters(TASK, [(P + "line", iri_term("urn:x#l"))]),
                    "issued")
    again = NextAction.from_answer(na.as_answer())
    assert again == na and again.params() == {"line": "l"}
    assert NextAction.from_answer(na) == na
    ended = NextAction.from_answer({"status": "ended", "detail": "all lines taped"})
    assert (ended.status, ended.message) == ("ended", "all lines taped")


def test_the_matched_skill_travels_with_the_answer_and_an_old_answer_names_none():
    doc = encode_parameters(TASK, [(P + "tool", iri_term("urn:x#spray_gun"))])
    na = NextAction.from_answer({"status": "action", "task": TASK, "action_type": "GET_TOOL", "parameters": doc,
                                 "skill": "CHANGE_TOOL", "skill_kind": "basic"})
    assert (na.skill, na.skill_kind, na.params()) == ("CHANGE_TOOL", "basic", {"tool": "spray_gun"})
    assert NextAction.from_answer(na.as_answer()) == na
    tree = NextAction.from_answer(dict(na.as_answer(), skill="GET_TOOL", skill_kind="composite"))
    assert (tree.skill, tree.skill_kind) == ("GET_TOOL", "composite")
    old = NextAction.from_answer({"status": "action", "task": TASK, "action_type": "GET_TOOL", "parameters": doc})
    assert (old.skill, old.skill_kind) == ("", "")
    assert NextAction.from_answer(dict(na.as_answer(), skill=None, skill_kind=None)).skill_kind == ""


@pytest.mark.parametrize("answer,msg", [
    ([], "must be an object, got list"),
    ({"status": "maybe"}, "status 'maybe' is not one of: action, ended, failed"),
    ({"status": "action", "task": TASK}, "'action_type' missing"),
    ({"status": "action", "action_type": "SCAN"}, "'task' (the task instance IRI) missing"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "parameters": 3}, "must be an N-Triples string"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "parameters": "garbage"},
     "parameters line 1 is not an N-Triples triple"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "parameters": "<urn:other> <urn:p#l> <urn:x> ."},
     "subject <urn:other> is not the task"),
    ({"status": "action", "action_type": "SCAN", "task": TASK,
      "parameters": '<%s> <urn:p#ok> "maybe"^^<%sboolean> .' % (TASK, XSD)}, "bad xsd:boolean"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "skill": "SCAN", "skill_kind": "atomic"},
     "skill_kind 'atomic' is not one of: composite, basic"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "skill": "SCAN"}, "'skill' and 'skill_kind' go together"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "skill_kind": "basic"}, "go together"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "skill": 3, "skill_kind": "basic"},
     "'skill' and 'skill_kind' must be strings"),
    ({"status": "action", "action_type": "SCAN", "task": TASK, "skill": "SCAN now", "skill_kind": "basic"},
     "without whitespace"),
])
def test_bad_answers_are_refused_naming_the_problem(answer, msg):
    with pytest.raises(NextActionError) as err:
        NextAction.from_answer(answer)
    assert msg in str(err.value)


def test_the_codec_imports_no_rdf_library():
    """HICEM reads the parameters with this module alone: it must not pull rdflib or pyoxigraph in."""
    path = os.path.join(os.path.dirname(__file__), "..", "..", "src", "locem_bridge", "common", "next_action.py")
    with open(path, encoding="utf-8") as handle:
        tree = ast.parse(handle.read())
    imported = {a.name.split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    imported |= {(n.module or "").split(".")[0] for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert imported <= {"re", "dataclasses", "typing"}, imported
