#!/usr/bin/env python3
"""Benchmark of the UR controller stand-in (prints numbers; no pass/fail).

1. RTDE stream rate and jitter over ``--seconds`` (default 10) at 500 Hz, for the 58-variable output recipe the
   ur_rtde receive interface requests, measured by a raw RTDE reader in this process. Baseline, same run: a bare
   Python 500 Hz sender of a same-sized package (no controller work) shows what this machine allows right now.
   "On time" = the package arrived within 1 ms of its slot on the ideal 2 ms grid (slot = the controller cycle in
   its timestamp; a dropped cycle counts as missing, not as late); also printed: the fraction of inter-arrival
   intervals within [1, 3] ms and the number of controller cycles missing from the stream.
2. CPU of the stand-in process (percent of one core): no client, idle with receive + control clients, moving.
3. moveJ latency: from the client's moveJ call until the streamed actual_q changes (real ur_rtde clients).
4. Path moves (ur_rtde moveL(path)), time scale 1, sampled by a receive interface at 500 Hz: the same three-segment
   path with two 90 degree corners for blend radii 0 (baseline: stop at each waypoint), 0.01, 0.02, 0.04 m:
   motion time, time saved against the baseline, closest approach to the corners and TCP speed there, largest
   distance of the sampled TCP from the ideal geometry (straight segments joined by the tangent circular arcs),
   end error; and the cost of the script re-upload: moveL(path) call vs a single moveL call (async, both).

Run: tools/run.sh python bench/bench_ur_standin.py [--seconds 10] [--address 127.62.0.1] [--paths-only]
"""
import argparse
import os
import socket
import struct
import subprocess
import sys
import textwrap
import time

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(_HERE), "src"))

from locem_bridge.sim.ur.process import StandInProcess  # noqa: E402

RECEIVE_DEFAULT_RECIPE = (
    "timestamp,target_q,target_qd,target_qdd,target_current,target_moment,actual_q,actual_qd,actual_current,"
    "joint_control_output,actual_TCP_pose,actual_TCP_speed,actual_TCP_force,target_TCP_pose,target_TCP_speed,"
    "actual_digital_input_bits,joint_temperatures,actual_execution_time,robot_mode,joint_mode,safety_mode,"
    "actual_tool_accelerometer,speed_scaling,target_speed_fraction,actual_momentum,actual_main_voltage,"
    "actual_robot_voltage,actual_robot_current,actual_joint_voltage,actual_digital_output_bits,runtime_state,"
    "standard_analog_input0,standard_analog_input1,standard_analog_output0,standard_analog_output1,"
    "robot_status_bits,safety_status_bits,ft_raw_wrench,payload,payload_cog,payload_inertia,output_int_register_2,"
    "output_int_register_12,output_int_register_13,output_int_register_14,output_int_register_15,"
    "output_int_register_16,output_int_register_17,output_int_register_18,output_int_register_19,"
    "output_double_register_12,output_double_register_13,output_double_register_14,output_double_register_15,"
    "output_double_register_16,output_double_register_17,output_double_register_18,output_double_register_19")

PERIOD = 0.002


def _read_packages(sock: socket.socket, seconds: float, want_type: int = 85):
    """Arrival times and payloads of data packages for ``seconds``."""
    arrivals, stamps = [], []
    buf = bytearray()
    t_end = time.perf_counter() + seconds
    sock.settimeout(0.5)
    while time.perf_counter() < t_end:
        try:
            chunk = sock.recv(65536)
        except socket.timeout:
            continue
        now = time.perf_counter()
        if not chunk:
            break
        buf += chunk
        while len(buf) >= 3:
            size = struct.unpack_from(">H", buf, 0)[0]
            if len(buf) < size:
                break
            if buf[2] == want_type:
                arrivals.append(now)
                if size >= 12:
                    stamps.append(struct.unpack_from(">d", buf, 4)[0])
            del buf[:size]
    return np.array(arrivals), np.array(stamps)


def jitter_stats(arrivals: np.ndarray, stamps: np.ndarray = None) -> dict:
    n = len(arrivals)
    if n < 3:
        return {"packages": n}
    if stamps is not None and len(stamps) == n:
        k = np.round((stamps - stamps[0]) / PERIOD)     # the controller's cycle number of each package
    else:
        k = np.arange(n)
    # ideal grid: slot k at t0 + k*T, t0 chosen so the earliest package is exactly on its slot
    t0 = np.min(arrivals - k * PERIOD)
    late = arrivals - (t0 + k * PERIOD)
    iv = np.diff(arrivals)
    out = {
        "packages": n,
        "rate_hz": (n - 1) / (arrivals[-1] - arrivals[0]),
        "interval_mean_ms": 1e3 * float(np.mean(iv)),
        "interval_std_ms": 1e3 * float(np.std(iv)),
        "interval_p99_ms": 1e3 * float(np.percentile(iv, 99)),
        "interval_max_ms": 1e3 * float(np.max(iv)),
        "intervals_in_1_3ms": float(np.mean((iv >= 0.001) & (iv <= 0.003))),
        "on_time_1ms": float(np.mean(late <= 0.001)),
    }
    if stamps is not None and len(stamps) == n:
        gaps = np.round(np.diff(stamps) / PERIOD)
        out["missing_cycles"] = int(np.sum(np.maximum(gaps - 1, 0)))
    return out


def rtde_stream(address: str, seconds: float) -> dict:
    s = socket.create_connection((address, 30004), timeout=2.0)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def req(ptype, payload=b""):
        s.sendall(struct.pack(">HB", len(payload) + 3, ptype) + payload)
        head = s.recv(3, socket.MSG_WAITALL)
        size = struct.unpack(">H", head[:2])[0]
        return s.recv(size - 3, socket.MSG_WAITALL) if size > 3 else b""

    req(86, struct.pack(">H", 2))
    req(118)
    body = req(79, struct.pack(">d", 500.0) + RECEIVE_DEFAULT_RECIPE.encode())
    assert body[0] == 1, body
    s.sendall(struct.pack(">HB", 3, 83))
    arrivals, stamps = _read_packages(s, seconds)
    s.close()
    return jitter_stats(arrivals, stamps)


_BASELINE_SENDER = textwrap.dedent("""
    import socket, struct, sys, time
    ls = socket.socket(); ls.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    ls.bind((sys.argv[1], 0)); ls.listen(1)
    print(ls.getsockname()[1], flush=True)
    c, _ = ls.accept(); c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    pkg = struct.pack(">HB", 1100, 85) + bytes(1097)
    nxt = time.perf_counter(); end = nxt + float(sys.argv[2]) + 1.0
    while nxt < end:
        nxt += 0.002
        d = nxt - time.perf_counter()
        if d > 0: time.sleep(d)
        try: c.sendall(pkg)
        except OSError: break
""")


def baseline_stream(address: str, seconds: float) -> dict:
    p = subprocess.Popen([sys.executable, "-c", _BASELINE_SENDER, address, str(seconds)], stdout=subprocess.PIPE,
                         universal_newlines=True)
    try:
        port = int(p.stdout.readline())
        s = socket.create_connection((address, port), timeout=2.0)
        arrivals, _ = _read_packages(s, seconds)
        s.close()
    finally:
        p.kill()
        p.wait()
    return jitter_stats(arrivals)


def cpu_seconds(pid: int) -> float:
    with open("/proc/%d/stat" % pid) as f:
        fields = f.read().rsplit(")", 1)[1].split()
    ticks = os.sysconf("SC_CLK_TCK")
    return (int(fields[11]) + int(fields[12])) / ticks


def cpu_percent(pid: int, seconds: float, work=None) -> float:
    c0, t0 = cpu_seconds(pid), time.perf_counter()
    t_end = t0 + seconds
    while time.perf_counter() < t_end:
        if work is not None:
            work()
        else:
            time.sleep(0.05)
    return 100.0 * (cpu_seconds(pid) - c0) / (time.perf_counter() - t0)


def _ideal_pieces(points, r: float) -> list:
    """The UR blend geometry the stand-in promises: straight segments through ``points`` joined by circular arcs
    tangent to both segments r before / after each interior point. Pieces: ("line", a, b) and
    ("arc", centre, radius, e1, e2, phi) with the arc ``centre + radius (-e1 cos th + e2 sin th)``, th in [0, phi]."""
    pts = [np.asarray(p, dtype=float) for p in points]
    pieces = []
    cur = pts[0]
    for k in range(1, len(pts)):
        d1 = (pts[k] - pts[k - 1]) / np.linalg.norm(pts[k] - pts[k - 1])
        if k < len(pts) - 1 and r > 0:
            d2 = (pts[k + 1] - pts[k]) / np.linalg.norm(pts[k + 1] - pts[k])
            p_in = pts[k] - r * d1
            pieces.append(("line", cur, p_in))
            phi = float(np.arccos(np.clip(np.dot(d1, d2), -1, 1)))
            radius = r / np.tan(phi / 2)
            nv = d2 - np.dot(d1, d2) * d1
            nv /= np.linalg.norm(nv)
            pieces.append(("arc", p_in + radius * nv, radius, nv, d1, phi))
            cur = pts[k] + r * d2
        else:
            pieces.append(("line", cur, pts[k]))
            cur = pts[k]
    return pieces


def _distance_to_pieces(p: np.ndarray, pieces: list) -> float:
    best = float("inf")
    for pc in pieces:
        if pc[0] == "line":
            a, b = pc[1], pc[2]
            ab = b - a
            t = float(np.clip(np.dot(p - a, ab) / max(np.dot(ab, ab), 1e-18), 0.0, 1.0))
            best = min(best, float(np.linalg.norm(p - (a + t * ab))))
        else:
            centre, radius, e1, e2, phi = pc[1:]
            v = p - centre
            x, y = float(np.dot(v, -e1)), float(np.dot(v, e2))
            th = float(np.clip(np.arctan2(y, x), 0.0, phi))
            q = centre + radius * (-e1 * np.cos(th) + e2 * np.sin(th))
            best = min(best, float(np.linalg.norm(p - q)))
    return best


def path_bench(address: str) -> None:
    """Section 4 (see the module docstring)."""
    import rtde_control
    import rtde_receive
    print("\n[4] path moves: moveL(path) with blends, time scale 1, v 0.25 m/s, a 1.2 m/s^2")
    ur = StandInProcess(address, time_scale=1.0).start()
    try:
        r = rtde_receive.RTDEReceiveInterface(address)
        c = rtde_control.RTDEControlInterface(address)
        p0 = r.getActualTCPPose()
        corners = [np.add(p0[:3], d) for d in ((0, 0.1, 0), (0, 0.1, 0.1), (0, 0.2, 0.1))]
        base = None
        print("  blend r   motion s   saved   closest to corner   speed there   max dev. from ideal   end error")
        for radius in (0.0, 0.01, 0.02, 0.04):
            path = [list(p) + list(p0[3:]) + [0.25, 1.2, radius if i < 2 else 0.0] for i, p in enumerate(corners)]
            assert c.moveL(path, True)
            samples = []
            t_end = time.time() + 20
            started = False
            while time.time() < t_end:
                prog = c.getAsyncOperationProgress()
                samples.append((r.getTimestamp(), r.getActualTCPPose()[:3], r.getActualTCPSpeed()[:3]))
                started = started or prog >= 0
                if started and prog < 0:
                    break
                time.sleep(0.0003)
            time.sleep(0.05)
            pos = np.array([s[1] for s in samples])
            speed = np.linalg.norm([s[2] for s in samples], axis=1)
            moving = [s[0] for s in samples if np.linalg.norm(s[2]) > 1e-6]
            duration = moving[-1] - moving[0]
            base = duration if base is None else base
            pieces = _ideal_pieces([p0[:3]] + corners, radius)
            dev = max(_distance_to_pieces(p, pieces) for p in pos)
            d = np.linalg.norm(pos - corners[0], axis=1)
            i = int(np.argmin(d))
            end_err = float(np.linalg.norm(np.subtract(r.getActualTCPPose()[:3], corners[-1])))
            print("  %5.3f m   %7.3f   %5.1f %%   %9.2f mm        %6.3f m/s      %8.4f mm        %.1e m"
                  % (radius, duration, 100.0 * (1 - duration / base), 1e3 * d[i], speed[i], 1e3 * dev, end_err))
            assert c.moveL(p0, 0.5, 1.2)
        t_path, t_single = [], []
        far = list(p0)
        far[1] += 0.05
        for i in range(5):
            t0 = time.perf_counter()
            c.moveL([far + [0.5, 1.2, 0.0]], True)
            t_path.append(time.perf_counter() - t0)
            while c.getAsyncOperationProgress() >= 0:
                time.sleep(0.002)
            t0 = time.perf_counter()
            c.moveL(p0, 0.5, 1.2, True)
            t_single.append(time.perf_counter() - t0)
            while c.getAsyncOperationProgress() >= 0:
                time.sleep(0.002)
        print("  call until the motion is started: moveL(path) median %.1f ms (stop script, script re-upload, "
              "command 45) vs moveL(pose) median %.1f ms; ratio %.1f"
              % (1e3 * np.median(t_path), 1e3 * np.median(t_single), np.median(t_path) / np.median(t_single)))
        c.stopScript()
        c.disconnect()
        r.disconnect()
    finally:
        ur.close()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--address", default="127.62.%d.1" % (1 + os.getpid() % 250))
    ap.add_argument("--paths-only", action="store_true", help="only section 4 (path moves)")
    args = ap.parse_args()
    path_address = args.address.rsplit(".", 1)[0] + ".2"
    if args.paths_only:
        path_bench(path_address)
        return
    import rtde_control
    import rtde_receive

    print("UR stand-in benchmark on %s, %d CPUs, load average %s" % (args.address, os.cpu_count(),
                                                                     os.getloadavg()))
    ur = StandInProcess(args.address, time_scale=1.0, log_level="ERROR").start()
    try:
        pid = ur.stats()["pid"]
        print("\n[1] RTDE stream, 500 Hz, 58-variable receive recipe, %.0f s" % args.seconds)
        base = baseline_stream(args.address, args.seconds)
        st0 = ur.stats()
        res = rtde_stream(args.address, args.seconds)
        st1 = ur.stats()
        keys = ["packages", "rate_hz", "on_time_1ms", "intervals_in_1_3ms", "interval_mean_ms", "interval_std_ms",
                "interval_p99_ms", "interval_max_ms", "missing_cycles"]
        print("  %-20s %14s %14s" % ("", "stand-in", "bare baseline"))
        for k in keys:
            a, b = res.get(k, float("nan")), base.get(k, float("nan"))
            fa = "%14.4f" % a if isinstance(a, float) else "%14s" % a
            fb = "%14.4f" % b if isinstance(b, float) else "%14s" % b
            print("  %-20s %s %s" % (k, fa, fb))
        if base.get("on_time_1ms"):
            print("  on-time ratio stand-in / baseline: %.3f" % (res["on_time_1ms"] / base["on_time_1ms"]))
        print("  controller stalls > 5 cycles during the stand-in run: %d, cycles dropped in them: %d"
              % (st1["overruns"] - st0["overruns"], st1["skipped_cycles"] - st0["skipped_cycles"]))

        print("\n[2] CPU of the stand-in process (%% of one core)")
        idle_alone = cpu_percent(pid, 5.0)
        print("  idle, no client:                         %6.1f %%" % idle_alone)
        r = rtde_receive.RTDEReceiveInterface(args.address)
        c = rtde_control.RTDEControlInterface(args.address)
        idle_clients = cpu_percent(pid, 5.0)
        print("  idle, receive + control clients (2x500Hz): %6.1f %%" % idle_clients)
        home = r.getActualQ()
        away = list(home)
        away[0] += 0.6
        away[5] -= 0.8
        targets = [away, home]
        state = {"i": 0}

        def move():
            c.moveJ(targets[state["i"] % 2], 1.0, 2.0)
            state["i"] += 1

        moving = cpu_percent(pid, 5.0, work=move)
        print("  moving (blocking moveJ back and forth):  %6.1f %%  (%d moves)" % (moving, state["i"]))
        lin = [r.getActualTCPPose()]
        p2 = list(lin[0])
        p2[2] += 0.15
        lin.append(p2)

        def movel():
            c.moveL(lin[state["i"] % 2 == 0], 0.5, 2.0)
            state["i"] += 1

        state["i"] = 1
        moving_l = cpu_percent(pid, 5.0, work=movel)
        print("  moving (blocking moveL, IK every cycle): %6.1f %%  (%d moves)" % (moving_l, state["i"] - 1))
        c.moveJ(home, 1.0, 2.0)

        print("\n[3] moveJ latency: client call -> streamed actual_q changes (20 moves, async moveJ)")
        lat = []
        for i in range(20):
            start = r.getActualQ()
            target = list(start)
            target[0] += 0.05 if i % 2 == 0 else -0.05
            t0 = time.perf_counter()
            c.moveJ(target, 1.0, 4.0, True)
            while r.getActualQ() == start and time.perf_counter() - t0 < 1.0:
                time.sleep(0.0001)
            lat.append(time.perf_counter() - t0)
            while c.getAsyncOperationProgress() >= 0 and time.perf_counter() - t0 < 2.0:
                time.sleep(0.001)
            time.sleep(0.02)
        lat_ms = 1e3 * np.array(lat)
        print("  median %.2f ms, p90 %.2f ms, max %.2f ms (control cycle %.1f ms)"
              % (np.median(lat_ms), np.percentile(lat_ms, 90), np.max(lat_ms), 1e3 * PERIOD))
        c.stopScript()
        c.disconnect()
        r.disconnect()
    finally:
        ur.close()
    path_bench(path_address)


if __name__ == "__main__":
    main()
