"""ROS side of the bridges: robot state out, velocity in, health everywhere.

=======================  ==========================================  =========================================
direction                name (relative: the robot namespace)        type
=======================  ==========================================  =========================================
publisher, 50 Hz         ``joint_states``                            ``sensor_msgs/JointState`` (arm)
publisher, 50 Hz         ``odom`` + TF ``odom -> base_link``         ``nav_msgs/Odometry`` (base; map = odom)
subscriber               ``cmd_vel``                                 ``geometry_msgs/Twist`` (base, open loop,
                                                                     held ``~cmd_vel_hold`` s, ignored while a
                                                                     GOTO runs)
subscriber (optional)    ``~localisation_topic`` of the LOCEM node   ``geometry_msgs/PoseWithCovarianceStamped``
                                                                     in map (AMCL, the simulator): taken as the
                                                                     odometry pose while the base stands still
publisher, 1 Hz          ``/diagnostics``                            ``diagnostic_msgs/DiagnosticArray``
publisher, on change     ``~status`` (the LOCEM node's)              ``locem_bridge/Status`` with
and every 2 s                                                        ``name = HEALTH``, ``interface = health``,
                                                                     ``result`` = every backend's health JSON
=======================  ==========================================  =========================================

Lifecycle: ``LocemDevices(robot, health_source)`` -> :meth:`start` (after ``rospy.init_node``) -> :meth:`shutdown`.
"""

import json
import math
import threading
from typing import Any, Optional

import rospy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped, Twist
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState

from locem_bridge.common.health import ERROR, grade
from locem_bridge.msg import Status


def _quat_z(yaw: float) -> Any:
    from geometry_msgs.msg import Quaternion
    return Quaternion(0.0, 0.0, math.sin(yaw / 2.0), math.cos(yaw / 2.0))


class LocemDevices:
    """Publishes the state and health of a :class:`locem_bridge.bridges.robot.Robot`; forwards ``cmd_vel``."""

    def __init__(self, robot: Any, health_source: Any, rate: float = 50.0, odom_frame: str = "odom",
                 base_frame: str = "base_link", cmd_vel_hold: float = 0.5, localisation_topic: str = "") -> None:
        self.robot = robot
        self.health_source = health_source      # callable -> {backend: health}
        self.rate = rate
        self.odom_frame = odom_frame
        self.base_frame = base_frame
        self.cmd_vel_hold = cmd_vel_hold
        self.localisation_topic = localisation_topic   # PoseWithCovarianceStamped in map (AMCL, the simulator)
        self.fixes_taken = 0
        self._last_health: Optional[str] = None
        self._last_health_stamp = 0.0
        self.health_repeat = 2.0          # s, a late subscriber hears the health within this time
        self._timers = []
        self._lock = threading.Lock()

    def start(self) -> None:
        from locem_bridge.bridges.interfaces import Base
        arm, base = self.robot.get("arm"), self.robot.get("base")
        self._status_pub = rospy.Publisher("~status", Status, queue_size=100)
        self._diag_pub = rospy.Publisher("/diagnostics", DiagnosticArray, queue_size=10)
        if arm is not None:
            self._joint_pub = rospy.Publisher("joint_states", JointState, queue_size=10)
        if base is not None:
            import tf2_ros
            self._odom_pub = rospy.Publisher("odom", Odometry, queue_size=10)
            self._tf = tf2_ros.TransformBroadcaster()
            self._cmd_sub = rospy.Subscriber("cmd_vel", Twist, self._on_cmd_vel, queue_size=10)
            if self.localisation_topic and base.supports(Base.LOCALISATION):
                from geometry_msgs.msg import PoseWithCovarianceStamped
                base.localisation_expected = True
                self._loc_sub = rospy.Subscriber(self.localisation_topic, PoseWithCovarianceStamped,
                                                 self._on_localisation, queue_size=1)
        self._timers.append(rospy.Timer(rospy.Duration(1.0 / self.rate), self._publish_state))
        self._timers.append(rospy.Timer(rospy.Duration(1.0), self._publish_diagnostics))
        self._timers.append(rospy.Timer(rospy.Duration(0.1), self._publish_health))

    def shutdown(self) -> None:
        for timer in self._timers:
            timer.shutdown()
        if getattr(self, "_cmd_sub", None) is not None:
            self._cmd_sub.unregister()

    # -- state ---------------------------------------------------------------------------------------------
    def _publish_state(self, _event: Any = None) -> None:
        now = rospy.Time.now()
        arm, base = self.robot.get("arm"), self.robot.get("base")
        if arm is not None:
            st = arm.cached_state()
            if st.get("q"):
                msg = JointState()
                msg.header.stamp = now
                msg.name = list(arm.joint_names)
                msg.position = list(st["q"])
                msg.velocity = list(st.get("qd", []))
                self._joint_pub.publish(msg)
        if base is not None and base.health().get("link") == "up":
            x, y, yaw = base.pose()
            vx, vy, wz = base.twist()
            odom = Odometry()
            odom.header.stamp = now
            odom.header.frame_id = self.odom_frame
            odom.child_frame_id = self.base_frame
            odom.pose.pose.position.x, odom.pose.pose.position.y = x, y
            odom.pose.pose.orientation = _quat_z(yaw)
            odom.twist.twist.linear.x, odom.twist.twist.linear.y, odom.twist.twist.angular.z = vx, vy, wz
            self._odom_pub.publish(odom)
            tf = TransformStamped()
            tf.header.stamp = now
            tf.header.frame_id = self.odom_frame
            tf.child_frame_id = self.base_frame
            tf.transform.translation.x, tf.transform.translation.y = x, y
            tf.transform.rotation = _quat_z(yaw)
            self._tf.sendTransform(tf)

    def _on_localisation(self, msg: Any) -> None:
        p, q = msg.pose.pose.position, msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        if self.robot.get("base").correct_pose(p.x, p.y, yaw):
            self.fixes_taken += 1

    def _on_cmd_vel(self, msg: Any) -> None:
        base = self.robot.get("base")
        if base is not None:
            base.set_velocity(msg.linear.x, msg.linear.y, msg.angular.z, hold=self.cmd_vel_hold)

    # -- health --------------------------------------------------------------------------------------------
    def _publish_diagnostics(self, _event: Any = None) -> None:
        array = DiagnosticArray()
        array.header.stamp = rospy.Time.now()
        for name, health in sorted(self.health_source().items()):
            status = DiagnosticStatus()
            status.level = grade(health)        # the levels are DiagnosticStatus's
            status.name = "locem: %s" % name
            status.hardware_id = name
            status.message = "link %s, device %s%s" % (health.get("link"), health.get("device"),
                                                        "; " + health["last_error"] if health.get("last_error") else "")
            status.values = [KeyValue(str(k), json.dumps(v, default=str) if not isinstance(v, str) else v)
                             for k, v in sorted(health.items())]
            array.status.append(status)
        self._diag_pub.publish(array)

    def _publish_health(self, _event: Any = None) -> None:
        health = self.health_source()
        key = json.dumps({n: [h.get("link"), h.get("device"), h.get("last_error"), h.get("fault", "")]
                          for n, h in sorted(health.items())})
        now = rospy.get_time()
        with self._lock:
            if key == self._last_health and now - self._last_health_stamp < self.health_repeat:
                return
            self._last_health = key
            self._last_health_stamp = now
        bad = [n for n, h in sorted(health.items()) if grade(h) == ERROR]
        msg = Status()
        msg.header.stamp = rospy.Time.now()
        msg.name = "HEALTH"
        msg.interface = "health"
        msg.state = "health"
        msg.code = "HARDWARE_ERROR" if bad else "OK"
        msg.message = ("; ".join("%s: link %s, %s%s" % (n, health[n].get("link"), health[n].get("device"),
                                                          " (%s)" % health[n]["last_error"]
                                                          if health[n].get("last_error") else "") for n in bad)
                       or "all backends up")
        msg.result = json.dumps(health, sort_keys=True, default=str)
        self._status_pub.publish(msg)
