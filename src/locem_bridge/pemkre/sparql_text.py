"""SPARQL text for a remote store: RDF terms written as N-Triples terms, values handed to a query as a ``VALUES``
block, and SPARQL 1.1 Query Results JSON read back into rdflib terms.

Values never enter query text as raw strings: :func:`term_text` writes each term in N-Triples form (IRIs checked
for the characters an IRI may not hold, literals escaped, language tags checked), so a value can never end the
term it is in. :func:`values_position` finds where a ``VALUES`` block goes in a prepared query (see there).
"""
import re
from typing import Dict, List, Mapping, Optional, Sequence, Tuple

from rdflib import BNode, Literal, URIRef
from rdflib.namespace import XSD
from rdflib.term import Node

from .errors import InvalidParameterError, StoreError
from .store import cached_uri

_XSD_STRING = str(XSD.string)
_IRI_BAD = re.compile(r'[\x00-\x20<>"{}|^`\\]')
_LANG_RE = re.compile(r"^[A-Za-z]+(-[A-Za-z0-9]+)*$")
_BNODE_RE = re.compile(r"^[A-Za-z0-9_]([A-Za-z0-9_.\-]*[A-Za-z0-9_\-])?$")
#: blank nodes travel to and from the server as IRIs under this prefix (skolemised), so one blank node stays one
#: node across update requests and graphs (a blank node label names a node within one request only)
SKOLEM_PREFIX = "urn:pemkre:bnode:"
_ESCAPES = {"\\": "\\\\", '"': '\\"', "\n": "\\n", "\r": "\\r"}
_ESCAPE_RE = re.compile(r'[\\"\n\r]')


def iri_text(iri: str) -> str:
    """``<iri>``; :class:`~locem_bridge.pemkre.errors.InvalidParameterError` for characters an IRI may not hold."""
    bad = _IRI_BAD.search(iri)
    if bad:
        raise InvalidParameterError("IRI %r holds %r, which an IRI may not contain" % (iri[:200], bad.group(0)))
    return "<%s>" % iri


def term_text(term: Node, blank: bool = True) -> str:
    """An rdflib term as an N-Triples / SPARQL term. A blank node is written as the IRI
    ``<urn:pemkre:bnode:LABEL>`` (skolemised: it keeps its identity across requests and graphs; :func:`json_term`
    and :func:`unskolem` turn it back into the blank node). ``blank`` is kept for callers; it changes nothing."""
    if isinstance(term, URIRef):
        return iri_text(str(term))
    if isinstance(term, Literal):
        lexical = _ESCAPE_RE.sub(lambda m: _ESCAPES[m.group(0)], str(term))
        if term.language:
            if not _LANG_RE.match(term.language):
                raise InvalidParameterError("language tag %r is not well-formed" % term.language)
            return '"%s"@%s' % (lexical, term.language)
        if term.datatype is not None and str(term.datatype) != _XSD_STRING:
            return '"%s"^^%s' % (lexical, iri_text(str(term.datatype)))
        return '"%s"' % lexical
    if isinstance(term, BNode):
        label = str(term)
        if not _BNODE_RE.match(label):
            raise InvalidParameterError("blank node label %r cannot be written to a SPARQL server" % label[:100])
        return iri_text(SKOLEM_PREFIX + label)
    raise InvalidParameterError("not an RDF term: %r" % (term,))


def unskolem(term: Node) -> Node:
    """The blank node a skolem IRI written by :func:`term_text` stands for; any other term unchanged."""
    if isinstance(term, URIRef) and term.startswith(SKOLEM_PREFIX):
        return BNode(term[len(SKOLEM_PREFIX):])
    return term


def values_block(bindings: Mapping[str, Node]) -> str:
    """``VALUES (?a ?b) { (t1 t2) }`` for the given variables (``None`` values are left out)."""
    names = [k for k, v in bindings.items() if v is not None]
    if not names:
        return ""
    return "VALUES (%s) { (%s) }" % (" ".join("?" + n for n in names),
                                     " ".join(term_text(bindings[n]) for n in names))


def values_position(text: str, kind: str) -> Optional[int]:
    """Where a ``VALUES`` block goes in ``text``: right after the ``{`` that opens the query's WHERE group, so the
    values join the whole group and its FILTERs see them (as a substituted value would); ``None`` when the block
    must trail the query instead (``CONSTRUCT WHERE {..}``, ``DESCRIBE`` without a group, or a group that is a
    sub-select).

    A small scanner: comments, strings and IRIs are skipped, braces inside parentheses (``EXISTS {..}`` in a
    projection) do not count. The WHERE group is the first top-level ``{`` (the second for ``CONSTRUCT``, whose
    first is the template).
    """
    groups = _top_level_braces(text, 2)
    want = 1 if kind == "CONSTRUCT" else 0
    if len(groups) <= want:
        return None
    pos = groups[want]
    rest = _skip_blank(text, pos + 1)
    if re.match(r"(?i)SELECT\b", text[rest:rest + 7]):
        return None
    return pos + 1


def _skip_blank(text: str, i: int) -> int:
    n = len(text)
    while i < n:
        if text[i].isspace():
            i += 1
        elif text[i] == "#":
            nl = text.find("\n", i)
            i = n if nl < 0 else nl + 1
        else:
            break
    return i


_IRIREF_RE = re.compile(r'<[^\x00-\x20<>"{}|^`\\]*>')


def _top_level_braces(text: str, limit: int) -> List[int]:
    """Positions of the first ``limit`` ``{`` that open a group at brace and parenthesis depth 0."""
    out: List[int] = []
    i, n = 0, len(text)
    braces = parens = 0
    while i < n and len(out) < limit:
        c = text[i]
        if c == "#":
            nl = text.find("\n", i)
            i = n if nl < 0 else nl + 1
            continue
        if c in "\"'":
            i = _skip_string(text, i)
            continue
        if c == "<":
            m = _IRIREF_RE.match(text, i)
            if m:
                i = m.end()
                continue
        elif c == "(":
            parens += 1
        elif c == ")":
            parens = max(0, parens - 1)
        elif c == "{":
            if braces == 0 and parens == 0:
                out.append(i)
            braces += 1
        elif c == "}":
            braces = max(0, braces - 1)
        i += 1
    return out


def _skip_string(text: str, i: int) -> int:
    q = text[i]
    long = text.startswith(q * 3, i)
    end = q * 3 if long else q
    j = i + len(end)
    n = len(text)
    while j < n:
        if text[j] == "\\":
            j += 2
            continue
        if text.startswith(end, j):
            return j + len(end)
        j += 1
    return n


# ------------------------------------------------------------------------------------------------ results


def json_term(value: object, where: str) -> Node:
    """One RDF term of a SPARQL 1.1 Query Results JSON answer as an rdflib term (``xsd:string`` literals become
    plain literals, as with the embedded stores); :class:`~locem_bridge.pemkre.errors.StoreError` naming
    ``where`` for anything else."""
    if not isinstance(value, dict):
        raise StoreError("%s: a result term is %r, not a JSON object" % (where, value))
    kind, v = value.get("type"), value.get("value")
    if not isinstance(v, str):
        raise StoreError("%s: a result term has no text value: %r" % (where, value))
    if kind == "uri":
        if v.startswith(SKOLEM_PREFIX):
            return BNode(v[len(SKOLEM_PREFIX):])
        return cached_uri(v)
    if kind in ("literal", "typed-literal"):
        lang = value.get("xml:lang")
        if lang:
            return Literal(v, lang=lang)
        dt = value.get("datatype")
        if dt and dt != _XSD_STRING:
            return Literal(v, datatype=URIRef(dt))
        return Literal(v)
    if kind == "bnode":
        return BNode(v)
    raise StoreError("%s: result term type %r is not supported (uri, literal, bnode)" % (where, kind))


def json_rows(doc: object, where: str) -> Tuple[List[str], List[Dict[str, Node]]]:
    """Variables and rows of a SELECT answer in SPARQL 1.1 Query Results JSON."""
    try:
        names = [str(v) for v in doc["head"]["vars"]]  # type: ignore[index]
        bindings: Sequence[Mapping[str, object]] = doc["results"]["bindings"]  # type: ignore[index]
        rows = [{k: json_term(t, where) for k, t in b.items()} for b in bindings]
    except (KeyError, TypeError, AttributeError):
        raise StoreError("%s: the answer is JSON but not a SPARQL SELECT result (no head.vars / "
                         "results.bindings)" % where) from None
    return names, rows
