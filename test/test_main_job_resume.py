"""``tools/main.sh --resume [RUN]`` refusing what it cannot resume, before anything is launched (one line, exit
status 2), and leaving a completed run alone. The resume itself, after a power loss: test_power_loss.py."""
import json
import os
import shutil

import pytest

from locem_bridge.ros import main_job

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
READY = os.environ.get("LOCEM_REPO") == REPO and shutil.which("roslaunch") is not None
pytestmark = pytest.mark.skipif(not READY, reason="needs the environment of tools/test.sh (setup done, ROS sourced)")
JOB = os.path.join(REPO, "config", "jobs", "plasterboard.yaml")


def a_run(results, name, started, job=JOB, report=None):
    """The state folder main_job leaves for a run (its run.json), optionally with the run's report."""
    args = main_job.arguments(["--results-dir", str(results), "--job", job])
    folder = main_job.write_run_file(args, name)
    with open(os.path.join(folder, main_job.RUN_FILE)) as handle:
        doc = json.load(handle)
    doc["started"] = started
    with open(os.path.join(folder, main_job.RUN_FILE), "w") as handle:
        json.dump(doc, handle)
    if report is not None:
        os.makedirs(str(results / name))
        with open(str(results / name / "report.json"), "w") as handle:
            json.dump(report, handle)
    return folder


def test_nothing_to_resume_and_an_unknown_run_are_refused_naming_what_there_is(tmp_path, capsys):
    results = tmp_path / "results"
    assert main_job.main(["--results-dir", str(results), "--resume"]) == 2
    assert "[main] cannot resume: no run to resume in %s" % results in capsys.readouterr().out
    a_run(results, "20261130-100000", 1.0)
    a_run(results, "20261130-110000", 2.0)
    assert main_job.main(["--results-dir", str(results), "--resume", "20261130-120000"]) == 2
    assert "no run '20261130-120000' to resume in %s; runs there: 20261130-100000, 20261130-110000" % results in \
        capsys.readouterr().out


def test_a_resumed_run_keeps_its_options(tmp_path, capsys):
    results = tmp_path / "results"
    a_run(results, "20261130-100000", 1.0)
    assert main_job.main(["--results-dir", str(results), "--resume", "--site", "other.yaml", "--time-scale", "2"]) == 2
    out = capsys.readouterr().out
    assert "--site, --time-scale cannot be given with --resume: run 20261130-100000 goes on with the options it " \
           "began with" in out and "--timeout" in out
    # also with the option's default value: the run may have begun with another
    assert main_job.main(["--results-dir", str(results), "--resume", "--time-scale=10"]) == 2
    assert "--time-scale cannot be given with --resume" in capsys.readouterr().out


def test_a_run_whose_launch_still_holds_its_lock_is_not_started_twice(tmp_path, capsys):
    results = tmp_path / "results"
    folder = a_run(results, "20261130-100000", 1.0)
    import fcntl
    with open(os.path.join(folder, "run.lock"), "w") as held:      # main.sh killed, its roslaunch still up
        fcntl.flock(held, fcntl.LOCK_EX)
        assert main_job.main(["--results-dir", str(results), "--resume"]) == 2
    out = capsys.readouterr().out
    assert "[main] cannot start: run 20261130-100000 is still running (a launch of it holds %s" % os.path.join(
        folder, "run.lock") in out


def test_the_latest_run_is_resumed_with_its_own_options_and_one_that_ran_to_its_end_is_left_alone(tmp_path, capsys):
    results = tmp_path / "results"
    a_run(results, "20261130-100000", 2.0)
    a_run(results, "20261130-110000", 3.0, report={"ended": {"reason": "process_failed", "early": False}})
    args, run = main_job.resumed_arguments(main_job.arguments(["--results-dir", str(results), "--resume",
                                                                 "--timeout", "50"]))
    assert run == "20261130-110000" and args.job == JOB and args.timeout == 50 and args.resume == "latest"
    assert main_job.main(["--results-dir", str(results), "--resume"]) == 0
    assert "[main] run 20261130-110000 ran to its end already: nothing to resume" in capsys.readouterr().out
    # the latest run ran to its end and its state is gone: not an older run cut short, resumed instead
    shutil.rmtree(str(results / ("20261130-110000" + main_job.STATE_SUFFIX)))
    assert main_job.main(["--results-dir", str(results), "--resume"]) == 0
    assert "[main] run 20261130-110000 ran to its end already" in capsys.readouterr().out
    os.remove(str(results / "20261130-110000" / "report.json"))
    os.makedirs(str(results / "20261130-120000"))
    with open(str(results / "20261130-120000" / "report.json"), "w") as handle:      # cut short, state removed
        json.dump({"ended": {"reason": "shutdown", "early": True}}, handle)
    assert main_job.main(["--results-dir", str(results), "--resume"]) == 2
    assert "no run to resume in %s: the latest, 20261130-120000, keeps no state" % results in capsys.readouterr().out


def test_a_run_whose_job_file_changed_is_refused_before_the_launch(tmp_path, capsys):
    results = tmp_path / "results"
    job = tmp_path / "job.yaml"
    shutil.copy(JOB, str(job))
    folder = a_run(results, "20261130-100000", 1.0, job=str(job))
    from locem_bridge.job.journal import JobJournal
    from locem_bridge.job.steps import load_steps
    JobJournal.fresh(os.path.join(folder, "20261130-100000_job.json"), load_steps(str(job))).begin_launch()
    with open(str(job)) as handle:
        text = handle.read()
    with open(str(job), "w") as handle:          # the sanding step taken out after the run began
        handle.write(text[:text.index("  - name: sanding")])
    assert main_job.main(["--results-dir", str(results), "--resume"]) == 2
    out = capsys.readouterr().out
    assert "[main] configuration error: %s" % os.path.join(folder, "20261130-100000_job.json") in out
    assert "the job file now has taping" in out and "resume with the job file the run began with" in out
