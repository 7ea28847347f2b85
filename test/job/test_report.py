"""The run report: fixed keys, manual joints excluded from tape coverage, atomic folder, results/latest."""
import datetime
import json
import os

import pytest

from locem_bridge.job.report import REQUIRED_OUTCOME_KEYS, ProcessRecord, ReportError, RunRecord, write_report


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
