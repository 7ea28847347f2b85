#!/usr/bin/env python3
"""Benchmark: the simulated worksite plus the LOCEM bridges at several time scales (prints numbers; no asserts).

Three processes, as in ``plasterboard.launch``:
- *sim*: the whole worksite (``Worksite``: PyBullet world, UR controller stand-in, compressor + Modbus server,
  four CiA 402 drives on python-can ``udp_multicast``) with the spray gun mounted; answers ground-truth
  queries on stdin;
- *locem*: the real bridges (``build_robot``: ur_rtde arm worker, pymodbus compressor, canopen base) in LOCEM's
  dispatcher, plus a listener on the base's CAN network that records every frame and every heartbeat arrival
  (wall clock, the same clock as the bridge's 1.5 x 100 ms heartbeat consumer);
- this coordinator, which runs the workload (compressor on and spraying, GOTOs back and forth while the arm
  moves with MOVE_J / MOVE_L) and compares the bridges' results with the sim's ground truth.

Printed per time scale (one row per repetition, then the median): CPU of the sim process and of the LOCEM process
(% of one core), CAN frames/s on the bus, worst heartbeat gap seen by the consumer (ms, timeout 150), heartbeat
losses latched by the base bridge, GOTO error against ground truth (worst of the run; tolerance 2 cm / 1 deg),
arm error (MOVE_J joint error in rad, MOVE_L TCP error in mm), pressure error after SET_PRESSURE, the achieved
sim/wall ratio of the UR controller's motion clock and the world steps per second. Other agents share the 2 cores:
compare the rows of the same run and repeat (``--repeat``).

Variants (``--variants``), measured in the same run: ``before`` = heartbeats from canopen's timer threads inside the
sim interpreter and cyclic TPDOs sampled per drive at its send time (the behaviour before the change); ``after`` =
heartbeats from the helper process (``locem_bridge.sim.can.heartbeat``) and the TPDOs of all drives sampled at one sim
instant per cycle; ``nosync`` = helper process, per-drive sampling; ``afterfix`` / ``nosyncfix`` = the same with
``patch_odometry``: on top of the bridge's own odometry (which now integrates while braking after a fault and along
the arc of the twist), it skips a cycle whose four wheel positions are not of one TPDO burst (drives synchronised
by SYNC only; an experiment, not in the bridge).
``machine_sched_late_worst_ms`` is a baseline from a lone process that sleeps 5 ms in a loop (how much the machine
itself stalls during the run); ``sim_sched_late_worst_ms`` is the same probe as a thread inside the sim.
``BENCH_VERBOSE=1`` prints every GOTO with ground truth and odometry. ``--load N`` adds N busy-loop processes.

Usage: python3 bench/bench_time_scale.py [--scales 1 5 10 20] [--repeat 2] [--seconds 12] [--threads]
"""
import argparse
import json
import math
import os
import random
import socket
import statistics
import subprocess
import sys
import threading
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SRC = os.path.join(ROOT, "src")
sys.path.insert(0, SRC)

from bench_worksite import CLK, cpu_seconds, free_address  # noqa: E402  (same folder: UR address, /proc CPU)
ROBOT_YAML = os.path.join(ROOT, "config", "robots", "rbkairos_ur10e.yaml")
SITE_YAML = os.path.join(ROOT, "config", "sites", "default.yaml")


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# ----------------------------------------------------------------------------------------------------- probes
class Probe:
    """In the sim process: heartbeat send gaps at the producer, world step time, and scheduling latency of a
    thread that sleeps 5 ms (a GIL / CPU contention probe)."""

    def __init__(self, node_ids):
        self.node_ids = node_ids
        self.reset()
        threading.Thread(target=self._latency, daemon=True).start()

    @staticmethod
    def thread_cpu():
        out = {}
        for t in threading.enumerate():
            tid = getattr(t, "native_id", None)
            try:
                with open("/proc/self/task/%d/stat" % tid) as fh:
                    f = fh.read().rsplit(")", 1)[1].split()
                name = t.name.split(" for ")[0] if t.name.startswith("Cyclic") else t.name
                out[name] = out.get(name, 0.0) + (int(f[11]) + int(f[12])) / CLK
            except (OSError, TypeError):
                pass
        return out

    def reset(self):
        self.cpu0 = self.thread_cpu()
        self.hb_last = {}
        self.hb_worst = 0.0
        self.step_total = 0.0
        self.parts = {}
        self.step_worst = 0.0
        self.lat_worst = 0.0
        self.lat_sum = 0.0
        self.lat_n = 0

    def _latency(self):
        while True:
            t = time.perf_counter()
            time.sleep(0.005)
            late = time.perf_counter() - t - 0.005
            self.lat_worst = max(self.lat_worst, late)
            self.lat_sum += late
            self.lat_n += 1

    def attach_sender(self, drives):
        bus = drives._bus
        inner_send = bus.send

        def send(msg, timeout=None):
            nid = msg.arbitration_id - 0x700
            if nid in self.node_ids:
                now = time.monotonic()
                prev = self.hb_last.get(nid)
                if prev is not None:
                    self.hb_worst = max(self.hb_worst, now - prev)
                self.hb_last[nid] = now
            return inner_send(msg, timeout)
        bus.send = send

    def attach_world(self, world):
        self.parts = {}
        for owner, name in ((world, "_check_collisions"), (world.outcome, "record"), (world, "_tcp"),
                            (world, "_place_robot")):
            self._wrap(owner, name)
        inner = world.step

        def step():
            t = time.perf_counter()
            inner()
            d = time.perf_counter() - t
            self.step_total += d
            self.step_worst = max(self.step_worst, d)
        world.step = step

    def _wrap(self, owner, name):
        inner = getattr(owner, name)

        def timed(*a, **kw):
            t = time.perf_counter()
            try:
                return inner(*a, **kw)
            finally:
                d = time.perf_counter() - t
                tot, worst, n = self.parts.get(name, (0.0, 0.0, 0))
                self.parts[name] = (tot + d, max(worst, d), n + 1)
        setattr(owner, name, timed)

    def report(self, wall):
        return {"producer_worst_hb_gap_ms": 1000 * self.hb_worst if self.hb_last else None,
                "world_step_share": self.step_total / wall,
                "world_step_worst_ms": 1000 * self.step_worst, "sim_sched_late_worst_ms": 1000 * self.lat_worst,
                "sim_sched_late_mean_ms": 1000 * self.lat_sum / max(1, self.lat_n),
                "parts": {k: "%.1f%% worst %.1f ms n/s %.0f" % (100 * v[0] / wall, 1000 * v[1], v[2] / wall)
                          for k, v in self.parts.items()},
                "threads": {k: round(100 * (v - self.cpu0.get(k, 0.0)) / wall, 1)
                            for k, v in sorted(self.thread_cpu().items(), key=lambda kv: -kv[1])}}


def busy():
    while True:
        pass


# ----------------------------------------------------------------------------------------------------- sim role
def role_sim(args):
    if args.switch_interval:
        sys.setswitchinterval(args.switch_interval)
    from locem_bridge.sim.worksite import Worksite
    ws = Worksite(host=args.host, modbus_port=args.modbus_port, can_interface="udp_multicast",
                  can_channel=args.can_group, can_port=args.can_port, time_scale=args.scale,
                  heartbeat_process=not args.hb_inproc)
    ws.start()
    ws.drives.sync_sampling = not args.no_sync
    ws.mount_tool("spray_gun")
    w = ws.world
    probe = Probe(set(d.node_id for d in ws.drives.drives))
    probe.attach_sender(ws.drives)
    probe.attach_world(w)
    print("READY " + json.dumps({"pose": w.base_pose()}), flush=True)
    marks = {}
    for line in sys.stdin:
        cmd = line.split()
        if not cmd:
            continue
        if cmd[0] == "quit":
            break
        out = {}
        if cmd[0] == "truth":
            out = {"pose": w.base_pose(), "q": ws.ur.get_joint_positions(), "tcp": ws.ur.get_tcp_pose(),
                   "pressure": ws.compressor.snapshot()["pressure"]}
        elif cmd[0] == "spray_lane":
            # UR poses (arm base frame) of a horizontal spray lane in front of wall_1 from the current base pose
            x0, x1, z, standoff = (float(v) for v in cmd[1:5])
            wall_y = 3.0
            out = {"poses": [w.tcp_target_in_arm_base([x, wall_y - standoff, z], [0.0, 1.0, 0.0]) for x in (x0, x1)],
                   "spray_coverage": ws.outcome()["spray_coverage"]}
        elif cmd[0] == "mark":
            marks[cmd[1]] = (time.monotonic(), ws.clock.now(), w.steps, ws.ur.arm.motion_time
                             if hasattr(ws.ur.arm, "motion_time") else 0.0, ws.ur.skipped_cycles)
        elif cmd[0] == "rate":
            a, b = marks[cmd[1]], marks[cmd[2]]
            wall = b[0] - a[0]
            out = {"sim_wall": (b[1] - a[1]) / wall, "steps_per_s": (b[2] - a[2]) / wall,
                   "ur_motion_wall": (b[3] - a[3]) / wall, "ur_skipped": b[4] - a[4]}
            out.update(probe.report(wall))
        elif cmd[0] == "reset_probe":
            probe.reset()
        print("OUT " + json.dumps(out), flush=True)
    ws.stop()


# --------------------------------------------------------------------------------------------------- locem role
class CanStats:
    """A python-can listener on the base bridge's notifier: frames per second and heartbeat arrival gaps."""

    def __init__(self, node_ids):
        import can

        class _L(can.Listener):
            def on_message_received(inner, msg):  # noqa: N805
                self.on_frame(msg)
        self.listener = _L()
        self.node_ids = node_ids
        self.reset()

    def reset(self):
        self.frames = 0
        self.t0 = time.monotonic()
        self.last_hb = {}
        self.worst_gap = 0.0
        self.gaps_over = 0

    def on_frame(self, msg):
        now = time.monotonic()
        self.frames += 1
        nid = msg.arbitration_id - 0x700
        if nid in self.node_ids:
            prev = self.last_hb.get(nid)
            self.last_hb[nid] = now
            if prev is not None:
                gap = now - prev
                self.worst_gap = max(self.worst_gap, gap)
                if gap > 0.15:
                    self.gaps_over += 1

    def report(self):
        wall = time.monotonic() - self.t0
        return {"frames_per_s": self.frames / wall, "worst_hb_gap_ms": 1000 * self.worst_gap,
                "hb_gaps_over_150ms": self.gaps_over}


def patch_odometry():
    """Experiment for a change proposed in the base bridge (not made in the bridge itself): integrate only four
    wheel positions of one TPDO burst (kernel receive stamps within half a control period), each increment along
    the circular arc of a constant twist (exact for it) instead of the chord at the midpoint heading, and keep
    integrating while a fault holds the base (the wheels still move while they brake).
    At time scale 20 one control cycle covers 0.4 s of motion, 0.2-0.3 rad of turn in a GOTO."""
    import math as _m
    from locem_bridge.bridges.cia402_base import Cia402Base
    from locem_bridge.common.geometry import wrap_angle
    orig_cycle = Cia402Base._cycle

    def _odometry(self):
        stamps = [node.tpdo[2].timestamp for node in self.nodes]
        if any(t is None for t in stamps) or max(stamps) - min(stamps) > 0.5 / self.rate:
            return                       # the four positions are not of one TPDO burst (yet)
        pos = []
        for node, pol in zip(self.nodes, self.polarity):
            counts = node.tpdo_values.get(0x6064)
            if counts is None:
                return
            pos.append(pol * counts / self.pos_scale)
        with self._lock:
            if self._last_pos is not None:
                d = [a - b for a, b in zip(pos, self._last_pos)]
                dx, dy, dth = self.kin.twist(d)
                if abs(dth) > 1e-9:
                    s, c = _m.sin(dth) / dth, (1.0 - _m.cos(dth)) / dth
                    dx, dy = dx * s - dy * c, dx * c + dy * s
                x, y, yaw = self._pose
                self._pose = [x + _m.cos(yaw) * dx - _m.sin(yaw) * dy, y + _m.sin(yaw) * dx + _m.cos(yaw) * dy,
                              wrap_angle(yaw + dth)]
            self._last_pos = pos
            speeds = []
            for node, pol in zip(self.nodes, self.polarity):
                v = node.tpdo_values.get(0x606C)
                speeds.append(pol * (v or 0) / self.vel_scale)
            self._twist = list(self.kin.twist(speeds))

    def _cycle(self, now, period):
        if self._fault is not None:
            _odometry(self)
        orig_cycle(self, now, period)
    Cia402Base._odometry = _odometry
    Cia402Base._cycle = _cycle


def role_locem(args):
    if args.odometry_fix:
        patch_odometry()
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.bridges.robot import build_robot
    from locem_bridge.locem.core import LocemCore
    import logging
    logging.basicConfig(level=logging.WARNING)
    logging.getLogger("canopen").setLevel(logging.ERROR)
    overrides = {"arm": {"controller": {"host": args.host}},
                 "compressor": {"host": args.host, "port": args.modbus_port},
                 "base": {"drives": {"can": {"interface": "udp_multicast", "channel": args.can_group,
                                             "port": args.can_port}}}}
    robot = build_robot(load_robot_config(ROBOT_YAML, overrides), site=SITE_YAML,
                        initial_pose=tuple(json.loads(args.pose)))
    core = LocemCore(grace=0.5)
    for cs in robot.command_sets:
        core.install(cs)
    robot.start()
    base = robot.get("base")
    ok = all(robot.get(k).wait_ready(60.0) for k in ("arm", "compressor", "base"))
    stats = CanStats(set(base.node_ids))
    base.network.notifier.add_listener(stats.listener)
    hb_losses = [0]
    print("READY " + json.dumps({"ok": ok}), flush=True)
    try:
        for line in sys.stdin:
            parts = line.strip().split(" ", 1)
            if not parts or not parts[0]:
                continue
            if parts[0] == "quit":
                break
            if parts[0] == "reset_stats":
                stats.reset()
                print("OUT {}", flush=True)
            elif parts[0] == "stats":
                out = stats.report()
                out["base_fault"] = base._fault or ""
                out["hb_losses"] = hb_losses[0]
                print("OUT " + json.dumps(out), flush=True)
            elif parts[0] == "cmd":
                r = core.dispatcher.execute(parts[1])
                if base._fault_kind == "heartbeat":
                    hb_losses[0] += 1
                print("OUT " + json.dumps({"success": bool(r.success), "message": str(r.message),
                                           "result": r.result}, default=str), flush=True)
            elif parts[0] == "submit":
                _ASYNC.append(core.dispatcher.submit(parts[1], _service_iface()))   # runs on; not awaited
                print("OUT {}", flush=True)
    finally:
        core.close()
        robot.close()


_ASYNC = []


def _service_iface():
    from locem_bridge.locem.registry import Interface
    return Interface.SERVICE



# ---------------------------------------------------------------------------------------------------- coordinator
class Child:
    def __init__(self, argv):
        env = dict(os.environ, PYTHONPATH=SRC + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.proc = subprocess.Popen([sys.executable, os.path.abspath(__file__)] + argv, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env, text=True, bufsize=1)
        self.ready = self._read("READY", 90.0)

    def _read(self, tag, timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            line = self.proc.stdout.readline()
            if not line:
                raise RuntimeError("child %s ended" % self.proc.args)
            if line.startswith(tag + " "):
                return json.loads(line[len(tag) + 1:])
        raise RuntimeError("child did not answer")

    def ask(self, text, timeout=120.0):
        self.proc.stdin.write(text + "\n")
        self.proc.stdin.flush()
        return self._read("OUT", timeout)

    def close(self):
        try:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.flush()
            self.proc.wait(20)
        except Exception:
            self.proc.kill()
            self.proc.wait()


SWITCH = 0.0


def angle_diff(a, b):
    return abs((a - b + math.pi) % (2 * math.pi) - math.pi)


def sched_probe(worst, stop):
    """Baseline in its own process: how late a thread that sleeps 5 ms wakes up (machine load, no GIL)."""
    while not stop.is_set():
        t = time.perf_counter()
        time.sleep(0.005)
        late = time.perf_counter() - t - 0.005
        if late > worst.value:
            worst.value = late


def run_scale(scale, seconds, variant):
    host, modbus_port = free_address(), free_port()
    group = "239.74.%d.%d" % (random.randint(170, 250), random.randint(1, 250))
    can_port = 45000 + random.randint(0, 999)
    common = ["--host", host, "--modbus-port", str(modbus_port), "--can-group", group, "--can-port", str(can_port),
              "--scale", str(scale)]
    sim = Child(["--role", "sim", "--switch-interval", str(SWITCH)] + common
                + (["--hb-inproc", "--no-sync"] if variant == "before" else [])
                + (["--no-sync"] if variant in ("nosync", "nosyncfix") else []))
    locem = None
    try:
        locem = Child(["--role", "locem", "--pose", json.dumps(sim.ready["pose"])] + common
                      + (["--odometry-fix"] if variant in ("afterfix", "nosyncfix") else []))
        if not locem.ready["ok"]:
            return {"error": "bridges not ready"}
        x0, y0, th0 = sim.ready["pose"]
        goals = [(x0 + 0.5, y0 - 0.3, th0 + 0.3), (x0, y0, th0)]
        q_a = [0.4, -1.3, 1.5, -1.7, -1.5708, 0.0]
        q_b = [-0.2, -1.6, 1.7, -1.6, -1.5708, 0.3]
        r = locem.ask("cmd COMPRESSOR_ON")
        r = locem.ask("cmd SET_PRESSURE 3")
        p_err = abs(sim.ask("truth")["pressure"] - 3.0) if r["success"] else float("nan")
        locem.ask("cmd SPRAY_ON")
        locem.ask("reset_stats")
        sim.ask("reset_probe")
        import multiprocessing
        worst, stop = multiprocessing.Value("d", 0.0), multiprocessing.Event()
        probe = multiprocessing.Process(target=sched_probe, args=(worst, stop), daemon=True)
        probe.start()
        sim.ask("mark a")
        c_sim, c_loc, t0 = cpu_seconds(sim.proc.pid), cpu_seconds(locem.proc.pid), time.monotonic()
        odo_err = 0.0
        goto_err, goto_ang, q_err, l_err, fails, n_goto = 0.0, 0.0, 0.0, 0.0, [], 0
        i = 0
        while time.monotonic() - t0 < seconds:
            goal = goals[i % 2]
            # the arm moves while the base drives (different resources run concurrently)
            locem.ask("submit MOVE_J %s speed=1.0" % " ".join("%.4f" % v for v in (q_a if i % 2 == 0 else q_b)))
            r = locem.ask("cmd GOTO %.4f %.4f %.4f speed=0.5" % goal)
            n_goto += 1
            if not r["success"]:
                fails.append(r["message"])
                locem.ask("cmd RESET_BASE")
            else:
                time.sleep(0.05)
                t = sim.ask("truth")
                x, y, th = t["pose"]
                goto_err = max(goto_err, math.hypot(x - goal[0], y - goal[1]))
                goto_ang = max(goto_ang, angle_diff(th, goal[2]))
                odo = locem.ask("cmd GET_POSE")["result"]["pose"]
                odo_err = max(odo_err, math.hypot(odo[0] - x, odo[1] - y))
                if os.environ.get("BENCH_VERBOSE"):
                    print("   goto %s truth %s odo %s result %s" % (goal, t["pose"], odo, r["result"]), flush=True)
            r = locem.ask("cmd MOVE_J %s speed=1.0" % " ".join("%.4f" % v for v in (q_a if i % 2 == 0 else q_b)))
            if r["success"]:
                t = sim.ask("truth")
                q_err = max(q_err, max(abs(a - b) for a, b in zip(t["q"], q_a if i % 2 == 0 else q_b)))
            else:
                fails.append(r["message"])
            if i % 2 == 1 and r["success"]:
                # back at the start pose: one spray lane along wall_1 (valve open: the outcome map is painted)
                lane = sim.ask("spray_lane 1.2 1.8 1.2 0.6")["poses"]
                for k, target in enumerate(lane):
                    r = locem.ask("cmd MOVE_L %s speed=%g" % (" ".join("%.5f" % v for v in target),
                                                                0.5 if k == 0 else 0.1))
                    if not r["success"]:
                        fails.append(r["message"])
                        break
                    t = sim.ask("truth")
                    l_err = max(l_err, 1000 * math.sqrt(sum((a - b) ** 2 for a, b in zip(t["tcp"][:3], target[:3]))))
            i += 1
        wall = time.monotonic() - t0
        stop.set()
        probe.join(2.0)
        cpu_sim = 100 * (cpu_seconds(sim.proc.pid) - c_sim) / wall
        cpu_loc = 100 * (cpu_seconds(locem.proc.pid) - c_loc) / wall
        sim.ask("mark b")
        st = locem.ask("stats")
        coverage = sim.ask("spray_lane 1.2 1.8 1.2 0.6")["spray_coverage"]
        rate = sim.ask("rate a b")
        locem.ask("cmd STOP")
        return {"cpu_sim": cpu_sim, "cpu_locem": cpu_loc, "frames_per_s": st["frames_per_s"],
                "worst_hb_gap_ms": st["worst_hb_gap_ms"], "hb_gaps_over_150ms": st["hb_gaps_over_150ms"],
                "gotos": n_goto, "goto_err_mm": 1000 * goto_err, "goto_err_deg": math.degrees(goto_ang),
                "odom_vs_truth_mm": 1000 * odo_err,
                "movej_err_rad": q_err, "movel_err_mm": l_err, "pressure_err_bar": p_err,
                "sim_wall": rate["sim_wall"], "ur_motion_wall": rate["ur_motion_wall"],
                "ur_skipped": rate["ur_skipped"], "steps_per_s": rate["steps_per_s"], "failures": fails[:3],
                "producer_worst_hb_gap_ms": rate["producer_worst_hb_gap_ms"],
                "world_step_share": rate["world_step_share"], "world_step_worst_ms": rate["world_step_worst_ms"],
                "sim_sched_late_worst_ms": rate["sim_sched_late_worst_ms"], "threads": rate["threads"],
                "parts": rate["parts"],
                "n_failures": len(fails), "spray_coverage": coverage,
                "machine_sched_late_worst_ms": 1000 * worst.value}
    finally:
        if locem is not None:
            locem.close()
        sim.close()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--role", choices=("coordinator", "sim", "locem"), default="coordinator")
    ap.add_argument("--scales", type=float, nargs="+", default=[1.0, 5.0, 10.0, 20.0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--seconds", type=float, default=15.0)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--variants", nargs="+", choices=("before", "nosync", "after", "afterfix", "nosyncfix"),
                    default=["before", "after"],
                    help="before: heartbeats from canopen threads in the sim process, TPDOs sampled per drive; "
                    "nosync: heartbeat helper process, TPDOs sampled per drive; after: helper process and TPDOs "
                    "of all drives sampled at one instant per cycle; afterfix / nosyncfix: the same with the "
                    "bridge odometry change proposed in patch_odometry")
    ap.add_argument("--host")
    ap.add_argument("--modbus-port", type=int)
    ap.add_argument("--can-group")
    ap.add_argument("--can-port", type=int)
    ap.add_argument("--pose")
    ap.add_argument("--odometry-fix", action="store_true", help="locem role: patch the bridge's odometry as "
                    "proposed (see patch_odometry)")
    ap.add_argument("--no-sync", action="store_true", help="cyclic TPDOs sampled per drive at its send time "
                    "(the behaviour before synchronous sampling)")
    ap.add_argument("--hb-inproc", action="store_true", help="heartbeats from canopen's in-process threads "
                    "(the behaviour before the heartbeat helper process; the baseline)")
    ap.add_argument("--switch-interval", type=float, default=0.0, help="sys.setswitchinterval in the sim process")
    ap.add_argument("--threads", action="store_true", help="print the CPU of each sim thread")
    ap.add_argument("--load", type=int, default=0, help="busy-loop processes started next to the stack (stand-in "
                    "for the other nodes of the full job: HICEM, PEMKRE, operator, roscore)")
    args = ap.parse_args()
    if args.role == "sim":
        return role_sim(args)
    if args.role == "locem":
        return role_locem(args)
    print("worksite + LOCEM bridges vs time scale (%d cores, %.0f s workload per run, %d repetition(s))"
          % (os.cpu_count(), args.seconds, args.repeat))
    cols = ("cpu_sim", "cpu_locem", "frames_per_s", "worst_hb_gap_ms", "hb_gaps_over_150ms", "gotos", "goto_err_mm",
            "goto_err_deg", "odom_vs_truth_mm", "movej_err_rad", "movel_err_mm", "pressure_err_bar", "sim_wall",
            "ur_motion_wall", "steps_per_s", "n_failures", "spray_coverage", "producer_worst_hb_gap_ms",
            "world_step_share", "world_step_worst_ms",
            "sim_sched_late_worst_ms", "machine_sched_late_worst_ms")
    global SWITCH
    SWITCH = args.switch_interval
    results = {}
    import multiprocessing
    loads = [multiprocessing.Process(target=busy, daemon=True) for _ in range(args.load)]
    for p in loads:
        p.start()
    if loads:
        print("with %d busy-loop process(es) next to the stack" % len(loads))
    runs = [(rep, scale, variant) for rep in range(args.repeat) for scale in args.scales for variant in args.variants]
    for rep, scale, variant in runs:
        r = run_scale(scale, args.seconds, variant)
        results.setdefault((scale, variant), []).append(r)
        print("scale %5.1f %-7s rep %d: %s" % (scale, variant, rep + 1, "  ".join(
            "%s=%s" % (k, ("%.3g" % r[k]) if isinstance(r.get(k), float) else r.get(k)) for k in cols)), flush=True)
        if args.threads:
            print("    sim threads (%% of one core): %s" % r.get("threads"))
            print("    world step parts: %s" % r.get("parts"))
        if r.get("failures"):
            print("    failures: %s" % r["failures"], flush=True)
    print("median over repetitions:")
    for (scale, variant), rows in results.items():
        med = {}
        for k in cols:
            vals = [r[k] for r in rows if isinstance(r.get(k), (int, float))]
            if vals:
                med[k] = statistics.median(vals)
        print("  scale %5.1f %-7s: %s" % (scale, variant, "  ".join("%s=%.3g" % (k, v) for k, v in med.items())))
        print("  scale %5.1f %-7s: worst heartbeat gap per repetition (ms): %s; heartbeat losses: %s"
              % (scale, variant, ", ".join("%.0f" % r.get("worst_hb_gap_ms", float("nan")) for r in rows),
                 sum(r.get("hb_gaps_over_150ms", 0) for r in rows)))
    for p in loads:
        p.terminate()
        p.join()


if __name__ == "__main__":
    main()
