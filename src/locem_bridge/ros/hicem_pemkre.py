"""PEMKRE side of the HICEM node: HICEM's ``PemkreClient`` over the ``/pemkre/*`` ROS services.

The service types belong to PEMKRE; this client finds each service's type from the master at first use and
fills requests by field name, so it needs only these fields (a missing one is a clear error):

- ``<pemkre>/start_process``: request ``process`` (+ ``options``, JSON text, if present) → ``process`` or
  ``specific_process``; ``<pemkre>/next_action``: → ``status``, ``action_type``, ``task``, ``parameters``,
  ``message`` (+ ``skill``, ``skill_kind`` if present); ``<pemkre>/set_task_status``: ``task``, ``status``,
  ``detail``; ``<pemkre>/update_world``: ``scan`` (SCAN result JSON text).
A response with ``success`` false raises :class:`PemkreCallError` with PEMKRE's message at once.

Calls outlive a PEMKRE restart (respawned in about 2 s) and a store that is away: while the service is away --
not registered, its registration left by a killed node (connection refused), or the connection dropped mid-call
-- or PEMKRE answers ``NOT_READY`` (its SPARQL server cannot be reached; the reply names the endpoint and the
reason) the call is sent
again with backoff (``backoff_s`` doubling up to ``max_backoff_s``) until ``deadline_s`` after its start, then
:class:`PemkreUnavailableError` names the peer, the call and the last reason (HICEM's controller then waits
for PEMKRE and calls again, see :mod:`locem_bridge.hicem.controller`). A call is sent again after it may have
reached PEMKRE only when it is idempotent: ``next_action`` (PEMKRE answers the same task until it is reported)
and ``update_world`` (a merge) are; a status report and a process start are made so by a request id
(``request_id``, docs/contracts.md): the same id for every attempt of one call (for a start, also when the
controller makes it again after this client gave up), so PEMKRE applies it once even when it applied it and died
before answering. A status report's id is derived from the task and the status (a
task takes each status once), so a report HICEM repeats after its own restart is applied once too.
"""
import json
import os
import time
from typing import Any, Callable, Dict, Optional

import rospy
import rosservice

from locem_bridge.common.next_action import NextAction
from locem_bridge.hicem.errors import PemkreCallError
from locem_bridge.hicem.interfaces import PemkreClient, PemkreUnavailableError, status_request_id

#: PEMKRE's reply code while its store cannot be reached (pemkre.errors.StoreUnavailable): the call is made again
NOT_READY = "NOT_READY"
#: rospy's ServiceException texts for a request that provably never left this node (no service to send it to)
_NOT_SENT = ("unavailable", "unable to connect to service", "unable to contact master")
#: ... and for one that may have reached the service (connection lost after sending)
_CUT = ("returned no response", "transport error completing service call")


class _Away(Exception):
    """PEMKRE's service is not there (``sent``: the request may have reached it)."""

    def __init__(self, reason: str, sent: bool) -> None:
        super().__init__(reason)
        self.sent = sent


class RosPemkreClient(PemkreClient):
    def __init__(self, pemkre_ns: str, wait_s: float = 30.0, deadline_s: float = 10.0, backoff_s: float = 0.1,
                 max_backoff_s: float = 2.0, log: Optional[Callable[[str], None]] = None) -> None:
        self.ns = pemkre_ns.rstrip("/")
        self.wait_s = wait_s            # the first look-up of a service (PEMKRE starting with the launch)
        self.deadline_s = deadline_s    # every call: how long PEMKRE may be away before the call fails
        self.backoff_s = backoff_s
        self.max_backoff_s = max_backoff_s
        self._log = log or (lambda text: rospy.logwarn("hicem: %s", text))
        self._proxies: Dict[str, Any] = {}
        self._unanswered_start: Optional[tuple] = None     # ((process, options), request id) not yet answered
        #: calls that needed more than one attempt: (call, attempts, seconds), newest last (tests read it)
        self.retried: list = []

    def _proxy(self, name: str, timeout: float) -> Any:
        if name not in self._proxies:
            full = "%s/%s" % (self.ns, name)
            try:
                rospy.wait_for_service(full, timeout=max(0.05, timeout))
                cls = rosservice.get_service_class_by_name(full)
            except (rospy.ROSException, rosservice.ROSServiceException) as exc:
                raise _Away("service %s is not available: %s" % (full, exc), sent=False) from None
            self._proxies[name] = rospy.ServiceProxy(full, cls)
        return self._proxies[name]

    def _request(self, name: str, proxy: Any, fields: Dict[str, Any]) -> Any:
        req = proxy.request_class()
        slots = list(getattr(req, "__slots__", []))
        for k, v in fields.items():
            if k not in slots:
                if v in ("", None) or k == "request_id":
                    continue      # an older PEMKRE without request ids: sent without it
                raise PemkreCallError("PEMKRE service %s/%s has no request field '%s' (fields: %s)" % (
                    self.ns, name, k, ", ".join(slots)))
            setattr(req, k, v)
        return req

    def _once(self, name: str, fields: Dict[str, Any], remaining: float) -> Any:
        proxy = self._proxy(name, min(remaining, self.wait_s))
        req = self._request(name, proxy, fields)
        try:
            return proxy(req)
        except rospy.ServiceException as exc:
            text = str(exc)
            if any(s in text for s in _NOT_SENT):
                raise _Away(text, sent=False) from None
            if any(s in text for s in _CUT):
                raise _Away(text, sent=True) from None
            raise PemkreCallError("PEMKRE %s failed: %s" % (name, exc)) from None
        except rospy.exceptions.TransportException as exc:     # the socket died while sending
            raise _Away("connection lost while sending: %s" % exc, sent=True) from None

    def _call(self, name: str, idempotent: bool, what: str = "", **fields: Any) -> Any:
        """One call, sent again while PEMKRE is away (see the module doc); PemkreCallError when it cannot be done."""
        t0 = time.monotonic()
        delay, attempts = self.backoff_s, 0
        while True:
            attempts += 1
            remaining = self.deadline_s - (time.monotonic() - t0)
            try:
                resp = self._once(name, fields, remaining)
                if getattr(resp, "code", "") == NOT_READY and not getattr(resp, "success", True):
                    # PEMKRE is there but its store is not (a SPARQL server away): like PEMKRE away; nothing
                    # was applied, or a write whose answer was lost is applied once by the request id
                    raise _Away("PEMKRE answered NOT_READY: %s" % getattr(resp, "message", ""), sent=False)
                break
            except _Away as away:
                label = "%s%s" % (name, (" (%s)" % what) if what else "")
                if away.sent and not idempotent:
                    raise PemkreCallError("PEMKRE %s: the connection to %s was lost during the call (%s); not sent "
                                      "again (not idempotent)" % (label, self.ns, away)) from None
                if rospy.is_shutdown():
                    raise PemkreUnavailableError("PEMKRE %s: node shutting down while %s was away (%s)"
                                      % (label, self.ns, away)) from None
                waited = time.monotonic() - t0
                if waited + delay > self.deadline_s:
                    raise PemkreUnavailableError("PEMKRE %s failed: %s did not answer within %.0f s (%d attempt(s)); last "
                                      "reason: %s" % (label, self.ns, self.deadline_s, attempts, away)) from None
                if attempts == 1:
                    self._log("PEMKRE %s: %s is away (%s); retrying for up to %.0f s"
                              % (label, self.ns, away, self.deadline_s))
                self._proxies.pop(name, None)    # a respawned PEMKRE: look the service up afresh
                time.sleep(delay)
                delay = min(self.max_backoff_s, delay * 2)
        if attempts > 1:
            took = time.monotonic() - t0
            self.retried.append((name, attempts, took))
            self._log("PEMKRE %s answered after %d attempts over %.1f s" % (name, attempts, took))
        if hasattr(resp, "success") and not resp.success:
            raise PemkreCallError("PEMKRE %s refused: %s" % (name, getattr(resp, "message", "")))
        return resp

    def start_process(self, process_iri: str, options: Optional[Dict[str, Any]] = None) -> str:
        # HICEM is PEMKRE's only executor: a process it starts replaces one left running by a stop before its
        # first task (PEMKRE marks that one failed), instead of being refused. The request id makes a start
        # that PEMKRE applied before dying answer that process when sent again (no second process).
        # A start that failed with PEMKRE away and is made again (HICEM's controller repeats it) keeps its id.
        text = json.dumps(options) if options else ""
        if self._unanswered_start is None or self._unanswered_start[0] != (process_iri, text):
            self._unanswered_start = ((process_iri, text), "hicem-start-%s" % os.urandom(9).hex())
        resp = self._call("start_process", True, process_iri, process=process_iri, options=text,
                          abort_running=True, request_id=self._unanswered_start[1])
        self._unanswered_start = None
        for f in ("specific_process", "process"):
            if hasattr(resp, f):
                return str(getattr(resp, f))
        return ""

    def next_action(self) -> NextAction:
        r = self._call("next_action", True)
        return NextAction(r.status, getattr(r, "process", ""), task=getattr(r, "task", ""), action_type=getattr(r, "action_type", ""),
                          parameters=getattr(r, "parameters", ""), task_status=getattr(r, "task_status", ""),
                          message=getattr(r, "message", ""), skill=getattr(r, "skill", ""),
                          skill_kind=getattr(r, "skill_kind", ""))

    def set_task_status(self, task: str, status: str, detail: str = "") -> None:
        self._call("set_task_status", True, "%s %s" % (status, task), task=task, status=status, detail=detail,
                   request_id=status_request_id(task, status))

    def report_world(self, update: Dict[str, Any]) -> None:
        self._call("update_world", True, scan=json.dumps(update))
