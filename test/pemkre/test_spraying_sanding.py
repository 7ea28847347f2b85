"""Spraying and sanding: the same flow-chart structure on wall areas, one test per branch."""
import pytest
from pemkre_testkit import json_dumps, run_process, scan_result

from locem_bridge.pemkre import PLB, PPR
from locem_bridge.pemkre.vocab import SITE

SPRAY, SAND = str(PLB.SprayingProcess), str(PLB.SandingProcess)
EMPTY = {"stamp": 1.0, "walls": [], "joints": [], "areas": []}


def _scan(scan):
    return lambda a: ("succeeded", json_dumps(scan) if a.action_type == "SCAN" else "")


@pytest.mark.parametrize("process", [SPRAY, SAND])
def test_nothing_at_all_goes_home_and_ends_early(make_engine, process):
    e = make_engine()
    e.start_process(process)
    seen = run_process(e, _scan(EMPTY))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "nothing_to_do"


def test_spraying_skips_the_scan_when_areas_are_left_and_sprays_each_once(make_engine):
    e = make_engine()
    e.update_world(scan_result(walls=2, joints_per_wall=1, areas_per_wall=2))
    e.start_process(SPRAY)
    seen = run_process(e)
    assert [s[0] for s in seen] == ["GET_TOOL"] + ["SPRAY_AREA"] * 4 + ["GO_HOME", "ENDED"]
    assert seen[0][1]["tool"] == "spray_gun"
    assert [s[1]["area"] for s in seen[1:5]] == ["wall_1_area_1", "wall_1_area_2", "wall_2_area_1", "wall_2_area_2"]
    for w in (1, 2):
        for a in (1, 2):
            area = SITE["wall_%d_area_%d" % (w, a)]
            assert e.store.value(area, PPR.sprayingStatus) == PPR.processed
            assert e.store.value(area, PPR.sandingStatus) == PPR.unprocessed
    assert e.check_consistency(full_inference=True) == []


def test_spraying_scans_first_when_nothing_is_left(make_engine):
    e = make_engine()
    e.start_process(SPRAY)
    seen = run_process(e, _scan(scan_result(areas_per_wall=2)))
    assert [s[0] for s in seen] == ["SCAN", "GET_TOOL", "SPRAY_AREA", "SPRAY_AREA", "GO_HOME", "ENDED"]


def test_sanding_works_only_on_sprayed_areas(make_engine):
    e = make_engine()
    e.update_world(scan_result(areas_per_wall=3))
    e.start_process(SPRAY)
    # spray two of three areas; the spray gun fails on the third every time: after RECOVER and the third failed
    # attempt on the same area (the bound of the failure transition) the process fails
    def decide(a):
        if a.action_type == "SPRAY_AREA" and a.params()["area"] == "wall_1_area_3":
            return "failed", "nozzle clogged"
        return "succeeded", ""
    seen = run_process(e, decide)
    assert [s[0] for s in seen] == (["GET_TOOL", "SPRAY_AREA", "SPRAY_AREA"] + ["SPRAY_AREA", "RECOVER"] * 2
                                    + ["SPRAY_AREA", "FAILED"])
    assert "nozzle clogged" in seen[-1][1]["message"] and "no failure transition" in seen[-1][1]["message"]
    e.start_process(SAND)
    seen = run_process(e)
    assert [s[0] for s in seen] == ["GET_TOOL", "SAND_AREA", "SAND_AREA", "GO_HOME", "ENDED"]
    assert seen[0][1]["tool"] == "sander"
    assert [s[1]["area"] for s in seen[1:3]] == ["wall_1_area_1", "wall_1_area_2"]
    assert e.store.value(SITE.wall_1_area_3, PPR.sandingStatus) == PPR.unprocessed
    # all sprayed areas sanded: the next sanding run scans, finds nothing ready, goes home early
    e.start_process(SAND)
    seen = run_process(e, _scan(scan_result(areas_per_wall=3)))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert e.check_consistency(full_inference=True) == []


def test_scan_keeps_the_state_of_known_features_and_adds_new_ones(make_engine):
    e = make_engine()
    e.update_world(scan_result(areas_per_wall=1))
    e.start_process(SPRAY)
    run_process(e)
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.processed
    e.start_process(SPRAY)
    seen = run_process(e, _scan(scan_result(areas_per_wall=2)))
    assert [s[0] for s in seen] == ["SCAN", "GET_TOOL", "SPRAY_AREA", "GO_HOME", "ENDED"]
    assert seen[2][1] == {"area": "wall_1_area_2"}
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.processed
