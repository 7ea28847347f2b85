"""The run report: fixed keys, manual joints excluded from tape coverage, atomic folder, results/latest."""
import datetime
import json
import os

import pytest

from locem_bridge.job.report import (ENDED_REASONS, REQUIRED_OUTCOME_KEYS, JobEnd, ProcessRecord, ReportError,
                                     RunRecord, write_report)


def outcome(manual=("w1_j2",)):
    joints = {"w1_j1": {"coverage": 1.0, "taped": True}, "w1_j2": {"coverage": 0.0, "taped": False},
              "w2_j1": {"coverage": 0.98, "taped": True}}
    for jid in manual:
        joints[jid]["manual"] = True
    return {"joints": joints, "spray_coverage": 0.991, "sand_coverage": 0.985,
            "walls": {"w1": {"thickness_cv": 0.08}, "w2": {"thickness_cv": 0.11}}}


def record(tmp_path, **kw):
    picture = tmp_path / "w1.png"
    picture.write_bytes(b"\x89PNG\r\n\x1a\nfake")
    values = dict(processes=[ProcessRecord("taping", "urn:p:taping", "succeeded", 61.24),
                             ProcessRecord("spraying", "urn:p:spraying", "failed", 12.0, "link lost")],
                  outcome=outcome(), operator_interventions=4, collisions=0, settings={"validate_lines": True},
                  kpis=[{"task_type": "TAPE_LINE", "count": 2, "success_rate": 1.0}],
                  timing={"wall_clock_s": 80.0, "pemkre_s": 0.4}, pictures=[str(picture)],
                  started=datetime.datetime(2026, 11, 22, 6, 30, 0))
    values.update(kw)
    return RunRecord(**values)


def test_report_has_the_fixed_keys_and_excludes_manual_joints(tmp_path):
    folder = write_report(record(tmp_path), str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    assert [p["name"] for p in report["processes"]] == ["taping", "spraying"]
    assert set(REQUIRED_OUTCOME_KEYS) <= set(report["outcome"])
    o = report["outcome"]
    assert (o["joints_total"], o["joints_taped"], o["joints_manual"]) == (3, 2, 1)
    assert o["tape_coverage"] == pytest.approx(0.99)  # mean of 1.0 and 0.98; the manual joint is excluded
    assert o["spray_thickness_cv"] == pytest.approx(0.11)
    assert report["pictures"] == ["w1.png"] and os.path.exists(os.path.join(folder, "w1.png"))
    md = open(os.path.join(folder, "report.md")).read()
    assert "| joints taped by the robot | 2 of 2 (1 manual) |" in md and "![w1](w1.png)" in md


def test_latest_points_at_the_newest_run(tmp_path):
    results = str(tmp_path / "results")
    write_report(record(tmp_path), results, run="first")
    write_report(record(tmp_path), results, run="second")
    assert os.readlink(os.path.join(results, "latest")) == "second"
    assert json.load(open(os.path.join(results, "latest", "report.json")))["run"] == "second"
    assert not [n for n in os.listdir(results) if n.endswith(".partial")]


def test_inconsistent_outcome_is_refused_and_nothing_is_written(tmp_path):
    results = tmp_path / "results"
    with pytest.raises(ReportError, match="outcome.joints"):
        write_report(record(tmp_path, outcome={"spray_coverage": 1.0}), str(results))
    bad = outcome()
    bad["spray_coverage"] = 1.7
    with pytest.raises(ReportError, match="spray_coverage = 1.7 is not a fraction"):
        write_report(record(tmp_path, outcome=bad), str(results))
    assert not results.exists() or not os.listdir(str(results))


def test_area_sections_left_for_manual_work_are_listed(tmp_path):
    manual = [{"work": "sand", "area": "wall_1_area_1", "section": 3, "along": [1.2, 1.8], "height": [0.0, 2.5]}]
    folder = write_report(record(tmp_path, manual_areas=manual), str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    assert report["outcome"]["areas_manual"] == manual
    md = open(os.path.join(folder, "report.md")).read()
    assert "| area sections left for manual work | sand wall_1_area_1 section 3 (along 1.2..1.8 m, height 0..2.5 m) |" \
        in md
    folder = write_report(record(tmp_path), str(tmp_path / "results2"))
    assert json.loads(open(os.path.join(folder, "report.json")).read())["outcome"]["areas_manual"] == []
    assert "| area sections left for manual work | none |" in open(os.path.join(folder, "report.md")).read()


def test_a_complete_job_says_it_ended_normally(tmp_path):
    folder = write_report(record(tmp_path), str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    assert report["ended"] == {"reason": "completed", "early": False, "what": ENDED_REASONS["completed"],
                               "detail": "", "not_run": [], "unread": []}
    assert report["outcome"]["measured"] is True


def test_a_job_cut_short_by_a_shutdown_still_gets_its_report(tmp_path):
    """The launch shut down during spraying: the simulation no longer answers, PEMKRE neither; the report says
    why the job ended, what never ran and what could not be read, with the outcome collected before."""
    ended = JobEnd("shutdown", "the launch shut down (signal-2) while spraying was running", not_run=["sanding"],
                   unread=["final outcome and pictures (sim/save_outcome): no answer within 2.0 s; the outcome "
                           "shown was read 4 s before the end", "KPI table (pemkre/query): no answer within 2.0 s"])
    rec = record(tmp_path, processes=[ProcessRecord("taping", "urn:p:taping", "succeeded", 61.2),
                                      ProcessRecord("spraying", "urn:p:spraying", "stopped", 12.0, "launch shut down")],
                 pictures=[], kpis=[], ended=ended)
    folder = write_report(rec, str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    assert report["ended"]["reason"] == "shutdown" and report["ended"]["early"] is True
    assert report["ended"]["not_run"] == ["sanding"] and len(report["ended"]["unread"]) == 2
    assert report["outcome"]["joints_taped"] == 2                     # what was collected is kept
    md = open(os.path.join(folder, "report.md")).read()
    assert "**Ended: shutdown** (early)" in md and "while spraying was running" in md
    assert "Not run: sanding" in md and "Could not be read: KPI table (pemkre/query)" in md


def test_nothing_measured_is_reported_not_refused(tmp_path):
    """Neither the simulation nor anyone else ever answered: still a report, saying the outcome is unmeasured."""
    rec = record(tmp_path, processes=[], outcome={}, pictures=[], kpis=[],
                 ended=JobEnd("hicem_unreachable", "hicem/start_process: unable to connect", ["taping", "spraying"],
                              ["outcome (sim/outcome): no answer within 2.0 s"]))
    folder = write_report(rec, str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    o = report["outcome"]
    assert o["measured"] is False and (o["joints_total"], o["tape_coverage"], o["spray_coverage"]) == (0, 0.0, 0.0)
    assert report["ended"]["reason"] == "hicem_unreachable" and report["ended"]["not_run"] == ["taping", "spraying"]
    assert "could not be measured" in open(os.path.join(folder, "report.md")).read()


def test_an_unknown_end_reason_is_refused(tmp_path):
    with pytest.raises(ReportError, match="ended.reason 'crashed' is not one of completed, process_failed"):
        write_report(record(tmp_path, ended=JobEnd("crashed")), str(tmp_path / "results"))
    assert not (tmp_path / "results").exists()


def test_early_means_the_job_did_not_run_to_its_end():
    assert JobEnd("shutdown", "while sanding was running").as_dict()["early"] is True    # last step cut short
    assert JobEnd("process_timeout").as_dict()["early"] is True
    assert JobEnd("process_failed", "spraying failed").as_dict()["early"] is False        # the job went on to its end
    assert JobEnd("process_failed", "taping not started", not_run=["spraying"]).as_dict()["early"] is True
