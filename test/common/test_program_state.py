"""The skill state machine (OPC UA Part 10 ProgramStateMachineType): the same in code and in the ontology,
forbidden methods refused with nothing changed, every transition told with its cause."""
import os

import pytest
import rdflib

from locem_bridge.common.program_state import (TRANSITIONS, Method, ProgramState, ProgramStateMachine,
                                               TransitionRefused, allowed_methods)

SKILL_TTL = os.path.join(os.path.dirname(__file__), "..", "..", "ontologies", "skill.ttl")


def test_the_transitions_are_those_declared_in_the_skill_ontology():
    g = rdflib.Graph().parse(SKILL_TTL, format="turtle")
    sk = dict(g.namespaces())["sk"]
    rows = g.query("""SELECT ?n ?name ?from ?to ?method WHERE {
        ?t a sk:StateTransition ; sk:transitionNumber ?n ; sk:opcuaBrowseName ?name ;
           sk:fromState/rdfs:label ?from ; sk:toState/rdfs:label ?to .
        OPTIONAL { ?t sk:causedBy/rdfs:label ?method } }""", initNs={"sk": sk, "rdfs": rdflib.RDFS})
    declared = sorted((int(n), str(name), str(f), str(t), str(m) if m is not None else None)
                      for n, name, f, t, m in rows)
    code = sorted((t.number, t.name, t.source.value, t.target.value, t.method.value if t.method else None)
                  for t in TRANSITIONS)
    assert declared == code and len(code) == 9


def test_a_forbidden_method_is_refused_naming_the_state_and_what_it_allows_and_nothing_changes():
    seen = []
    m = ProgramStateMachine("7", "SPRAY_AREA", listener=seen.append)
    with pytest.raises(TransitionRefused) as error:
        m.call(Method.RESUME, "operator")
    assert "Resume is not allowed" in str(error.value) and "Ready" in str(error.value)
    assert "Start, Halt" in str(error.value)
    assert m.state is ProgramState.READY and seen == []
    m.call(Method.START, "HICEM")
    m.call(Method.SUSPEND, "person in bay")
    with pytest.raises(TransitionRefused):
        m.call(Method.SUSPEND)
    assert m.allowed() == [Method.RESUME, Method.HALT]
    m.call(Method.HALT, "hose kinked")
    with pytest.raises(TransitionRefused):
        m.call(Method.RESUME)
    assert m.complete() is None and m.state is ProgramState.HALTED
    m.call(Method.RESET, "operator")
    assert [(t.name, t.method, t.cause) for t in seen] == [
        ("ReadyToRunning", "Start", "HICEM"), ("RunningToSuspended", "Suspend", "person in bay"),
        ("SuspendedToHalted", "Halt", "hose kinked"), ("HaltedToReady", "Reset", "operator")]
    assert [t.number for t in seen] == [2, 5, 7, 1]


def test_the_program_completes_and_fails_by_itself():
    m = ProgramStateMachine("t1", "TAPE_LINE")
    m.call(Method.START)
    assert m.complete().name == "RunningToReady"
    m.call(Method.START)
    t = m.fail("LOCEM HARDWARE_ERROR")
    assert (t.name, t.method, t.cause) == ("RunningToHalted", "", "LOCEM HARDWARE_ERROR")
    assert allowed_methods(ProgramState.HALTED) == [Method.RESET]
    assert Method.parse("suspend") is Method.SUSPEND
    with pytest.raises(ValueError, match="allowed: Start, Suspend, Resume, Halt, Reset"):
        Method.parse("pause")
