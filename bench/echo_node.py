#!/usr/bin/env python3
"""Baseline for bench_locem.py: a bare rospy service and action server of the LOCEM types that do nothing."""
import actionlib
import rospy
from locem_bridge.msg import CommandAction, CommandResult
from locem_bridge.srv import Command, CommandResponse


def main():
    rospy.init_node("echo")
    rospy.Service("~command", Command, lambda req: CommandResponse(True, "OK", "echo", "{}"))
    server = None

    def execute(goal):
        server.set_succeeded(CommandResult(True, "OK", "echo", "{}"))

    server = actionlib.SimpleActionServer("~command_action", CommandAction, execute, auto_start=False)
    server.start()
    rospy.spin()


if __name__ == "__main__":
    main()
