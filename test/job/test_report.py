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


def _measured(manual):
    """A real measurement: a 4 m wall sprayed up to the strip planned for the hand, joint 1 taped above its
    manual foot, joint 3 planned wholly manual (and a bit of tape laid on it), joint 2 sent to manual taping."""
    import numpy as np
    from locem_bridge.sim.config import load_robot, validate_site
    from locem_bridge.sim.outcome import OutcomeRecorder
    from locem_bridge.sim.site import Site
    cfg = validate_site({
        "site": {"name": "bay", "room": {"inside": [2.0, 1.5]}, "walls": [
            {"id": "wall_1", "p0": [0.0, 3.0], "p1": [4.0, 3.0], "height": 2.4, "panel_width": 1.2}]},
        "simulation": {"outcome": {"grid": 0.02, "tape_lateral_tolerance": 0.015, "contact_tolerance": 0.01,
                                   "spray_rate": 0.004, "spray_target_thickness": 0.001}}})
    site = Site(cfg)
    tools = load_robot()["robot"]["tools"]
    rec = OutcomeRecorder(site, tools, cfg["simulation"]["outcome"])
    wall = site.wall("wall_1")
    off = tools["spray_gun"]["standoff"] * wall.n
    for t in np.arange(0.0, 2.4 + 1e-9, 0.15):
        rec.record("spray_gun", True, wall.from_wall_coords(-0.1, t) + off, wall.from_wall_coords(3.4, t) + off,
                   -wall.n, 7.0)
    for s, t0, t1 in ((1.2, 0.4, 2.4), (3.6, 1.0, 1.5)):
        a, b = wall.from_wall_coords(s, t0), wall.from_wall_coords(s, t1)
        rec.record("taping_tool", True, a, b, -wall.n, 1.0)
        rec.record("taping_tool", False, b, b, -wall.n, 0.1)
    rec.mark_manual_taping("wall_1_joint_2")
    return rec.summary(manual)


def test_the_reachable_figures_and_the_joint_parts_left_for_manual_work_are_reported(tmp_path):
    areas = [{"work": "spray", "area": "wall_1_area_1", "section": 4, "along": [3.4, 4.0], "height": [0.0, 2.4]}]
    joints = [{"joint": "wall_1_joint_1", "part": 1, "along": [0.0, 0.4], "reason": "below the tool's reach"},
              {"joint": "wall_1_joint_3", "part": 1, "along": [0.0, 2.4], "reason": "out of reach"}]
    plan = {"areas": [{k: m[k] for k in ("work", "area", "along", "height")} for m in areas],
            "joints": [{"joint": m["joint"], "along": m["along"]} for m in joints]}
    folder = write_report(record(tmp_path, outcome=_measured(plan), manual_areas=areas, manual_joints=joints),
                          str(tmp_path / "results"))
    report = json.loads(open(os.path.join(folder, "report.json")).read())
    o = report["outcome"]
    assert set(REQUIRED_OUTCOME_KEYS) <= set(o) and o["areas_manual"] == areas
    assert o["joints_planned_manual"] == joints
    r = o["reachable"]
    assert set(r) == {"tape_coverage_min", "tape_coverage", "spray_coverage", "sand_coverage", "spray_thickness_cv"}
    # robot joints: joint 1 (taped on its reachable part); joint 2 went to manual taping, joint 3 is wholly manual
    assert r["tape_coverage"] == r["tape_coverage_min"] == pytest.approx(1.0)
    assert o["tape_coverage"] == pytest.approx((2.0 / 2.4 + 0.5 / 2.4) / 2, abs=0.01)    # the plain figure: 1 and 3
    assert r["spray_coverage"] >= 0.995 and o["spray_coverage"] == pytest.approx(0.85, abs=0.01)
    assert 0.0 < r["spray_thickness_cv"] < 0.1
    assert o["manual_touched"]["tape_m"] == pytest.approx(0.5, abs=0.03)     # tape laid on joint 3
    assert o["manual_touched"]["spray_m2"] == 0.0 and o["manual_touched"]["sand_m2"] == 0.0
    assert o["joints"]["wall_1_joint_3"]["coverage_reachable"] is None
    md = open(os.path.join(folder, "report.md")).read()
    assert "| tape coverage of the reachable parts | 100.0 % (lowest joint 100.0 %) |" in md
    assert "| spray coverage of the reachable parts | %.1f %% (thickness CV %.3f) |" % (
        100 * r["spray_coverage"], r["spray_thickness_cv"]) in md
    assert "| sand coverage of the reachable parts | 0.0 % |" in md
    assert ("| joint parts left for manual work | wall_1_joint_1 part 1 (along 0..0.4 m; below the tool's reach); "
            "wall_1_joint_3 part 1 (along 0..2.4 m; out of reach) |") in md
    assert "| work done inside the planned manual parts | tape %.2f m, spray 0.000 m2, sand 0.000 m2 |" % (
        o["manual_touched"]["tape_m"]) in md
    assert "| area sections left for manual work | spray wall_1_area_1 section 4" in md


def test_without_planned_manual_parts_the_reachable_figures_are_the_plain_ones(tmp_path):
    folder = write_report(record(tmp_path, outcome=_measured(None)), str(tmp_path / "results"))
    o = json.loads(open(os.path.join(folder, "report.json")).read())["outcome"]
    r = o["reachable"]
    assert (r["tape_coverage"], r["spray_coverage"], r["sand_coverage"], r["spray_thickness_cv"]) == \
        (o["tape_coverage"], o["spray_coverage"], o["sand_coverage"], o["spray_thickness_cv"])
    assert r["tape_coverage_min"] == pytest.approx(0.5 / 2.4, abs=0.01)      # joint 3, partly taped
    assert o["joints_planned_manual"] == [] and o["manual_touched"] == {"tape_m": 0.0, "spray_m2": 0.0, "sand_m2": 0.0}
    md = open(os.path.join(folder, "report.md")).read()
    assert "| joint parts left for manual work | none |" in md


def test_an_outcome_measured_without_a_plan_still_reports_the_reachable_figures(tmp_path):
    """An outcome without the reachable figures (read before the plan was known, or an older worksite): the
    report's reachable figures are the plain ones, nothing touched."""
    folder = write_report(record(tmp_path), str(tmp_path / "results"))
    o = json.loads(open(os.path.join(folder, "report.json")).read())["outcome"]
    assert o["reachable"] == {"tape_coverage_min": 0.98, "tape_coverage": 0.99, "spray_coverage": 0.991,
                              "sand_coverage": 0.985, "spray_thickness_cv": 0.11}
    assert o["manual_touched"] == {"tape_m": 0.0, "spray_m2": 0.0, "sand_m2": 0.0}
