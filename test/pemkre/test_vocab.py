"""The ontologies are valid OWL 2 in Turtle, every term used is declared, and vocab.py mirrors them."""
import glob
import os

import pytest
from rdflib import BNode, Graph, Literal, URIRef
from rdflib.namespace import OWL, RDF, RDFS

from locem_bridge.pemkre import vocab
from locem_bridge.pemkre.ontology import default_ontology_dir
from locem_bridge.pemkre.reasoning import SchemaRules, bounded_closure

FILES = sorted(glob.glob(os.path.join(default_ontology_dir(), "*.ttl")))
OURS = (str(vocab.PROC), str(vocab.PPR), str(vocab.PLB), str(vocab.SK))
DECLARATIONS = {OWL.Class, OWL.ObjectProperty, OWL.DatatypeProperty, OWL.AnnotationProperty, OWL.NamedIndividual,
                RDFS.Datatype, OWL.Ontology}


@pytest.fixture(scope="module")
def graph():
    g = Graph()
    for f in FILES:
        g.parse(f, format="turtle")
    return g


def test_every_file_is_an_owl_ontology():
    assert len(FILES) >= 5
    for f in FILES:
        g = Graph().parse(f, format="turtle")
        assert len(list(g.subjects(RDF.type, OWL.Ontology))) == 1, f


def test_every_term_of_our_namespaces_is_declared_once_as_one_kind(graph):
    used = {t for triple in graph for t in triple if isinstance(t, URIRef) and str(t).startswith(OURS)}
    for term in used:
        kinds = set(graph.objects(term, RDF.type)) & DECLARATIONS
        individual_types = {c for c in graph.objects(term, RDF.type) if str(c).startswith(OURS)}
        assert kinds or individual_types, "undeclared term %s" % term
        props = kinds & {OWL.ObjectProperty, OWL.DatatypeProperty, OWL.AnnotationProperty}
        assert len(props) <= 1, "%s is declared as %s (OWL 2 DL forbids mixing property kinds)" % (term, props)


def test_vocab_namespaces_mirror_the_turtle(graph):
    for cls in (vocab.PROC, vocab.PPR, vocab.PLB, vocab.SK):
        ns = str(cls)
        in_ttl = {str(t)[len(ns):] for triple in graph for t in triple
                  if isinstance(t, URIRef) and str(t).startswith(ns)}
        in_py = set(cls.__annotations__)
        assert in_ttl == in_py, (ns, sorted(in_ttl - in_py), sorted(in_py - in_ttl))


def test_the_schema_closes_under_owl_rl_without_inconsistency(graph):
    closed = bounded_closure(graph, max_seconds=120)
    assert len(closed) > len(graph)
    # owlrl marks inconsistencies by typing something owl:Nothing
    assert not list(closed.subjects(RDF.type, OWL.Nothing))
    assert SchemaRules(closed, graph).unsupported == []
    # the defined classes the processes query are really there
    assert (vocab.PPR.TapingPending, RDFS.subClassOf, vocab.PPR.WallFeature) not in graph
    assert (vocab.PPR.JointLine, RDFS.subClassOf, vocab.PPR.Product) in closed


def test_the_skill_vocabulary_has_the_part_10_state_machine_and_every_task_type_a_capability(graph):
    SK, PLB, PROC = vocab.SK, vocab.PLB, vocab.PROC
    machine = SK.ProgramStateMachine
    states = set(graph.objects(machine, SK.hasState))
    assert states == {SK.Ready, SK.Running, SK.Suspended, SK.Halted}
    assert set(graph.objects(machine, SK.hasMethod)) == {SK.Start, SK.Suspend, SK.Resume, SK.Halt, SK.Reset}
    moves = {(graph.value(t, SK.fromState), graph.value(t, SK.toState)): graph.value(t, SK.causedBy)
             for t in graph.objects(machine, SK.hasTransition)}
    assert len(moves) == 9
    assert moves[(SK.Ready, SK.Running)] == SK.Start and moves[(SK.Halted, SK.Ready)] == SK.Reset
    assert moves[(SK.Running, SK.Suspended)] == SK.Suspend and moves[(SK.Suspended, SK.Running)] == SK.Resume
    assert {k for k, m in moves.items() if m == SK.Halt} == {(SK.Running, SK.Halted), (SK.Suspended, SK.Halted),
                                                            (SK.Ready, SK.Halted)}
    assert {k for k, m in moves.items() if m is None} == {(SK.Running, SK.Ready), (SK.Suspended, SK.Ready)}
    # each state and transition names its OPC UA node; the CSS terms are aligned by equivalence
    assert all(graph.value(x, SK.opcuaNodeId) for x in states | set(graph.objects(machine, SK.hasTransition)))
    css = "http://www.w3id.org/hsu-aut/css#"
    assert (SK.Capability, OWL.equivalentClass, URIRef(css + "Capability")) in graph
    # properties: sub-properties both ways (owl:equivalentProperty is outside what PEMKRE's reasoner supports)
    assert (SK.isRealizedBySkill, RDFS.subPropertyOf, URIRef(css + "isRealizedBy")) in graph
    assert (URIRef(css + "isRealizedBy"), RDFS.subPropertyOf, SK.isRealizedBySkill) in graph
    # every task type of the use case requires a declared capability
    task_types = [c for c in graph.subjects(RDFS.subClassOf, PROC.TaskExecution) if str(c).startswith(str(PLB))]
    assert len(task_types) >= 9
    for t in task_types:
        cap = graph.value(t, SK.requiresCapability)
        assert cap is not None and (cap, RDF.type, SK.Capability) in graph, t
