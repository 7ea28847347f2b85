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

Every run keeps its state in ``<results-dir>/<run>.state/`` (PEMKRE's store, HICEM's HDICT, the simulated
world's state, the job's journal and ``run.json``: the run's options), so a run cut short -- a power loss,
``kill -9``, Ctrl-C -- goes on where it stopped with ``--resume [RUN]`` (default: the latest run): the same options
(only ``--port``, ``--hmi-port``, ``--timeout``, ``--verbose``, ``--max-runs`` and ``--keep-state`` may be given
again), the processes it
finished are not run again, HICEM goes on with the interrupted one from its HDICT, the world from its saved maps,
and the run's report covers every launch. A run whose report says it ran to its end is not started again, nor one
whose launch still holds its lock (``<state>/run.lock``; its nodes may outlive a killed main.sh). The state folder of a
run that ran to its end is removed (its report holds the results) unless ``--keep-state``.

Node output other than the job's goes to the ROS log folder (``--verbose`` shows it).
"""

import argparse
import contextlib
import fcntl
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from typing import Any, Dict, List, Optional, Tuple

from locem_bridge.common.files import write_whole
from locem_bridge.job.report import run_name
from locem_bridge.job.runs import RunEntry, RunRegistry, RunsError, addresses_of

from .params import package_share
from .processes import free_port
from .startup import LINE as NODE_CONFIG_ERROR

PROGRESS = re.compile(r"^\[(\d+/\d+ [^\]]+|job)\]")


STATE_SUFFIX = ".state"      # <results-dir>/<run>.state: the run's state folder
RUN_FILE = "run.json"         # in it: the run's options, for --resume
#: options a resumed run may be given again (the others are the run's, from its run.json)
RESUME_OPTIONS = ("results_dir", "resume", "port", "hmi_port", "timeout", "verbose", "max_runs", "keep_state")


def state_folder(args: argparse.Namespace, run: str) -> str:
    return os.path.join(os.path.abspath(args.results_dir), run + STATE_SUFFIX)


def launch_args(args: argparse.Namespace) -> Dict[str, str]:
    """The ``--launch-arg name:=value`` given, by name (the last of a name wins, as with roslaunch)."""
    return dict(a.split(":=", 1) for a in args.launch_arg if ":=" in a)


def run_state_dir(args: argparse.Namespace, run: str) -> str:
    """Where the nodes keep ``run``'s state: its state folder, or the folder a ``state_dir:=`` launch argument
    names (run.json stays in the state folder)."""
    return launch_args(args).get("state_dir") or state_folder(args, run)


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
    if entry is not None:       # this run's own device addresses, run folder name and state
        cmd += ["robot_overrides:=%s" % json.dumps(entry.addresses.overrides(), sort_keys=True), "run:=%s" % entry.run,
                "state_dir:=%s" % state_folder(args, entry.run), "run_id:=%s" % entry.run,
                "resume:=%s" % ("true" if args.resume else "false")]
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


def claim_addresses(args: argparse.Namespace, ports: List[int], run: str = "") -> RunEntry:
    """This run's slot in the machine's run registry: its own device addresses (raises NoFreeAddresses or
    RunsError with a one-line reason). ``run``: the name of a run to resume (else a new name, the start time)."""
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.robot_file import load_robot
    try:
        path = robot_file(list(args.launch_arg), args.robot)
        robot = load_robot(path)["robot"]      # the loader the nodes use (preflight has checked the file)
    except ConfigError as exc:
        raise RunsError("cannot read the device addresses: %s" % exc)
    results = os.path.abspath(args.results_dir)
    registry = RunRegistry()
    if run:             # main() holds the run's lock: a live run of this name is another resume (claim adds -2)
        return registry.claim(run, addresses_of(robot), max_slots=args.max_runs, ports=ports)
    return registry.claim(run_name(), addresses_of(robot), max_slots=args.max_runs, ports=ports,
                          taken_names=lambda name: os.path.lexists(os.path.join(results, name)) or
                          os.path.lexists(os.path.join(results, name + STATE_SUFFIX)))


def preflight(args: argparse.Namespace, robot_overrides: Optional[Dict[str, Any]] = None) -> Optional[str]:
    """Check the files the launch will read (site, robot plus its overrides, HICEM parameters and trees, Turtle
    ontologies, job) with the nodes' own loaders; the one-line error, or None when all load (under a second)."""
    from locem_bridge.config_check import check_files
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.common.folders import split_folders

    share = package_share()
    launch = launch_args(args)

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
    return _parser().parse_args(argv)


def _parser() -> argparse.ArgumentParser:
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
    parser.add_argument("--keep-state", action="store_true", help="keep the run's state folder (<results-dir>/"
                        "<run>.state: PEMKRE's store with the execution log, HDICT, world state) when the job "
                        "completed; by default it is removed then (the report holds the results) and kept otherwise, "
                        "for --resume")
    parser.add_argument("--resume", nargs="?", const="latest", default=None, metavar="RUN", help="go on with a run "
                        "cut short (power loss, kill, Ctrl-C) where it stopped, with the options it began with: RUN "
                        "names its folder under --results-dir (default: the latest run there)")
    return parser


class ResumeError(Exception):
    """A run cannot be resumed (one line: which run, what is wrong, what there is)."""


class ResumeDone(Exception):
    """The run to resume ran to its end: nothing to do (``run``, its ``report``)."""

    def __init__(self, run: str, report: str) -> None:
        super().__init__(run)
        self.run, self.report = run, report


def _absolute(args: argparse.Namespace) -> Dict[str, Any]:
    """``args`` as saved in run.json: file and folder options as absolute paths (a resume may run elsewhere)."""
    saved = dict(vars(args))
    for key in ("site", "job"):
        saved[key] = os.path.abspath(saved[key]) if saved[key] else ""
    if saved["robot"]:
        saved["robot"] = resolve_robot(saved["robot"])
    for key in ("ontologies", "trees"):
        saved[key] = [os.path.abspath(d) for d in saved[key]]
    saved["results_dir"] = os.path.abspath(saved["results_dir"])
    saved["resume"] = None
    return saved


def write_run_file(args: argparse.Namespace, run: str) -> str:
    """Create the run's state folder with its run.json (the run's options); returns the folder."""
    folder = state_folder(args, run)
    write_whole(os.path.join(folder, RUN_FILE),
                json.dumps({"run": run, "started": time.time(), "args": _absolute(args)}, indent=1, sort_keys=True))
    return folder


def resumable_runs(results_dir: str) -> List[str]:
    """The runs under ``results_dir`` that keep their state (a run.json), oldest first (names are start times)."""
    try:
        names = os.listdir(results_dir)
    except OSError:
        return []
    return sorted(name[:-len(STATE_SUFFIX)] for name in names
                  if name.endswith(STATE_SUFFIX) and os.path.isfile(os.path.join(results_dir, name, RUN_FILE)))


def latest_run(results_dir: str) -> str:
    """The newest run under ``results_dir``: a state folder or a run folder with its report ('' when none)."""
    try:
        names = os.listdir(results_dir)
    except OSError:
        names = []
    runs = resumable_runs(results_dir) + [n for n in names if not os.path.islink(os.path.join(results_dir, n)) and
                                          os.path.isfile(os.path.join(results_dir, n, "report.json"))]
    return max(runs) if runs else ""


def given_options(argv: List[str]) -> List[str]:
    """The options (their ``dest`` names) written on the command line ``argv``, whatever their values."""
    names = {flag: action.dest for action in _parser()._actions for flag in action.option_strings}
    found: List[str] = []
    for token in argv:
        dest = names.get(token.split("=", 1)[0])
        if dest is not None and dest not in found:
            found.append(dest)
    return found


def resumed_arguments(given: argparse.Namespace, argv: Optional[List[str]] = None) -> Tuple[argparse.Namespace, str]:
    """The options of the run ``given.resume`` names ("latest": the newest under ``given.results_dir``) with the
    ones a resume may change taken from ``given``, and the run's name; ResumeError says why not (also for an
    option of the command line ``argv`` a resume may not change, even given its default value)."""
    results = os.path.abspath(given.results_dir)
    runs = resumable_runs(results)
    run = latest_run(results) if given.resume == "latest" else given.resume
    if run not in runs:
        report = finished_report(given, run) if run and given.resume == "latest" else ""
        if report:
            raise ResumeDone(run, report)
        if given.resume == "latest":
            raise ResumeError("no run to resume in %s%s (a run keeps its state in <results-dir>/<run>%s/%s)" % (
                results, ": the latest, %s, keeps no state" % run if run else "", STATE_SUFFIX, RUN_FILE))
        raise ResumeError("no run %r to resume in %s; runs there: %s" % (run, results, ", ".join(runs) or "none"))
    defaults = arguments([])
    changed = sorted(set(k for k, v in vars(given).items() if k not in RESUME_OPTIONS and v != getattr(defaults, k))
                     | set(k for k in given_options(argv or []) if k not in RESUME_OPTIONS))
    if changed:
        raise ResumeError("%s cannot be given with --resume: run %s goes on with the options it began with (may be "
                          "given: %s)" % (", ".join("--" + k.replace("_", "-") for k in changed), run,
                                          ", ".join("--" + k.replace("_", "-") for k in RESUME_OPTIONS)))
    path = os.path.join(results, run + STATE_SUFFIX, RUN_FILE)
    try:
        with open(path, encoding="utf-8") as handle:
            saved = json.load(handle)["args"]
        merged = vars(defaults)
        merged.update({k: v for k, v in saved.items() if k in merged})
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        raise ResumeError("%s cannot be read: %s" % (path, exc))
    keep = bool(merged.get("keep_state"))
    merged.update({k: getattr(given, k) for k in RESUME_OPTIONS})
    merged["results_dir"] = results
    merged["keep_state"] = keep or given.keep_state
    return argparse.Namespace(**merged), run


def finished_report(args: argparse.Namespace, run: str) -> str:
    """The report.md of ``run`` when its report says the job ran to its end (every process ran: completed, or a
    process failed by itself), else '' (cut short, or no report)."""
    folder = os.path.join(os.path.abspath(args.results_dir), run)
    try:
        with open(os.path.join(folder, "report.json"), encoding="utf-8") as handle:
            ended = json.load(handle).get("ended") or {}
    except (OSError, ValueError, AttributeError):
        return ""
    return os.path.join(folder, "report.md") if ended and not ended.get("early", True) else ""


def lock_run(args: argparse.Namespace, run: str) -> int:
    """Hold the run's lock (``<state>/run.lock``) for as long as this process or its launch lives (the descriptor
    is handed to roslaunch); RunsError when another launch of the run holds it (its nodes may outlive a killed
    main.sh)."""
    folder = state_folder(args, run)
    os.makedirs(folder, exist_ok=True)
    fd = os.open(os.path.join(folder, "run.lock"), os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        os.close(fd)
        raise RunsError("run %s is still running (a launch of it holds %s): stop it before resuming it"
                        % (run, os.path.join(folder, "run.lock")))
    return fd


def check_journal(args: argparse.Namespace, run: str) -> Optional[str]:
    """One line when the run's job journal cannot be resumed with the run's job file, else None."""
    from locem_bridge.common.config_errors import ConfigError
    from locem_bridge.job.journal import JobJournal, JournalError
    from locem_bridge.job.steps import load_steps
    launch = launch_args(args)
    path = os.path.join(run_state_dir(args, run), run + "_job.json")
    if not os.path.exists(path):
        return None                 # the job node goes by PEMKRE's log alone (and says so)
    job = launch.get("job") or args.job or os.path.join(package_share(), "config", "jobs", "plasterboard.yaml")
    validate = launch.get("validate_lines") or ("true" if args.validate_lines else "false")
    try:       # the steps as the job node reads them (the launch's validate_lines overrides the file's option)
        JobJournal.load(path, load_steps(os.path.abspath(job), validate))
    except (ConfigError, JournalError) as exc:
        return str(exc) if isinstance(exc, JournalError) else exc.one_line()
    return None


def main(argv: Optional[List[str]] = None) -> int:
    args = arguments(argv)
    started = time.monotonic()
    if threading.current_thread() is threading.main_thread():
        # Ctrl-C / SIGINT stops the run (the job writes its report) also when this was started from a script in
        # the background, which hands its children SIGINT ignored
        signal.signal(signal.SIGINT, signal.default_int_handler)
    resuming = ""
    # a state folder given as a launch argument, as an absolute path (the nodes run in ROS_HOME)
    args.launch_arg = ["state_dir:=%s" % os.path.abspath(a[len("state_dir:="):]) if a.startswith("state_dir:=") else a
                       for a in args.launch_arg]
    if args.resume is not None:
        try:
            args, resuming = resumed_arguments(args, sys.argv[1:] if argv is None else argv)
            done = finished_report(args, resuming)
            if done:
                raise ResumeDone(resuming, done)
        except ResumeError as exc:
            print("[main] cannot resume: %s" % exc, flush=True)
            return 2
        except ResumeDone as exc:
            print("[main] run %s ran to its end already: nothing to resume; report: %s" % (exc.run, exc.report),
                  flush=True)
            return 0
    problem = preflight(args) or (check_journal(args, resuming) if resuming else None)
    if problem:
        print("[main] configuration error: %s" % problem, flush=True)
        return 2
    registry = RunRegistry()
    used = set(registry.used_ports())
    args.hmi_port = args.hmi_port or free_port(avoid=used)
    port = args.port or free_port(avoid=used | {args.hmi_port})
    lock = -1
    try:
        if resuming:
            lock = lock_run(args, resuming)
        entry = claim_addresses(args, [port, args.hmi_port], run=resuming)
        if resuming and entry.run != resuming:      # another resume of it claimed the name first
            registry.release(entry.run)
            raise RunsError("run %s is still running: stop it before resuming it" % resuming)
        if not resuming:
            lock = lock_run(args, entry.run)
    except (RunsError, OSError) as exc:            # NoFreeAddresses included; a state folder it cannot write
        if lock >= 0:
            os.close(lock)
        print("[main] cannot start: %s" % exc, flush=True)
        return 2
    try:
        if resuming:
            print("[main] resuming run %s (state %s)" % (resuming, state_folder(args, resuming)), flush=True)
        else:
            write_run_file(args, entry.run)
        return run(args, port, entry, started, lock)
    finally:
        registry.release(entry.run)
        if lock >= 0:
            os.close(lock)


def run(args: argparse.Namespace, port: int, entry: RunEntry, started: float, lock: int = -1) -> int:
    """Run the launch on this run's addresses to its report; the exit status of :func:`main`. ``lock``: the
    run's lock, held by roslaunch too (:func:`lock_run`)."""
    env = dict(os.environ, ROS_MASTER_URI="http://127.0.0.1:%d" % port, ROS_IP="127.0.0.1")
    env.pop("ROS_HOSTNAME", None)
    cmd = launch_command(args, port, entry)
    print("[main] %s" % " ".join(cmd), flush=True)
    print("[main] run %s: devices %s" % (entry.run, entry.addresses.describe()), flush=True)
    print("[main] operator page: http://127.0.0.1:%d/" % args.hmi_port, flush=True)
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1,
                            start_new_session=True, pass_fds=(lock,) if lock >= 0 else ())
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
        print_resume_hint(args, entry.run)
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
    if ended and not ended.get("early", True):
        if not args.keep_state:
            drop_state(args, entry.run)
    else:
        print_resume_hint(args, entry.run)
    return 0 if ok else 1


def print_resume_hint(args: argparse.Namespace, run: str) -> None:
    print("[main] the run's state is kept: bash tools/main.sh --results-dir %s --resume %s goes on with it" % (
        os.path.abspath(args.results_dir), run), flush=True)


def drop_state(args: argparse.Namespace, run: str) -> None:
    """Remove the state folder of ``run`` (completed: nothing to resume), the parts a launch argument put elsewhere
    (``state_dir:=``) included."""
    base = run_state_dir(args, run)
    for name in os.listdir(base) if os.path.isdir(base) else []:
        if name.startswith(run + "_"):           # the nodes' state (in the state folder or the one given)
            path = os.path.join(base, name)
            if os.path.isdir(path):
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.remove(path)
    shutil.rmtree(state_folder(args, run), ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
