"""What the operator sees from PEMKRE: processes to offer, KPI tables, progress -- pure functions, no ROS.

- :func:`processes_from_ontologies` reads the abstract processes (``proc:AbstractProcess``) and their labels from
  the Turtle files, so a new use case appears on the page without code (rdflib, imported when called).
- :func:`rows_from_result` turns a PEMKRE query answer into flat rows: the W3C SPARQL 1.1 Query Results JSON
  (what ``QueryResult.to_sparql_json`` produces; typed literals become numbers/booleans), a plain list of row
  objects, or ``{"rows": [...]}``; JSON text or already decoded.
- :func:`taping_progress` summarizes the ``feature_counts`` query (joint lines per taping status).
- :func:`work_progress` summarizes the ``feature_status`` query for the work the running process does: joints
  while taping, areas while spraying or sanding (see :func:`locem_bridge.hmi.hicem_view.WorkFollower`).
- :func:`match_view` turns PEMKRE's skill matching of a process (``/pemkre/match``, ``ProcessMatch.to_dict()``)
  into what the page shows per task: the chosen skill (or template and its steps' skills) and every rejected
  candidate with its reason.
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


def _text(value: Any) -> str:
    return "" if value is None else str(value)


def _chosen(real: Dict[str, Any]) -> Dict[str, Any]:
    if real.get("kind") == "template":
        steps = []
        for st in real.get("steps") or []:
            if not isinstance(st, dict):
                raise ValueError("a template step must be an object, got %s" % type(st).__name__)
            args = " ".join(_text(a) for a in st.get("arguments") or [])
            steps.append({"index": st.get("index"), "name": _text(st.get("name")), "kind": _text(st.get("skill_kind")),
                          "capability": _local(st.get("capability")), "arguments": args,
                          "operator": bool(st.get("involves_operator"))})
        return {"kind": "template", "name": _text(real.get("name")) or _local(real.get("template")),
                "steps": steps, "operator": bool(real.get("involves_operator"))}
    return {"kind": _text(real.get("skill_kind")) or _text(real.get("kind")), "name": _text(real.get("name")),
            "iri": _text(real.get("skill")), "steps": [], "operator": bool(real.get("involves_operator"))}


def match_view(raw: Union[str, bytes, Dict[str, Any]]) -> Dict[str, Any]:
    """``{"process", "robot", "robot_name", "ok", "tasks": [...]}`` from a process match (JSON text or decoded): per task node
    ``node``, ``task`` (its local name), ``action_type``, ``task_type``, ``capability`` (local name; "" = none
    required, the action type's tree runs), ``ok``, ``chosen`` (``{"kind": basic|composite|template, "name",
    "steps": [{"index", "name", "kind", "capability", "arguments"}], "operator"}`` or None), ``rejected``
    (``[{"name", "kind", "reason"}]``) and ``problem``. Raises ``ValueError`` naming what is malformed."""
    if isinstance(raw, (str, bytes)):
        try:
            raw = json.loads(raw)
        except ValueError as err:
            raise ValueError("process match is not JSON: %s" % err)
    if not isinstance(raw, dict) or not isinstance(raw.get("nodes"), list):
        raise ValueError("process match must be an object with a 'nodes' list, got %.80r" % (raw,))
    tasks = []
    for n in raw["nodes"]:
        if not isinstance(n, dict) or not n.get("node"):
            raise ValueError("each matched task node must be an object with 'node', got %.80r" % (n,))
        real = n.get("realization")
        if real is not None and not isinstance(real, dict):
            raise ValueError("task node %s: 'realization' must be an object or null" % n["node"])
        rejected = []
        for r in n.get("rejected") or []:
            if not isinstance(r, dict):
                raise ValueError("task node %s: a rejected candidate must be an object" % n["node"])
            rejected.append({"name": _text(r.get("name")) or _local(r.get("candidate")), "kind": _text(r.get("kind")),
                             "reason": _text(r.get("reason"))})
        capability = _text(n.get("capability"))
        tasks.append({"node": _text(n["node"]), "task": _local(n["node"]), "action_type": _text(n.get("action_type")),
                      "task_type": _local(n.get("task_type")), "capability": _local(capability),
                      "ok": bool(n.get("ok", real is not None or not capability)),
                      "chosen": _chosen(real) if real else None, "rejected": rejected,
                      "problem": _text(n.get("problem"))})
    robot = _text(raw.get("robot"))
    return {"process": _text(raw.get("process")), "robot": robot, "robot_name": _robot_name(robot),
            "ok": bool(raw.get("ok", all(t["ok"] for t in tasks))), "tasks": tasks}


def _robot_name(iri: str) -> str:
    """``diffdrive_ur5e`` for ``.../robot/diffdrive_ur5e/robot`` (the generated model's robot IRI), else the
    local name."""
    parts = iri.rstrip("/").split("/")
    if len(parts) >= 3 and parts[-1] == "robot" and parts[-3] == "robot":
        return parts[-2]
    return _local(iri)
