"""Section progress of area work: a retried or resumed area task skips the sections it finished before, the
record survives a HICEM restart (SQLite HDICT) and is gone once the area is done."""
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from hicem_rig import TREES, params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager, MemoryStore, SqliteStore
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.interfaces import LocemReply
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.section_progress import PROGRESS
from locem_bridge.hicem.xml_loader import TreeLibrary

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


def _store(path):
    return DataManager(MemoryStore(), SqliteStore(str(path)), persistent_collections=["features", PROGRESS])


def _spray_tree(store, locem):
    hdh = DataHandler(store)
    hdh.ingest_scan(SITE)
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=OperatorDesk(), data_handler=hdh)
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    bb.update({"param_area": "wall_1_area_1"})
    lib = TreeLibrary()
    lib.load_directory(TREES)
    return lib.build("SPRAY_AREA", ctx, bb), ctx


def _tick(tree, locem, fail_at=None):
    for _ in range(200):
        if fail_at is not None and sum(c.startswith("SPRAY_AREA ") for c in locem.sent) == fail_at - 1:
            locem.fail_next["SPRAY_AREA"] = LocemReply(False, "HARDWARE_ERROR", "compressor: link down")
            fail_at = None
        st = tree.tick()
        if st != R:
            return st
    raise AssertionError("tree still running")


def _sprays(locem):
    return [c for c in locem.sent if c.startswith("SPRAY_AREA ")]


def test_a_failed_area_resumes_at_the_failed_section_after_a_restart_and_the_record_goes_when_done(tmp_path):
    # wall_1_area_1 is 4.8 m wide: 8 sections of 0.6 m; the 4th spray command fails
    store = _store(tmp_path / "hdict.sqlite")
    first = LocemDouble()
    tree, _ = _spray_tree(store, first)
    assert _tick(tree, first, fail_at=4) == F
    assert len(_sprays(first)) == 4
    assert store.value(PROGRESS, "spray/wall_1_area_1") == {"done": [0, 1, 2]}
    store.close()
    # HICEM restarts on the same HDICT file and runs the task again
    store = _store(tmp_path / "hdict.sqlite")
    again = LocemDouble()
    tree, _ = _spray_tree(store, again)
    assert _tick(tree, again) == S
    assert _sprays(again) == _sprays(first)[3:4] + _sprays(again)[1:] and len(_sprays(again)) == 5
    assert not set(_sprays(first)[:3]) & set(_sprays(again))            # no second coat on sections 0-2
    assert store.get(PROGRESS, "spray/wall_1_area_1") is None           # area done: the record is gone
    # the next job on the same area starts from its first section again
    later = LocemDouble()
    tree, _ = _spray_tree(store, later)
    assert _tick(tree, later) == S and len(_sprays(later)) == 8
    store.close()


def _leaf_tree(body, store):
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">%s</BehaviorTree></root>' % body)
    bb = Blackboard()
    bb.update({"secs": [{"index": 0}, {"index": 1}, {"index": 2}]})
    return lib.build("T", NodeContext(store=store), bb), bb


def test_pending_sections_keeps_the_order_and_counts_what_is_done():
    store = DataManager()
    tree, bb = _leaf_tree('<Sequence><RecordSectionDone area_id="a" work="sand" index="1"/>'
                          '<RecordSectionDone area_id="a" work="sand" index="1"/>'
                          '<PendingSections sections="{secs}" area_id="a" work="sand" pending="{p}" done_count="{n}"/>'
                          '<PendingSections sections="{secs}" area_id="a" work="spray" pending="{q}" done_count="{m}"/>'
                          '</Sequence>', store)
    assert tree.tick() == S
    assert bb.get("p") == [{"index": 0}, {"index": 2}] and bb.get("n") == 1
    assert bb.get("q") == bb.get("secs") and bb.get("m") == 0             # spraying and sanding kept apart
    assert store.value(PROGRESS, "sand/a") == {"done": [1]}                # recorded once


def test_bad_ports_fail_with_the_reason():
    tree, _ = _leaf_tree('<RecordSectionDone area_id="a" work="" index="1"/>', DataManager())
    assert tree.tick() == F
    assert "work must be a non-empty name without '/'" in tree.ctx.last_failure()[1]
    tree, bb = _leaf_tree('<PendingSections sections="{secs}" area_id="a" work="spray" pending="{p}" '
                          'done_count="{n}"/>', DataManager())
    bb.set("secs", [{"origin": [0, 0, 0]}])
    assert tree.tick() == F
    assert "sections must be a list of objects with an 'index'" in tree.ctx.last_failure()[1]
