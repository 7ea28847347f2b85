"""LOCEM side of the HICEM node: the action client behind HICEM's ``LocemClient`` interface, and the health feed.

- :class:`RosLocemClient`: one ``actionlib.ActionClient`` on ``<locem>/command_action``; every ``send`` is a goal
  of its own (several may run at once, e.g. under a Parallel node); ``cancel`` cancels that goal, which LOCEM
  turns into a device stop; the latest feedback's text is the handle's ``feedback()``. A command sent while LOCEM is away (restarting) waits for it, within a deadline; a
  running command whose LOCEM went away ends ``ABORTED`` and is not sent again. The goal's LOCEM command id comes
  with its feedback (the first right after LOCEM accepted it); ``suspend`` / ``resume`` send ``SUSPEND id=N
  cause=WORD`` / ``RESUME ...`` through the ``<locem>/command`` service.
- :class:`LocemHealthFeed`: polls ``STATUS`` through the ``<locem>/command`` service every ``period`` seconds —
  an answer is LOCEM's heartbeat, each backend's ``health`` entry becomes module ``locem/<backend>`` at the level
  :func:`locem_bridge.common.health.grade` gives it — and
  forwards ``diagnostics`` (``diagnostic_msgs/DiagnosticArray``) and ``<locem>/status`` (any message is a sign of life) to the HDH.
"""
import json
import re
import threading
import time
from typing import Any, Optional

import actionlib
import rospy
from diagnostic_msgs.msg import DiagnosticArray

from locem_bridge.common.health import grade, problems
from locem_bridge.hicem.errors import HicemError, LocemCallError
from locem_bridge.hicem.interfaces import LOCEM_LOST, CommandHandle, LocemClient, LocemReply
from locem_bridge.msg import CommandAction, CommandGoal, Status
from locem_bridge.srv import Command

#: how long the action server of a running goal may be gone before the goal counts as lost (s)
LOST_GRACE_S = 0.5
#: how long ``suspend`` / ``resume`` wait for the goal's command id (its first feedback) before giving up (s)
ID_WAIT_S = 1.0
#: how long a ``SUSPEND`` / ``RESUME`` call waits for the ``<locem>/command`` service (s)
METHOD_CALL_WAIT_S = 2.0

_CAUSE_BAD = re.compile(r"[^A-Za-z0-9_.:/#\-]+")


def cause_token(cause: str) -> str:
    """``cause`` as one word of LOCEM's grammar (letters, digits, ``_ . : / # -``): every other run of characters
    becomes ``_``, at most 120 characters; empty stays empty."""
    return _CAUSE_BAD.sub("_", str(cause or "").strip())[:120].strip("_")


class _Goal(CommandHandle):
    """One command: sent at once when LOCEM's action server is there, else held (never sent) and sent as soon as
    it is, within ``wait_s``; not sent by then, it ends ``NOT_READY`` naming the server and the command."""

    def __init__(self, client: "RosLocemClient", command: str, wait_s: float) -> None:
        self._client = client
        self.command = command
        self._lock = threading.Lock()
        self._gh: Any = None
        self._unsent: Optional[LocemReply] = None      # the reply of a command that never left HICEM / was lost
        self._lost_at: Optional[float] = None
        self._feedback: Optional[str] = None            # the latest action feedback's message
        self._id = 0                                    # the goal's LOCEM command id, from its feedback
        self._id_known = threading.Event()
        self._deadline = time.monotonic() + wait_s
        self._wait_s = wait_s
        self._try_send()

    def _try_send(self) -> None:
        """Send if not yet sent and the server is there (caller holds no lock or the lock)."""
        if self._gh is not None or self._unsent is not None:
            return
        if self._client.server_ready():
            self._gh = self._client.send_goal(self.command, self._on_feedback)
            return
        if time.monotonic() >= self._deadline:
            self._unsent = LocemReply(False, "NOT_READY", "LOCEM action server %s not available for %.0f s: %r "
                                      "was not sent" % (self._client.name, self._wait_s, self.command))

    def _on_feedback(self, _gh: Any, feedback: Any) -> None:
        command_id = getattr(feedback, "id", 0)
        if command_id and not self._id_known.is_set():
            self._id = int(command_id)
            self._id_known.set()
        if feedback.message or self._feedback is not None:  # the first (the id only) carries no text
            self._feedback = feedback.message

    @property
    def command_id(self) -> int:
        """The goal's LOCEM command id, 0 until its first feedback arrived."""
        return self._id

    def suspend(self, cause: str = "") -> None:
        self._skill_method("SUSPEND", cause)

    def resume(self, cause: str = "") -> None:
        self._skill_method("RESUME", cause)

    def _skill_method(self, name: str, cause: str) -> None:
        """``NAME id=<id> [cause=<word>]`` through LOCEM's command service; LocemCallError when the goal has no
        command id within ``ID_WAIT_S`` (not sent, not accepted yet) or LOCEM refuses (its code and message)."""
        with self._lock:
            self._try_send()
            unsent = self._unsent
        if unsent is not None:
            raise LocemCallError("%s of %r: the command is not running in LOCEM (%s: %s)"
                                 % (name, self.command, unsent.code, unsent.message), unsent.code)
        if not self._id_known.wait(ID_WAIT_S):
            reply = self.reply()
            if reply is not None:
                raise LocemCallError("%s of %r: the goal ended without a LOCEM command id (%s: %s)"
                                     % (name, self.command, reply.code, reply.message), reply.code)
            raise LocemCallError("%s of %r: LOCEM has not told its command id within %.1f s (no feedback of the goal "
                                 "yet%s)" % (name, self.command, ID_WAIT_S,
                                             "" if self._gh is not None else "; not sent yet, LOCEM away"),
                                 "NOT_READY")
        token = cause_token(cause)
        text = "%s id=%d" % (name, self._id) + (" cause=%s" % token if token else "")
        reply = self._client.call_command(text)
        if not reply.success:
            raise LocemCallError("%s refused by LOCEM (%s): %s" % (text, reply.code, reply.message), reply.code)

    def feedback(self) -> Optional[str]:
        return self._feedback

    def done(self) -> bool:
        with self._lock:
            self._try_send()
            if self._unsent is not None:
                return True
            if self._gh is None:
                return False
            if self._gh.get_comm_state() == actionlib.CommState.DONE:
                return True
            self._check_server()
            return self._unsent is not None

    def _check_server(self) -> None:
        """A sent goal whose server went away (LOCEM died) will never get its result: after ``LOST_GRACE_S`` it
        ends ABORTED. It is not sent again: LOCEM commands are not idempotent."""
        if self._client.server_ready():
            self._lost_at = None
            return
        now = time.monotonic()
        if self._lost_at is None:
            self._lost_at = now
        elif now - self._lost_at >= LOST_GRACE_S:
            self._unsent = LocemReply(False, "ABORTED", "LOCEM action server %s %s %r; not sent again (LOCEM "
                                      "commands are not idempotent)" % (self._client.name, LOCEM_LOST,
                                                                        self.command))

    def reply(self) -> Optional[LocemReply]:
        if not self.done():
            return None
        if self._unsent is not None:
            return self._unsent
        res = self._gh.get_result()
        if res is None:
            return LocemReply(False, "ABORTED", "LOCEM goal ended (status %d) without a result"
                              % self._gh.get_goal_status())
        try:
            result = json.loads(res.result) if res.result else {}
        except ValueError:
            return LocemReply(res.success, res.code, "%s [result is not JSON: %r]" % (res.message, res.result[:80]),
                              None)
        return LocemReply(res.success, res.code, res.message, result if isinstance(result, dict) else None)

    def cancel(self) -> None:
        with self._lock:
            if self._unsent is not None:
                return
            if self._gh is None:
                if self._unsent is None:
                    self._unsent = LocemReply(False, "ABORTED", "cancelled before LOCEM was there to take %r"
                                              % self.command)
                return
            if self._gh.get_comm_state() != actionlib.CommState.DONE:
                self._gh.cancel()


class RosLocemClient(LocemClient):
    """LOCEM commands as actionlib goals. A command is sent again only when it provably never reached LOCEM: while
    the action server is away (LOCEM restarting) it is held and sent when the server is back, within ``wait_s``
    (see :class:`_Goal`). LOCEM commands are not idempotent (a TAPE twice tapes twice), so a goal whose server
    vanished after it was sent is never sent again: that is a failure of the action (HICEM's health monitor
    halts the tree when LOCEM's heartbeat stops; the trees' RECOVER handles the rest)."""

    def __init__(self, locem_ns: str, wait_s: float = 10.0) -> None:
        self.name = locem_ns.rstrip("/") + "/command_action"
        self.wait_s = wait_s
        self._service_name = locem_ns.rstrip("/") + "/command"
        self._service = rospy.ServiceProxy(self._service_name, Command, persistent=False)
        self._client = actionlib.ActionClient(self.name, CommandAction)
        if not self._client.wait_for_server(rospy.Duration(wait_s)):
            rospy.logwarn("hicem: LOCEM action server %s not up yet; commands wait up to %.0f s for it",
                          self.name, wait_s)

    def server_ready(self) -> bool:
        # a timeout of 0 means "forever" to actionlib: 1 ms is one look (plus its 10 ms sleep when not ready)
        return bool(self._client.wait_for_server(rospy.Duration(0, 1000000)))

    def send_goal(self, command: str, feedback_cb: Any = None) -> Any:
        return self._client.send_goal(CommandGoal(command=command), feedback_cb=feedback_cb)

    def send(self, command: str) -> CommandHandle:
        return _Goal(self, command, self.wait_s)

    def call_command(self, command: str) -> LocemReply:
        """One command through ``<locem>/command`` (the service; for the skill methods on a goal's command);
        LocemCallError when the service cannot be reached."""
        try:
            rospy.wait_for_service(self._service_name, timeout=METHOD_CALL_WAIT_S)
            response = self._service(command)
        except (rospy.ServiceException, rospy.ROSException) as error:
            raise LocemCallError("%r: LOCEM service %s not reachable: %s" % (command, self._service_name, error),
                                 "NOT_READY") from error
        return LocemReply(response.success, response.code, response.message)


class LocemHealthFeed:
    def __init__(self, data_handler: Any, locem_ns: str, period_s: float, diagnostics_topic: str) -> None:
        self.hdh = data_handler
        self.locem_ns = locem_ns.rstrip("/")
        self._status = rospy.ServiceProxy(self.locem_ns + "/command", Command, persistent=False)
        self._subs = [rospy.Subscriber(diagnostics_topic, DiagnosticArray, self._on_diagnostics, queue_size=20),
                      rospy.Subscriber(self.locem_ns + "/status", Status, self._on_status, queue_size=50)]
        self._timer = rospy.Timer(rospy.Duration(period_s), self._poll)

    def _poll(self, _event: Any) -> None:
        try:
            resp = self._status("STATUS")
        except (rospy.ServiceException, rospy.ROSException):
            return  # no answer, no heartbeat: the HEM's timeout decides
        if not resp.success:
            return
        self.hdh.heartbeat("locem")
        try:
            health = json.loads(resp.result).get("health", {})
        except ValueError:
            return
        for name, h in sorted(health.items()):
            if not isinstance(h, dict):
                continue
            self._ingest({"module": "locem/%s" % name, "level": grade(h),
                          "message": "%s%s" % (", ".join(problems(h)) or "link up, device ok",
                                               ("; " + str(h["last_error"])) if h.get("last_error") else "")})

    def _on_status(self, _msg: Any) -> None:
        self.hdh.heartbeat("locem")

    def _on_diagnostics(self, msg: Any) -> None:
        entries = []
        for s in msg.status:
            level = s.level if isinstance(s.level, int) else ord(s.level)
            entries.append({"name": s.name, "level": level, "message": s.message})
        try:
            self.hdh.ingest_diagnostics(entries)
        except HicemError as exc:
            rospy.logwarn_throttle(5.0, "hicem: bad /diagnostics entry: %s" % exc)

    def _ingest(self, status: Any) -> None:
        try:
            self.hdh.ingest_status(status)
        except HicemError as exc:
            rospy.logwarn_throttle(5.0, "hicem: bad LOCEM health entry: %s" % exc)

    def shutdown(self) -> None:
        self._timer.shutdown()
        for s in self._subs:
            s.unregister()
