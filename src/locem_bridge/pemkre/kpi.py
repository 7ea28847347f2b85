"""KPIs computed from the execution log (the specific processes) by the SPARQL queries stored in process.ttl.

:func:`compute_kpis` runs ``kpi_by_process`` and ``kpi_by_task_type`` and returns plain JSON-ready dicts: per
process and per task (action) type -- count, succeeded, failed, success rate, duration, operator interventions,
manual fallbacks. :func:`export_kpis` writes them to a JSON file for the run report. Read-only.
"""
import json
import os
from typing import Any, Dict, List, Optional

from rdflib import Literal, URIRef

from .terms import check_iri, local_name


def _py(term: Any) -> Any:
    if term is None:
        return None
    if isinstance(term, URIRef):
        return str(term)
    if isinstance(term, Literal):
        v = term.toPython()
        if hasattr(v, "isoformat"):
            return v.isoformat()
        try:
            from decimal import Decimal
            if isinstance(v, Decimal):
                return float(v)
        except ImportError:  # pragma: no cover
            pass
        return v
    return str(term)


def compute_kpis(engine: Any, process: Optional[str] = None) -> Dict[str, List[Dict[str, Any]]]:
    """``{"processes": [...], "task_types": [...]}`` for one specific process IRI or (default) all of them."""
    bindings = {"process": check_iri(process, "process IRI")} if process else None
    procs = engine.query("kpi_by_process", bindings)
    types = engine.query("kpi_by_task_type", bindings)
    out_p = []
    for row in procs.rows:
        d = {k: _py(v) for k, v in row.items()}
        d["name"] = local_name(d.get("abstractProcess", ""))
        out_p.append(d)
    out_t = [{k: _py(v) for k, v in row.items()} for row in types.rows]
    return {"processes": out_p, "task_types": out_t}


def export_kpis(engine: Any, path: str, process: Optional[str] = None) -> Dict[str, List[Dict[str, Any]]]:
    """Compute the KPIs and write them as JSON to ``path`` (directories created); returns what was written."""
    data = compute_kpis(engine, process)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    tmp = path + ".tmp"
    with open(tmp, "w") as fh:
        json.dump(data, fh, indent=2, sort_keys=True)
    os.replace(tmp, path)
    return data
