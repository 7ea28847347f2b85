"""The README's main job: the full simulated plasterboard job, headless, on the embedded defaults.

Runs ``roslaunch locem_bridge plasterboard.launch`` (simulated worksite with its RTDE / Modbus / CAN stand-ins,
LOCEM with its bridges, PEMKRE, HICEM, the automatic operator and the job node) on a private ROS master port,
shows the job's progress as it goes (process, action, joint n of N), and ends with where the report is and its
outcome table. Exit status 0 when taping, spraying and sanding all succeeded, 1 otherwise.

    python -m locem_bridge.ros.main_job                      # defaults: results/ in the current folder
    python -m locem_bridge.ros.main_job --validate-lines --reject wall_1_joint_2
    python -m locem_bridge.ros.main_job --launch-arg gui:=true
    python -m locem_bridge.ros.main_job --ontologies my_use_case --trees my_use_case --job my_use_case/job.yaml

Each run takes its own device addresses (loopback address, Modbus port, CAN channel; see
:mod:`locem_bridge.job.runs`), so two runs on one machine never reach each other's devices; when none are left it
refuses at once with one line naming what is taken and by which run (exit status 2).

Node output other than the job's goes to the ROS log folder (``--verbose`` shows it).
"""

import argparse
import json
import os
import re
import subprocess
import sys
import threading
import time
from typing import Any, Dict, List, Optional

from locem_bridge.job.report import run_name
from locem_bridge.job.runs import RunEntry, RunRegistry, RunsError, addresses_of

from .params import package_share
from .processes import free_port
from .startup import LINE as NODE_CONFIG_ERROR

PROGRESS = re.compile(r"^\[(\d+/\d+ [^\]]+|job)\]")


def launch_command(args: argparse.Namespace, port: int, entry: Optional[RunEntry] = None) -> List[str]:
    cmd = ["roslaunch", "-p", str(port), "locem_bridge", "plasterboard.launch",
           "results_dir:=%s" % os.path.abspath(args.results_dir), "time_scale:=%g" % args.time_scale,
           "validate_lines:=%s" % ("true" if args.validate_lines else "false"),
           "reject_lines:=%s" % args.reject, "hmi_port:=%d" % args.hmi_port,
           "output:=%s" % ("screen" if args.verbose else "log")]
    if args.site:
        cmd.append("site:=%s" % os.path.abspath(args.site))
    if args.robot:
        cmd.append("robot:=%s" % resolve_robot(args.robot))
    if args.job:
        cmd.append("job:=%s" % os.path.abspath(args.job))
    if args.ontologies:       # an integrator's folders, beside the package's (roslaunch args hold one text)
        cmd.append("extra_ontology_dirs:=%s" % ":".join(os.path.abspath(d) for d in args.ontologies))
    if args.trees:
        cmd.append("extra_trees_dirs:=%s" % ":".join(os.path.abspath(d) for d in args.trees))
    if entry is not None:       # this run's own device addresses and run folder name
        cmd += ["robot_overrides:=%s" % json.dumps(entry.addresses.overrides(), sort_keys=True), "run:=%s" % entry.run]
    return cmd + list(args.launch_arg)


def robots_dir() -> str:
    return os.path.join(package_share(), "config", "robots")


def resolve_robot(robot: str) -> str:
    """``--robot``'s value as a file: a path (it names a folder or ends in .yaml / .yml) or the name of a robot
    file of the package's ``config/robots/`` (``rbkairos_ur10e``); an unknown name raises ConfigError listing
    the names there."""
    from locem_bridge.common.config_errors import ConfigError
    if os.sep in robot or robot.endswith((".yaml", ".yml")):
        return os.path.abspath(robot)
    path = os.path.join(robots_dir(), robot + ".yaml")
    if not os.path.isfile(path):
        names = sorted(f[:-5] for f in os.listdir(robots_dir()) if f.endswith(".yaml"))
        raise ConfigError("no robot of this name in %s (or give a robot YAML's path)" % robots_dir(),
                          key="--robot %s" % robot, allowed=names)
    return path


def robot_file(launch_args: List[str], robot: str = "") -> str:
    """The robot YAML the launch will read (``--launch-arg robot:=FILE``, ``--robot NAME|FILE`` or the package
    default)."""
    for arg in reversed(launch_args):
        if arg.startswith("robot:="):
            return os.path.abspath(arg[len("robot:="):])
    if robot:
        return resolve_robot(robot)
    return os.path.join(robots_dir(), "rbkairos_ur10e.yaml")    # the launch's default


def claim_addresses(args: argparse.Namespace, ports: List[int]) -> RunEntry:
    """This run's slot in the machine's run registry: its own device addresses (raises NoFreeAddresses or
    RunsError with a one-line reason)."""
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.robot_file import load_robot
    try:
        path = robot_file(list(args.launch_arg), args.robot)
        robot = load_robot(path)["robot"]      # the loader the nodes use (preflight has checked the file)
    except ConfigError as exc:
        raise RunsError("cannot read the device addresses: %s" % exc)
    results = os.path.abspath(args.results_dir)
    return RunRegistry().claim(run_name(), addresses_of(robot), max_slots=args.max_runs, ports=ports,
                               taken_names=lambda name: os.path.lexists(os.path.join(results, name)))


def preflight(args: argparse.Namespace, robot_overrides: Optional[Dict[str, Any]] = None) -> Optional[str]:
    """Check the files the launch will read (site, robot plus its overrides, HICEM parameters and trees, Turtle
    ontologies, job) with the nodes' own loaders; the one-line error, or None when all load (under a second)."""
    from locem_bridge.config_check import check_files
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.common.folders import split_folders

    share = package_share()
    launch = dict(a.split(":=", 1) for a in args.launch_arg if ":=" in a)

    def path(name: str, default: str) -> str:
        return os.path.abspath(launch.get(name) or default)
    try:
        overrides = dict(robot_overrides or {})
        if launch.get("robot_overrides", "").strip():
            import yaml
            try:
                extra = yaml.safe_load(launch["robot_overrides"])
            except yaml.YAMLError as error:
                raise ConfigError("not valid YAML: %s" % (getattr(error, "problem", None) or error),
                                  key="robot_overrides:=")
            if not isinstance(extra, dict):
                raise ConfigError("must be a YAML mapping, found %r" % (extra,), key="robot_overrides:=")
            from locem_bridge.common.config_keys import deep_merge
            overrides = deep_merge(overrides, extra)
        check_files(site=os.path.abspath(args.site) if args.site else path("site", os.path.join(
                        share, "config", "sites", "default.yaml")),
                    robot=robot_file(list(args.launch_arg), args.robot),
                    robot_overrides=overrides,
                    params_file=path("params_file", os.path.join(share, "config", "hicem", "plasterboard.yaml")),
                    trees_dir=path("trees_dir", os.path.join(share, "trees")),
                    ontology_dir=path("ontology_dir", os.path.join(share, "ontologies")),
                    extra_trees_dirs=list(args.trees) + split_folders(launch.get("extra_trees_dirs")),
                    extra_ontology_dirs=list(args.ontologies) + split_folders(launch.get("extra_ontology_dirs")),
                    job=path("job", args.job or os.path.join(share, "config", "jobs", "plasterboard.yaml")))
    except ConfigError as error:
        return error.one_line()
    return None


def summarise(report_md: str) -> List[str]:
    """The report's process and outcome tables (what a person wants to see at the end)."""
    try:
        with open(report_md, encoding="utf-8") as handle:
            text = handle.read()
    except OSError:
        return []
    keep, lines = False, []
    for line in text.splitlines():
        if line.startswith("## "):
            keep = line[3:].strip() in ("Processes", "Outcome")
        if keep and line.strip():
            lines.append(line)
    return lines


def _follow(proc: "subprocess.Popen[str]", verbose: bool, found: Dict[str, str], stop: threading.Event) -> None:
    """Echo the launch's progress lines (all of its output with ``verbose``), note the report's path and a node's
    configuration error line; ``stop`` is set at such a line and when the output ends."""
    assert proc.stdout is not None
    for raw in proc.stdout:
        line = re.sub(r"\x1b\[[0-9;]*m", "", raw.rstrip())
        ended_normally = "report" in found and "REQUIRED process" in line   # the job node ends the launch
        if NODE_CONFIG_ERROR.match(line) and "config_error" not in found:
            found["config_error"] = line          # a node refused its configuration: it will not get better
            print(line, flush=True)
            stop.set()
            continue
        if verbose or PROGRESS.match(line) or (("REQUIRED process" in line or "ERROR" in line
                                                or "cannot start" in line) and not ended_normally):
            print(line, flush=True)
        match = re.match(r"^\[job\] report: (.+)$", line)
        if match:
            found["report"] = match.group(1).strip()
    stop.set()


def arguments(argv: Optional[List[str]] = None) -> argparse.Namespace:
    """The command line of :func:`main` (``tools/main.sh``'s arguments)."""
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--results-dir", default="results", help="folder receiving one subfolder per run")
    parser.add_argument("--time-scale", type=float, default=10.0, help="sim seconds per wall second (default 10: the "
                        "job in about 2 minutes on 2 cores; the launch and the rostests use 5)")
    parser.add_argument("--validate-lines", action="store_true", help="the operator validates every joint first")
    parser.add_argument("--reject", default="", help="comma list of joint ids the automatic operator rejects")
    parser.add_argument("--site", default="", help="site YAML (default: config/sites/default.yaml)")
    parser.add_argument("--robot", default="", metavar="NAME|FILE", help="robot: a name under config/robots/ "
                        "(e.g. rbkairos_ur10e) or a robot YAML's path (default: rbkairos_ur10e)")
    parser.add_argument("--ontologies", action="append", default=[], metavar="DIR", help="a folder of your own "
                        "Turtle files, loaded by PEMKRE beside the package's ontologies/ (repeat for several)")
    parser.add_argument("--trees", action="append", default=[], metavar="DIR", help="a folder of your own tree "
                        "XML files, loaded by HICEM beside the package's trees/ (repeat for several)")
    parser.add_argument("--job", default="", metavar="FILE", help="job YAML: the processes run in order "
                        "(default: config/jobs/plasterboard.yaml)")
    parser.add_argument("--hmi-port", type=int, default=0, help="operator web page port (default: a free one)")
    parser.add_argument("--port", type=int, default=0, help="ROS master port (default: a free one)")
    parser.add_argument("--timeout", type=float, default=900.0, help="wall seconds before the run is abandoned")
    parser.add_argument("--launch-arg", action="append", default=[], help="extra roslaunch arg name:=value")
    parser.add_argument("--verbose", action="store_true", help="show every node's output")
    parser.add_argument("--max-runs", type=int, default=8, help="runs at once on this machine, each on its own "
                        "device addresses (default 8)")
    return parser.parse_args(argv)


def main(argv: Optional[List[str]] = None) -> int:
    args = arguments(argv)
    started = time.monotonic()
    problem = preflight(args)
    if problem:
        print("[main] configuration error: %s" % problem, flush=True)
        return 2
    registry = RunRegistry()
    used = set(registry.used_ports())
    args.hmi_port = args.hmi_port or free_port(avoid=used)
    port = args.port or free_port(avoid=used | {args.hmi_port})
    try:
        entry = claim_addresses(args, [port, args.hmi_port])
    except RunsError as exc:            # NoFreeAddresses included
        print("[main] cannot start: %s" % exc, flush=True)
        return 2
    try:
        return run(args, port, entry, started)
    finally:
        registry.release(entry.run)


def run(args: argparse.Namespace, port: int, entry: RunEntry, started: float) -> int:
    """Run the launch on this run's addresses to its report; the exit status of :func:`main`."""
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1")
    env.pop("ROS_HOSTNAME", None)
    cmd = launch_command(args, port, entry)
    print("[main] %s" % " ".join(cmd), flush=True)
    print("[main] run %s: devices %s" % (entry.run, entry.addresses.describe()), flush=True)
    print("[main] operator page: http://127.0.0.1:%d/" % args.hmi_port, flush=True)
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
                            start_new_session=True)
    found: Dict[str, str] = {}
    stop = threading.Event()
    reader = threading.Thread(target=_follow, args=(proc, args.verbose, found, stop), name="main-output",
                              daemon=True)
    reader.start()
    try:
        # until the launch ends, a node refuses its configuration (it will not get better) or the time is up
        if not stop.wait(max(0.0, args.timeout - (time.monotonic() - started))):
            print("[main] no end after %.0f s: stopping" % args.timeout, flush=True)
    except KeyboardInterrupt:
        print("\n[main] interrupted: stopping (the job writes its report)", flush=True)
    finally:
        if stop.is_set() and "config_error" not in found:
            try:
                proc.wait(10)               # the output ended: roslaunch is on its way out
            except subprocess.TimeoutExpired:
                pass
        if proc.poll() is None:
            os.killpg(proc.pid, 2)          # SIGINT: roslaunch stops every node; the job node writes its report
            try:
                proc.wait(30)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, 9)
                proc.wait()
        reader.join(5.0)
    report, config_error = found.get("report", ""), found.get("config_error", "")
    elapsed = time.monotonic() - started
    if config_error:
        print("[main] stopped after %.0f s: a node refused its configuration (above)" % elapsed, flush=True)
        return 2
    if not report:
        print("[main] the job wrote no report (%.0f s); see the ROS logs (~/.ros/log/latest)" % elapsed, flush=True)
        return 1
    for line in summarise(report):
        print(line)
    with open(os.path.join(os.path.dirname(report), "report.json"), encoding="utf-8") as handle:
        data = json.load(handle)
    statuses = [p.get("status") for p in data.get("processes", [])]
    ok = bool(statuses) and all(s == "succeeded" for s in statuses) and not data.get("ended", {}).get("early")
    ended = data.get("ended") or {}
    if ended and ended.get("reason") != "completed":
        print("[main] ended%s: %s -- %s%s" % (" early" if ended.get("early") else "", ended.get("reason"),
                                             ended.get("what", ""), (": " + ended["detail"]) if ended.get("detail")
                                             else ""), flush=True)
        for item in ended.get("unread") or []:
            print("[main] could not be read: %s" % item, flush=True)
    print("[main] %s in %.0f s wall clock; report: %s" % ("job done" if ok else "job NOT completed", elapsed, report),
          flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
