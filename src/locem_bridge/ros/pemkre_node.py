"""The PEMKRE ROS node: the process engine (ROS-free core) exposed as services.

=====================  ==============================  =====================================
service                name (node name ``pemkre``)     type
=====================  ==============================  =====================================
start a process        ``~start_process``              ``locem_bridge/PemkreStartProcess``
next action            ``~next_action``                ``locem_bridge/PemkreNextAction``
report a task status   ``~set_task_status``            ``locem_bridge/PemkreSetTaskStatus``
predefined query       ``~query``                      ``locem_bridge/PemkreQuery``
world update (SCAN)    ``~update_world``               ``locem_bridge/PemkreUpdateWorld``
skill matching         ``~match``                      ``locem_bridge/PemkreMatchProcess``
=====================  ==============================  =====================================

Lifecycle: ``main()`` inits the node, then :meth:`PemkreNode.start` opens the store and loads the ontologies
(connecting late: nothing is advertised before the engine is ready, so ``wait_for_service`` is the readiness
signal) and advertises the services; ``shutdown`` closes the store. Every reply carries ``success``, ``code``
(``OK`` or the PEMKRE error code) and ``message``; a refused call changes nothing. ``NOT_READY``: the store cannot
be reached now (a SPARQL server away; the message names the endpoint and the reason): the same call, made again
later with the same request id, is answered. At start the node waits for a store it cannot reach (one line per
attempt naming the endpoint); a store that answers wrongly is a configuration error (one line, see ros/startup.py).

Parameters: ``~store_path`` (directory of the persistent store; default ``$ROS_HOME/pemkre_store``),
``~store`` (``journal`` default, ``rocksdb``, ``memory``, ``sparql``: a SPARQL 1.1 server at ``~query_url`` and
``~update_url``, read from an exact copy in the node unless ``~sparql_copy`` is false; ``~sparql_timeout``: seconds per
request, default 10), ``~fsync`` (journal: flush
each change to disk),
``~ontology_dir`` (default: the package's ``ontologies/``), ``~extra_ontology_dirs`` (an integrator's folders of
Turtle loaded beside it, separated by ``:`` or ``,``), ``~trees_dir`` and ``~extra_trees_dirs`` (the tree folders
HICEM runs, for the robot's resource model), ``~robot`` (the robot YAML: its resource model -- generated from it,
the LOCEM registry and the tree folders -- is loaded into the store and every process is matched to the robot's
skills; empty = no matching), ``~site`` (the site YAML whose name the store must hold: a store holding another
site's data, or a PEMKRE's without a site, is refused in one configuration line before anything is read or
written; an empty store is claimed; empty = not checked),
``~site_namespace``, ``~log_namespace``,
``~reasoning_max_seconds``, ``~fresh`` (delete the store first: tests and demos only).
"""
import gc
import json
import os
import threading
from typing import Any, Callable, Optional

import rospkg
import rospy

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.common.folders import folder_files, split_folders
from locem_bridge.pemkre import ProcessEngine
from locem_bridge.pemkre.engine import load_json
from locem_bridge.pemkre.errors import PemkreError, StoreError
from locem_bridge.pemkre.robot_model import match_robot
from locem_bridge.pemkre.store_factory import claim_site_or_close, open_store, open_store_waiting
from locem_bridge.pemkre.terms import bindings_from_strings
from locem_bridge.ros.params import package_share, param
from locem_bridge.srv import (PemkreMatchProcess, PemkreMatchProcessResponse, PemkreNextAction,
                              PemkreNextActionResponse, PemkreQuery, PemkreQueryResponse,
                              PemkreSetTaskStatus, PemkreSetTaskStatusResponse, PemkreStartProcess,
                              PemkreStartProcessResponse, PemkreUpdateWorld, PemkreUpdateWorldResponse)
from locem_bridge.ros.startup import config_guard
from locem_bridge.sim.config import load_site



def _seconds(name: str, default: float) -> float:
    """The private parameter ``name`` as a number of seconds above 0 (``param`` refuses what is not a number);
    ValueError naming it otherwise."""
    value = param(name, default)
    if not float(value) > 0:
        raise ValueError("~%s must be a number of seconds above 0, got %r" % (name, value))
    return float(value)

def _guard(response_cls: Callable[[], Any], body: Callable[[Any, Any], None]) -> Callable[[Any], Any]:
    """Run ``body(request, response)``; turn PEMKRE errors into ``success=False`` with their code."""
    def handler(req: Any) -> Any:
        resp = response_cls()
        try:
            body(req, resp)
            resp.success, resp.code = True, "OK"
        except PemkreError as exc:
            resp.success, resp.code, resp.message = False, exc.code, str(exc)
            if exc.code == "NOT_READY":      # the store is away (a SPARQL server): the caller asks again
                rospy.logwarn_throttle(5.0, "PEMKRE not ready: %s" % exc)
        except Exception as exc:  # a bug must not kill the node; it is reported to the caller
            rospy.logerr("PEMKRE internal error: %r", exc)
            resp.success, resp.code, resp.message = False, "INTERNAL_ERROR", "%s: %s" % (type(exc).__name__, exc)
        return resp
    return handler


class PemkreNode:
    """Adapter around a :class:`ProcessEngine` built by ``engine_factory`` (called in :meth:`start`)."""

    def __init__(self, engine_factory: Callable[[], ProcessEngine]) -> None:
        self._factory = engine_factory
        self.engine: Optional[ProcessEngine] = None
        self._services: list = []
        self._lock = threading.Lock()

    def start(self) -> None:
        self.engine = self._factory()
        self._services = [
            rospy.Service("~start_process", PemkreStartProcess, _guard(PemkreStartProcessResponse, self._start)),
            rospy.Service("~next_action", PemkreNextAction, _guard(PemkreNextActionResponse, self._next)),
            rospy.Service("~set_task_status", PemkreSetTaskStatus,
                          _guard(PemkreSetTaskStatusResponse, self._status)),
            rospy.Service("~query", PemkreQuery, _guard(PemkreQueryResponse, self._query)),
            rospy.Service("~update_world", PemkreUpdateWorld, _guard(PemkreUpdateWorldResponse, self._world)),
            rospy.Service("~match", PemkreMatchProcess, _guard(PemkreMatchProcessResponse, self._match)),
        ]

    # ---------------------------------------------------------------- handlers
    def _start(self, req: Any, resp: Any) -> None:
        from locem_bridge.pemkre.errors import InvalidParameterError

        options = {}
        if req.options.strip():
            try:
                options = load_json(req.options, "options")
            except InvalidParameterError:
                raise
            except ValueError as exc:
                raise InvalidParameterError("options must be a JSON object: %s" % exc) from None
            if not isinstance(options, dict):
                raise InvalidParameterError("options must be a JSON object, got %s" % type(options).__name__)
        assert self.engine is not None
        resp.specific_process = self.engine.start_process(req.process, options, abort_running=req.abort_running,
                                                          request_id=req.request_id)
        resp.message = "started %s" % resp.specific_process

    def _next(self, req: Any, resp: Any) -> None:
        assert self.engine is not None
        a = self.engine.next_action(req.process or None)
        resp.status, resp.process, resp.task = a.status, a.process, a.task
        resp.action_type, resp.parameters, resp.task_status, resp.message = \
            a.action_type, a.parameters, a.task_status, a.message
        resp.skill, resp.skill_kind = a.skill, a.skill_kind

    def _status(self, req: Any, resp: Any) -> None:
        assert self.engine is not None
        r = self.engine.set_task_status(req.task, req.status, req.detail, request_id=req.request_id)
        if r.repeated:
            resp.message = "%s is %s: already applied (request id %s), nothing changed" % (
                r.task, r.status, req.request_id)
            return
        resp.message = "%s is %s (%d effect(s) applied, %d world triple(s) changed)" % (
            r.task, r.status, r.effects_applied, r.world_triples_changed)

    def _query(self, req: Any, resp: Any) -> None:
        assert self.engine is not None
        bindings = bindings_from_strings(req.binding_names, req.binding_values)
        result = self.engine.query(req.name, bindings)
        resp.results = json.dumps(result.to_sparql_json())
        resp.message = "%d row(s)" % len(result.rows) if result.kind != "ASK" else str(result.boolean).lower()

    def _world(self, req: Any, resp: Any) -> None:
        assert self.engine is not None
        resp.changed = self.engine.update_world(req.scan)
        resp.message = "%d world triple(s) changed" % resp.changed

    def _match(self, req: Any, resp: Any) -> None:
        assert self.engine is not None
        m = self.engine.match_process(req.process)
        resp.match = json.dumps(m.to_dict())
        nodes = list(m.nodes)
        problems = m.problems()
        resp.message = ("%d task node(s), all matched" % len(nodes) if not problems else
                        "%d of %d task node(s) not matched: %s" % (len(problems), len(nodes), "; ".join(problems)))

    def shutdown(self) -> None:
        for s in self._services:
            s.shutdown()
        if self.engine is not None:
            self.engine.store.close()


@config_guard("pemkre")
def main() -> None:
    """Entry point of ``rosrun locem_bridge pemkre_node``."""
    rospy.init_node("pemkre")
    path = param("store_path", os.path.join(rospkg.get_ros_home(), "pemkre_store"))
    kind = param("store", "journal")
    # the package's Turtle plus an integrator's folders (a clash of ontology IRIs is refused naming both files)
    onto_dirs = [param("ontology_dir", os.path.join(package_share(), "ontologies"))] + \
        split_folders(param("extra_ontology_dirs", ""))
    files = folder_files(onto_dirs, ".ttl", "ontology folder")
    onto_dir = os.pathsep.join(onto_dirs)
    # the tree folders HICEM runs (the package's plus the extra ones): the resource model's composite skills are
    # generated from the same ones (build_resource_model(robot, tree_dirs, ontology_files=files): an
    # integrator's tree realizes a capability of an integrator's Turtle)
    tree_dirs = [param("trees_dir", os.path.join(package_share(), "trees"))] + \
        split_folders(param("extra_trees_dirs", ""))
    folder_files(tree_dirs, ".xml", "trees folder")
    robot_file = param("robot", "")
    site_file = param("site", "")
    # the site this store must hold (its name, from the same site YAML the launch gives the world and scanner)
    site = load_site(site_file)["site"]["name"] if site_file else None
    query_url = param("query_url", "")
    where = query_url if kind == "sparql" else (path if kind != "memory" else "the memory store")

    def factory() -> ProcessEngine:
        store = open_store_waiting(lambda: open_store(kind, path, param("fsync", False), param("fresh", False),
                                                      query_url=query_url,
                                                      update_url=param("update_url", ""),
                                                      mirror=param("sparql_copy", True),
                                                      **({"timeout_s": _seconds("sparql_timeout", 10.0)}
                                                         if kind == "sparql" else {})),
                                   kind, log=rospy.logwarn, stop=rospy.is_shutdown)
        if site is not None and claim_site_or_close(store, site, where, site_file):
            rospy.loginfo("PEMKRE: %s now holds site %r", where, site)
        try:
            engine = ProcessEngine(store, files,
                                   site_namespace=param("site_namespace", "") or None,
                                   log_namespace=param("log_namespace", "") or None,
                                   reasoning_max_seconds=param("reasoning_max_seconds", 5.0))
        except ConfigError as exc:          # a process-model error names no file: name the folder it came from
            store.close()
            raise exc.in_file(onto_dir)
        except Exception:
            store.close()
            raise
        try:
            match_robot(engine, robot_file, tree_dirs, files)
        except Exception:
            store.close()
            raise
        return engine

    node = PemkreNode(factory)
    try:
        node.start()
    except StoreError:
        if rospy.is_shutdown():          # stopped while it waited for its store: nothing to report
            return
        raise
    rospy.on_shutdown(node.shutdown)
    # The ontologies, compiled model and caches live as long as the node: move them out of the cyclic garbage
    # collector's reach so a full collection does not pause a decision (measured in bench/bench_pemkre.py).
    gc.collect()
    gc.freeze()
    assert node.engine is not None
    rospy.loginfo("PEMKRE ready on %s (store %s at %s): processes %s; running: %s; %s", rospy.resolve_name("~next_action"),
                  kind, path, ", ".join(node.engine.processes()), node.engine.active_process() or "none",
                  "tasks matched to the skills of %s" % robot_file if node.engine.matching else "no matching")
    rospy.spin()


if __name__ == "__main__":
    main()
