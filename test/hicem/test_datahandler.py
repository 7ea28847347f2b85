"""HDH: SCAN results into wall features with geometry, forwarding to PEMKRE, outbox, pruning, bad scans."""
import copy

import pytest

from hicem_doubles import SITE
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager, MemoryStore, PruneRule, SqliteStore
from locem_bridge.hicem.errors import PemkreCallError, ScanFormatError
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec


class WorldSink:
    """Records report_world calls; can be told to fail like an unreachable PEMKRE."""

    def __init__(self):
        self.updates = []
        self.down = False

    def report_world(self, update):
        if self.down:
            raise PemkreCallError("PEMKRE unreachable")
        self.updates.append(update)


def make(tmp_path):
    store = DataManager(MemoryStore(), SqliteStore(str(tmp_path / "h.sqlite")),
                        ["features", "scan", "outbox"], [PruneRule("features", below=("scan_seq", "scan", "latest_seq"))])
    sink = WorldSink()
    return DataHandler(store, sink), sink, store


def test_scan_becomes_features_with_geometry_and_is_forwarded(tmp_path):
    hdh, sink, store = make(tmp_path)
    res = hdh.ingest_scan(SITE)
    assert sorted(res.new) == sorted(["wall_1", "wall_2", "wall_1_joint_1", "wall_1_joint_2", "wall_2_joint_1",
                                      "wall_1_area_1"])
    j = hdh.feature("wall_1_joint_1", "joint")
    assert j["start"] == [1.2, 3.0, 0.0] and j["type"] == "joint" and j["status"] == "detected"
    assert store.persistent.value("features", "wall_1")["normal"] == [0.0, -1.0, 0.0]
    assert len(sink.updates) == 1 and len(sink.updates[0]["joints"]) == 3
    assert store.entries("outbox") == []


def test_rescan_forwards_only_changes_keeps_status_and_prunes_vanished(tmp_path):
    hdh, sink, store = make(tmp_path)
    hdh.ingest_scan(SITE)
    hdh.mark_feature("wall_1_joint_1", "taped")
    scan2 = copy.deepcopy(SITE)
    scan2["joints"] = [j for j in scan2["joints"] if j["id"] != "wall_1_joint_2"]
    scan2["joints"][0]["width"] = 0.06  # wall_1_joint_1 changed
    res = hdh.ingest_scan(scan2)
    assert res.new == [] and res.changed == ["wall_1_joint_1"] and res.removed == ["wall_1_joint_2"]
    assert [j["id"] for j in sink.updates[-1]["joints"]] == ["wall_1_joint_1"]
    assert hdh.feature("wall_1_joint_1")["status"] == "taped"
    n = len(sink.updates)
    hdh.ingest_scan(scan2)
    assert len(sink.updates) == n  # nothing new: nothing forwarded


def test_unreachable_pemkre_keeps_update_in_outbox_until_flushed(tmp_path):
    hdh, sink, store = make(tmp_path)
    sink.down = True
    res = hdh.ingest_scan(SITE)
    assert not res.forwarded and len(store.entries("outbox")) == 1
    assert hdh.feature("wall_1_joint_1")  # stored anyway
    sink.down = False
    assert hdh.flush_outbox() and len(sink.updates) == 1 and store.entries("outbox") == []


@pytest.mark.parametrize("mutate,msg", [
    (lambda s: s.update(joints="x"), "'joints' must be a list"),
    (lambda s: s["joints"][0].update(id="1bad"), "joints[0].id must match"),
    (lambda s: s["joints"][0].update(kind="diagonal"), "joints[0].kind must be vertical or horizontal"),
    (lambda s: s["joints"][0].update(wall="wall_9"), "joints[0].wall 'wall_9' is not a known wall"),
    (lambda s: s["joints"][0].update(start=[1, 2]), "joints[0].start must be a list of 3 numbers"),
    (lambda s: s["joints"][0].update(end=[1.2, 3.0, float("inf")]), "joints[0].end[2] must be a finite number"),
    (lambda s: s["walls"][0].update(height=-1), "walls[0].height must be > 0"),
    (lambda s: s["walls"][0].update(normal=[0, 0, 0]), "walls[0].normal must not be the zero vector"),
    (lambda s: s["areas"][0].update(width="wide"), "areas[0].width must be a finite number"),
    (lambda s: s.update(robots=[]), "unknown keys ['robots']"),
    (lambda s: s["joints"].append(dict(s["joints"][0])), "appears twice"),
    (lambda s: s["areas"][0].update(finish="painted"),
     "areas[0].finish must be one of bare, sprayed, sanded, got 'painted'"),
    (lambda s: s["areas"][0].update(finish=1), "areas[0].finish must be one of bare, sprayed, sanded, got 1"),
    (lambda s: s["areas"][0].update(finish="Sanded"), "areas[0].finish must be one of bare, sprayed, sanded"),
    (lambda s: s["walls"][0].update(openings=[{"id": "d1", "kind": "gate", "s": [1, 2], "t": [0, 2]}]),
     "walls[0].openings[0].kind must be door or window, got 'gate'"),
    (lambda s: s["walls"][0].update(openings=[{"id": "d1", "kind": "door", "s": [2, 1], "t": [0, 2]}]),
     "walls[0].openings[0].s must be two numbers first < second"),
    (lambda s: s["walls"][0].update(corners=[{"end": 2, "angle": 1.0}]), "walls[0].corners[0] must be an object "
     "with end 0 (at p0) or 1 (at p1)"),
    (lambda s: s["walls"][0].update(corners=[{"end": 0, "angle": 7.0}]), "walls[0].corners[0].angle must be "
     "between 0 and 2 pi rad"),
    (lambda s: s["areas"][0].update(holes=[{"s": [0.5, 1.0]}]), "areas[0].holes[0].t must be a list of 2 numbers"),
])
def test_bad_scan_is_rejected_naming_the_field_and_nothing_is_stored(tmp_path, mutate, msg):
    hdh, sink, store = make(tmp_path)
    scan = copy.deepcopy(SITE)
    mutate(scan)
    with pytest.raises(ScanFormatError) as ei:
        hdh.ingest_scan(scan)
    assert msg in str(ei.value)
    assert store.entries("features") == [] and sink.updates == []


def test_status_and_diagnostics_feed_the_health_monitor(tmp_path):
    store = DataManager()
    hem = HealthMonitor([ModuleSpec("arm", crucial=True)], store=store)
    hdh = DataHandler(store, None, hem)
    hdh.ingest_diagnostics([{"name": "arm", "level": 2, "message": "protective stop"}])
    assert hem.faults() == [("arm", "arm reports ERROR: protective stop")]
    assert store.value("modules", "arm") == {"level": "ERROR", "message": "protective stop"}
    hdh.ingest_status({"module": "arm", "level": "OK", "message": ""})
    assert hem.faults() == []
    with pytest.raises(Exception) as ei:
        hdh.ingest_status({"level": 0})
    assert "'module'" in str(ei.value)


def _finish(scan, fid, finish):
    out = copy.deepcopy(scan)
    for a in out["areas"]:
        if a["id"] == fid:
            a["finish"] = finish
    return out


def test_area_finish_is_stored_and_a_changed_finish_is_forwarded_like_a_geometry_change(tmp_path):
    hdh, sink, store = make(tmp_path)
    res = hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "bare"))
    assert hdh.feature("wall_1_area_1", "area")["finish"] == "bare"
    assert sink.updates[-1]["areas"][0]["finish"] == "bare"
    # the same area, the same geometry, compound on it now: a change, forwarded with the finish
    res = hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "sprayed"))
    assert res.new == [] and res.changed == ["wall_1_area_1"]
    assert sink.updates[-1]["joints"] == [] and sink.updates[-1]["walls"] == []
    (fwd,) = sink.updates[-1]["areas"]
    assert fwd["id"] == "wall_1_area_1" and fwd["finish"] == "sprayed" and fwd["width"] == 4.8
    assert store.persistent.value("features", "wall_1_area_1")["finish"] == "sprayed"
    n = len(sink.updates)
    hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "sprayed"))  # seen again: nothing new
    hdh.ingest_scan(SITE)                                        # not reported: the stored finish stays
    assert len(sink.updates) == n
    assert hdh.feature("wall_1_area_1")["finish"] == "sprayed"
    res = hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "sanded"))
    assert res.changed == ["wall_1_area_1"] and sink.updates[-1]["areas"][0]["finish"] == "sanded"


def test_area_finish_reaches_the_pemkre_engine(tmp_path):
    """Through the in-process PEMKRE client into the real engine: a known area reported sprayed becomes sprayed."""
    from locem_bridge.hicem.pemkre_local import EngineClient
    from locem_bridge.pemkre import PPR, JournaledStore, ProcessEngine
    from locem_bridge.pemkre.vocab import SITE as SITE_NS

    pstore = JournaledStore(str(tmp_path / "pemkre"))
    try:
        engine = ProcessEngine(pstore)
        store = DataManager(MemoryStore(), SqliteStore(str(tmp_path / "h.sqlite")), ["features", "scan", "outbox"],
                            [PruneRule("features", below=("scan_seq", "scan", "latest_seq"))])
        hdh = DataHandler(store, EngineClient(engine))
        area = SITE_NS.wall_1_area_1

        def status():
            return pstore.value(area, PPR.sprayingStatus), pstore.value(area, PPR.sandingStatus)
        assert hdh.ingest_scan(SITE).forwarded
        assert status() == (PPR.unprocessed, PPR.unprocessed)
        assert hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "sprayed")).forwarded
        assert status() == (PPR.processed, PPR.unprocessed)
        assert hdh.ingest_scan(_finish(SITE, "wall_1_area_1", "bare")).forwarded    # forwarded, never a downgrade
        assert status() == (PPR.processed, PPR.unprocessed)
        assert engine.check_consistency(full_inference=True) == []
    finally:
        pstore.close()


def test_openings_corners_and_holes_are_stored_with_the_geometry(tmp_path):
    hdh, sink, store = make(tmp_path)
    scan = copy.deepcopy(SITE)
    scan["walls"][0].update(openings=[{"id": "door_1", "kind": "door", "s": [1.5, 2.4], "t": [0, 2.05],
                                       "frame": 0.05}], corners=[{"end": 1, "angle": 2.0944}])
    scan["areas"][0].update(holes=[{"s": [1.45, 2.45], "t": [0, 2.0]}])
    hdh.ingest_scan(scan)
    assert hdh.feature("wall_1", "wall")["openings"][0]["s"] == [1.5, 2.4]
    assert hdh.feature("wall_1", "wall")["corners"] == [{"end": 1, "angle": 2.0944}]
    assert hdh.feature(scan["areas"][0]["id"], "area")["holes"] == [{"s": [1.45, 2.45], "t": [0.0, 2.0]}]
