#!/usr/bin/env python3
"""LOCEM benchmark: parse+validate cost, service round trip vs a bare rospy echo service, action round trip.

Run with the project environment:  tools/run.sh python bench/bench_locem.py [--calls N]
Everything is measured in this one run; ratios compare LOCEM to a bare rospy baseline started alongside it,
in rounds of interleaved calls (each side first in every other pair) so machine load hits both alike.
Goals (issue 2): parse+validate median <= 50 us; /locem/command STATUS round trip median ratio <= 1.3.
"""
import argparse
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def percentile(values, q):
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(round(q / 100.0 * (len(ordered) - 1))))]


def bench_parse(n):
    from locem_bridge.locem.core import LocemCore
    from locem_bridge.locem.registry import Arg, CommandSpec

    core = LocemCore()
    core.registry.declare(CommandSpec("MOVE_L", "six numbers", args=tuple(
        Arg.number(n_, "m", -2, 2, n_) for n_ in ("x", "y", "z")) + tuple(
        Arg.number(n_, "rad", -6.3, 6.3, n_) for n_ in ("rx", "ry", "rz")) + (
        Arg.number("speed", "m/s", 0.001, 1.0, "speed", default=0.1, keyword_only=True),), category="arm"))
    commands = ["STATUS", "WAIT 1.5 hold=arm", "HELP wait", "MOVE_L 0.4 -0.2 0.5 0 3.14 0 speed=0.25"]
    print("parse + validate (grammar, registry binding), %d calls per command:" % n)
    medians = []
    for text in commands:
        samples = []
        bind = core.dispatcher._bind_uncached  # the parse itself, not the dispatcher's cache of accepted strings
        for _ in range(n):
            start = time.perf_counter_ns()
            bind(text, None, 0)
            samples.append((time.perf_counter_ns() - start) / 1000.0)
        medians.append(statistics.median(samples))
        print("  %-42s median %6.1f us   p99 %6.1f us" % (text, medians[-1], percentile(samples, 99)))
    core.close()
    print("  => worst median %.1f us (goal <= 50 us): %s" % (max(medians), "MET" if max(medians) <= 50 else "MISSED"))


def bench_ros(calls, goals):
    import actionlib
    import rospy
    from locem_bridge.msg import CommandAction, CommandGoal
    from locem_bridge.ros.processes import RosProcesses
    from locem_bridge.srv import Command

    with RosProcesses() as ros:
        ros.start_master()
        os.environ.update(ros.env)
        ros.spawn(["rosrun", "locem_bridge", "locem_node"], "locem")
        ros.spawn([sys.executable, os.path.join(HERE, "echo_node.py")], "echo")
        ros.wait_for_service("/locem/command")
        ros.wait_for_service("/echo/command")
        rospy.init_node("bench_locem", anonymous=True, disable_signals=True)
        for persistent in (True, False):
            locem = rospy.ServiceProxy("/locem/command", Command, persistent=persistent)
            echo = rospy.ServiceProxy("/echo/command", Command, persistent=persistent)
            for _ in range(50):  # warm up both
                locem("STATUS")
                echo("STATUS")
            a, b = [], []
            round_ratios = []
            rounds = 10
            for r in range(rounds):  # rounds of interleaved pairs, each side first in every other pair
                ra, rb = [], []
                for i in range(max(1, calls // rounds)):
                    for side in ((0, 1) if (i + r) % 2 == 0 else (1, 0)):
                        start = time.perf_counter()
                        reply = (locem if side == 0 else echo)("STATUS")
                        (ra if side == 0 else rb).append((time.perf_counter() - start) * 1000)
                        assert reply.success, reply.message
                round_ratios.append(statistics.median(ra) / statistics.median(rb))
                a += ra
                b += rb
            ratio = statistics.median(a) / statistics.median(b)
            label = "persistent connection" if persistent else "new connection per call (rosservice default)"
            print("/locem/command STATUS round trip, %s, %d calls:" % (label, len(a)))
            print("  LOCEM       median %.3f ms  p10 %.3f ms  p99 %.3f ms"
                  % (statistics.median(a), percentile(a, 10), percentile(a, 99)))
            print("  bare rospy  median %.3f ms  p10 %.3f ms  p99 %.3f ms"
                  % (statistics.median(b), percentile(b, 10), percentile(b, 99)))
            print("  ratio per round of %d pairs: %s (spread shows the machine's load)"
                  % (calls // rounds, " ".join("%.2f" % x for x in round_ratios)))
            print("  p10 ratio %.2f" % (percentile(a, 10) / percentile(b, 10)))
            print("  => median ratio %.2f (goal <= 1.3): %s" % (ratio, "MET" if ratio <= 1.3 else "MISSED"))
            if persistent:
                locem.close()
                echo.close()
        clients = {"LOCEM WAIT 0": actionlib.SimpleActionClient("/locem/command_action", CommandAction),
                   "bare actionlib": actionlib.SimpleActionClient("/echo/command_action", CommandAction)}
        results = {}
        for name, client in clients.items():
            assert client.wait_for_server(rospy.Duration(30))
            samples = []
            for i in range(goals + 10):
                start = time.perf_counter()
                client.send_goal(CommandGoal("WAIT 0"))
                client.wait_for_result(rospy.Duration(10))
                if i >= 10:
                    samples.append((time.perf_counter() - start) * 1000)
                assert client.get_result().success
            results[name] = samples
        print("action round trip (send goal -> result), %d goals:" % goals)
        for name, samples in results.items():
            print("  %-15s median %.3f ms  p99 %.3f ms" % (name, statistics.median(samples), percentile(samples, 99)))
        print("  => median ratio %.2f" % (statistics.median(results["LOCEM WAIT 0"]) /
                                         statistics.median(results["bare actionlib"])))
        rospy.signal_shutdown("benchmark done")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--parse-calls", type=int, default=20000)
    parser.add_argument("--calls", type=int, default=2000, help="service calls per side")
    parser.add_argument("--goals", type=int, default=200, help="action goals per side")
    args = parser.parse_args()
    print("machine: %d cores; python %s" % (os.cpu_count() or 0, sys.version.split()[0]))
    bench_parse(args.parse_calls)
    bench_ros(args.calls, args.goals)


if __name__ == "__main__":
    main()
