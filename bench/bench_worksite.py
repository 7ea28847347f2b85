#!/usr/bin/env python3
"""Benchmark of the simulated worksite (prints numbers; no asserts).

A. CPU of the whole site (``python3 -m locem_bridge.sim``: world + UR stand-in + Modbus + CAN drives, one process)
   while idle and while moving (base wheels turning through the CAN master, arm moving through ur_rtde, spray
   gun mounted with the valve open), measured from /proc/<pid>/stat as % of one core. Baseline in the same run:
   the same site without the UR stand-in (``--no-ur``). Goal: idle <= 60 % of one core.
B. Achieved simulation rate vs time scale (in-process site, no UR): sim seconds per wall second, world steps per
   second against ``world_rate``, and the base distance error for a commanded wheel speed.

The worksite together with the LOCEM bridges at time scales 1-20 (heartbeat gaps, CAN frames/s, GOTO and arm
errors against ground truth) is measured by bench/bench_time_scale.py.

Usage: python3 bench/bench_worksite.py [--seconds 5]
"""
import argparse
import copy
import math
import os
import signal
import socket
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
SRC = os.path.join(os.path.dirname(HERE), "src")
sys.path.insert(0, SRC)

from locem_bridge.sim.config import load_robot, load_site, resolve_relative  # noqa: E402

CLK = os.sysconf("SC_CLK_TCK")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def free_address():
    third = 1 + os.getpid() % 250
    for last in range(1, 250):
        addr = "127.63.%d.%d" % (third, last)
        try:
            for port in (29999, 30003, 30004):
                with socket.socket() as s:
                    s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                    s.bind((addr, port))
            return addr
        except OSError:
            continue
    raise RuntimeError("no free loopback address")


def cpu_seconds(pid):
    with open("/proc/%d/stat" % pid) as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / CLK


def measure(pid, seconds):
    c0, t0 = cpu_seconds(pid), time.monotonic()
    time.sleep(seconds)
    return 100.0 * (cpu_seconds(pid) - c0) / (time.monotonic() - t0)


def start_site(extra, can_port, modbus_port, addr):
    cmd = [sys.executable, "-m", "locem_bridge.sim", "--host", addr, "--modbus-port", str(modbus_port),
           "--can-interface", "udp_multicast", "--can-channel", "239.74.163.2", "--can-port", str(can_port),
           "--log-level", "WARNING"] + extra
    env = dict(os.environ, PYTHONPATH=SRC)
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, env=env, text=True)
    deadline = time.monotonic() + 40
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line or "SIGTERM stops it" in line:
            break
    if proc.poll() is not None:
        raise RuntimeError("site did not start: " + proc.stdout.read())
    return proc


def stop_site(proc):
    proc.send_signal(signal.SIGTERM)
    try:
        proc.communicate(timeout=20)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()


def enable_drives(robot, can_port):
    import canopen
    from locem_bridge.common.can_bus import open_bus
    eds = resolve_relative(robot, robot["robot"]["base"]["eds"])
    net = canopen.Network(open_bus({"interface": "udp_multicast", "channel": "239.74.163.2", "port": can_port}))
    net.NOTIFIER_CYCLE = 0.1
    net.connect()
    nodes = []
    for w in robot["robot"]["base"]["drives"]["wheels"]:
        n = canopen.BaseNode402(w["node_id"], eds)
        net.add_node(n)
        n.nmt.wait_for_heartbeat(2.0)
        n.setup_402_state_machine()
        n.nmt.state = "OPERATIONAL"
        n.op_mode = "PROFILED VELOCITY"
        n.state = "OPERATION ENABLED"
        nodes.append(n)
    return net, nodes


def part_a(seconds):
    robot = load_robot()
    print("A. CPU of the whole site (%% of one core, %.0f s windows, %d cores on this machine)"
          % (seconds, os.cpu_count()))
    rows = []
    for label, extra in (("site without UR stand-in (baseline)", ["--no-ur"]), ("whole site", [])):
        addr, can_port, modbus_port = free_address(), free_port(), free_port()
        proc = start_site(extra + ["--mount-tool", "spray_gun"], can_port, modbus_port, addr)
        ctl = rcv = None
        try:
            time.sleep(1.0)
            idle = measure(proc.pid, seconds)
            # clients connected, nothing moving: CAN master with drives OPERATIONAL (TPDOs, heartbeats),
            # RTDE receive interface streaming at 500 Hz, compressor motor running
            net, nodes = enable_drives(robot, can_port)
            from pymodbus.client import ModbusTcpClient
            mb = ModbusTcpClient(addr, port=modbus_port)
            mb.connect()
            mb.write_register(0, 400, device_id=1)
            mb.write_coil(0, True, device_id=1)
            if not extra:
                import rtde_control
                import rtde_receive
                rcv = rtde_receive.RTDEReceiveInterface(addr)
                ctl = rtde_control.RTDEControlInterface(addr)
            connected = measure(proc.pid, seconds)
            # moving: wheels turning, compressor spraying, arm moving (when the UR stand-in runs)
            mb.write_coil(1, True, device_id=1)
            for n, w in zip(nodes, robot["robot"]["base"]["drives"]["wheels"]):
                n.rpdo[2]["Target velocity"].raw = int(w["polarity"] * 500)        # 0.5 rad/s
                n.rpdo[2].transmit()
            q0 = rcv.getActualQ() if rcv else None
            if ctl is not None:
                ctl.moveJ([0.6, -1.2, 1.2, -1.5708, -1.5708, 0.0], 0.2, 0.5, True)   # asynchronous move
            moving = measure(proc.pid, seconds)
            arm_moved = (max(abs(a - b) for a, b in zip(rcv.getActualQ(), q0)) if rcv else 0.0)
            if ctl is not None:
                ctl.stopJ(2.0)
            for n in nodes:
                n.rpdo[2]["Target velocity"].raw = 0
                n.rpdo[2].transmit()
            mb.close()
            net.disconnect()
        finally:
            for client in (ctl, rcv):
                if client is not None:
                    client.disconnect()
            stop_site(proc)
        rows.append((label, idle, connected, moving))
        print("  %-38s idle %5.1f %%  idle+clients %5.1f %%  moving %5.1f %%%s"
              % (label, idle, connected, moving, ("  (arm moved %.2f rad)" % arm_moved) if not extra else ""))
    base, whole = rows[0], rows[1]
    print("  whole site / baseline: idle x%.2f, idle+clients x%.2f, moving x%.2f"
          % (whole[1] / max(base[1], 1e-6), whole[2] / max(base[2], 1e-6), whole[3] / max(base[3], 1e-6)))
    print("  goal idle <= 60 %% of one core: %s (idle %.1f %%, idle with clients streaming %.1f %%)"
          % ("met" if max(whole[1], whole[2]) <= 60 else "NOT met", whole[1], whole[2]))


def part_b(seconds):
    from locem_bridge.sim.worksite import Worksite
    print("B. achieved simulation rate vs time scale (in-process site without UR, %.0f s per scale)" % seconds)
    site, robot = load_site(), load_robot()
    for scale in (1.0, 4.0, 16.0):
        ws = Worksite(copy.deepcopy(site), robot, modbus_port=free_port(), can_interface="virtual",
                      can_channel="bench-%d-%d" % (os.getpid(), int(scale)), time_scale=scale, with_ur=False)
        ws.start()
        try:
            w = ws.world
            r = robot["robot"]["base"]["wheel"]["radius"]
            # rad/s at each wheel, straight ahead; about 1 m of travel in the window (the room is 3.6 m deep)
            speed = min(1.0, 1.0 / (r * scale * (seconds + 0.5)))
            for d, pol in zip(ws.drives.drives, ws.drives.polarity):
                d._controlword(0x06)
                d._controlword(0x0F)
                d.mode = 3
                d.target_units = int(pol * speed * d.vel_scale)
            time.sleep(0.5)                                        # past the acceleration ramp
            p0, s0, n0, t0 = w.base_pose(), ws.clock.now(), w.steps, time.monotonic()
            time.sleep(seconds)
            p1, s1, n1, t1 = w.base_pose(), ws.clock.now(), w.steps, time.monotonic()
            dist = math.hypot(p1[0] - p0[0], p1[1] - p0[1])
            expected = speed * r * (s1 - s0)
            print("  time_scale %5.1f: sim/wall %6.2f   world steps/s %6.1f (rate %.0f)   base %6.3f m, "
                  "expected %6.3f m, error %.2f %%" % (scale, (s1 - s0) / (t1 - t0), (n1 - n0) / (t1 - t0),
                                                       w.rate, dist, expected, 100 * abs(dist - expected) / expected))
        finally:
            ws.stop()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0)
    args = ap.parse_args()
    part_a(args.seconds)
    part_b(min(args.seconds, 3.0))


if __name__ == "__main__":
    main()
