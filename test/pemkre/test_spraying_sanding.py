"""Spraying and sanding: the same flow-chart structure on wall areas, one test per branch."""
import pytest
from pemkre_testkit import json_dumps, run_process, scan_result
from rdflib.namespace import RDF

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
    assert seen[-1][1]["message"] == "completed"
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
    assert seen[-1][1]["message"] == "completed"


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
    assert seen[-1][1]["message"] == "completed"
    assert seen[0][1]["tool"] == "sander"
    assert [s[1]["area"] for s in seen[1:3]] == ["wall_1_area_1", "wall_1_area_2"]
    assert e.store.value(SITE.wall_1_area_3, PPR.sandingStatus) == PPR.unprocessed
    # all sprayed areas sanded: the next sanding run scans, finds nothing ready, goes home early
    e.start_process(SAND)
    seen = run_process(e, _scan(scan_result(areas_per_wall=3)))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "nothing_to_do"
    assert e.check_consistency(full_inference=True) == []


def test_scan_keeps_the_state_of_known_features_and_adds_new_ones(make_engine):
    e = make_engine()
    e.update_world(scan_result(areas_per_wall=1))
    e.start_process(SPRAY)
    assert run_process(e)[-1] == ("ENDED", {"message": "completed"})
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.processed
    e.start_process(SPRAY)
    seen = run_process(e, _scan(scan_result(areas_per_wall=2)))
    assert [s[0] for s in seen] == ["SCAN", "GET_TOOL", "SPRAY_AREA", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "completed"
    assert seen[2][1] == {"area": "wall_1_area_2"}
    assert e.store.value(SITE.wall_1_area_1, PPR.sprayingStatus) == PPR.processed


def _with_finish(scan, finishes):
    """``scan`` with ``finish`` set on the areas named in ``finishes`` (others keep the default, bare)."""
    for a in scan["areas"]:
        if a["id"] in finishes:
            a["finish"] = finishes[a["id"]]
    return scan


def _is(e, fid, cls):
    return any(True for _ in e.store.quads(SITE[fid], RDF.type, cls))


def _statuses(e, fid):
    return e.store.value(SITE[fid], PPR.sprayingStatus), e.store.value(SITE[fid], PPR.sandingStatus)


def test_sanding_on_a_fresh_store_sands_the_areas_the_scan_finds_sprayed(make_engine):
    # another robot (or a person) sprayed the walls; this store has never seen them: the sanding run scans,
    # the perception reports compound on three of four areas (one already sanded), the run sands the two sprayed ones
    e = make_engine()
    scan = _with_finish(scan_result(walls=2, joints_per_wall=0, areas_per_wall=2),
                        {"wall_1_area_1": "sprayed", "wall_1_area_2": "sanded", "wall_2_area_2": "sprayed"})
    e.start_process(SAND)
    seen = run_process(e, _scan(scan))
    assert [s[0] for s in seen] == ["SCAN", "GET_TOOL", "SAND_AREA", "SAND_AREA", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "completed"
    assert seen[1][1]["tool"] == "sander"
    assert [s[1]["area"] for s in seen[2:4]] == ["wall_1_area_1", "wall_2_area_2"]
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.processed)
    assert _statuses(e, "wall_1_area_2") == (PPR.processed, PPR.processed)      # reported sanded: not sanded again
    assert _statuses(e, "wall_2_area_1") == (PPR.unprocessed, PPR.unprocessed)  # bare: left for spraying
    assert e.check_consistency(full_inference=True) == []
    # the spraying run that follows sprays only the bare area
    e.start_process(SPRAY)
    seen = run_process(e)
    assert [s[0] for s in seen] == ["GET_TOOL", "SPRAY_AREA", "GO_HOME", "ENDED"]
    assert seen[1][1] == {"area": "wall_2_area_1"} and seen[-1][1]["message"] == "completed"


def test_sanding_on_a_fresh_store_with_only_bare_areas_ends_early(make_engine):
    e = make_engine()
    e.start_process(SAND)
    seen = run_process(e, _scan(_with_finish(scan_result(areas_per_wall=2), {"wall_1_area_1": "bare"})))
    assert [s[0] for s in seen] == ["SCAN", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "nothing_to_do"


def test_scan_finish_upgrades_a_known_area_and_never_downgrades_it(make_engine):
    e = make_engine()
    scan = scan_result(areas_per_wall=2)
    e.update_world(scan)
    assert _statuses(e, "wall_1_area_1") == (PPR.unprocessed, PPR.unprocessed)
    assert not _is(e, "wall_1_area_1", PPR.SandingReady)
    # sprayed by hand since the last scan: spraying done, now ready for sanding (the inferred class follows)
    assert e.update_world(_with_finish(scan, {"wall_1_area_1": "sprayed"})) > 0
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.unprocessed)
    assert _statuses(e, "wall_1_area_2") == (PPR.unprocessed, PPR.unprocessed)
    assert _is(e, "wall_1_area_1", PPR.SandingReady) and not _is(e, "wall_1_area_1", PPR.SprayingPending)
    # the perception misses the compound (bare) or reports it again: nothing changes
    assert e.update_world(_with_finish(scan, {"wall_1_area_1": "bare"})) == 0
    assert e.update_world(_with_finish(scan, {"wall_1_area_1": "sprayed"})) == 0
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.unprocessed)
    # sanded: the sanding status follows; a later "sprayed" does not take it back
    e.update_world(_with_finish(scan, {"wall_1_area_1": "sanded", "wall_1_area_2": "sanded"}))
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.processed)
    assert _statuses(e, "wall_1_area_2") == (PPR.processed, PPR.processed)      # bare -> sanded in one step
    assert e.update_world(_with_finish(scan, {"wall_1_area_1": "sprayed", "wall_1_area_2": "bare"})) == 0
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.processed)
    assert not any(True for _ in e.store.quads(None, RDF.type, PPR.SandingReady))
    assert e.check_consistency(full_inference=True) == []


def test_an_area_sprayed_by_the_robot_stays_sprayed_when_a_scan_reports_it_bare(make_engine):
    e = make_engine()
    scan = scan_result(areas_per_wall=1)
    e.update_world(scan)
    e.start_process(SPRAY)
    assert run_process(e)[-1] == ("ENDED", {"message": "completed"})
    e.update_world(_with_finish(scan, {"wall_1_area_1": "bare"}))
    assert _statuses(e, "wall_1_area_1") == (PPR.processed, PPR.unprocessed)
    e.start_process(SAND)
    seen = run_process(e)
    assert [s[0] for s in seen] == ["GET_TOOL", "SAND_AREA", "GO_HOME", "ENDED"]
    assert seen[-1][1]["message"] == "completed"
