#!/usr/bin/env python3
"""rostest: the real LOCEM node with its bridges (RTDE arm, Modbus compressor, CAN base over udp_multicast)
against the worksite stand-ins; ground truth and outcome from the PyBullet world in this process."""
import math
import threading
import time
import unittest

import actionlib
import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from locem_bridge.msg import CommandAction, CommandGoal, Status
from nav_msgs.msg import Odometry
from sensor_msgs.msg import JointState

from actionlib_msgs.msg import GoalStatus, GoalStatusArray

from bridges_rig import ArmMotionSampler, Locem, start_worksite
from bridge_rigs import last_motion, sim_time_of
from rostest_support import result_of, rosservice_call, wait_until

PKG = "locem_bridge"
NORMAL = "0 -1 0"


def truth_error(world, goal):
    x, y, th = world.base_pose()
    return math.hypot(x - goal[0], y - goal[1]), abs((th - goal[2] + math.pi) % (2 * math.pi) - math.pi)


class BridgesWorksiteTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("bridges_worksite_test", anonymous=True)
        cls.rig = start_worksite()
        cls.locem = Locem()
        cls.locem.wait_ready()
        cls.messages = {"joint_states": [], "odom": [], "diagnostics": [], "health": [], "events": [],
                        "goal_status": []}
        rospy.Subscriber("/joint_states", JointState, lambda m: cls.messages["joint_states"].append(m))
        rospy.Subscriber("/odom", Odometry, lambda m: cls.messages["odom"].append(m))
        rospy.Subscriber("/diagnostics", DiagnosticArray, lambda m: cls.messages["diagnostics"].append(m))
        rospy.Subscriber("/locem/status", Status,
                         lambda m: cls.messages["health" if m.name == "HEALTH" else "events"].append(m))
        rospy.Subscriber("/locem/command_action/status", GoalStatusArray,
                         lambda m: cls.messages["goal_status"].append(m))
        import tf2_ros
        cls.tf_buffer = tf2_ros.Buffer()
        cls.tf_listener = tf2_ros.TransformListener(cls.tf_buffer)
        cls.action = actionlib.SimpleActionClient("/locem/command_action", CommandAction)
        assert cls.action.wait_for_server(rospy.Duration(30))

    @classmethod
    def tearDownClass(cls):
        cls.locem("STOP")
        cls.rig.close()

    def goto(self, goal, **kw):
        reply = rosservice_call("/locem/command", "command: 'GOTO %g %g %g'" % goal, timeout=120)
        self.assertTrue(reply["success"], reply["message"])
        time.sleep(0.1)
        d, a = truth_error(self.rig.world, goal)
        self.assertLess(d, 0.02)
        self.assertLess(a, math.radians(1.0))

    def test_01_state_topics_and_health(self):
        m = self.messages
        self.assertTrue(wait_until(lambda: m["joint_states"] and m["odom"] and m["diagnostics"] and m["health"],
                                   timeout=10.0), {k: len(v) for k, v in m.items()})
        js = m["joint_states"][-1]
        self.assertEqual(js.name[0], "shoulder_pan_joint")
        q = self.rig.standin.get_joint_positions()
        self.assertLess(max(abs(a - b) for a, b in zip(js.position, q)), 1e-3)
        odom = m["odom"][-1]
        self.assertAlmostEqual(odom.pose.pose.position.x, self.rig.world.base_pose()[0], delta=0.01)
        self.assertEqual((odom.header.frame_id, odom.child_frame_id), ("odom", "base_link"))
        tf = self.tf_buffer.lookup_transform("odom", "base_link", rospy.Time(0), rospy.Duration(5.0))
        self.assertAlmostEqual(tf.transform.translation.y, self.rig.world.base_pose()[1], delta=0.01)
        names = {s.name: s.level for s in m["diagnostics"][-1].status}
        for backend in ("arm", "compressor", "base"):
            self.assertEqual(names.get("locem: %s" % backend), 0, names)
        health = result_of(m["health"][-1].result)
        self.assertEqual({health[b]["link"] for b in ("arm", "compressor", "base")}, {"up"})
        status = self.locem("STATUS")
        self.assertEqual(status.data["health"]["base"]["link"], "up")

    def test_02_goto_through_the_rosservice_cli_matches_ground_truth(self):
        self.goto((2.6, 2.6, 1.4))
        self.goto((2.4, 2.8, 1.5708))

    def test_03_move_l_within_1mm(self):
        pose = self.locem("GET_TCP_POSE").data["pose"]
        target = list(pose)
        target[2] -= 0.05
        target[1] += 0.05
        reply = self.locem("MOVE_L %s speed=0.3" % " ".join("%.6f" % v for v in target))
        self.assertTrue(reply.success, reply.message)
        reached = self.rig.standin.get_tcp_pose()
        self.assertLess(math.sqrt(sum((a - b) ** 2 for a, b in zip(reached[:3], target[:3]))), 0.001)

    def test_04_apply_tape_covers_the_joint(self):
        self.goto((2.4, 2.8, 1.5708))
        if self.rig.world.mounted_tool:
            self.rig.world.remove_tool()
        self.rig.world.mount_tool("taping_tool")
        self.assertTrue(self.locem("MOUNT_TOOL taping_tool").success)
        reply = self.locem("APPLY_TAPE 1.8 3.6 1.25 3.0 3.6 1.25 %s speed=0.1" % NORMAL)
        self.assertTrue(reply.success, reply.message)
        time.sleep(0.2)
        self.assertGreaterEqual(self.rig.world.outcome.joint_coverage("wall_1_joint_1"), 0.99)
        self.assertTrue(self.rig.nothing_running())

    def test_05_spray_area_covers_the_area(self):
        reply = self.locem("GOTO_TAG spray_station")
        self.assertTrue(reply.success, reply.message)
        self.rig.world.remove_tool()
        self.rig.world.mount_tool("spray_gun")
        self.assertTrue(self.locem("MOUNT_TOOL spray_gun").success)
        reply = self.locem("SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 standoff=0.3 speed=0.1 pressure=3.5"
                           % NORMAL)
        self.assertTrue(reply.success, reply.message)
        time.sleep(0.2)
        self.assertGreaterEqual(self.rig.area_coverage("wall_1", (0.2, 1.0), (0.9, 1.5)), 0.98)
        self.assertEqual(self.rig.running(), ["compressor motor on"])     # kept on for a next section
        self.assertTrue(self.locem("COMPRESSOR_OFF").success)
        self.assertTrue(self.rig.nothing_running(), self.rig.running())

    # -- stops: measured from the moment the node accepted STOP / the cancel (its own stamp) to the last ground-truth
    # sample with motion, in sim time (time scale 4). Base: the drive stand-ins' recorded motion segments, evaluated
    # on a 1 ms sim grid (exact model, the standstill lies within 1 ms after the last moving sample). Arm: the UR
    # stand-in's own record of the last control cycle with motion, its sim time mapped to the wall clock by samples
    # every 10 ms (ArmMotionSampler; the mapping's spread is reported).
    def stop_accepted(self, since):
        """Wall stamp at which the node accepted a STOP sent after ``since`` (its /locem/status event)."""
        def stamp():
            found = [m.header.stamp.to_sec() for m in list(self.messages["events"])
                     if m.name == "STOP" and m.header.stamp.to_sec() >= since - 0.05]
            return min(found) if found else None
        accepted = wait_until(stamp, timeout=3.0)
        self.assertIsNotNone(accepted, "no STOP event on /locem/status")
        return accepted

    def cancel_accepted(self, since):
        """Wall stamp at which the action server accepted the cancel (first status PREEMPTING / RECALLING)."""
        def stamp():
            found = [m.header.stamp.to_sec() for m in list(self.messages["goal_status"])
                     if m.header.stamp.to_sec() >= since - 0.05
                     and any(g.status in (GoalStatus.PREEMPTING, GoalStatus.RECALLING) for g in m.status_list)]
            return min(found) if found else None
        accepted = wait_until(stamp, timeout=3.0)
        self.assertIsNotNone(accepted, "no PREEMPTING status from the action server")
        return accepted

    def assert_stop_during_move_j_within_200ms(self, stop, accepted_since, what):
        """A long MOVE_J through the action; ``stop()`` while it runs; the arm's ground truth shows it still at most
        200 ms sim time after the node accepted the stop (``accepted_since(wall)`` -> the node's stamp)."""
        self.assertTrue(self.locem("HOME").success)
        self.action.send_goal(CommandGoal(command="MOVE_J 1.5 -1.5708 1.5708 -1.5708 -1.5708 0 speed=0.3"))
        self.assertTrue(wait_until(lambda: self.rig.standin.get_state()["moving"], timeout=10.0))
        sampler = ArmMotionSampler(self.rig.standin)
        try:
            time.sleep(0.1)
            sent = time.time()
            stop()
            self.assertTrue(wait_until(lambda: not self.rig.standin.get_state()["moving"], timeout=3.0))
            time.sleep(0.1)
        finally:
            sampler.close()
        took, spread = sampler.stop_time(accepted_since(sent))
        rospy.loginfo("%s: arm moving %.3f s sim after acceptance (wall -> sim mapping within %.4f s sim)",
                      what, took, spread)
        self.assertLessEqual(took, 0.2, "%s: arm moving %.3f s sim after it was accepted (mapping within %.4f s)"
                             % (what, took, spread))
        self.assertTrue(self.action.wait_for_result(rospy.Duration(5)))
        self.assertEqual(self.action.get_result().code, "ABORTED")
        self.assertTrue(wait_until(self.rig.nothing_running, timeout=2.0), self.rig.running())

    def test_06_action_cancel_stops_the_arm_within_200ms_sim_time(self):
        self.assert_stop_during_move_j_within_200ms(self.action.cancel_goal, self.cancel_accepted, "action cancel")

    def test_07_stop_during_goto_stops_the_base_within_200ms_sim_time(self):
        goal = CommandGoal(command="GOTO 2.4 1.0 1.5708 speed=0.8")
        self.action.send_goal(goal)
        self.assertTrue(wait_until(lambda: abs(self.rig.drives.wheel_speeds()[0]) > 3.0, timeout=10.0))
        sent = time.time()
        reply = self.locem("STOP")
        self.assertTrue(reply.success)
        self.assertTrue(wait_until(lambda: all(abs(v) < 1e-9 for v in self.rig.drives.wheel_speeds()),
                                   timeout=2.0, period=0.002))
        accepted = sim_time_of(self.rig.clock, self.stop_accepted(sent))
        took = last_motion(self.rig.drives, accepted, self.rig.clock.now(), step=0.001) - accepted
        rospy.loginfo("STOP: base wheels still %.3f s sim after acceptance (1 ms sim grid)", took)
        self.assertLessEqual(took, 0.2, "base wheels turning %.3f s sim after STOP was accepted" % took)
        self.assertTrue(self.action.wait_for_result(rospy.Duration(5)))
        self.assertEqual(self.action.get_result().code, "ABORTED")
        self.assertTrue(wait_until(self.rig.nothing_running, timeout=2.0), self.rig.running())

    def test_08_cmd_vel_moves_the_base(self):
        pub = rospy.Publisher("/cmd_vel", Twist, queue_size=10)
        x0, y0, th0 = self.rig.world.base_pose()
        end = time.monotonic() + 0.5
        twist = Twist()
        twist.linear.x = 0.2
        while time.monotonic() < end:
            pub.publish(twist)
            time.sleep(0.05)
        self.assertTrue(wait_until(lambda: all(abs(v) < 1e-9 for v in self.rig.drives.wheel_speeds()), timeout=3.0))
        x1, y1, _ = self.rig.world.base_pose()
        moved = (x1 - x0) * math.cos(th0) + (y1 - y0) * math.sin(th0)
        self.assertGreater(moved, 0.05)

    def test_09_stop_during_move_j_stops_the_arm_within_200ms_sim_time(self):
        self.assert_stop_during_move_j_within_200ms(lambda: self.assertTrue(self.locem("STOP").success),
                                                    self.stop_accepted, "STOP")
        self.assertTrue(self.locem("HOME").success)


if __name__ == "__main__":
    rostest.rosrun(PKG, "bridges_worksite", BridgesWorksiteTest)
