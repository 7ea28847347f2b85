"""The LOCEM ROS node: the core dispatcher exposed as service, action, procedure, subscriber and publisher.

All names are private to the node (``~command`` ...), so with the default node name ``locem`` they are
``/locem/command`` etc., and a robot namespace (``ROS_NAMESPACE=robot1``) moves them all together.

=====================  ==========================================  ====================================
interface              name                                        type
=====================  ==========================================  ====================================
service                ``~command``                                ``locem_bridge/Command``
action                 ``~command_action``                         ``locem_bridge/CommandAction``
subscriber             ``~command_in``                             ``locem_bridge/CommandString``
publisher              ``~status``                                 ``locem_bridge/Status``
skill state publisher  ``~skill_state`` (every transition)         ``locem_bridge/SkillTransition``
procedure services     ``~procedure/{add,query_state,cancel,       ``locem_bridge/ProcedureAdd``,
                       pause,resume,suspend,halt,reset}``          ``locem_bridge/ProcedureControl``
procedure publisher    ``~procedure/state`` (on change, latched)   ``locem_bridge/ProcedureState``
=====================  ==========================================  ====================================

Skill methods (OPC UA Part 10 on each command, :mod:`locem_bridge.common.program_state`): the system commands
``SUSPEND|RESUME|HALT|RESET id=N cause=WORD`` on any interface, and ``~procedure/{suspend,resume,halt,reset}`` on a
procedure's command (``pause`` is ``suspend``; ``halt`` answers once the command has ended; ``reset`` acts on a
finished one). Every transition of a command's skill state is published on ``~skill_state`` (stamped with the
transition's time; not latched). An action goal's feedback carries its command's ``id`` (the goal's first feedback
is sent as soon as the goal is accepted), which a client needs to call those methods on its goal.

Accounting of ``~command_in``: the subscriber keeps no bounded queue of its own (rospy's ``queue_size``
discards all but the newest N messages of a burst without a word), so every message read is handed to the
dispatcher in rospy's receive thread, and a sender faster than LOCEM is slowed by TCP instead of losing
commands. Each one is answered on ``~status``: ``running`` then a final state, or ``rejected`` with its code
(``BUSY`` past ``~max_running``). ``~status`` queues up to ``~status_queue_size`` events per subscriber.
"""

import json
import threading
from typing import Any, Callable, Dict, Optional

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus

from locem_bridge.bridges.errors import BadRequest
from locem_bridge.bridges.tool_memory import read_tool_file, write_tool_file
from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.dispatcher import DEFAULT_MAX_RUNNING
from locem_bridge.locem.errors import LocemError
from locem_bridge.locem.execution import CommandEvent, ExecState, Execution
from locem_bridge.locem.procedures import ProcedureSnapshot
from locem_bridge.locem.registry import Interface
from locem_bridge.locem.response import Response, encode_result
from locem_bridge.msg import (
    CommandString,
    CommandAction,
    CommandFeedback,
    CommandResult,
    ProcedureState,
    SkillTransition,
    Status,
)
from locem_bridge.srv import (
    Command,
    CommandResponse,
    ProcedureAdd,
    ProcedureAddResponse,
    ProcedureControl,
    ProcedureControlResponse,
)
from locem_bridge.ros.params import as_list, param
from locem_bridge.ros.startup import config_guard


_CODE_TEXT = {code: code.value for code in Code}  # Enum.value is a slow property; the service path is hot

STATUS_QUEUE_SIZE = 10000
"""Default ``~status_queue_size``: events queued per ``~status`` subscriber before rospy drops the oldest."""


class LocemNode:
    """Wraps a :class:`LocemCore`; ``start()`` advertises every interface (call after ``rospy.init_node``)."""

    def __init__(self, core: LocemCore, status_queue_size: int = STATUS_QUEUE_SIZE) -> None:
        self.core = core
        self._status_queue_size = int(status_queue_size)
        self._goals: Dict[str, Execution] = {}
        self._goals_lock = threading.Lock()

    def start(self) -> None:
        dispatcher = self.core.dispatcher
        self._status_pub = rospy.Publisher("~status", Status, queue_size=self._status_queue_size)
        self._procedure_pub = rospy.Publisher("~procedure/state", ProcedureState, queue_size=100, latch=True)
        self._skill_pub = rospy.Publisher("~skill_state", SkillTransition, queue_size=self._status_queue_size)
        dispatcher.add_listener(self._publish_status)
        dispatcher.add_listener(self._publish_skill_state)
        self.core.procedures.add_listener(self._publish_procedure)
        procedures = self.core.procedures
        self._services = [
            rospy.Service("~command", Command, self._on_command),
            rospy.Service("~procedure/add", ProcedureAdd, self._on_procedure_add),
            rospy.Service("~procedure/query_state", ProcedureControl, self._procedure_op(procedures.query_state)),
            rospy.Service("~procedure/cancel", ProcedureControl, self._procedure_op(procedures.cancel)),
            rospy.Service("~procedure/pause", ProcedureControl, self._procedure_op(procedures.pause)),
            rospy.Service("~procedure/resume", ProcedureControl,
                          self._procedure_op(lambda i: procedures.resume(i, "procedure/resume service"))),
            rospy.Service("~procedure/suspend", ProcedureControl,
                          self._procedure_op(lambda i: procedures.suspend(i, "procedure/suspend service"))),
            rospy.Service("~procedure/halt", ProcedureControl,
                          self._procedure_op(lambda i: procedures.halt(i, "procedure/halt service"))),
            rospy.Service("~procedure/reset", ProcedureControl,
                          self._procedure_op(lambda i: procedures.reset(i, "procedure/reset service"))),
        ]
        # queue_size=None: rospy discards nothing; the callback is quick, so TCP paces a sender (see module doc)
        self._subscriber = rospy.Subscriber("~command_in", CommandString, self._on_command_in, queue_size=None)
        self._action = actionlib.ActionServer("~command_action", CommandAction, self._on_goal, self._on_cancel,
                                              auto_start=False)
        self._action.start()

    def shutdown(self) -> None:
        for service in self._services:
            service.shutdown("LOCEM node shutting down")
        self._subscriber.unregister()
        self.core.close()

    # -- service ------------------------------------------------------------------------------------------
    def _on_command(self, request: Any) -> CommandResponse:
        response = self.core.dispatcher.execute(request.command, Interface.SERVICE)
        code = response.code  # (success and result_json spelled out: two calls fewer on the hot path)
        return CommandResponse(code is Code.OK, _CODE_TEXT[code], response.message, encode_result(response.result))

    # -- subscriber ---------------------------------------------------------------------------------------
    def _on_command_in(self, message: Any) -> None:
        try:
            self.core.dispatcher.submit(message.command, Interface.SUBSCRIBER)
        except LocemError:
            pass  # the rejection is published on ~status by the dispatcher

    # -- publisher ----------------------------------------------------------------------------------------
    def _publish_status(self, event: CommandEvent) -> None:
        message = Status()
        message.header.stamp = rospy.Time.from_sec(event.stamp)
        message.id = event.id
        message.command = event.command
        message.name = event.name
        message.interface = event.interface
        message.state = event.state.value
        message.code = event.code
        message.message = event.message
        message.result = json.dumps(event.result, sort_keys=True, default=str)
        message.progress = event.progress
        self._status_pub.publish(message)

    def _publish_skill_state(self, event: CommandEvent) -> None:
        transition = event.transition
        if transition is None:
            return
        message = SkillTransition()
        message.header.stamp = rospy.Time.from_sec(transition.stamp)
        message.instance = transition.instance
        message.skill = transition.skill
        message.number = transition.number
        message.transition = transition.name
        message.from_state = transition.source.value
        message.to_state = transition.target.value
        message.method = transition.method
        message.cause = transition.cause
        self._skill_pub.publish(message)

    # -- action -------------------------------------------------------------------------------------------
    def _on_goal(self, goal_handle: Any) -> None:
        goal_id = goal_handle.get_goal_id().id
        lock = threading.Lock()        # the first feedback (the id) goes out before any progress feedback
        accepted = [False]

        def feedback(event: CommandEvent) -> None:
            if event.state.terminal:
                return
            with lock:
                if accepted[0]:
                    goal_handle.publish_feedback(CommandFeedback(event.state.value, event.progress, event.message,
                                                                 event.id))

        try:
            execution = self.core.dispatcher.submit(goal_handle.get_goal().command, Interface.ACTION,
                                                    listener=feedback)
        except LocemError as error:
            goal_handle.set_rejected(_action_result(Response.from_error(error)), error.message)
            return
        with self._goals_lock:
            self._goals[goal_id] = execution
        goal_handle.set_accepted("running as command %d" % execution.id)
        with lock:  # the goal's command id, at once: what a client needs for SUSPEND / RESUME id=N
            state = execution.state
            goal_handle.publish_feedback(CommandFeedback(ExecState.RUNNING.value if state.terminal else state.value,
                                                         0.0, "", execution.id))
            accepted[0] = True
        threading.Thread(target=self._finish_goal, args=(goal_handle, goal_id, execution),
                         name="locem-goal-%d" % execution.id, daemon=True).start()

    def _finish_goal(self, goal_handle: Any, goal_id: str, execution: Execution) -> None:
        response = execution.wait()
        with self._goals_lock:
            self._goals.pop(goal_id, None)
        result = _action_result(response)
        status = goal_handle.get_goal_status().status
        if response.success:
            goal_handle.set_succeeded(result, response.message)
        elif response.code is Code.ABORTED and status in (GoalStatus.PREEMPTING, GoalStatus.RECALLING):
            goal_handle.set_canceled(result, response.message)
        else:
            goal_handle.set_aborted(result, response.message)

    def _on_cancel(self, goal_handle: Any) -> None:
        with self._goals_lock:
            execution = self._goals.get(goal_handle.get_goal_id().id)
        if execution is not None:
            execution.cancel("action goal canceled by its client")

    # -- procedures ---------------------------------------------------------------------------------------
    def _on_procedure_add(self, request: Any) -> ProcedureAddResponse:
        try:
            snapshot = self.core.procedures.add(request.command)
        except LocemError as error:
            return ProcedureAddResponse(False, error.code.value, error.message, 0, "")
        return ProcedureAddResponse(True, Code.OK.value, "queued as procedure %d" % snapshot.id, snapshot.id,
                                    snapshot.state.value)

    def _procedure_op(self, operation: Callable[[int], ProcedureSnapshot]) -> Callable[[Any], Any]:
        def serve(request: Any) -> ProcedureControlResponse:
            try:
                snapshot = operation(request.id)
            except LocemError as error:
                return ProcedureControlResponse(False, error.code.value, error.message, "", "", "{}", 0.0)
            return ProcedureControlResponse(True, Code.OK.value, snapshot.message or snapshot.state.value,
                                            snapshot.state.value, snapshot.code,
                                            json.dumps(snapshot.result, sort_keys=True, default=str),
                                            snapshot.progress)
        return serve

    def _publish_procedure(self, snapshot: ProcedureSnapshot) -> None:
        message = ProcedureState()
        message.header.stamp = rospy.Time.now()
        message.id = snapshot.id
        message.command = snapshot.command
        message.state = snapshot.state.value
        message.code = snapshot.code
        message.message = snapshot.message
        message.result = json.dumps(snapshot.result, sort_keys=True, default=str)
        message.progress = snapshot.progress
        self._procedure_pub.publish(message)


def _action_result(response: Optional[Response]) -> CommandResult:
    assert response is not None
    return CommandResult(response.success, response.code.value, response.message, response.result_json)


def _keep_tool(wall: Any) -> None:
    """The mounted tool outlives a LOCEM restart: kept in the private parameter ``~active_tool`` (the master
    outlives a respawned node) and, given ``~tool_file``, in that file too (it outlives the master: a power loss),
    and restored from the parameter, else the file, at start."""
    last, source = param("active_tool", ""), "~active_tool"
    path = param("tool_file", "")
    if not last and path:
        last, source = read_tool_file(path), path
    if last:
        try:
            wall.restore_tool(last)
            rospy.logwarn("LOCEM restarted with the %s mounted (from %s)", last, source)
        except BadRequest as exc:       # a robot file changed since: start with no tool, MOUNT_TOOL tells it again
            rospy.logwarn("LOCEM restarted without a tool: %s names %s, not a tool of this robot (%s)", source, last,
                          exc)

    def keep(tool: str) -> None:
        rospy.set_param("~active_tool", tool)
        if path:
            try:
                write_tool_file(path, tool)
            except OSError as exc:
                rospy.logwarn("LOCEM could not keep the mounted tool in %s: %s", path, exc)
    wall.tool_listener = keep


@config_guard("locem")
def main() -> None:
    """Entry point of ``rosrun locem_bridge locem_node``.

    Without ``~robot_config`` LOCEM serves the system commands only. With it, the bridges named in the robot YAML
    are built (lazily imported through :mod:`locem_bridge.bridges.backends`), installed into the core, and their
    state is published by :mod:`.locem_devices`. Parameters: ``~robot_config`` (path), ``~robot_overrides``
    (dict deep-merged into the ``robot`` section, e.g. another address), ``~devices`` (comma list, default
    ``arm,compressor,base,lift,scanner,tool_changer``; a device the robot file lacks is skipped), ``~site_config``
    (site YAML for the simulated scanner), ``~initial_pose``
    ([x, y, theta] in map; default: the site's ``robot_start``, else the origin), ``~named_poses`` ({name: [x, y, theta]} for GOTO_TAG).
    Always: ``~grace``, ``~stop_timeout`` (s), ``~max_running`` (commands running at once, default 64; one more is
    answered BUSY), ``~status_queue_size`` (``~status`` events queued per subscriber, default 10000).
    """
    rospy.init_node("locem")
    core = LocemCore(grace=param("grace", 1.0), stop_timeout=param("stop_timeout", 2.0),
                     max_running=param("max_running", DEFAULT_MAX_RUNNING))
    robot = devices = None
    robot_config = param("robot_config", "")
    if robot_config:
        from locem_bridge.bridges.config import load_robot_config
        from locem_bridge.bridges.robot import build_robot
        from locem_bridge.ros.locem_devices import LocemDevices

        robot_cfg = load_robot_config(robot_config, param("robot_overrides", {}))
        site_config = param("site_config", "") or None
        pose = param("initial_pose", None) or None
        if pose is None and site_config:           # odometry starts where the site says the robot stands
            from locem_bridge.sim.config import load_site
            pose = load_site(site_config)["site"]["robot_start"]
        robot = build_robot(robot_cfg,
                            devices=as_list(param("devices", "arm,compressor,base,lift,scanner,tool_changer")),
                            site=site_config,
                            initial_pose=tuple(float(v) for v in pose) if pose else None,
                            named_base_poses=param("named_poses", {}))
        for command_set in robot.command_sets:
            core.install(command_set)
            if hasattr(command_set, "restore_tool"):
                _keep_tool(command_set)
        robot.start()
        devices = LocemDevices(robot, core.dispatcher.health,
                               localisation_topic=param("localisation_topic", ""))
    node = LocemNode(core, status_queue_size=param("status_queue_size", STATUS_QUEUE_SIZE))
    node.start()
    if devices is not None:
        devices.start()

    def shutdown() -> None:
        if devices is not None:
            devices.shutdown()
        node.shutdown()
        if robot is not None:
            robot.close()
    rospy.on_shutdown(shutdown)
    served = [s.name for s in core.registry.specs() if core.registry.handler(s.name)]
    rospy.loginfo("LOCEM ready on %s: %d commands (%s)", rospy.resolve_name("~command"), len(served),
                  ", ".join(served))
    rospy.spin()


if __name__ == "__main__":
    main()
