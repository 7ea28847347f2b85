#!/usr/bin/env python3
"""Plasterboard job benchmark: the whole launch, end to end, timed by layer (prints numbers; no asserts).

Runs ``roslaunch locem_bridge plasterboard.launch operator:=auto`` headless on its own ROS master port, with a
fresh results_dir / state_dir under /tmp, and watches it from outside:

1. wall clock of the launch, of the job (first process start -> last process end) and of each process
   (taping / spraying / sanding), from ``/hicem/state``;
2. the split of each process by layer (:mod:`locem_bridge.job.layers`): device time (an arm joint moving on
   ``joint_states`` or the base moving on ``sim/ground_truth/base_pose``), LOCEM command handling (a command
   running on ``/locem/status`` while no device moves), PEMKRE calls (exact when HICEM runs with the call-log
   hook of :mod:`locem_bridge.job.call_log` - the benchmark sets ``LOCEM_CALL_LOG`` for the launch - else
   estimated from HICEM's starting/asking/reporting phases), operator prompts, health waits and HICEM's own
   time (the rest). Baseline measured in the same run: the device time (process wall / device time = the
   factor the software stack adds to the work itself);
3. peak memory of the whole launch (sum of RSS over its process tree, sampled from /proc), per node peak RSS,
   next to this benchmark process (a bare rospy node with five subscriptions) as the baseline;
4. CPU seconds and mean CPU % of one core per node (nodes found by ``__name:=`` on their command lines;
   processes a node forks count for that node), over the whole launch and during the job.

The same numbers go to ``<results_dir>/<run>/bench.json`` (the job's report folder; ``bench-<time>`` when the
job wrote none). Exit status: 0 when every process of the job succeeded, 1 when the job failed, timed out or
never ran (the split is still printed for what ran), 2 when the benchmark could not start.

Run:  tools/run.sh python bench/bench_job.py [--time-scale 5] [--site FILE] [--robot NAME|FILE]
      [--validate-lines true|false] [--keep] [--timeout 600]
Without --keep, the run's PEMKRE store, HDICT and ROS logs are deleted at the end; the results folder (report,
pictures, bench.json), launch.log and the PEMKRE call log stay.
"""
import argparse
import json
import logging
import math
import os
import re
import resource
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

try:
    import yaml
    from locem_bridge.job.call_log import ENV_VAR, read_call_log
    from locem_bridge.job.layers import LAYERS, JobRecording, analyse
    from locem_bridge.job.procstat import ProcessTreeSampler, ProcStatError, read_proc, same_process, tree_pids
except ImportError as exc:  # pragma: no cover - environment problem
    sys.exit("bench_job: %s; source the project environment first (env-ws-*.sh)" % exc)

ARM_SPEED = 2e-3      # rad/s: an arm joint faster than this is moving
BASE_SPEED = 2e-3     # m/s or rad/s: the base faster than this is moving
PROGRESS = re.compile(r"^\[(job|\d+/\d+ [\w-]+)\]|REQUIRED process|has died|Traceback|Error:")


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return int(sock.getsockname()[1])


def port_busy(host: str, port: int) -> bool:
    with socket.socket() as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError:
            return True
    return False


def device_ports(robot_path: str) -> List[Tuple[str, int]]:
    """TCP endpoints the simulated worksite will listen on (UR stand-in, compressor)."""
    with open(robot_path, encoding="utf-8") as handle:
        robot = (yaml.safe_load(handle) or {}).get("robot", {})
    ctl = robot.get("arm", {}).get("controller", {})
    out = [(str(ctl.get("host", "127.0.0.1")), int(ctl[k])) for k in ("dashboard_port", "script_port", "rtde_port")
           if k in ctl]
    for device in ("compressor", "tool_changer"):
        if "port" in robot.get(device, {}):
            out.append((str(robot[device].get("host", "127.0.0.1")), int(robot[device]["port"])))
    return out


def load_steps(path: str) -> List[Tuple[str, str]]:
    with open(path, encoding="utf-8") as handle:
        doc = yaml.safe_load(handle) or {}
    return [(str(s["name"]), str(s["process"])) for s in doc.get("steps", [])]


class Launch:
    """The roslaunch child: output to a log file (job progress echoed), stopped with everything it started."""

    def __init__(self, argv: List[str], env: Dict[str, str], log_path: str, verbose: bool) -> None:
        self.log = open(log_path, "w", encoding="utf-8")
        self.verbose = verbose
        self.proc = subprocess.Popen(argv, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     stdin=subprocess.DEVNULL, start_new_session=True, text=True, bufsize=1)
        first = read_proc(self.proc.pid)
        self.known: Dict[int, int] = {self.proc.pid: first.start} if first is not None else {}
        self.tail: List[str] = []
        self._reader = threading.Thread(target=self._read, name="launch-output", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.log.write(line)
            self.log.flush()
            self.tail = (self.tail + [line.rstrip()])[-40:]
            if self.verbose or PROGRESS.search(line.strip()):
                print("  | " + line.rstrip(), flush=True)

    def running(self) -> bool:
        return self.proc.poll() is None

    def remember_tree(self, extra: Optional[Dict[int, int]] = None) -> None:
        if self.running():
            self.known.update(tree_pids(self.proc.pid))
        self.known.update(extra or {})

    def stop(self) -> None:
        """SIGINT to roslaunch (it stops its nodes), then TERM/KILL anything of the tree still alive."""
        self.remember_tree()
        if self.running():
            try:
                os.killpg(self.proc.pid, signal.SIGINT)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                pass
        for sig, grace in ((signal.SIGTERM, 5.0), (signal.SIGKILL, 2.0)):
            left = [pid for pid, start in self.known.items() if same_process(pid, start)]
            if not left:
                break
            for pid in left:
                try:
                    os.kill(pid, sig)  # each node is its own session leader; signal exactly the known pids
                except ProcessLookupError:
                    pass
            end = time.monotonic() + grace
            while time.monotonic() < end and any(same_process(p, self.known[p]) for p in left):
                time.sleep(0.1)
        try:
            self.proc.wait(5)
        except subprocess.TimeoutExpired:
            pass
        self._reader.join(2.0)
        self.log.close()


class Recorder:
    """rospy subscriptions filling a :class:`JobRecording` (callbacks only append tuples)."""

    def __init__(self, rec: JobRecording) -> None:
        import rospy
        from geometry_msgs.msg import Pose2D
        from locem_bridge.msg import HicemPrompt, HicemState, Status
        from sensor_msgs.msg import JointState

        self.rec = rec
        self._last_q: Optional[Tuple[float, List[float]]] = None
        self._last_pose: Optional[Tuple[float, float, float, float]] = None
        self.counts = {"hicem_state": 0, "prompts": 0, "locem_status": 0, "joint_states": 0, "base_pose": 0}
        self.subs = [
            rospy.Subscriber("/hicem/state", HicemState, self._state, queue_size=1000),
            rospy.Subscriber("/hicem/prompts", HicemPrompt, self._prompt, queue_size=1000),
            rospy.Subscriber("/locem/status", Status, self._status, queue_size=1000),
            rospy.Subscriber("/joint_states", JointState, self._joints, queue_size=200),
            rospy.Subscriber("/sim/ground_truth/base_pose", Pose2D, self._pose, queue_size=200),
        ]

    @staticmethod
    def _stamp(msg: Any) -> float:
        stamp = msg.header.stamp.to_sec()
        return stamp if stamp > 0 else time.time()

    def _state(self, m: Any) -> None:
        self.counts["hicem_state"] += 1
        self.rec.hicem_states.append((self._stamp(m), {"process": m.process, "phase": m.phase,
                                                       "action_type": m.action_type, "task": m.task,
                                                       "skill": getattr(m, "skill", ""), "detail": m.detail}))

    def _prompt(self, m: Any) -> None:
        self.counts["prompts"] += 1
        self.rec.prompts.append((time.time(), m.id, m.event))

    def _status(self, m: Any) -> None:
        self.counts["locem_status"] += 1
        self.rec.locem_events.append((self._stamp(m), int(m.id), m.name, m.interface, m.state))

    def _joints(self, m: Any) -> None:
        self.counts["joint_states"] += 1
        t = self._stamp(m)
        q = list(m.position)
        if m.velocity:
            moving = max(abs(v) for v in m.velocity) > ARM_SPEED
        elif self._last_q is not None and t > self._last_q[0] and len(q) == len(self._last_q[1]):
            dt = t - self._last_q[0]
            moving = max(abs(a - b) for a, b in zip(q, self._last_q[1])) / dt > ARM_SPEED
        else:
            moving = False
        self._last_q = (t, q)
        self.rec.arm_samples.append((t, moving))

    def _pose(self, m: Any) -> None:
        self.counts["base_pose"] += 1
        t = time.time()
        if self._last_pose is not None and t > self._last_pose[0]:
            t0, x0, y0, th0 = self._last_pose
            dt = t - t0
            turn = abs(math.atan2(math.sin(m.theta - th0), math.cos(m.theta - th0)))
            moving = math.hypot(m.x - x0, m.y - y0) / dt > BASE_SPEED or turn / dt > BASE_SPEED
            self.rec.base_samples.append((t, moving))
        self._last_pose = (t, m.x, m.y, m.theta)

    def close(self) -> None:
        for sub in self.subs:
            sub.unregister()


def wait_master(port: int, launch: Launch, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end and launch.running():
        with socket.socket() as sock:
            sock.settimeout(0.3)
            if sock.connect_ex(("127.0.0.1", port)) == 0:
                return True
        time.sleep(0.2)
    return False


def mb(n: float) -> str:
    return "%.0f MB" % (n / 1e6)


def pct(part: float, whole: float) -> str:
    return "%.0f%%" % (100.0 * part / whole) if whole > 0 else "-"


def print_time(t: Dict[str, Any], steps: List[Tuple[str, str]]) -> None:
    print("1. wall clock")
    print("   launch (roslaunch start -> exit)        %7.1f s" % t["launch_s"])
    print("   start-up (launch -> first process)      %7.1f s" % t["startup_s"])
    print("   job (first process start -> last end)   %7.1f s   goal <= 180 s for the whole launch: %s" % (
        t["job_s"], "met" if t["launch_s"] <= 180 else "NOT met"))
    print("   after the job (report, shutdown)        %7.1f s" % t["teardown_s"])
    ran = {p["name"]: p for p in t["processes"]}
    for name, _iri in steps:
        p = ran.get(name)
        if p is None:
            print("   %-10s not started" % name)
        else:
            print("   %-10s %7.1f s  %s" % (name, p["wall_s"], p["status"]))
    print("2. split by layer (seconds; %% of the process; PEMKRE from %s)" % (
        "the call log inside HICEM (exact)" if t["pemkre_source"] == "call_log"
        else "HICEM's starting/asking/reporting phases (estimate: the call-log hook is not in hicem_node)"))
    short = {"device": "device", "locem_handling": "LOCEM", "pemkre": "PEMKRE", "operator": "operator",
             "health_wait": "health", "hicem": "HICEM"}
    print("   %-9s %7s" % ("process", "wall") + "".join(" %13s" % short[n] for n in LAYERS) + "  wall/device")
    rows = list(t["processes"]) + ([{"name": "all", "wall_s": sum(p["wall_s"] for p in t["processes"]),
                                     "layers": t["layers"]}] if t["processes"] else [])
    for p in rows:
        ly = p["layers"]
        device = ly["device"]
        print("   %-9s %6.1fs" % (p["name"], p["wall_s"]) + "".join(
            " %6.1fs %5s" % (ly[n], pct(ly[n], p["wall_s"])) for n in LAYERS)
            + ("  x%.2f" % (p["wall_s"] / device) if device > 0 else "  (no device motion)"))
    if t["processes"]:
        print("   LOCEM = command running, no device moving; HICEM = the rest (ticks, data store, gaps); "
              "between processes (job node) %.2f s" % t["layers"]["between_processes"])
        print("   LOCEM commands running %.1f s; devices moving %.1f s (arm %.1f s, base %.1f s; %.1f s outside any "
              "command); PEMKRE %.1f s" % (t["locem_commands_s"], t["device_s"], t["arm_moving_s"],
                                           t["base_moving_s"], t["device_outside_commands_s"], t["pemkre_calls_s"]))
    if t["actions"]:
        print("   per HICEM action:  " + "; ".join("%s%s x%d %.1f s (device %.1f)" % (
            k, " [skill %s]" % ", ".join(v["skills"]) if v.get("skills", [k]) not in ([k], []) else "", v["count"],
            v["wall_s"], v["device_s"]) for k, v in t["actions"].items()))
    if t["commands"]:
        print("   per LOCEM command: " + "; ".join("%s x%d %.1f s (device %.1f%s)" % (
            k, v["count"], v["total_s"], v["device_s"], ", %d not ok" % v["failed"] if v["failed"] else "")
            for k, v in t["commands"].items()))
    if t["pemkre_call_table"]:
        print("   per PEMKRE call:   " + "; ".join("%s x%d %.2f s (max %.0f ms)" % (
            k, v["count"], v["total_s"], 1e3 * v["max_s"]) for k, v in t["pemkre_call_table"].items()))


def print_resources(mem: Dict[str, Any], cpu: Dict[str, Dict[str, float]], window: Optional[Tuple[float, float]]
                    ) -> None:
    print("3. memory of the whole launch (sum of RSS over its process tree, %d samples)" % mem["samples"])
    print("   peak %s at +%.1f s (%d processes); baseline: this benchmark process (rospy, 5 subscriptions) %s"
          " -> launch = x%.1f" % (mb(mem["peak_rss"]), mem["peak_at_s"], mem["peak_processes"],
                                 mb(mem["baseline_rss"]), mem["peak_rss"] / max(mem["baseline_rss"], 1)))
    print("4. CPU per node (%d cores on this machine; %% of one core)" % (os.cpu_count() or 0))
    print("   %-22s %9s %9s %10s %9s %10s %9s" % ("node", "peak RSS", "CPU s", "mean CPU", "lifetime",
                                                  "job CPU s", "job CPU"))
    for name, r in sorted(cpu.items(), key=lambda kv: -kv[1]["cpu_s"]):
        print("   %-22s %9s %9.1f %9.1f%% %8.0fs %10s %10s" % (
            name, mb(r["peak_rss"]), r["cpu_s"], r["cpu_pct"], r["lifetime_s"],
            "%.1f" % r["window_cpu_s"] if window else "-", "%.1f%%" % r["window_cpu_pct"] if window else "-"))
    total_cpu = sum(r["cpu_s"] for r in cpu.values())
    line = "   all nodes: %.1f CPU s" % total_cpu
    if window:
        used = sum(r["window_cpu_s"] for r in cpu.values())
        line += "; during the job %.1f CPU s = %.2f of %d cores busy" % (
            used, used / max(window[1] - window[0], 1e-9), os.cpu_count() or 0)
    print(line)


def read_report(results_dir: str, since: float) -> Tuple[Optional[str], Optional[Dict[str, Any]]]:
    """The run folder and report.json the job wrote after ``since`` (an older ``latest`` is not this run's)."""
    latest = os.path.join(results_dir, "latest")
    folder = os.path.realpath(latest)
    if not os.path.isdir(folder) or os.path.getmtime(folder) < since - 1.0:
        return None, None
    try:
        with open(os.path.join(folder, "report.json"), encoding="utf-8") as handle:
            return folder, json.load(handle)
    except (OSError, ValueError):
        return folder, None


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--time-scale", type=float, default=5.0, help="sim seconds per wall second (default 5)")
    ap.add_argument("--site", default=os.path.join(ROOT, "config", "sites", "default.yaml"), help="site YAML")
    ap.add_argument("--robot", default="rbkairos_ur10e",
                    help="robot of config/robots/ by name, or a robot YAML's path (default rbkairos_ur10e)")
    ap.add_argument("--validate-lines", choices=("true", "false"), default="false",
                    help="the automatic operator validates each joint before taping")
    ap.add_argument("--keep", action="store_true", help="keep the PEMKRE store, HDICT and ROS logs too")
    ap.add_argument("--timeout", type=float, default=600.0, help="wall seconds before the launch is stopped")
    ap.add_argument("--results-dir", default="", help="results_dir of the launch (default: fresh under /tmp)")
    ap.add_argument("--sample-period", type=float, default=0.5, help="seconds between /proc samples")
    ap.add_argument("--wait-free", type=float, default=120.0,
                    help="seconds to wait for another worksite to free the device ports")
    ap.add_argument("--verbose", action="store_true", help="echo all launch output")
    args = ap.parse_args()
    if args.time_scale <= 0 or args.timeout <= 0 or args.sample_period <= 0:
        print("bench_job: --time-scale, --timeout and --sample-period must be > 0", file=sys.stderr)
        return 2
    site = os.path.abspath(args.site)
    if not os.path.isfile(site):
        print("bench_job: --site %s is not a file" % site, file=sys.stderr)
        return 2
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.ros.main_job import resolve_robot     # tools/main.sh's --robot, the same names and paths
    try:
        robot = resolve_robot(args.robot)
    except ConfigError as exc:
        print("bench_job: %s" % exc, file=sys.stderr)
        return 2
    steps = load_steps(os.path.join(ROOT, "config", "jobs", "plasterboard.yaml"))

    ports = device_ports(robot)
    end = time.monotonic() + args.wait_free
    while any(port_busy(h, p) for h, p in ports):
        if time.monotonic() > end:
            print("bench_job: device ports %s are in use (another simulated worksite runs?); gave up after %.0f s"
                  % (", ".join("%s:%d" % hp for hp in ports if port_busy(*hp)), args.wait_free), file=sys.stderr)
            return 2
        time.sleep(2.0)

    work = tempfile.mkdtemp(prefix="locem_bench_job_")
    results_dir = os.path.abspath(args.results_dir) if args.results_dir else os.path.join(work, "results")
    state_dir, ros_home = os.path.join(work, "state"), os.path.join(work, "ros_home")
    call_log = os.path.join(work, "pemkre_calls.jsonl")
    for d in (results_dir, state_dir, ros_home):
        os.makedirs(d, exist_ok=True)
    port, hmi_port = free_port(), free_port()
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1", ROS_HOME=ros_home,
               PYTHONUNBUFFERED="1")
    env[ENV_VAR] = call_log
    env.pop("ROS_HOSTNAME", None)
    os.environ.update({k: env[k] for k in ("ROS_MASTER_URI", "ROS_IP", "ROS_HOME")})
    os.environ.pop("ROS_HOSTNAME", None)
    os.environ.pop(ENV_VAR, None)
    argv = ["roslaunch", "-p", str(port), "locem_bridge", "plasterboard.launch", "operator:=auto",
            "results_dir:=%s" % results_dir, "state_dir:=%s" % state_dir, "site:=%s" % site, "robot:=%s" % robot,
            "time_scale:=%g" % args.time_scale, "validate_lines:=%s" % args.validate_lines,
            "hmi_port:=%d" % hmi_port, "output:=log", "process_timeout:=%d" % max(60, int(args.timeout - 120))]
    load_at_start = os.getloadavg()[0]
    print("Plasterboard job benchmark (python %s; load average %.2f on %d CPUs - numbers vary with load)" % (
        sys.version.split()[0], load_at_start, os.cpu_count() or 0))
    print("   %s\n   master port %d, work folder %s" % (" ".join(argv), port, work), flush=True)

    stop_requested = []

    def on_signal(signum: int, _frame: Any) -> None:
        stop_requested.append(signum)
    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)

    t_start = time.time()
    rec = JobRecording(steps=steps, start=t_start, end=t_start)
    launch = Launch(argv, env, os.path.join(work, "launch.log"), args.verbose)
    try:
        sampler = ProcessTreeSampler(launch.proc.pid, period=args.sample_period).start()
    except ProcStatError as exc:
        launch.stop()
        print("bench_job: cannot follow the launch: %s; see %s" % (exc, os.path.join(work, "launch.log")),
              file=sys.stderr)
        return 2
    recorder = None
    outcome = "unknown"
    rospy = None
    try:
        if not wait_master(port, launch, 30.0):
            outcome = "no master"
        else:
            import rospy as _rospy
            rospy = _rospy
            rospy.init_node("bench_job", anonymous=True, disable_signals=True, disable_rosout=True)
            logging.getLogger("rosout").setLevel(logging.ERROR)  # the master goes away with the launch
            recorder = Recorder(rec)
            deadline = time.monotonic() + args.timeout
            while launch.running() and not stop_requested and time.monotonic() < deadline:
                time.sleep(0.5)
            outcome = ("interrupted" if stop_requested else "timeout" if launch.running() else "launch ended")
    finally:
        rec.end = time.time()
        launch.remember_tree(sampler.seen)
        if recorder is not None:
            recorder.close()
        if rospy is not None:
            rospy.signal_shutdown("benchmark done")
        launch.stop()
        sampler.stop()
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if outcome in ("timeout", "interrupted"):
        print("   launch stopped by the benchmark: %s after %.0f s" % (outcome, rec.end - t_start))

    rec.pemkre_calls = read_call_log(call_log)
    timing = analyse(rec)
    window = None
    if timing["processes"]:
        window = (timing["processes"][0]["start"], timing["processes"][-1]["end"])
    cpu = sampler.summary(window)
    baseline_rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    mem = {"peak_rss": sampler.peak_rss, "peak_at_s": max(0.0, sampler.peak_rss_at - t_start),
           "peak_processes": sampler.peak_processes, "samples": sampler.samples, "baseline_rss": baseline_rss}
    folder, report = read_report(results_dir, t_start)
    statuses = [p["status"] for p in (report or {}).get("processes", [])]
    hicem_ok = len(timing["processes"]) == len(steps) and all(p["status"] == "ended" for p in timing["processes"])
    ok = (outcome == "launch ended" and report is not None and len(statuses) == len(steps)
          and all(s == "succeeded" for s in statuses) and hicem_ok)

    print_time(timing, steps)
    print_resources(mem, cpu, window)
    print("5. job result: %s (%s; report %s)" % ("SUCCEEDED" if ok else "FAILED", outcome,
                                                 "processes " + ", ".join(statuses) if report else "not written"))
    if report:
        o = report.get("outcome", {})
        print("   joints taped %s of %s, tape %.3f, spray %.3f (CV %.3f), sand %.3f, collisions %s" % (
            o.get("joints_taped"), o.get("joints_total"), o.get("tape_coverage", 0), o.get("spray_coverage", 0),
            o.get("spray_thickness_cv", 0), o.get("sand_coverage", 0), o.get("collisions")))
    seen = recorder.counts if recorder is not None else {}
    print("   messages seen: " + ", ".join("%s %d" % kv for kv in sorted(seen.items())) +
          "; PEMKRE call records %d" % len(rec.pemkre_calls))
    if not ok:
        for p in timing["processes"]:
            if p["status"] != "ended":
                details = [s.get("detail", "") for _t, s in rec.hicem_states if s["process"] == p["iri"]]
                print("   %s: %s - %s" % (p["name"], p["status"], details[-1] if details else "no detail"))
        if report is None:
            print("   last launch output:\n" + "\n".join("   | " + line for line in launch.tail[-15:]))

    if folder is None or not os.path.isdir(folder):
        folder = os.path.join(results_dir, "bench-%s" % time.strftime("%Y%m%d-%H%M%S", time.localtime(t_start)))
        os.makedirs(folder, exist_ok=True)
    doc = {
        "settings": {"time_scale": args.time_scale, "site": site, "validate_lines": args.validate_lines,
                     "timeout_s": args.timeout, "master_port": port, "cpus": os.cpu_count(),
                     "load_average_at_start": load_at_start},
        "result": {"ok": ok, "launch": outcome, "report": folder if report else None,
                   "process_status": statuses, "hicem_status": [p["status"] for p in timing["processes"]]},
        "time": {k: v for k, v in timing.items()},
        "memory": mem,
        "cpu_by_node": cpu,
        "messages_seen": seen,
    }
    for p in doc["time"]["processes"]:
        p["start_s"], p["end_s"] = p.pop("start") - t_start, p.pop("end") - t_start
    with open(os.path.join(folder, "bench.json"), "w", encoding="utf-8") as handle:
        json.dump(doc, handle, indent=2, sort_keys=True)
    print("   bench.json: %s" % os.path.join(folder, "bench.json"))
    if not args.keep:
        for d in (state_dir, ros_home):
            shutil.rmtree(d, ignore_errors=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
