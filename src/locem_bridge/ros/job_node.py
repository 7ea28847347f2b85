"""ROS node ``plasterboard_job``: runs a job (processes in order) through HICEM and writes the run report.

Parameters (private): ``job`` (YAML with ``steps: [{name, process, options}]``, default
``config/jobs/plasterboard.yaml``), ``validate_lines`` (overrides the taping option; empty = the file's),
``results_dir`` (default ``$LOCEM_RESULTS`` or ``./results``), ``process_timeout`` (s per process),
``settings`` (JSON copied into the report). Services used: ``hicem/start_process``, ``sim/outcome``,
``sim/scan``, ``sim/save_outcome``, and ``pemkre/query`` for the KPI table when present. Exits when the job is
done (0 when every process ended, 1 otherwise), so a launch file can mark it ``required``.
"""

import json
import os
import tempfile
import time
from typing import Any, Dict, List

import rospkg
import rospy
import yaml

from locem_bridge.config_errors import ConfigError
from locem_bridge.job.report import RunRecord, write_report
from locem_bridge.job.tracker import JobStep, JobTracker
from locem_bridge.msg import HicemPrompt, HicemState
from locem_bridge.srv import HicemStartProcess, JsonCall, PemkreQuery
from locem_bridge.ros.startup import config_guard


def load_steps(path: str, validate_lines: Any) -> List[JobStep]:
    """The job file's steps; a bad file raises :class:`ConfigError` (one line: file, key, problem)."""
    try:
        with open(path, encoding="utf-8") as handle:
            doc = yaml.safe_load(handle) or {}
    except OSError as exc:
        raise ConfigError("cannot be read: %s" % exc.strerror, file=path)
    except yaml.YAMLError as exc:
        raise ConfigError("not valid YAML: %s" % (getattr(exc, "problem", None) or exc), file=path)
    if not isinstance(doc, dict) or not isinstance(doc.get("steps", []), list):
        raise ConfigError("must hold a mapping with a list 'steps'", file=path, key="steps")
    steps = []
    for i, entry in enumerate(doc.get("steps", [])):
        key = "steps[%d]" % i
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) or \
                not isinstance(entry.get("process"), str):
            raise ConfigError("needs a name and a process (IRI), found %r" % (entry,), file=path, key=key)
        options = entry.get("options") or {}
        if not isinstance(options, dict):
            raise ConfigError("must be a mapping, found %r" % (options,), file=path, key=key + ".options")
        options = dict(options)
        if validate_lines not in ("", None) and "validateLines" in options:
            options["validateLines"] = str(validate_lines).lower() in ("true", "1", "yes")
        steps.append(JobStep(entry["name"], entry["process"], options))
    if not steps:
        raise ConfigError("lists no steps", file=path, key="steps")
    return steps


def kpi_rows(reply: Any) -> List[Dict[str, Any]]:
    if not reply.success:
        return []
    results = json.loads(reply.results)
    rows = []
    for binding in results.get("results", {}).get("bindings", []):
        rows.append({name: value.get("value") for name, value in binding.items()})
    return rows


def _json_call(name: str, **args: Any) -> Dict[str, Any]:
    reply = rospy.ServiceProxy(name, JsonCall)(json.dumps(args))
    if not reply.success:
        raise RuntimeError("%s: %s" % (name, reply.message))
    return json.loads(reply.result)


@config_guard("job")
def main() -> None:
    rospy.init_node("job")
    share = rospkg.RosPack().get_path("locem_bridge")
    steps = load_steps(rospy.get_param("~job", os.path.join(share, "config", "jobs", "plasterboard.yaml")),
                       rospy.get_param("~validate_lines", ""))
    results_dir = rospy.get_param("~results_dir", "") or os.environ.get("LOCEM_RESULTS") or os.path.abspath("results")
    timeout = float(rospy.get_param("~process_timeout", 900.0))
    settings = json.loads(rospy.get_param("~settings", "{}") or "{}")
    for service in ("hicem/start_process", "sim/outcome", "sim/scan", "sim/save_outcome"):
        rospy.wait_for_service(service, timeout=120)
    scan = _json_call("sim/scan")
    totals = {"joints": len(_json_call("sim/outcome").get("joints", {})), "areas": len(scan.get("areas", []))}
    tracker = JobTracker(steps, totals, say=lambda line: print(line, flush=True))
    rospy.Subscriber("hicem/state", HicemState, lambda m: tracker.on_state(
        {"process": m.process, "phase": m.phase, "action_type": m.action_type, "task": m.task, "detail": m.detail}))
    rospy.Subscriber("hicem/prompts", HicemPrompt, lambda m: tracker.on_prompt(
        {"event": m.event, "kind": m.kind, "text": m.text, "answer": m.answer}))
    start_process = rospy.ServiceProxy("hicem/start_process", HicemStartProcess)
    started = time.time()
    rospy.sleep(0.5)  # let the latched state arrive before the first start
    for index, step in enumerate(steps):
        tracker.begin(index)
        reply = start_process(step.iri, json.dumps(dict(step.options)))
        if not reply.success:
            tracker.end(status="failed", detail="not started: %s" % reply.message)
            break
        deadline = time.monotonic() + timeout
        while tracker.finished is None and not rospy.is_shutdown() and time.monotonic() < deadline:
            rospy.sleep(0.1)
        if tracker.finished is None:
            tracker.end(status="timeout" if not rospy.is_shutdown() else "stopped",
                        detail="no end state within %.0f s" % timeout)
            break
        if tracker.end().status == "stopped":     # the operator pressed STOP: the job ends here
            break
    pictures_dir = tempfile.mkdtemp(prefix="locem_job_")
    try:
        outcome = _json_call("sim/save_outcome", folder=pictures_dir)
    except (rospy.ServiceException, rospy.ROSException, RuntimeError) as exc:   # the launch is shutting down
        print("[job] no outcome from the simulation (%s): report without pictures" % exc, flush=True)
        outcome = {}
    kpis: List[Dict[str, Any]] = []
    try:
        rospy.wait_for_service("pemkre/query", timeout=2.0)
        kpis = kpi_rows(rospy.ServiceProxy("pemkre/query", PemkreQuery)("kpi_by_task_type", [], []))
    except rospy.ROSException:
        pass
    settings.setdefault("interventions_by_kind", tracker.interventions)
    record = RunRecord(processes=tracker.records, outcome=outcome, operator_interventions=tracker.total_interventions,
                       collisions=int(outcome.get("collisions", 0)), settings=settings, kpis=kpis,
                       timing={"wall_clock_s": time.time() - started},
                       pictures=[os.path.join(pictures_dir, p) for p in outcome.get("pictures", [])],
                       manual_areas=tracker.manual_areas)
    folder = write_report(record, results_dir)
    print("[job] report: %s" % os.path.join(folder, "report.md"), flush=True)
    ok = all(r.status == "succeeded" for r in tracker.records) and len(tracker.records) == len(steps)
    rospy.signal_shutdown("job done")
    raise SystemExit(0 if ok else 1)


if __name__ == "__main__":
    main()
