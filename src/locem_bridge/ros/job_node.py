"""ROS node ``plasterboard_job``: runs a job (processes in order) through HICEM and writes the run report.

Parameters (private): ``job`` (YAML with ``steps: [{name, process, options}]``, default
``config/jobs/plasterboard.yaml``), ``validate_lines`` (overrides the taping option; empty = the file's),
``results_dir`` (default ``$LOCEM_RESULTS`` or ``./results``), ``process_timeout`` (s per process),
``settings`` (JSON copied into the report; ``devices`` is added: the device addresses LOCEM was given, i.e. the
robot file's with ``locem/robot_overrides`` merged), ``run`` (run folder name; default the start time),
``peer_wait`` (s to wait for HICEM or PEMKRE when they are away, default 120; see :class:`ProcessSequencer`: the
job goes on with the next process only when a process failed by itself), ``journal`` (the run's journal file,
:mod:`locem_bridge.job.journal`; empty: none), ``resume`` (true: go on with the run of that journal -- the processes
it or PEMKRE's log (``pemkre/query kpi_by_process``) shows ended are not run again, the one HICEM resumes from its
HDICT is followed, not started, and the report covers every launch; false: a fresh run, refused when the journal
exists). Services used: ``hicem/start_process``,
``sim/outcome``, ``sim/scan``, ``sim/save_outcome``, and ``pemkre/query`` for the KPI table when present. Exits when the job is
done (0 when every process ended, 1 otherwise), so a launch file can mark it ``required``.

Every ``sim/outcome`` and ``sim/save_outcome`` call carries the parts HICEM left for manual work so far
(``manual``: :meth:`JobTracker.manual_plan`), so the worksite measures the parts the robot was to work and draws
the manual ones; should the worksite refuse that plan, the outcome is read without it and the report says so.

A report is always written, also when the job ends early (the launch shuts down, a process times out, HICEM or
PEMKRE cannot be reached): ``ended`` in report.json says why (see :mod:`locem_bridge.job.report`). The node
does not need the other nodes alive for it: the worksite's outcome is read at every process boundary and every
``OUTCOME_PERIOD_S`` while a process runs, every call at the end gets ``END_CALL_TIMEOUT_S``, and what could not
be read is named in the report (roslaunch allows a node 15 s after SIGINT).
"""

import json
import os
import re
import signal
import tempfile
import threading
import time
from typing import Any, Callable, Dict, List, Optional, Tuple

import rospy

from locem_bridge.common.config_errors import ConfigError
from locem_bridge.job.journal import NOT_STARTED, SAVE_PERIOD_S, JobJournal, JournalError, resume_point
from locem_bridge.job.report import JobEnd, RunRecord, write_report
from locem_bridge.job.steps import load_steps
from locem_bridge.job.tracker import TERMINAL_PHASES, JobStep, JobTracker, with_manual_plan
from locem_bridge.msg import HicemPrompt, HicemState
from locem_bridge.srv import HicemStartProcess, JsonCall, PemkreQuery
from locem_bridge.ros.calls import CallFailed, timed
from locem_bridge.ros.params import package_share, param
from locem_bridge.ros.startup import config_guard


def kpi_rows(reply: Any) -> List[Dict[str, Any]]:
    if not reply.success:
        return []
    results = json.loads(reply.results)
    rows = []
    for binding in results.get("results", {}).get("bindings", []):
        rows.append({name: value.get("value") for name, value in binding.items()})
    return rows


#: HICEM's words for a process that failed because PEMKRE was away (hicem/controller.py, ros/hicem_pemkre.py),
#: not because one of its tasks failed
_PEER_AWAY = re.compile(r"PEMKRE .*failed: \S+ did not answer within")
RESUME_LOOK_S = 5.0         # a resumed job waits this long for HICEM to name the process it goes on with


class ProcessSequencer:
    """Runs one job step through HICEM, telling the process's own failure from its peers being away.

    HICEM's ``start_process`` is waited for (HICEM respawning) within ``peer_wait`` s and sent again only when it
    never reached HICEM; a start cut mid-way counts as done when ``/hicem/state`` shows the step's process. A
    process that ends ``failed`` because PEMKRE stayed away past HICEM's own wait is started again once PEMKRE is
    back (PEMKRE's world state makes the new run go on where the old one stopped), at most ``reruns`` times.
    A respawned HICEM resumes its interrupted process by itself: the job just keeps waiting for its end.
    """

    def __init__(self, tracker: JobTracker, timeout: float, peer_wait: float, reruns: int = 2,
                 while_waiting: Callable[[], None] = lambda: None,
                 shutdown_reason: Callable[[], str] = lambda: "ROS shutdown",
                 checkpoint: Callable[[], None] = lambda: None) -> None:
        self.tracker = tracker
        self.timeout = timeout
        self.peer_wait = peer_wait
        self.reruns = reruns
        self.last_state: Dict[str, Any] = {}
        self.while_waiting = while_waiting          # called about every 0.1 s while a process runs
        self.shutdown_reason = shutdown_reason
        self.checkpoint = checkpoint                # called when a process begins and when it ends (the journal)
        self.ended: Optional[JobEnd] = None         # why the job must end here, when run() says so

    def _shut_down(self, step: JobStep) -> bool:
        self.tracker.end(status="interrupted", detail="launch shut down")
        self.checkpoint()
        self.ended = JobEnd("shutdown", "the launch shut down (%s) while %s was running" % (
            self.shutdown_reason(), step.name))
        return False

    def on_state(self, state: Dict[str, Any]) -> None:
        """A ``/hicem/state`` message as the tracker takes it (process, phase, action_type, task, ...)."""
        self.last_state = dict(state)

    def _hicem_goes_on(self, step: JobStep, look_s: float = RESUME_LOOK_S) -> bool:
        """After a restart of the job: True when HICEM resumed ``step``'s process by itself (its HDICT held it):
        its state names the process within ``look_s`` s, running or already ended (then handed to the tracker)."""
        deadline = time.monotonic() + look_s
        while not rospy.is_shutdown() and time.monotonic() < deadline:
            state = dict(self.last_state)
            if state.get("process") == step.iri and state.get("phase") not in ("", "idle"):
                self.tracker.on_state(state)          # an end HICEM reached before the job looked is kept
                return True
            time.sleep(0.1)
        return False

    def _start(self, step: JobStep) -> Any:
        """(success, message) of HICEM's start_process, waiting for HICEM while it is away."""
        deadline = time.monotonic() + self.peer_wait
        while not rospy.is_shutdown():
            try:
                rospy.wait_for_service("hicem/start_process", timeout=max(0.1, deadline - time.monotonic()))
                reply = rospy.ServiceProxy("hicem/start_process", HicemStartProcess)(
                    step.iri, json.dumps(dict(step.options)))
                return reply.success, reply.message
            except rospy.ROSException as exc:      # wait_for_service timed out
                return False, "HICEM's start_process not available within %.0f s: %s" % (self.peer_wait, exc)
            except rospy.ServiceException as exc:
                text = str(exc)
                never_sent = "unavailable" in text or "unable to connect" in text
                if not never_sent and self.last_state.get("process") == step.iri and \
                        self.last_state.get("phase") not in ("idle",) + TERMINAL_PHASES:
                    return True, "started (the answer was lost: %s)" % text
                if time.monotonic() >= deadline:
                    return False, "HICEM's start_process failed for %.0f s: %s" % (self.peer_wait, text)
                print("[job] HICEM away (%s); waiting for it" % text, flush=True)
                time.sleep(0.5)
        return False, "the launch is shutting down"

    def run(self, index: int, step: JobStep, resuming: bool = False, carried_s: float = 0.0) -> bool:
        """Run ``step`` to its end; False when the job must end here (not started, timeout, STOP). ``resuming``:
        the job was restarted while ``step`` ran (``carried_s`` s spent on it then): when HICEM goes on with it by
        itself the job follows it instead of starting it."""
        for attempt in range(self.reruns + 1):
            again = resuming and attempt == 0
            self.tracker.begin(index, carried_s=carried_s, resumed=again)
            self.checkpoint()
            if again and self._hicem_goes_on(step):
                ok, message = True, "resumed by HICEM"
            else:
                ok, message = self._start(step)
            if not ok:
                if rospy.is_shutdown():
                    return self._shut_down(step)
                self.tracker.end(status="failed", detail="%s: %s" % (NOT_STARTED, message))
                self.ended = JobEnd("hicem_unreachable" if message.startswith("HICEM's start_process") else
                                    "process_failed", "%s not started: %s" % (step.name, message))
                return False
            deadline = time.monotonic() + self.timeout
            while self.tracker.finished is None and not rospy.is_shutdown() and time.monotonic() < deadline:
                time.sleep(0.1)
                self.while_waiting()
            if self.tracker.finished is None:
                if rospy.is_shutdown():
                    return self._shut_down(step)
                self.tracker.end(status="timeout", detail="no end state within %.0f s" % self.timeout)
                self.ended = JobEnd("process_timeout", "%s did not end within %.0f s" % (step.name, self.timeout))
                return False
            final = self.tracker.finished
            if again and final.get("phase") == "failed" and str(final.get("detail", "")).startswith(
                    "resume failed") and attempt < self.reruns:
                # HICEM could not go on with it from its HDICT: the process is started again (PEMKRE's world state
                # makes it go on where it stopped), not counted as its own failure
                print("[job] HICEM could not resume %s (%s); starting it again" % (step.name, final.get("detail")),
                      flush=True)
                self.tracker.end()
                carried_s = self.tracker.records.pop().duration_s
                continue
            if final.get("phase") == "failed" and _PEER_AWAY.search(final.get("detail", "")) and \
                    attempt < self.reruns:
                # not the process's failure: wait for PEMKRE, then the same process again (its record replaced)
                print("[job] %s ended because PEMKRE was away (%s); waiting for it to run it again"
                      % (step.name, final.get("detail", "")), flush=True)
                try:
                    rospy.wait_for_service("pemkre/next_action", timeout=self.peer_wait)
                except rospy.ROSException:
                    pass
                self.tracker.end()
                self.tracker.records.pop()
                continue
            # the operator pressed STOP: the job ends here; a failed process (a task of its own failed): go on
            record = self.tracker.end()
            self.checkpoint()
            if record.status == "stopped":
                self.ended = JobEnd("operator_stop", "%s stopped%s" % (step.name, (": " + record.detail)
                                                                       if record.detail else ""))
                return False
            return True
        return False


def signal_name(reason: str) -> str:
    """rospy's shutdown reason, with ``signal-2`` spelled ``SIGINT`` (``signal-15``: ``SIGTERM``)."""
    found = re.match(r"signal-(\d+)\Z", reason)
    if found:
        try:
            return signal.Signals(int(found.group(1))).name
        except ValueError:
            pass
    return reason


def _json_call(name: str, **args: Any) -> Dict[str, Any]:
    reply = rospy.ServiceProxy(name, JsonCall)(json.dumps(args))
    if not reply.success:
        raise RuntimeError("%s: %s" % (name, reply.message))
    return json.loads(reply.result)


def _outcome_call(name: str, manual: Dict[str, Any], **args: Any) -> Tuple[Dict[str, Any], str]:
    """``name`` (sim/outcome, sim/save_outcome) called with the planned manual parts ``manual``, without them when
    the worksite refuses them: (the result, the refusal or ''); see :func:`with_manual_plan`."""
    return with_manual_plan(_json_call, name, manual, **args)


OUTCOME_PERIOD_S = 10.0     # the worksite's outcome is read this often while a process runs
END_CALL_TIMEOUT_S = 2.0    # each call made to write the report (the launch may be shutting down)


def _every(period_s: float, action: Callable[[], None]) -> Callable[[], None]:
    """A callable that runs ``action`` when ``period_s`` passed since it last did."""
    due = {"at": time.monotonic() + period_s}

    def tick() -> None:
        if time.monotonic() >= due["at"]:
            due["at"] = time.monotonic() + period_s
            action()
    return tick


class OutcomeCache:
    """The latest worksite outcome the job could read, and when (read in the background, never blocking)."""

    def __init__(self) -> None:
        self.outcome: Dict[str, Any] = {}
        self.at = 0.0
        #: the planned manual parts every read carries (the job's tracker sets it)
        self.manual: Callable[[], Dict[str, Any]] = lambda: {"areas": [], "joints": []}
        self.refused = ""                     # the worksite's refusal of the manual parts at the last read
        self._busy = threading.Lock()

    def refresh_every(self, period_s: float) -> Callable[[], None]:
        """A callable that refreshes the outcome when ``period_s`` passed since its last refresh."""
        return _every(period_s, self.refresh)

    def refresh(self, wait: bool = False) -> None:
        if not self._busy.acquire(blocking=False):
            return
        worker = threading.Thread(target=self._read, name="job-outcome", daemon=True)
        worker.start()
        if wait:
            worker.join(END_CALL_TIMEOUT_S)

    def _read(self) -> None:
        try:
            outcome, refused = timed(lambda: _outcome_call("sim/outcome", self.manual()), END_CALL_TIMEOUT_S * 2,
                                     "sim/outcome")
            if isinstance(outcome.get("joints"), dict):
                self.outcome, self.at, self.refused = outcome, time.monotonic(), refused
        except CallFailed:
            pass
        finally:
            self._busy.release()


def device_addresses(robot_path: str) -> Dict[str, Any]:
    """The device addresses this run's LOCEM uses (robot file + LOCEM's ``robot_overrides``), for the report."""
    from locem_bridge.bridges.config import load_robot_config
    from locem_bridge.job.runs import addresses_of
    try:
        return addresses_of(load_robot_config(robot_path, param("locem/robot_overrides", {}, private=False))).as_dict()
    except Exception as exc:  # the report is written anyway; it says why the addresses are missing
        return {"error": str(exc).splitlines()[0] if str(exc) else type(exc).__name__}


def open_journal(path: str, steps: List[JobStep], resume: bool) -> Tuple[Optional[JobJournal], Optional[float]]:
    """The run's journal at ``path`` (none without a path) and, when ``resume``, since when PEMKRE's processes
    belong to this run (None: a fresh run). A journal that cannot be used for these steps is a configuration
    error; a resume without a journal goes by PEMKRE's log alone (every process it holds counts)."""
    if not path:
        if resume:
            raise ConfigError("resume needs the run's journal (the job node's ~journal parameter is empty)",
                              key="journal")
        return None, None
    if not resume:
        if os.path.exists(path):
            raise ConfigError("%s exists: this run_id's run has begun before; give resume:=true to go on with it, "
                              "or another run_id for a fresh run" % path, key="resume")
        journal = JobJournal.fresh(path, steps)
        since: Optional[float] = None
    elif os.path.exists(path):
        try:
            journal = JobJournal.load(path, steps)
        except JournalError as exc:
            raise ConfigError(str(exc), key="resume")
        since = journal.launches[0].started if journal.launches else 0.0
    else:
        print("[job] resume: no job journal at %s; going by PEMKRE's log alone" % path, flush=True)
        journal, since = JobJournal.fresh(path, steps), 0.0
    try:
        journal.begin_launch()
    except OSError as exc:
        raise ConfigError("cannot write the job's journal: %s" % exc, key="journal")
    return journal, since


def save_journal(journal: JobJournal, tracker: JobTracker) -> None:
    try:
        journal.capture(tracker)
    except OSError as exc:         # the job goes on; a resume would repeat what was not saved
        rospy.logwarn_throttle(60.0, "job: the journal %s could not be written: %s" % (journal.path, exc))


def resume_job(steps: List[JobStep], journal: JobJournal, tracker: JobTracker, since: float) -> Tuple[int, float]:
    """Where the resumed job goes on (the index of the step, the time already spent on it): from the journal and
    PEMKRE's execution log (``kpi_by_process``; the journal alone when PEMKRE does not answer)."""
    rows: List[Dict[str, Any]] = []
    try:
        timed(lambda: rospy.wait_for_service("pemkre/query", timeout=30.0), 31.0, "pemkre/query")
        rows = kpi_rows(timed(lambda: rospy.ServiceProxy("pemkre/query", PemkreQuery)("kpi_by_process", [], []),
                              10.0, "pemkre/query kpi_by_process"))
    except CallFailed as exc:
        print("[job] resume: PEMKRE's log could not be read (%s); going by the job's journal alone" % exc, flush=True)
    point = resume_point(steps, journal, rows, since)
    journal.restore(tracker, point.records)
    for note in point.notes:
        print("[job] resume: %s" % note, flush=True)
    done = ", ".join("%s %s" % (r.name, r.status) for r in point.records) or "none"
    print("[job] resuming the run (launch %d): done before: %s; %s" % (
        len(journal.launches), done, ("going on with %s" % steps[point.index].name) if point.index < len(steps)
        else "nothing left to run"), flush=True)
    return point.index, point.carried_s


@config_guard("job")
def main() -> None:
    rospy.init_node("job")
    shutdown: Dict[str, str] = {}
    rospy.core.add_preshutdown_hook(lambda reason: shutdown.setdefault("reason", signal_name(str(reason))))
    steps = load_steps(param("job", os.path.join(package_share(), "config", "jobs", "plasterboard.yaml")),
                       param("validate_lines", ""))
    results_dir = param("results_dir", "") or os.environ.get("LOCEM_RESULTS") or os.path.abspath("results")
    timeout = param("process_timeout", 900.0)
    settings = json.loads(param("settings", "{}"))
    if settings.get("robot"):       # read now, while the master is surely there
        settings.setdefault("devices", device_addresses(str(settings["robot"])))
    journal, since = open_journal(param("journal", ""), steps, param("resume", False))
    outcomes = OutcomeCache()
    scan: Dict[str, Any] = {}
    not_started: Optional[JobEnd] = None       # the job could not begin: still a report saying why
    service = ""
    try:
        for service in ("hicem/start_process", "sim/outcome", "sim/scan", "sim/save_outcome"):
            rospy.wait_for_service(service, timeout=120)
        service = "sim/scan"
        scan = _json_call(service)
        service = "sim/outcome"
        outcomes.outcome, outcomes.at = _outcome_call(service, outcomes.manual())[0], time.monotonic()
    except (rospy.ROSException, rospy.ServiceException, RuntimeError) as exc:
        not_started = (JobEnd("shutdown", "the launch shut down (%s) before the job started" % shutdown.get(
            "reason", "ROS shutdown")) if rospy.is_shutdown() else
            JobEnd("hicem_unreachable" if service.startswith("hicem") else "worksite_unreachable",
                   "%s: %s" % (service, exc)))
    totals = {"joints": len(outcomes.outcome.get("joints", {})), "areas": len(scan.get("areas", []))}
    tracker = JobTracker(steps, totals, say=lambda line: print(line, flush=True))
    outcomes.manual = tracker.manual_plan
    checkpoint = (lambda: save_journal(journal, tracker)) if journal is not None else (lambda: None)
    refresh = outcomes.refresh_every(OUTCOME_PERIOD_S)
    keep = _every(SAVE_PERIOD_S, checkpoint)
    sequencer = ProcessSequencer(tracker, timeout, param("peer_wait", 120.0),
                                 while_waiting=lambda: (refresh(), keep()),
                                 shutdown_reason=lambda: shutdown.get("reason", "ROS shutdown"),
                                 checkpoint=checkpoint)

    def on_state(m: Any) -> None:
        state = {"process": m.process, "phase": m.phase, "action_type": m.action_type, "task": m.task,
                 "skill": getattr(m, "skill", ""), "detail": m.detail}
        sequencer.on_state(state)
        tracker.on_state(state)
    rospy.Subscriber("hicem/state", HicemState, on_state)
    rospy.Subscriber("hicem/prompts", HicemPrompt, lambda m: tracker.on_prompt(
        {"event": m.event, "kind": m.kind, "text": m.text, "answer": m.answer}))
    started = time.time()
    time.sleep(0.5)  # let the latched state arrive before the first start
    sequencer.ended = not_started
    first, carried = 0, 0.0
    if journal is not None and since is not None and not_started is None:
        first, carried = resume_job(steps, journal, tracker, since)
        checkpoint()
    for index, step in enumerate(steps if not_started is None else []):
        if index < first:
            continue
        if rospy.is_shutdown():
            sequencer.ended = JobEnd("shutdown", "the launch shut down (%s) before %s started" % (
                shutdown.get("reason", "ROS shutdown"), step.name))
            break
        if not sequencer.run(index, step, resuming=index == first and since is not None,
                             carried_s=carried if index == first else 0.0):
            break
        outcomes.refresh()
    ended = sequencer.ended
    if ended is None:
        failed = [r for r in tracker.records if r.status != "succeeded"]
        ended = JobEnd("process_failed", "; ".join("%s %s%s" % (r.name, r.status, (": " + r.detail) if r.detail
                                                                 else "") for r in failed)) if failed else \
            JobEnd("completed")
    # steps never run, and steps HICEM never started (a resume runs them): the job did not run to its end
    ended.not_run = [r.name for r in tracker.records if r.detail.startswith(NOT_STARTED)] + \
        [s.name for s in steps[len(tracker.records):]]
    if ended.reason == "process_failed":
        try:   # a process that failed because PEMKRE was gone is not the process's own failure
            timed(lambda: rospy.wait_for_service("pemkre/query", timeout=END_CALL_TIMEOUT_S), END_CALL_TIMEOUT_S + 0.5,
                  "pemkre/query")
        except CallFailed:
            ended.reason = "pemkre_unreachable"
    pictures_dir = tempfile.mkdtemp(prefix="locem_job_")
    refused = ""
    try:
        outcome, refused = timed(lambda: _outcome_call("sim/save_outcome", tracker.manual_plan(), folder=pictures_dir),
                                 END_CALL_TIMEOUT_S, "sim/save_outcome")
    except CallFailed as exc:   # the launch is shutting down: use what was collected
        outcome, refused = outcomes.outcome, outcomes.refused
        age = time.monotonic() - outcomes.at
        ended.unread.append("final outcome and wall pictures (%s); the outcome shown was read %.0f s before the "
                            "end" % (exc, age) if outcome else "the worksite's outcome (%s)" % exc)
        print("[job] no final outcome from the simulation (%s): report with the outcome read %.0f s earlier, no "
              "pictures" % (exc, age), flush=True)
    if refused:
        ended.unread.append("the parts planned for manual work, in the outcome (%s): its figures count the whole "
                            "work as the robot's" % refused)
    kpis: List[Dict[str, Any]] = []
    try:
        kpis = kpi_rows(timed(lambda: rospy.ServiceProxy("pemkre/query", PemkreQuery)("kpi_by_task_type", [], []),
                              END_CALL_TIMEOUT_S, "pemkre/query kpi_by_task_type"))
    except CallFailed as exc:
        ended.unread.append("KPI table (%s)" % exc)
    settings.setdefault("interventions_by_kind", tracker.interventions)
    timing = {"wall_clock_s": time.time() - started}
    launches: List[Dict[str, Any]] = []
    if journal is not None:
        try:
            journal.capture(tracker)
            journal.end_launch(ended.reason)
        except OSError as exc:
            print("[job] the job's journal %s could not be written: %s" % (journal.path, exc), flush=True)
        launches = journal.report_launches()
        timing.update(journal.report_timing())       # one report over every launch of the run
    record = RunRecord(processes=tracker.records, outcome=outcome, operator_interventions=tracker.total_interventions,
                       collisions=int(outcome.get("collisions", 0)), settings=settings, kpis=kpis, launches=launches,
                       timing=timing,
                       pictures=[os.path.join(pictures_dir, p) for p in outcome.get("pictures", [])],
                       manual_areas=tracker.manual_areas, manual_joints=tracker.manual_joints, ended=ended)
    folder = write_report(record, results_dir, run=param("run", "") or None)
    print("[job] ended: %s%s%s" % (ended.reason, " (early)" if ended.as_dict()["early"] else "",
                                   (": " + ended.detail) if ended.detail else ""), flush=True)
    print("[job] report: %s" % os.path.join(folder, "report.md"), flush=True)
    ok = all(r.status == "succeeded" for r in tracker.records) and len(tracker.records) == len(steps)
    rospy.signal_shutdown("job done")
    raise SystemExit(0 if ok else 1)


if __name__ == "__main__":
    main()
