"""The job's journal on disk and where a resumed job goes on (``tools/main.sh --resume``)."""
import datetime
import json
import os

import pytest

from locem_bridge.job.journal import JobJournal, JournalError, resume_point
from locem_bridge.job.report import JobEnd, ProcessRecord, RunRecord, render_markdown, build_report
from locem_bridge.job.tracker import JobStep, JobTracker

TAPING = JobStep("taping", "urn:p#Taping", {"validateLines": False})
SPRAYING = JobStep("spraying", "urn:p#Spraying")
SANDING = JobStep("sanding", "urn:p#Sanding")
STEPS = [TAPING, SPRAYING, SANDING]
T0 = 1_800_000_000.0


class Clock:
    def __init__(self, t=T0):
        self.t = t

    def __call__(self):
        return self.t


def running_job(tmp_path, clock):
    """A journal and a tracker of a job that finished taping and has worked 12 s on spraying."""
    journal = JobJournal.fresh(str(tmp_path / "run_job.json"), STEPS, clock=clock)
    journal.begin_launch()
    tracker = JobTracker(STEPS, {"joints": 2, "areas": 1}, say=lambda line: None, clock=clock)
    tracker.begin(0)
    clock.t += 30.0
    tracker.on_state({"process": TAPING.iri, "phase": "ended", "detail": "completed"})
    tracker.end()
    tracker.on_prompt({"event": "answered", "kind": "mount_tool"})
    tracker.begin(1)
    tracker.manual_areas.append({"work": "spray", "area": "a1", "section": 2, "along": [0.0, 0.5],
                                 "height": [1.5, 2.0]})
    clock.t += 12.0
    journal.capture(tracker)
    return journal, tracker


def pemkre_row(step, status, started, ended=None, duration=None):
    row = {"abstractProcess": step.iri, "status": status,
           "startedAt": datetime.datetime.fromtimestamp(started, tz=datetime.timezone.utc).isoformat()}
    if ended is not None:
        row["endedAt"] = ended
    if duration is not None:
        row["durationSeconds"] = str(duration)
    return row


def test_a_saved_journal_reads_back_whole_and_the_resumed_job_goes_on_with_the_running_process(tmp_path):
    clock = Clock()
    journal, _ = running_job(tmp_path, clock)
    assert not os.path.exists(journal.path + ".tmp")
    back = JobJournal.load(journal.path, STEPS, clock=clock)
    assert [r.name for r in back.records] == ["taping"] and back.records[0].status == "succeeded"
    assert back.records[0].duration_s == pytest.approx(30.0)
    assert back.current == {"index": 1, "spent_s": 12.0}
    assert back.interventions == {"mount_tool": 1}
    assert back.manual_areas[0]["area"] == "a1"
    assert len(back.launches) == 1 and back.launches[0].ended == ""

    point = resume_point(STEPS, back, [pemkre_row(TAPING, "ended", T0 + 1), pemkre_row(SPRAYING, "running", T0 + 31)])
    assert point.index == 1 and point.carried_s == pytest.approx(12.0) and point.notes == []
    tracker = JobTracker(STEPS, {}, say=lambda line: None, clock=clock)
    back.restore(tracker, point.records)
    tracker.begin(point.index, carried_s=point.carried_s, resumed=True)
    clock.t += 8.0
    tracker.on_state({"process": SPRAYING.iri, "phase": "ended"})
    record = tracker.end()
    # the process's time covers both launches; interventions and manual parts of the first launch are kept
    assert record.duration_s == pytest.approx(20.0)
    assert [r.name for r in tracker.records] == ["taping", "spraying"]
    assert tracker.interventions == {"mount_tool": 1} and tracker.manual_plan()["areas"][0]["area"] == "a1"


def test_an_end_the_journal_missed_is_taken_from_pemkres_log_and_older_processes_do_not_count(tmp_path):
    clock = Clock()
    journal = JobJournal.fresh(str(tmp_path / "j.json"), STEPS, clock=clock)
    journal.begin_launch()
    journal.current = {"index": 0, "spent_s": 40.0}      # cut after taping ended, before the journal said so
    rows = [pemkre_row(TAPING, "ended", T0 + 2, duration=41.5),
            pemkre_row(SPRAYING, "ended", T0 - 3600)]   # an earlier job's spraying in the same store
    point = resume_point(STEPS, journal, rows)
    assert point.index == 1 and point.carried_s == 0.0
    assert point.records[0].status == "succeeded" and point.records[0].duration_s == pytest.approx(41.5)
    assert "PEMKRE's log" in point.records[0].detail and point.notes == [
        "taping succeeded according to PEMKRE's log (not in the job's journal)"]
    # PEMKRE's latest process of a step decides; a failed one is done (the job goes on, as it did live)
    rows += [pemkre_row(SPRAYING, "failed", T0 + 50), pemkre_row(SPRAYING, "running", T0 + 40)]
    point = resume_point(STEPS, journal, rows)
    assert [(r.name, r.status) for r in point.records] == [("taping", "succeeded"), ("spraying", "failed")]
    assert point.index == 2


def test_a_stopped_interrupted_or_never_started_process_runs_again_and_a_finished_job_has_nothing_left(tmp_path):
    journal = JobJournal.fresh(str(tmp_path / "j.json"), STEPS, clock=Clock())
    journal.records = [ProcessRecord("taping", TAPING.iri, "succeeded", 10.0),
                       ProcessRecord("spraying", SPRAYING.iri, "interrupted", 5.0, "launch shut down")]
    journal.current = None
    point = resume_point(STEPS, journal, [pemkre_row(SPRAYING, "ended", T0 + 5)], since=T0)
    assert point.index == 1 and [r.name for r in point.records] == ["taping"]
    assert point.carried_s == pytest.approx(5.0)        # the time it ran before the Ctrl-C
    # HICEM never ran it (unreachable, or busy): recorded failed "not started: ...", it is not done
    journal.records[1] = ProcessRecord("spraying", SPRAYING.iri, "failed", 0.0, "not started: HICEM away")
    assert resume_point(STEPS, journal, [], since=T0).index == 1
    journal.records = [ProcessRecord(s.name, s.iri, "succeeded", 1.0) for s in STEPS]
    assert resume_point(STEPS, journal, []).index == 3


def test_a_job_that_runs_one_process_twice_does_not_take_the_first_run_for_the_second(tmp_path):
    steps = [SPRAYING, SANDING, JobStep("spraying_again", SPRAYING.iri)]
    journal = JobJournal.fresh(str(tmp_path / "j.json"), steps, clock=Clock())
    journal.begin_launch()
    journal.current = {"index": 1, "spent_s": 3.0}            # the journal missed the ends of steps 0 and 1
    rows = [pemkre_row(SPRAYING, "failed", T0 + 1),            # started again after PEMKRE was away ...
            pemkre_row(SPRAYING, "ended", T0 + 20),             # ... and ended
            pemkre_row(SANDING, "ended", T0 + 60, duration="3.5")]
    point = resume_point(steps, journal, rows)
    assert [(r.name, r.status) for r in point.records] == [("spraying", "succeeded"), ("sanding", "succeeded")]
    assert point.index == 2                                    # the second spraying has not run
    rows.append(pemkre_row(SPRAYING, "running", T0 + 90))
    assert resume_point(steps, journal, rows).index == 2


def test_pemkres_times_with_any_number_of_fraction_digits_are_read():
    from locem_bridge.job.journal import _epoch
    assert _epoch("2026-11-30T05:00:00.5Z") == pytest.approx(_epoch("2026-11-30T05:00:00Z") + 0.5)
    assert _epoch("2026-11-30T05:00:00.1234567+00:00") == pytest.approx(_epoch("2026-11-30T05:00:00Z") + 0.123456)


@pytest.mark.parametrize("content, expected", [
    (None, "no job journal there"),
    ("{not json", "cannot be read as a job journal"),
    (json.dumps({"format": 99}), "not a job journal of format 1 (found 99)"),
    (json.dumps({"format": 1, "steps": []}), "missing or bad entry"),
])
def test_a_journal_that_cannot_be_used_is_refused_naming_the_file(tmp_path, content, expected):
    path = tmp_path / "j.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(JournalError) as err:
        JobJournal.load(str(path), STEPS)
    assert str(path) in str(err.value) and expected in str(err.value)


def test_a_journal_of_other_steps_is_refused_naming_both(tmp_path):
    journal = JobJournal.fresh(str(tmp_path / "j.json"), STEPS, clock=Clock())
    journal.begin_launch()
    with pytest.raises(JournalError) as err:
        JobJournal.load(journal.path, [TAPING, SANDING])
    text = str(err.value)
    assert "spraying (urn:p#Spraying)" in text and "the job file now has taping (urn:p#Taping, options " \
        '{"validateLines": false}), sanding (urn:p#Sanding)' in text
    # the same steps with another option are another job too
    with pytest.raises(JournalError) as err:
        JobJournal.load(journal.path, [JobStep("taping", TAPING.iri, {"validateLines": True}), SPRAYING, SANDING])
    assert 'options {"validateLines": true}' in str(err.value)


def test_a_save_cut_short_leaves_the_last_whole_journal(tmp_path, monkeypatch):
    clock = Clock()
    journal, tracker = running_job(tmp_path, clock)
    before = open(journal.path).read()

    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(os, "fsync", full_disk)         # the new file cannot reach the disk
    with pytest.raises(OSError):
        journal.capture(tracker)
    monkeypatch.undo()
    assert open(journal.path).read() == before
    assert JobJournal.load(journal.path, STEPS).current == {"index": 1, "spent_s": 12.0}


def test_the_report_lists_every_launch_of_a_resumed_run(tmp_path):
    clock = Clock()
    journal, _ = running_job(tmp_path, clock)
    clock.t += 100.0                                  # power loss; the next launch starts
    journal = JobJournal.load(journal.path, STEPS, clock=clock)
    journal.begin_launch()
    clock.t += 60.0
    journal.end_launch("completed")
    launches = journal.report_launches()
    assert [x["ended"] for x in launches] == ["", "completed"]
    assert launches[0]["wall_clock_s"] == pytest.approx(42.0) and launches[1]["wall_clock_s"] == pytest.approx(60.0)
    report = build_report(RunRecord(processes=[ProcessRecord("taping", TAPING.iri, "succeeded", 30.0)], outcome={},
                                    operator_interventions=1, collisions=0, launches=launches,
                                    ended=JobEnd("completed")), "run1")
    assert [x["ended"] for x in report["launches"]] == ["cut off (no end recorded: a power loss, kill or crash)",
                                                         "completed"]
    text = render_markdown(report)
    assert "## Launches" in text and "one report over its 2 launches" in text and "| 1 |" in text and "| 42 s |" in text
