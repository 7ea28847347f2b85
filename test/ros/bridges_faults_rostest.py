#!/usr/bin/env python3
"""rostest: device faults through the real LOCEM node; every test also asserts that nothing is left running on
any device (no arm motion or force mode, digital outputs off, spray valve closed, compressor motor off, wheels
still) without sending anything that would switch a device off first, and that ``/diagnostics`` reports the
faulty backend at ERROR level, naming the fault, while the fault lasts."""
import threading
import time
import unittest

import rospy
import rostest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus

from bridges_rig import Locem, start_worksite
from rostest_support import wait_until

PKG = "locem_bridge"
NORMAL = "0 -1 0"


class Background:
    """Runs one LOCEM command in a thread (the service call blocks until the command ends)."""

    def __init__(self, locem, text):
        self.reply = None
        self.ended = None
        self._thread = threading.Thread(target=self._run, args=(locem, text), daemon=True)
        self._thread.start()

    def _run(self, locem, text):
        self.reply = locem(text)
        self.ended = time.monotonic()

    def wait(self, timeout):
        self._thread.join(timeout)
        return self.reply


class BridgesFaultsTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        rospy.init_node("bridges_faults_test", anonymous=True)
        cls.rig = start_worksite()
        cls.locem = Locem()
        cls.locem.wait_ready()
        cls.diagnostics = []
        rospy.Subscriber("/diagnostics", DiagnosticArray, lambda m: cls.diagnostics.append((time.monotonic(), m)))

    @classmethod
    def tearDownClass(cls):
        cls.locem("STOP")
        cls.rig.close()

    def assertNothingRunning(self):
        self.assertTrue(wait_until(self.rig.nothing_running, timeout=3.0), "still running: %s" % self.rig.running())

    def assertDiagnosticsError(self, backend, words, since, timeout=4.0):
        """A /diagnostics array published after ``since`` (monotonic) shows ``locem: <backend>`` at ERROR level
        with every one of ``words`` in its message (published at 1 Hz)."""
        def seen():
            for stamp, array in list(self.diagnostics):
                for st in array.status:
                    if (stamp >= since and st.name == "locem: %s" % backend and st.level == DiagnosticStatus.ERROR
                            and all(w in st.message for w in words)):
                        return st
            return None
        found = wait_until(seen, timeout=timeout, period=0.05)
        last = [(st.name, st.level, st.message) for st in self.diagnostics[-1][1].status] if self.diagnostics else []
        self.assertTrue(found, "no ERROR for %s naming %s on /diagnostics; last: %s" % (backend, words, last))

    def test_1_compressor_link_lost_mid_spray_area(self):
        self.assertTrue(self.locem("GOTO 2.4 2.5 1.5708").success)
        if self.rig.world.mounted_tool:
            self.rig.world.remove_tool()
        self.rig.world.mount_tool("spray_gun")
        self.assertTrue(self.locem("MOUNT_TOOL spray_gun").success)
        job = Background(self.locem, "SPRAY_AREA 2.0 3.6 0.9 1 0 0 0.8 0.6 %s spacing=0.1 speed=0.1 pressure=3.5"
                         % NORMAL)
        self.assertTrue(wait_until(lambda: self.rig.model.snapshot()["valve_open"], timeout=60.0))
        self.rig.server.drop_link(duration=None, mode="silent")
        t0, t0_wall = time.monotonic(), time.time()
        reply = job.wait(10.0)
        self.assertIsNotNone(reply)
        self.assertEqual(reply.code, "HARDWARE_ERROR", reply.message)
        self.assertIn("compressor", reply.message)
        self.assertLess(job.ended - t0, 1.0)
        # nobody can reach the device, but its own communication watchdog closes the valve and stops the motor
        self.assertTrue(wait_until(lambda: not self.rig.model.snapshot()["valve_open"]
                                   and not self.rig.model.snapshot()["motor_on"], timeout=3.0))
        stops = self.rig.model.history()[-2:]
        self.assertEqual([(e["what"], e["cause"]) for e in stops], [("valve_open", "watchdog"), ("motor_on", "watchdog")])
        self.assertLessEqual(stops[-1]["wall"] - t0_wall, 1.0, stops)
        self.assertDiagnosticsError("compressor", ["link down", "does not answer"], since=t0)
        self.rig.server.restore_link()
        # the link is back: the backend keeps the compressor in its safe state (valve closed, motor off) and
        # re-arms the watchdog; no COMPRESSOR_OFF is sent here
        self.assertTrue(wait_until(lambda: not self.rig.model.snapshot()["valve_open"], timeout=3.0))
        self.assertNothingRunning()

    def test_2_drive_heartbeat_lost_mid_goto(self):
        job = Background(self.locem, "GOTO 2.4 1.5 1.5708 speed=0.6")
        self.assertTrue(wait_until(lambda: abs(self.rig.drives.wheel_speeds()[0]) > 2.0, timeout=10.0))
        self.rig.drives.drive(2).inject_heartbeat_loss()
        t0 = time.monotonic()
        reply = job.wait(5.0)
        self.assertIsNotNone(reply)
        self.assertEqual(reply.code, "HARDWARE_ERROR", reply.message)
        self.assertIn("heartbeat", reply.message)
        self.assertNothingRunning()
        self.assertDiagnosticsError("base", ["fault", "heartbeat lost"], since=t0)
        self.assertIn("heartbeat", self.locem("STATUS").data["health"]["base"]["fault"])
        refused = self.locem("MOVE_BASE_REL 0.1 0 0")
        self.assertIn(refused.code, ("HARDWARE_ERROR", "NOT_READY"))
        self.rig.drives.drive(2).restore()
        self.assertTrue(wait_until(lambda: self.locem("STATUS").data["health"]["base"]["link"] == "up"
                                   and not self.locem("STATUS").data["health"]["base"]["fault"], timeout=15.0))
        reply = self.locem("GOTO 2.4 2.8 1.5708")
        self.assertTrue(reply.success, (reply.code, reply.message))
        self.assertNothingRunning()

    def test_3_protective_stop_mid_move_l_is_latched_until_reset_arm(self):
        self.assertTrue(self.locem("HOME").success)
        pose = self.locem("GET_TCP_POSE").data["pose"]
        target = list(pose)
        target[2] -= 0.3
        job = Background(self.locem, "MOVE_L %s speed=0.05" % " ".join("%.6f" % v for v in target))
        self.assertTrue(wait_until(lambda: self.rig.standin.get_state()["moving"], timeout=10.0))
        self.rig.standin.inject_protective_stop("rostest: collision")
        t0 = time.monotonic()
        reply = job.wait(5.0)
        self.assertEqual(reply.code, "HARDWARE_ERROR", reply.message)
        self.assertIn("protective stop", reply.message)
        self.assertNothingRunning()
        self.assertDiagnosticsError("arm", ["safety stop", "protective stop"], since=t0)
        refused = self.locem("MOVE_HOME")
        self.assertEqual(refused.code, "HARDWARE_ERROR")
        self.assertIn("RESET_ARM", refused.message)
        reset = self.locem("RESET_ARM")
        self.assertTrue(reset.success, reset.message)
        self.assertTrue(self.locem("MOVE_HOME").success)
        self.assertNothingRunning()

    def test_4_ur_controller_killed_and_restarted_reconnects_by_itself(self):
        from locem_bridge.sim.ur.process import StandInProcess
        q = self.rig.standin.get_joint_positions()
        self.rig.standin.proc.kill()                 # the controller dies without a goodbye
        self.rig.standin.close()
        self.assertTrue(wait_until(lambda: self.locem("STATUS").data["health"]["arm"]["link"] != "up", timeout=5.0))
        self.assertIn(self.locem("MOVE_HOME").code, ("HARDWARE_ERROR", "NOT_READY"))
        self.rig.standin = StandInProcess(self.rig.address, time_scale=4.0, model="ur10", q0=q).start()
        self.rig.world.arm_source.standin = self.rig.standin
        self.assertTrue(wait_until(lambda: self.locem("STATUS").data["health"]["arm"]["link"] == "up", timeout=30.0))
        reply = self.locem("MOVE_J 0.3 -1.5708 1.5708 -1.5708 -1.5708 0")
        self.assertTrue(reply.success, reply.message)
        self.assertLess(abs(self.rig.standin.get_joint_positions()[0] - 0.3), 1e-3)
        self.assertGreaterEqual(self.locem("STATUS").data["health"]["arm"]["reconnects"], 1)
        self.assertNothingRunning()


if __name__ == "__main__":
    rostest.rosrun(PKG, "bridges_faults", BridgesFaultsTest)
