"""PEMKRE: the semantic layer (ROS-free). Ontologies in a triplestore, process engine, execution log, KPIs.

Typical use::

    from locem_bridge.pemkre import JournaledStore, ProcessEngine, PLB
    store = JournaledStore("/var/lib/locem_bridge/pemkre")     # persistent, survives kill -9
    engine = ProcessEngine(store)                               # loads ontologies/*.ttl
    engine.start_process(str(PLB.TapingProcess), {"validateLines": True})
    action = engine.next_action()       # action.action_type, action.task, action.parameters (N-Triples)
    engine.set_task_status(action.task, "succeeded", "valid")
"""
from .engine import NextAction, ProcessEngine, TaskStatusReport
from .errors import PemkreError
from .kpi import compute_kpis, export_kpis
from .journal_store import JournaledStore
from .oxigraph_store import OxigraphStore
from .rdflib_store import RdflibStore
from .sparql_store import SparqlStore
from .store import QueryResult, TripleStore
from .vocab import PLB, PPR, PROC, SK

__all__ = ["NextAction", "ProcessEngine", "TaskStatusReport", "PemkreError", "compute_kpis", "export_kpis",
           "JournaledStore", "OxigraphStore", "RdflibStore", "SparqlStore", "QueryResult", "TripleStore", "PLB", "PPR", "PROC", "SK"]
