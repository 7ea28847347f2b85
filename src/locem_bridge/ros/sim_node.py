"""ROS node ``sim_worksite``: the simulated worksite (PyBullet world + RTDE, Modbus and CAN stand-ins).

The stand-ins speak their device protocols on the addresses of the robot YAML, exactly as the real devices
would; this node adds what only a simulator has, as ``locem_bridge/JsonCall`` services under ``~`` (``/sim/``
with the default node name):

==================  =====================================================  ======================================
service             args (JSON object)                                     result
==================  =====================================================  ======================================
``~scan``           ``{}``                                                 SCAN result (docs/contracts.md)
``~mount_tool``     ``{"name": "spray_gun"}`` (the operator mounts it)     ``{"tool": name}``
``~remove_tool``    ``{}``                                                 ``{"tool": removed name or null}``
``~manual_taping``  ``{"joint": "wall_1_joint_2"}`` (taped by hand)        ``{}``
``~inject_fault``   ``{"kind": ..., ...}`` (see Worksite.inject_fault)     ``{}``
``~clear_fault``    ``{"kind": ..., ...}``                                 ``{}``
``~outcome``        ``{}``, or ``{"manual": plan}`` (see below)            outcome numbers (+ collisions)
``~save_outcome``   ``{"folder": "/abs/path"}``, optional ``"manual"``     numbers + picture file names
``~compressor``     ``{}``                                                 the compressor as the device knows
                                                                           it: state, watchdog, valve / motor
                                                                           history (Worksite.compressor_state)
``~tool_changer``   ``{}``                                                 the tool changer as the device knows
                                                                           it: lock, coupled tool, rack slots,
                                                                           history (a robot file with a
                                                                           ``tool_changer``; else an error)
==================  =====================================================  ======================================

``manual`` (optional): the parts HICEM planned for the hand, ``{"areas": [{"work": "spray"|"sand", "area": id,
"along": [a, b], "height": [c, d]}], "joints": [{"joint": id, "along": [a, b]}]}`` (along: m from the area's
origin or the joint's start; height: m above the floor): the numbers add the figures on the parts the robot was
to work and the work done deep inside the manual parts (``reachable``, ``manual_touched``, see
:meth:`locem_bridge.sim.outcome.OutcomeRecorder.summary`), the pictures draw the manual parts. A plan that does not
fit the site is refused, naming what is wrong.

Topic ``~localisation`` (``geometry_msgs/PoseWithCovarianceStamped``, map frame, 5 Hz): the localisation a real
robot gets from AMCL or similar, here the true pose with ``~localisation_noise`` (default 0.002 m / rad) of
Gaussian noise; LOCEM takes it as its odometry pose while the base stands still (``localisation_topic``).
Topic ``~ground_truth/base_pose`` (``geometry_msgs/Pose2D``, map frame, 20 Hz): the simulator's true base pose,
for tests and for the HMI; nothing in the control path reads it.

``~state_dir`` (default empty: nothing kept): a folder keeping the world's state across a crash of this node
(outcome maps, base pose, arm joints, mounted tool; :mod:`locem_bridge.sim.world_state`); the node starts from what
it holds, so the walls keep what was done to them as real walls do through a power loss.
"""

import json
import math
import random
import sys
from typing import Any, Callable, Dict

import rospy
from geometry_msgs.msg import Pose2D

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.robot_file import default_robot_path
from locem_bridge.ros.params import package_share, param
from locem_bridge.sim.config import default_site_path, load_robot, load_site
from locem_bridge.sim.errors import SimError
from locem_bridge.sim.worksite import Worksite
from locem_bridge.srv import JsonCall, JsonCallResponse
from locem_bridge.ros.startup import config_guard


class SimNode:
    def __init__(self, worksite: Worksite) -> None:
        self.worksite = worksite
        self._services = []

    def start(self) -> None:
        site = self.worksite
        operations: Dict[str, Callable[[Dict[str, Any]], Dict[str, Any]]] = {
            "scan": lambda a: site.scan(),
            "mount_tool": lambda a: (site.mount_tool(_need(a, "name")), {"tool": a["name"]})[1],
            "remove_tool": lambda a: {"tool": site.remove_tool()},
            "manual_taping": lambda a: (site.mark_manual_taping(_need(a, "joint")), {})[1],
            "inject_fault": lambda a: (site.inject_fault(_need(a, "kind"), **_rest(a, "kind")), {})[1],
            "clear_fault": lambda a: (site.clear_fault(_need(a, "kind"), **_rest(a, "kind")), {})[1],
            "outcome": lambda a: site.outcome(a.get("manual")),
            "save_outcome": lambda a: site.save_outcome(_need(a, "folder"), a.get("manual")),
            "compressor": lambda a: site.compressor_state(),
            "tool_changer": lambda a: site.tool_changer_state(),
        }
        for name, operation in operations.items():
            self._services.append(rospy.Service("~" + name, JsonCall, _serve(name, operation)))
        self._pose_pub = rospy.Publisher("~ground_truth/base_pose", Pose2D, queue_size=1)
        self._timer = rospy.Timer(rospy.Duration(0.05), self._publish_pose)
        from geometry_msgs.msg import PoseWithCovarianceStamped
        self._loc_msg = PoseWithCovarianceStamped
        self._loc_pub = rospy.Publisher("~localisation", PoseWithCovarianceStamped, queue_size=1)
        self._loc_noise = param("localisation_noise", 0.002)
        self._loc_rng = random.Random(1)
        self._loc_timer = rospy.Timer(rospy.Duration(0.2), self._publish_localisation)

    def _publish_pose(self, _event: Any) -> None:
        world = self.worksite.world
        if world is None:
            return
        x, y, yaw = world.base_pose()
        self._pose_pub.publish(Pose2D(x, y, yaw))

    def _publish_localisation(self, _event: Any) -> None:
        """A localisation stand-in (what AMCL gives on the robot): the true pose with Gaussian noise of
        ``~localisation_noise`` (m in x and y, rad in yaw), 5 Hz, map frame."""
        world = self.worksite.world
        if world is None:
            return
        x, y, yaw = world.base_pose()
        s = self._loc_noise
        yaw += self._loc_rng.gauss(0.0, s) if s > 0 else 0.0
        msg = self._loc_msg()
        msg.header.stamp = rospy.Time.now()
        msg.header.frame_id = "map"
        msg.pose.pose.position.x = x + (self._loc_rng.gauss(0.0, s) if s > 0 else 0.0)
        msg.pose.pose.position.y = y + (self._loc_rng.gauss(0.0, s) if s > 0 else 0.0)
        msg.pose.pose.orientation.z = math.sin(yaw / 2.0)
        msg.pose.pose.orientation.w = math.cos(yaw / 2.0)
        msg.pose.covariance[0] = msg.pose.covariance[7] = s * s
        msg.pose.covariance[35] = s * s
        self._loc_pub.publish(msg)

    def shutdown(self) -> None:
        self._timer.shutdown()
        self._loc_timer.shutdown()
        for service in self._services:
            service.shutdown("sim_worksite shutting down")
        self.worksite.stop()


def _need(args: Dict[str, Any], key: str) -> Any:
    if key not in args:
        raise ValueError("missing argument '%s'" % key)
    return args[key]


def _rest(args: Dict[str, Any], *skip: str) -> Dict[str, Any]:
    return {k: v for k, v in args.items() if k not in skip}


def _serve(name: str, operation: Callable[[Dict[str, Any]], Dict[str, Any]]) -> Callable[[Any], Any]:
    def handle(request: Any) -> JsonCallResponse:
        try:
            args = json.loads(request.args or "{}")
            if not isinstance(args, dict):
                raise ValueError("args must be a JSON object, got %s" % type(args).__name__)
            result = operation(args)
        except (SimError, ValueError, KeyError, TypeError) as error:
            return JsonCallResponse(False, "%s refused: %s" % (name, error), "{}")
        return JsonCallResponse(True, "%s done" % name, json.dumps(result or {}, sort_keys=True, default=str))
    return handle


@config_guard("sim")
def main() -> None:
    """Entry point of ``rosrun locem_bridge sim_worksite``. A worksite that cannot start (a stand-in's address
    taken, a bad file) ends the node with one line naming what and where, not a traceback."""
    rospy.init_node("sim")
    overrides = {key: param(key) for key in ("host", "modbus_port", "can_interface", "can_channel", "can_port",
                                             "time_scale", "gui")}
    worksite = Worksite(load_site(param("site", default_site_path(package_share()))),
                        load_robot(param("robot", default_robot_path(package_share())), param("robot_overrides", {})),
                        state_dir=param("state_dir", "") or None,
                        **{key: value for key, value in overrides.items() if value is not None})
    try:
        endpoints = worksite.start()
    except ConfigError:
        raise                    # config_guard's one line
    except (SimError, OSError) as exc:
        line = "sim_worksite: cannot start: %s" % " ".join(str(exc).split())
        print(line, file=sys.stderr, flush=True)
        rospy.signal_shutdown(line)
        raise SystemExit(1)
    node = SimNode(worksite)
    node.start()
    rospy.on_shutdown(node.shutdown)
    for what, where in sorted(endpoints.items()):
        rospy.loginfo("sim_worksite: %s: %s", what, where)
    rospy.spin()


if __name__ == "__main__":
    main()
