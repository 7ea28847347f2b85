"""The export command: Turtle that rdflib parses, that imports the vocabulary for Protégé and holds every skill."""
import os
import subprocess
import sys

import owlrl
from rdflib import Graph, URIRef
from rdflib.namespace import OWL, RDF

from locem_bridge.common.paths import child_env
from locem_bridge.pemkre.reasoning import SchemaRules
from locem_bridge.pemkre.vocab import PPR, SK

from skills_testkit import ONTOLOGIES, ROBOT, TREES


def test_export_writes_turtle_that_round_trips_the_skill_count(tmp_path, shipped_model):
    out = tmp_path / "model" / "rbkairos.ttl"
    proc = subprocess.run([sys.executable, "-m", "locem_bridge.skills", "export", "--robot", ROBOT, "--trees", TREES,
                           "--out", str(out)], capture_output=True, text=True, env=child_env(), timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "47 skills (37 basic, 10 composite; 47 offered)" in proc.stdout
    g = Graph().parse(str(out), format="turtle")
    skills = set(g.subjects(RDF.type, SK.BasicSkill)) | set(g.subjects(RDF.type, SK.CompositeSkill))
    assert len(skills) == len(shipped_model.skills()) == 47
    robot = URIRef("https://locem-bridge.example.org/robot/rbkairos_ur10e/robot")
    assert set(g.objects(robot, SK.providesSkill)) == skills
    # Protégé: the file is an ontology importing the vocabulary, and the catalog beside it maps those IRIs to files
    onto = URIRef("https://locem-bridge.example.org/robot/rbkairos_ur10e")
    assert (onto, RDF.type, OWL.Ontology) in g
    assert {str(i) for i in g.objects(onto, OWL.imports)} == {"https://locem-bridge.example.org/ont/skill",
                                                              "https://locem-bridge.example.org/ont/ppr",
                                                              "https://locem-bridge.example.org/ont/plasterboard"}
    catalog = (tmp_path / "model" / "catalog-v001.xml").read_text()
    assert 'name="https://locem-bridge.example.org/ont/skill"' in catalog and "skill.ttl" in catalog
    # the model with the vocabulary closes under OWL 2 RL without inconsistency, in constructs PEMKRE supports
    full = Graph()
    for name in ("skill.ttl", "ppr.ttl", "process.ttl", "plasterboard.ttl"):
        full.parse(os.path.join(ONTOLOGIES, name), format="turtle")
    full += g
    asserted = Graph()
    asserted += full
    owlrl.DeductiveClosure(owlrl.OWLRL_Semantics).expand(full)
    assert not list(full.subjects(RDF.type, OWL.Nothing))
    assert SchemaRules(full, asserted).unsupported == []
    # reasoning brings the CSS view: skills are css:Skill, the robot css:providesSkill them
    css = "http://www.w3id.org/hsu-aut/css#"
    assert (shipped_model.iri("skill_GOTO"), RDF.type, URIRef(css + "Skill")) in full
    assert (robot, URIRef(css + "providesSkill"), shipped_model.iri("skill_tree_TAPE_LINE")) in full
    assert (shipped_model.iri("spray_gun"), RDF.type, PPR.Tool) in full
    # no blank nodes: the model can go into a store's world graph like a world seed
    assert not [t for t in g for n in t if not isinstance(n, URIRef) and n.__class__.__name__ == "BNode"]
