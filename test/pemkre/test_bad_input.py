"""Every bad input of the issue: a clear error naming the culprit, and the store unchanged and consistent."""
import os
import shutil

import pytest
from pemkre_testkit import json_dumps, quads_snapshot, scan_result
from rdflib import Literal, URIRef

from locem_bridge.pemkre import PLB, JournaledStore, ProcessEngine
from locem_bridge.pemkre.errors import (BindingError, ConditionError, InvalidParameterError, InvalidStatusError,
                                        MalformedIriError, OntologySyntaxError, ProcessModelError, QueryError,
                                        TaskStateError, UnknownProcessError, UnknownQueryError, UnknownTaskError,
                                        WorldUpdateError)
from locem_bridge.pemkre.ontology import default_ontology_files
from locem_bridge.pemkre.terms import bindings_from_strings, parse_term

TAPING = str(PLB.TapingProcess)


@pytest.fixture
def engine(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=2))
    e.start_process(TAPING, {"validateLines": True})
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")   # GET_TOOL done
    return e


def _rejected(e, call, exc, *fragments):
    """``call`` raises ``exc`` whose message holds every fragment; nothing is written; the store is consistent."""
    before = quads_snapshot(e.store)
    with pytest.raises(exc) as info:
        call()
    msg = str(info.value)
    for f in fragments:
        assert f in msg, (f, msg)
    assert quads_snapshot(e.store) == before
    assert e.check_consistency(full_inference=True) == []
    return msg


def test_unknown_process_iri(engine):
    msg = _rejected(engine, lambda: engine.start_process("https://example.org/NoSuchProcess", abort_running=True),
                    UnknownProcessError, "https://example.org/NoSuchProcess", "known processes", "TapingProcess")
    assert "SandingProcess" in msg
    _rejected(engine, lambda: engine.next_action("https://example.org/NoSuchProcess"), UnknownProcessError,
              "NoSuchProcess")


@pytest.mark.parametrize("bad", ["", "not an iri", "TapingProcess", "http://exa mple.org/x", "<http://a>b>",
                                 "https://example.org/x>\" . <a> <b> <c", "urn:x:{}"])
def test_malformed_iris(engine, bad):
    _rejected(engine, lambda: engine.start_process(bad, abort_running=True), MalformedIriError, "IRI")
    _rejected(engine, lambda: engine.set_task_status(bad, "succeeded"), MalformedIriError, "task IRI")
    if bad:  # next_action("") / next_action(None) means "the running process" (the ROS request's empty field)
        _rejected(engine, lambda: engine.next_action(bad), MalformedIriError, "process IRI",
                  repr(bad.strip("<>"))[1:-1][:20])
    # an IRI binding of a predefined query (a URIRef, as scripts pass world instances) is checked like any IRI
    _rejected(engine, lambda: engine.query("feature_status", {"feature": URIRef(bad)}), MalformedIriError,
              "binding 'feature'", "IRI")
    _rejected(engine, lambda: engine.query("kpi_by_process", {"process": URIRef(bad)}), MalformedIriError,
              "binding 'process'", "IRI")
    # the running process is untouched: the same task is still the next action
    assert engine.next_action().action_type == "VALIDATE_TAPE_LINE"


def test_free_text_detail_survives_a_restart_unchanged(make_engine, tmp_path):
    """Quotes, braces, ``>``, newlines, triple quotes and a backslash in ``detail`` are data: stored as given,
    replayed from the journal as given, nothing else touched."""
    e = make_engine("detail_db")
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING, {"validateLines": False})
    a = e.next_action()                                              # GET_TOOL
    detail = ('operator said: "tool {A} > tool {B}" \\ \n ok\n'
              '"""long string""" } ; DROP ALL ; { <urn:x> <urn:y> <urn:z> .\r\n\ttab, \\" end\\')
    assert all(c in detail for c in ('"', "{", "}", ">", "\n", '"""', "\\"))
    e.set_task_status(a.task, "in_progress")
    e.set_task_status(a.task, "succeeded", detail)
    from locem_bridge.pemkre.vocab import PROC
    assert e.store.value(URIRef(a.task), PROC.detail) == Literal(detail)
    before = quads_snapshot(e.store)
    e.store.close()
    store = JournaledStore(str(tmp_path / "detail_db"))
    try:
        assert store.replayed_records > 0 and store.dropped_bytes == 0     # read back from the journal
        assert quads_snapshot(store) == before                             # nothing else changed
        assert store.value(URIRef(a.task), PROC.detail) == Literal(detail)  # the detail, character for character
        e2 = ProcessEngine(store, clock=e.clock)
        assert e2.check_consistency(full_inference=True) == []
        nxt = e2.next_action()
        assert nxt.action_type == "TAPE_LINE" and nxt.task != a.task       # the run continues where it stopped
    finally:
        store.close()


def test_statuses_for_tasks_that_are_not_running(engine):
    a = engine.next_action()                                   # VALIDATE_TAPE_LINE, issued
    old = URIRef(a.task.replace("_task_2", "_task_1"))          # the GET_TOOL task, already succeeded
    _rejected(engine, lambda: engine.set_task_status(str(old), "succeeded"), TaskStateError,
              str(old), "succeeded", "not running")
    _rejected(engine, lambda: engine.set_task_status(a.task + "_nope", "succeeded"), UnknownTaskError,
              a.task + "_nope", "next_action")
    _rejected(engine, lambda: engine.set_task_status(a.task, "done"), InvalidStatusError,
              "'done'", "in_progress, succeeded, failed")
    engine.set_task_status(a.task, "in_progress")
    _rejected(engine, lambda: engine.set_task_status(a.task, "in_progress"), TaskStateError, "already in_progress")
    # the operator's answer must be valid/invalid
    _rejected(engine, lambda: engine.set_task_status(a.task, "succeeded", "maybe"), InvalidStatusError,
              "'valid'", "'invalid'", "maybe")
    engine.abort_process(reason="test")
    _rejected(engine, lambda: engine.set_task_status(a.task, "succeeded", "valid"), TaskStateError, "failed")


def test_metacharacters_in_parameters_are_values_not_query_text(engine):
    nasty = ['"} ; DROP ALL ; {"', "wall_1_joint_1> . ?x ?y ?z", "' OR 1=1 --", "\\\" } UNION { ?s ?p ?o }",
             "<https://locem-bridge.example.org/site/wall_1_joint_1>", "\n.\n", "?feature"]
    for value in nasty:
        before = quads_snapshot(engine.store)
        res = engine.query("feature_by_id", {"id": value})      # a literal id: no such feature, no injection
        assert res.rows == []
        assert quads_snapshot(engine.store) == before
    # the same id as a proper literal finds the feature
    rows = engine.query("feature_by_id", {"id": "wall_1_joint_1"}).rows
    assert {str(r["feature"]).rsplit("/", 1)[1] for r in rows} == {"wall_1_joint_1"}
    assert {str(r["class"]).rsplit("#", 1)[1] for r in rows} >= {"VerticalJointLine", "JointLine", "WallFeature",
                                                                  "TapingPending"}  # asserted + inferred
    _rejected(engine, lambda: engine.query("feature_by_id", {"feature": "x"}), InvalidParameterError,
              "'feature'", "accepts id")
    _rejected(engine, lambda: engine.query("no_such_query"), UnknownQueryError, "no_such_query", "pending_joint_lines")
    _rejected(engine, lambda: engine.query("feature_by_id", {"id": float("nan")}), InvalidParameterError, "finite")
    # N-Triples terms (the ROS form of bindings) are parsed by an RDF parser; junk is refused, naming the binding
    for junk in ['"abc', "<a b>", '"x" . <s> <p> <o>', "_:b1", "?x", "<https://ok.example/x> <https://ok.example/y>"]:
        with pytest.raises(InvalidParameterError, match="N-Triples term|blank nodes|exactly one"):
            bindings_from_strings(["id"], [junk])
    assert parse_term('"a \\"quoted\\" } ; DROP ALL"') == Literal('a "quoted" } ; DROP ALL')
    # an option with metacharacters is refused (it is a boolean)
    _rejected(engine, lambda: engine.start_process(TAPING, {"validateLines": 'true" } ; DROP ALL'}, abort_running=True),
              InvalidParameterError, "validateLines", "boolean")
    _rejected(engine, lambda: engine.start_process(TAPING, {"validate": True}, abort_running=True),
              InvalidParameterError, "'validate'", "validateLines")


def test_bad_scan_results_name_the_path(engine):
    s = scan_result()
    s["joints"][0]["start"] = [1.0, "x", 0.0]
    _rejected(engine, lambda: engine.update_world(s), WorldUpdateError, "joints[0].start[1]", "number")
    s = scan_result()
    s["joints"][1]["id"] = "1bad id"
    _rejected(engine, lambda: engine.update_world(s), WorldUpdateError, "joints[1].id", "[A-Za-z]")
    s = scan_result()
    s["areas"][0]["wall"] = "wall_9"
    _rejected(engine, lambda: engine.update_world(s), WorldUpdateError, "areas[0].wall", "wall_9")
    s = scan_result()
    s["joints"][0]["kind"] = "diagonal"
    _rejected(engine, lambda: engine.update_world(s), WorldUpdateError, "joints[0].kind", "horizontal", "vertical")
    _rejected(engine, lambda: engine.update_world("{not json"), WorldUpdateError, "not valid JSON")
    for finish in ("painted", "SPRAYED", "", 1, True, ["sprayed"]):
        s = scan_result()
        s["areas"][0]["finish"] = finish
        _rejected(engine, lambda: engine.update_world(s), WorldUpdateError, "areas[0].finish", "bare, sprayed, sanded",
                  repr(finish))
    s = scan_result()
    s["walls"][0]["height"] = float("inf")
    _rejected(engine, lambda: engine.update_world(json_dumps(s).replace("Infinity", "1e999")), WorldUpdateError,
              "walls[0].height", "finite")


def _copy_ontologies(tmp_path):
    d = tmp_path / "onto"
    d.mkdir()
    for f in default_ontology_files():
        shutil.copy(f, d)
    return d


def test_ontology_file_with_a_syntax_error(tmp_path, make_engine):
    e = make_engine("db")
    before = quads_snapshot(e.store)
    e.store.close()
    d = _copy_ontologies(tmp_path)
    bad = d / "plasterboard.ttl"
    lines = bad.read_text().splitlines()
    lines[40] = lines[40] + " this is ; not turtle ]"
    bad.write_text("\n".join(lines) + "\n")
    store = JournaledStore(str(tmp_path / "db"))
    try:
        with pytest.raises(OntologySyntaxError) as info:
            ProcessEngine(store, sorted(str(p) for p in d.iterdir()))
        assert "plasterboard.ttl" in str(info.value)
        assert info.value.source.endswith("plasterboard.ttl")
        assert quads_snapshot(store) == before
        e2 = ProcessEngine(store)                        # the shipped files still load on the untouched store
        assert e2.check_consistency(full_inference=True) == []
    finally:
        store.close()


def _with_condition(tmp_path, condition: str):
    d = _copy_ontologies(tmp_path)
    p = d / "plasterboard.ttl"
    text = p.read_text()
    old = 'proc:condition "ASK { ?process plb:validateLines true }"'
    assert old in text
    p.write_text(text.replace(old, 'proc:condition "%s"' % condition))
    return sorted(str(x) for x in d.iterdir())


def test_condition_query_that_does_not_parse_is_refused_at_load(tmp_path, make_engine):
    files = _with_condition(tmp_path, "ASK { ?process plb:validateLines true ")
    store = JournaledStore(str(tmp_path / "db2"))
    try:
        with pytest.raises(QueryError) as info:
            ProcessEngine(store, files)
        assert "taping_t12" in str(info.value) and "parse" in str(info.value)
        assert len(store) == 0 if hasattr(store, "__len__") else store.count() == 0
    finally:
        store.close()


def test_condition_query_that_fails_at_run_time(tmp_path, make_engine):
    # SERVICE to a closed port on loopback: parses fine, fails when evaluated
    files = _with_condition(tmp_path, "ASK { SERVICE <http://127.0.0.1:9/sparql> { ?process ?p ?o } }")
    e = make_engine("db3", ontology_files=files)
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING)
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")
    msg = _rejected(e, e.next_action, ConditionError, "taping_t12", "taping_validateOption")
    assert "failed" in msg
    assert e.active_process() is not None                # the process is still there, at the same place


def test_binding_query_without_a_value(make_engine):
    e = make_engine()
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING)
    # remove the taping tool from the world: GET_TOOL cannot be parameterized
    from locem_bridge.pemkre.store import G_WORLD, ChangeSet
    from rdflib.namespace import RDF
    from locem_bridge.pemkre.vocab import BASE, PPR
    tool = URIRef(BASE + "robot/rbkairos_ur10e/taping_tool")       # the default robot's (ontologies/default_robot.ttl)
    e.store.apply(e.reasoner.infer(e.store, ChangeSet(remove=[(tool, RDF.type, PPR.TapingTool, G_WORLD)])))
    _rejected(e, e.next_action, BindingError, "'tool'", "taping_getTool", "p_tapingTool")


def test_process_model_errors_name_the_node(tmp_path, make_engine):
    e = make_engine("db4")                               # a store in use: world, a finished run, a running one
    e.update_world(scan_result(joints_per_wall=1))
    e.start_process(TAPING, {"validateLines": False})
    a = e.next_action()
    e.set_task_status(a.task, "succeeded")
    before = quads_snapshot(e.store)
    e.store.close()
    d = _copy_ontologies(tmp_path)
    p = d / "plasterboard.ttl"
    text = p.read_text()
    old = ("plb:taping_t20 a proc:Transition, owl:NamedIndividual ; proc:source plb:taping_goHome ; "
           "proc:target plb:taping_end .")
    assert old in text
    p.write_text(text.replace(old, ""))
    store = JournaledStore(str(tmp_path / "db4"))
    try:
        with pytest.raises(ProcessModelError, match="taping_goHome.*no outgoing transition"):
            ProcessEngine(store, sorted(str(x) for x in d.iterdir()))
        assert quads_snapshot(store) == before           # nothing written
        e2 = ProcessEngine(store, clock=e.clock)         # the shipped files still load on the untouched store
        assert e2.check_consistency(full_inference=True) == []
        assert e2.next_action().action_type == "TAPE_LINE"
    finally:
        store.close()


def test_second_process_while_one_runs(engine):
    _rejected(engine, lambda: engine.start_process(str(PLB.SprayingProcess)), TaskStateError,
              "still running", "abort_running")


def test_a_turtle_syntax_error_is_one_line_naming_file_and_line(tmp_path):
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.pemkre.ontology import load_files
    d = _copy_ontologies(tmp_path)
    bad = d / "process.ttl"
    lines = bad.read_text().splitlines()
    lines.append("this is ; not turtle ]")
    bad.write_text("\n".join(lines) + "\n")
    with pytest.raises(ConfigError) as info:
        load_files(sorted(str(p) for p in d.iterdir()))
    line = str(info.value)
    assert line.startswith("%s: line %d: Turtle syntax error: " % (bad, len(lines))), line
    assert "\n" not in line


@pytest.mark.parametrize("depth", [33, 10000])
def test_deeply_nested_json_is_refused_naming_the_argument_and_the_depth(make_engine, depth):
    """'[[[[...]]]]' 10000 deep used to be an INTERNAL_ERROR (Python's recursion limit); now every JSON argument
    of PEMKRE's services refuses it as INVALID_PARAMETER naming the argument and the allowed 32 levels, and
    nothing is applied. 32 levels (the limit) still parse."""
    from locem_bridge.pemkre.engine import MAX_JSON_DEPTH, load_json
    assert MAX_JSON_DEPTH == 32
    deep_text = "[" * depth + "]" * depth
    deep_obj = {"walls": [], "joints": [], "areas": [], "extra": "x"}
    node = deep_obj
    for _ in range(depth - 1):                           # the same depth as a Python value (update_world(dict))
        node["extra"] = {}
        node = node["extra"]
    e = make_engine("deep")
    e.start_process(TAPING, {"validateLines": False})
    scan = e.next_action()
    assert scan.action_type == "SCAN"
    e.set_task_status(scan.task, "in_progress")
    for what, call in (
            ("options", lambda: load_json('{"validateLines": %s}' % deep_text, "options")),
            ("options", lambda: e.start_process(TAPING, {"validateLines": deep_obj}, abort_running=True)),
            ("scan", lambda: e.update_world('{"walls": %s}' % deep_text)),
            ("scan", lambda: e.update_world(deep_obj)),
            ("detail (the SCAN result)", lambda: e.set_task_status(scan.task, "succeeded",
                                                                   '{"joints": %s}' % deep_text))):
        msg = _rejected(e, call, InvalidParameterError, what, "deeper than the allowed 32 levels")
        assert InvalidParameterError.code == "INVALID_PARAMETER", msg
    # the limit itself is fine, and the SCAN task still takes its (flat) result
    assert load_json("[" * 32 + "]" * 32, "options") is not None
    e.set_task_status(scan.task, "succeeded", json_dumps(scan_result(joints_per_wall=1)))
    assert e.next_action().action_type == "GET_TOOL"
