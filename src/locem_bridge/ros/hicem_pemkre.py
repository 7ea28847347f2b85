"""PEMKRE side of the HICEM node: HICEM's ``PemkreClient`` over the ``/pemkre/*`` ROS services.

The service types belong to PEMKRE; this client finds each service's type from the master at first use and
fills requests by field name, so it needs only these fields (a missing one is a clear error):

- ``<pemkre>/start_process``: request ``process`` (+ ``options``, JSON text, if present) → ``process`` or
  ``specific_process``; ``<pemkre>/next_action``: → ``status``, ``action_type``, ``task``, ``parameters``,
  ``message``; ``<pemkre>/set_task_status``: ``task``, ``status``, ``detail``;
  ``<pemkre>/update_world``: ``scan`` (SCAN result JSON text).
A response with ``success`` false (or a service error) raises :class:`PemkreError` with PEMKRE's message.
"""
import json
from typing import Any, Dict, Optional

import rospy
import rosservice

from locem_bridge.hicem.errors import PemkreError
from locem_bridge.hicem.interfaces import PemkreClient


class RosPemkreClient(PemkreClient):
    def __init__(self, pemkre_ns: str, wait_s: float = 30.0) -> None:
        self.ns = pemkre_ns.rstrip("/")
        self.wait_s = wait_s
        self._proxies: Dict[str, Any] = {}

    def _proxy(self, name: str) -> Any:
        if name not in self._proxies:
            full = "%s/%s" % (self.ns, name)
            try:
                rospy.wait_for_service(full, timeout=self.wait_s)
                cls = rosservice.get_service_class_by_name(full)
            except (rospy.ROSException, rosservice.ROSServiceException) as exc:
                raise PemkreError("PEMKRE service %s is not available: %s" % (full, exc))
            self._proxies[name] = rospy.ServiceProxy(full, cls)
        return self._proxies[name]

    def _call(self, name: str, **fields: Any) -> Any:
        proxy = self._proxy(name)
        req = proxy.request_class()
        slots = list(getattr(req, "__slots__", []))
        for k, v in fields.items():
            if k not in slots:
                if v in ("", None):
                    continue
                raise PemkreError("PEMKRE service %s/%s has no request field '%s' (fields: %s)" % (
                    self.ns, name, k, ", ".join(slots)))
            setattr(req, k, v)
        try:
            resp = proxy(req)
        except (rospy.ServiceException, rospy.ROSException) as exc:
            raise PemkreError("PEMKRE %s failed: %s" % (name, exc))
        if hasattr(resp, "success") and not resp.success:
            raise PemkreError("PEMKRE %s refused: %s" % (name, getattr(resp, "message", "")))
        return resp

    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        # HICEM is PEMKRE's only executor: a process it starts replaces one left running by a stop before its
        # first task (PEMKRE marks that one failed), instead of being refused
        resp = self._call("start_process", process=process_iri, options=json.dumps(options) if options else "",
                          abort_running=True)
        for f in ("specific_process", "process"):
            if hasattr(resp, f):
                return str(getattr(resp, f))
        return ""

    def next_action(self) -> Dict[str, Any]:
        r = self._call("next_action")
        return {"status": r.status, "action_type": getattr(r, "action_type", ""), "task": getattr(r, "task", ""),
                "parameters": getattr(r, "parameters", ""), "detail": getattr(r, "message", "")}

    def set_task_status(self, task: str, status: str, detail: str = "") -> None:
        self._call("set_task_status", task=task, status=status, detail=detail)

    def report_world(self, update: Dict[str, Any]) -> None:
        self._call("update_world", scan=json.dumps(update))
