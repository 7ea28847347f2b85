"""Checking and converting the strings that cross the PEMKRE API: IRIs, N-Triples terms and documents.

Terms from outside (bindings) are parsed by a real RDF parser (pyoxigraph); nothing here builds query text. The
next action's parameter document is written by the one codec in :mod:`locem_bridge.common.next_action`, which
also gives :func:`local_name`.
"""
import math
import re
from typing import Dict, Iterable, Mapping, Optional, Tuple

import pyoxigraph as ox
from rdflib import Literal, URIRef
from rdflib.namespace import XSD
from rdflib.term import Node

from ..common.next_action import encode_parameters, iri_term, literal_term, local_name  # noqa: F401 (re-export)
from .errors import InvalidParameterError, MalformedIriError
from .oxigraph_store import from_ox

_SCHEME_RE = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")
_NT_S = "<urn:locem-bridge:s>"
_NT_P = "<urn:locem-bridge:p>"
FEATURE_ID_RE = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def check_iri(value: object, what: str = "IRI") -> URIRef:
    """Return ``value`` as a URIRef if it is an absolute IRI, else raise :class:`MalformedIriError`."""
    if isinstance(value, URIRef):
        value = str(value)
    if not isinstance(value, str) or not value:
        raise MalformedIriError("%s must be a non-empty string holding an absolute IRI, got %r" % (what, value))
    if value.startswith("<") and value.endswith(">"):
        value = value[1:-1]
    if not _SCHEME_RE.match(value):
        raise MalformedIriError("%s %r is not an absolute IRI (it needs a scheme such as https:)" % (what, value[:200]))
    try:
        ox.NamedNode(value)
    except ValueError as exc:
        raise MalformedIriError("%s %r is not a valid IRI: %s (spaces, quotes, <>{}|\\^` are not allowed)"
                                % (what, value[:200], exc)) from None
    return URIRef(value)


def parse_term(text: str, what: str = "term") -> Node:
    """Parse one N-Triples term (``<iri>``, ``"lit"``, ``"lit"@en``, ``"1"^^<dt>``); raise on anything else."""
    if not isinstance(text, str) or not text.strip():
        raise InvalidParameterError("%s must be an N-Triples term such as <https://...> or \"text\", got %r"
                                    % (what, text))
    doc = "%s %s %s .\n" % (_NT_S, _NT_P, text.strip())
    try:
        triples = list(ox.parse(doc.encode("utf-8"), format=ox.RdfFormat.N_TRIPLES))
    except (SyntaxError, ValueError) as exc:
        raise InvalidParameterError("%s %r is not a valid N-Triples term (<iri>, \"literal\", \"v\"^^<datatype>, "
                                    "\"v\"@lang): %s" % (what, text[:200], exc)) from None
    if len(triples) != 1:
        raise InvalidParameterError("%s %r must be exactly one N-Triples term" % (what, text[:200]))
    obj = triples[0].object
    if isinstance(obj, ox.BlankNode):
        raise InvalidParameterError("%s %r: blank nodes are not allowed" % (what, text[:200]))
    return from_ox(obj)


def to_term(value: object, what: str = "value") -> Node:
    """Python value -> RDF term: URIRef/Literal as given, bool/int/float typed, str as a plain literal."""
    if isinstance(value, (URIRef, Literal)):
        if isinstance(value, URIRef):
            return check_iri(value, what)
        return value
    if isinstance(value, bool):
        return Literal(value)
    if isinstance(value, int):
        return Literal(value)
    if isinstance(value, float):
        if math.isnan(value) or math.isinf(value):
            raise InvalidParameterError("%s must be a finite number, got %r" % (what, value))
        return Literal(value, datatype=XSD.double)
    if isinstance(value, str):
        return Literal(value)
    raise InvalidParameterError("%s has unsupported type %s (allowed: IRI, literal, str, int, float, bool)"
                                % (what, type(value).__name__))


def nt_term(term: Node, what: str = "parameter value") -> str:
    """An IRI or literal as N-Triples text, written by the one parameter codec
    (:mod:`locem_bridge.common.next_action`)."""
    if isinstance(term, URIRef):
        return iri_term(str(term))
    if isinstance(term, Literal):
        return literal_term(str(term), str(term.datatype) if term.datatype is not None else None, term.language)
    raise InvalidParameterError("%s must be an IRI or a literal, got %r" % (what, term))


def parameter_document(task: URIRef, parameters: Iterable[Tuple[Node, Node, Node]]) -> str:
    """The N-Triples parameter document of a next action (docs/contracts.md), one line per ``(task, p, o)``."""
    return encode_parameters(str(task), [(str(p), nt_term(o)) for _, p, o in parameters])


def bindings_from_strings(names: Iterable[str], values: Iterable[str]) -> Mapping[str, Node]:
    """Pair variable names with N-Triples term strings (the ROS service form of query bindings)."""
    names, values = list(names), list(values)
    if len(names) != len(values):
        raise InvalidParameterError("bindings need as many values as names (%d names, %d values)"
                                    % (len(names), len(values)))
    out: Dict[str, Node] = {}
    for n, v in zip(names, values):
        out[n] = parse_term(v, "binding %r" % n)
    return out


def optional_iri(value: Optional[str], what: str) -> Optional[URIRef]:
    if value is None or value == "":
        return None
    return check_iri(value, what)
