#!/usr/bin/env python3
"""Bridge benchmark: what LOCEM adds on top of the device libraries, and the base control loop rate.

1. GET_PRESSURE through /locem/command (rospy service -> LOCEM node -> pymodbus client -> compressor stand-in)
   vs a raw pymodbus read from this process of exactly what GET_PRESSURE reads: two requests, input registers
   0..3 (pressure, current, fault, status bits) and holding register 0 (set-point), see
   ``ModbusCompressor._read_state`` (goal: median overhead <= 2 ms). The single-register read (pressure only) is
   printed next to it for scale;
2. GET_JOINTS through /locem/command (-> ur_rtde worker process -> RTDE stream of the UR stand-in) vs a raw
   ur_rtde RTDEReceiveInterface.getActualQ() in this process;
3. the base control loop (canopen BaseNode402 drives on a virtual CAN bus): achieved vs configured rate over
   ``--loop-seconds`` (goal >= 98 %).

Run with the project environment:  tools/run.sh python bench/bench_bridges.py [--calls N] [--loop-seconds S]
Everything is measured in this one run on this machine; numbers are printed, nothing is asserted.
"""
import argparse
import copy
import os
import statistics
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)

sys.path.insert(0, os.path.join(REPO, "test", "bridges"))


def stats(samples_us):
    ordered = sorted(samples_us)
    return statistics.median(ordered), ordered[min(len(ordered) - 1, int(0.99 * (len(ordered) - 1)))]


def timed(fn, n, warmup=20):
    for _ in range(warmup):
        fn()
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t0) * 1e6)
    return out


def line(label, samples):
    med, p99 = stats(samples)
    print("  %-52s median %8.1f us   p99 %8.1f us" % (label, med, p99))
    return med


def bench_ros(calls):
    import rospy
    from pymodbus.client import ModbusTcpClient
    import rtde_receive

    from bridge_rigs import CompressorRig, ROBOT_YAML, next_ur_address
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.ros.processes import RosProcesses
    from locem_bridge.sim.ur.process import StandInProcess
    from locem_bridge.srv import Command

    robot = load_robot_config(ROBOT_YAML)
    rig = CompressorRig(robot, time_scale=1.0)
    address = next_ur_address()
    standin = StandInProcess(address, time_scale=1.0).start()
    overrides = "{arm: {controller: {host: '%s'}}, compressor: {port: %d}}" % (address, rig.cfg["port"])
    try:
        with RosProcesses() as ros:
            ros.start_master()
            os.environ.update(ros.env)
            ros.spawn(["rosrun", "locem_bridge", "locem_node", "_robot_config:=%s" % ROBOT_YAML,
                       "_robot_overrides:=%s" % overrides, "_devices:=arm,compressor"], "locem")
            ros.wait_for_service("/locem/command", timeout=60)
            rospy.init_node("bench_bridges", anonymous=True, disable_signals=True)
            call = rospy.ServiceProxy("/locem/command", Command, persistent=True)
            end = time.monotonic() + 60
            while time.monotonic() < end:
                import json
                health = json.loads(call("STATUS").result)["health"]
                if all(health.get(d, {}).get("link") == "up" for d in ("arm", "compressor")):
                    break
                time.sleep(0.2)
            else:
                raise RuntimeError("bridges did not come up: %s" % health)

            print("GET_PRESSURE, %d calls each:" % calls)
            raw = ModbusTcpClient("127.0.0.1", port=rig.cfg["port"], timeout=0.5)
            raw.connect()
            check = call("GET_PRESSURE")
            assert check.success, check.message
            from locem_bridge.bridges.modbus_compressor import HOLD_SETPOINT, IN_PRESSURE
            dev = {"device_id": rig.cfg["device_id"]}

            def same_as_get_pressure():
                # what GET_PRESSURE reads (ModbusCompressor._read_state): 2 requests, 4 input + 1 holding register
                a = raw.read_input_registers(IN_PRESSURE, count=4, **dev)
                b = raw.read_holding_registers(HOLD_SETPOINT, count=1, **dev)
                assert not a.isError() and not b.isError()

            one_med = line("raw pymodbus: 1 request, input register 0 only",
                           timed(lambda: raw.read_input_registers(IN_PRESSURE, count=1, **dev), calls))
            r_med = line("raw pymodbus: GET_PRESSURE's 2 requests (IR 0..3, HR 0)", timed(same_as_get_pressure, calls))
            l_med = line("/locem/command GET_PRESSURE (persistent rospy proxy)",
                         timed(lambda: call("GET_PRESSURE"), calls))
            print("  => overhead vs the same 2 raw requests: %.2f ms median (goal <= 2 ms): %s; ratio %.1fx"
                  % ((l_med - r_med) / 1000.0, "MET" if l_med - r_med <= 2000 else "MISSED", l_med / r_med))
            print("     (vs the single-register read: %.2f ms, ratio %.1fx; GET_PRESSURE makes 2 Modbus requests,"
                  " and shares the node's client with the 15 Hz poll)" % ((l_med - one_med) / 1000.0, l_med / one_med))
            raw.close()

            print("GET_JOINTS, %d calls each:" % calls)
            recv = rtde_receive.RTDEReceiveInterface(address)
            check = call("GET_JOINTS")
            assert check.success, check.message
            r_med = line("raw ur_rtde RTDEReceiveInterface.getActualQ()", timed(recv.getActualQ, calls))
            l_med = line("/locem/command GET_JOINTS (persistent rospy proxy)", timed(lambda: call("GET_JOINTS"), calls))
            print("  => overhead %.2f ms median; ratio %.0fx (the raw getter reads a cached RTDE sample in-process;"
                  " GET_JOINTS crosses ROS and the ur_rtde worker pipe)" % ((l_med - r_med) / 1000.0, l_med / r_med))
            recv.disconnect()
            call.close()
    finally:
        standin.close()
        rig.close()


def bench_loop(seconds, rates):
    from bridge_rigs import BaseRig, ROBOT_YAML
    from locem_bridge.bridges.cia402_base import Cia402Base
    from locem_bridge.bridges.config import load_robot_config

    robot = load_robot_config(ROBOT_YAML)
    print("base control loop (4 CiA 402 drives, canopen over python-can virtual bus), %.0f s each:" % seconds)
    for rate in rates:
        rig = BaseRig(robot, world=False)
        cfg = copy.deepcopy(rig.cfg)
        cfg["control_rate"] = rate
        base = Cia402Base(cfg, rig.eds)
        base.start()
        try:
            if not base.wait_ready(15.0):
                print("  %5.0f Hz: drives not enabled: %s" % (rate, base.health()["last_error"]))
                continue
            base.set_velocity(0.1, 0.0, 0.0, hold=seconds + 1.0)     # a moving base: commands and odometry
            time.sleep(0.5)
            c0, t0, late0 = base.cycles, time.monotonic(), base.loop_rate()["late"]
            time.sleep(seconds)
            c1, t1, late1 = base.cycles, time.monotonic(), base.loop_rate()["late"]
            achieved = (c1 - c0) / (t1 - t0)
            print("  configured %6.1f Hz  achieved %7.2f Hz  (%5.1f %%; goal >= 98 %%: %s), late cycles %d of %d"
                  % (rate, achieved, 100 * achieved / rate, "MET" if achieved >= 0.98 * rate else "MISSED",
                     late1 - late0, c1 - c0))
        finally:
            base.close()
            rig.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--calls", type=int, default=300)
    ap.add_argument("--loop-seconds", type=float, default=10.0)
    ap.add_argument("--skip-ros", action="store_true", help="only the control loop (no ROS master needed)")
    args = ap.parse_args()
    if not args.skip_ros:
        bench_ros(args.calls)
    bench_loop(args.loop_seconds, (50.0, 100.0))


if __name__ == "__main__":
    main()
