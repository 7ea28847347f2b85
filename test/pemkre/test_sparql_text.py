"""SPARQL text for the remote store, without a server: terms written so that no value can end the term it is in,
and the VALUES block placed in the WHERE group (or after the query where a group cannot take it), giving text that
still parses."""
import pytest
from rdflib import BNode, Literal, URIRef
from rdflib.namespace import XSD
from rdflib.plugins.sparql import prepareQuery

from locem_bridge.pemkre.errors import InvalidParameterError, StoreError
from locem_bridge.pemkre.sparql_text import json_rows, json_term, term_text, values_block, values_position


def test_terms_are_written_as_n_triples_and_cannot_break_out():
    assert term_text(URIRef("https://ex.example/a#b")) == "<https://ex.example/a#b>"
    assert term_text(Literal('x" } ; DROP ALL ; {\n\\')) == '"x\\" } ; DROP ALL ; {\\n\\\\"'
    assert term_text(Literal("chat", lang="fr")) == '"chat"@fr'
    assert term_text(Literal(3)) == '"3"^^<http://www.w3.org/2001/XMLSchema#integer>'
    assert term_text(Literal("s", datatype=XSD.string)) == '"s"'
    with pytest.raises(InvalidParameterError, match="may not contain"):
        term_text(URIRef("https://ex.example/a> } ; DROP ALL ; <x"))
    assert term_text(BNode("b1")) == term_text(BNode("b1"), blank=True) == "<urn:pemkre:bnode:b1>"
    with pytest.raises(InvalidParameterError, match="blank node"):
        term_text(BNode("b 1"))
    assert json_rows({"head": {"vars": ["a"]}, "results": {"bindings": [
        {"a": {"type": "uri", "value": "urn:pemkre:bnode:b1"}}]}}, "here")[1] == [{"a": BNode("b1")}]


@pytest.mark.parametrize("text, kind, before", [
    ("SELECT ?s WHERE { ?s ?p ?o }", "SELECT", "SELECT ?s WHERE {"),
    ("PREFIX ex: <https://ex.example/a#>\nASK { ?s ex:p '}' }", "ASK", "PREFIX ex: <https://ex.example/a#>\nASK {"),
    ("# a { comment\nSELECT (EXISTS { ?a ?b ?c } AS ?e) ?s WHERE { ?s ?p \"{\" }", "SELECT",
     "# a { comment\nSELECT (EXISTS { ?a ?b ?c } AS ?e) ?s WHERE {"),
    ("SELECT ?s WHERE { ?s ?p ?o FILTER(?o < 3 && ?o > 1) }", "SELECT", "SELECT ?s WHERE {"),
    ("CONSTRUCT { ?s ?p ?o } WHERE { ?s ?p ?o }", "CONSTRUCT", "CONSTRUCT { ?s ?p ?o } WHERE {"),
    ("CONSTRUCT WHERE { ?s ?p ?o }", "CONSTRUCT", None),
    ("SELECT ?s WHERE { SELECT ?s WHERE { ?s ?p ?o } }", "SELECT", None),
    ("DESCRIBE ?s", "DESCRIBE", None),
])
def test_the_values_block_goes_into_the_where_group_or_after_the_query(text, kind, before):
    pos = values_position(text, kind)
    assert (text[:pos] if pos is not None else None) == before
    block = values_block({"s": URIRef("https://ex.example/s"), "unused": None})
    assert block == "VALUES (?s) { (<https://ex.example/s>) }"
    full = "%s\n%s" % (text, block) if pos is None else "%s %s %s" % (text[:pos], block, text[pos:])
    prepareQuery(full)  # still SPARQL


def test_results_json_becomes_rdflib_terms_and_anything_else_is_named():
    doc = {"head": {"vars": ["a", "b"]}, "results": {"bindings": [
        {"a": {"type": "uri", "value": "https://ex.example/a"},
         "b": {"type": "literal", "value": "1", "datatype": str(XSD.integer)}},
        {"a": {"type": "bnode", "value": "x1"}, "b": {"type": "literal", "value": "s", "datatype": str(XSD.string)}},
        {"b": {"type": "typed-literal", "value": "hi", "xml:lang": "en"}}]}}
    names, rows = json_rows(doc, "here")
    assert names == ["a", "b"]
    assert rows == [{"a": URIRef("https://ex.example/a"), "b": Literal(1)}, {"a": BNode("x1"), "b": Literal("s")},
                    {"b": Literal("hi", lang="en")}]
    with pytest.raises(StoreError, match="here: the answer is JSON but not a SPARQL SELECT result"):
        json_rows({"boolean": True}, "here")
    with pytest.raises(StoreError, match="result term type 'triple' is not supported"):
        json_term({"type": "triple", "value": "x"}, "here")
