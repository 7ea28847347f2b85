"""What the operator sees from PEMKRE: processes to offer, KPI tables, progress -- pure functions, no ROS.

- :func:`processes_from_ontologies` reads the abstract processes (``proc:AbstractProcess``) and their labels from
  the Turtle files, so a new use case appears on the page without code (rdflib, imported when called).
- :func:`rows_from_result` turns a PEMKRE query answer into flat rows: the W3C SPARQL 1.1 Query Results JSON
  (what ``QueryResult.to_sparql_json`` produces; typed literals become numbers/booleans), a plain list of row
  objects, or ``{"rows": [...]}``; JSON text or already decoded.
- :func:`taping_progress` summarizes the ``feature_counts`` query (joint lines per taping status).
- :func:`work_progress` summarizes the ``feature_status`` query for the work the running process does: joints
  while taping, areas while spraying or sanding (see :func:`locem_bridge.hmi.hicem_view.WorkFollower`).
"""
import json
from typing import Any, Dict, Iterable, List, Optional, Union

PROC = "https://locem-bridge.example.org/ont/process#"
PPR = "https://locem-bridge.example.org/ont/ppr#"
XSD = "http://www.w3.org/2001/XMLSchema#"
_INTS = {XSD + t for t in ("integer", "int", "long", "short", "byte", "nonNegativeInteger", "positiveInteger",
                           "unsignedInt", "unsignedLong", "negativeInteger", "nonPositiveInteger")}
_FLOATS = {XSD + t for t in ("decimal", "double", "float")}
DONE_TAPING_STATES = ("processed", "processedManually")
KPI_QUERIES = (("processes", "kpi_by_process"), ("task_types", "kpi_by_task_type"))
# work -> (status property's local name, what is counted, what done means)
WORK_STATUS = {"taping": ("tapingStatus", "joints", "taped or done by hand"),
               "spraying": ("sprayingStatus", "areas", "sprayed"),
               "sanding": ("sandingStatus", "areas", "sanded")}


def _value(binding: Dict[str, Any]) -> Any:
    value = binding.get("value")
    dtype = binding.get("datatype", "")
    try:
        if dtype in _INTS:
            return int(value)
        if dtype in _FLOATS:
            return float(value)
    except (TypeError, ValueError):
        return value
    if dtype == XSD + "boolean":
        return str(value).lower() in ("true", "1")
    return value


def rows_from_result(result: Union[str, bytes, Dict[str, Any], List[Any], None]) -> List[Dict[str, Any]]:
    """Flat rows from a query answer (see the module docstring); raises ``ValueError`` naming the shape found."""
    if result is None or result == "" or result == b"":
        return []
    if isinstance(result, (str, bytes)):
        try:
            result = json.loads(result)
        except ValueError as err:
            raise ValueError("query answer is not JSON: %s" % err)
    if isinstance(result, list):
        if not all(isinstance(r, dict) for r in result):
            raise ValueError("query answer list must hold row objects")
        return [dict(r) for r in result]
    if isinstance(result, dict):
        if isinstance(result.get("results"), dict) and isinstance(result["results"].get("bindings"), list):
            return [{k: _value(v) if isinstance(v, dict) else v for k, v in b.items()}
                    for b in result["results"]["bindings"]]
        if isinstance(result.get("rows"), list):
            return rows_from_result(result["rows"])
        if "boolean" in result:
            return [{"boolean": bool(result["boolean"])}]
    raise ValueError("query answer has an unknown shape (expected SPARQL results JSON, a list of rows or "
                     "{\"rows\": [...]}): %.80r" % (result,))


def taping_progress(rows: Iterable[Dict[str, Any]]) -> Optional[Dict[str, Any]]:
    """``{"done", "total", "text"}`` from ``feature_counts`` rows (``state`` IRI, ``lines`` count); None if no
    joint lines are known yet."""
    total = done = 0
    for row in rows:
        try:
            n = int(row.get("lines", 0))
        except (TypeError, ValueError):
            continue
        total += n
        state = str(row.get("state", ""))
        if state.rsplit("#", 1)[-1].rsplit("/", 1)[-1] in DONE_TAPING_STATES:
            done += n
    if total == 0:
        return None
    return {"done": done, "total": total, "text": "joints taped or done by hand: %d of %d" % (done, total)}


def _local(iri: Any) -> str:
    return str(iri or "").rsplit("#", 1)[-1].rsplit("/", 1)[-1]


def work_progress(rows: Iterable[Dict[str, Any]], work: str) -> Optional[Dict[str, Any]]:
    """``{"done", "total", "text"}`` of ``work`` (a key of :data:`WORK_STATUS`) from ``feature_status`` rows
    (``feature``, ``property``, ``state``); None if no feature of that work is known yet."""
    prop, unit, done_means = WORK_STATUS[work]
    states: Dict[str, str] = {}
    for row in rows:
        if _local(row.get("property")) == prop:
            states[str(row.get("feature", ""))] = _local(row.get("state"))
    if not states:
        return None
    done = sum(1 for st in states.values() if st in DONE_TAPING_STATES)
    return {"done": done, "total": len(states), "text": "%s %s: %d of %d" % (unit, done_means, done, len(states))}


def processes_from_ontologies(paths: Iterable[str]) -> List[Dict[str, str]]:
    """Every ``proc:AbstractProcess`` in the Turtle files ``paths``: ``{"iri", "name", "description"}`` sorted by
    name (name = local name, description = English or plain ``rdfs:label``). Raises ``ValueError`` naming a
    file that cannot be parsed."""
    from rdflib import RDF, RDFS, Graph, URIRef

    graph = Graph()
    for path in paths:
        try:
            graph.parse(path, format="turtle")
        except Exception as err:  # rdflib raises several parser exception types
            raise ValueError("cannot read ontology %s: %s" % (path, err))
    out = []
    for proc in set(graph.subjects(RDF.type, URIRef(PROC + "AbstractProcess"))):
        iri = str(proc)
        labels = {getattr(lbl, "language", None): str(lbl) for lbl in graph.objects(proc, RDFS.label)}
        name = iri.rsplit("#", 1)[-1].rsplit("/", 1)[-1]
        out.append({"iri": iri, "name": name, "description": labels.get("en") or labels.get(None) or ""})
    return sorted(out, key=lambda p: (p["name"], p["iri"]))
