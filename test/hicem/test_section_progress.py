"""Section progress of area work: a retried or resumed area task skips the sections it finished before, the
record survives a HICEM restart (SQLite HDICT) and is gone once the area is done."""
import copy

import pytest
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
from locem_bridge.hicem.nodes.area_work import PROGRESS, parse_manual_work
from locem_bridge.hicem.xml_loader import TreeLibrary

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


# the doubles' site with the area inside what the spray gun reaches (planned by GetWallReach: wall_2 moved 0.6 m
# away, the area 0.1..2.0 m high), so these tests see only the sections LOCEM refuses or a failure cuts
REACHABLE = copy.deepcopy(SITE)
REACHABLE["walls"][0]["p1"] = [5.4, 3.0]
REACHABLE["walls"][1].update(p0=[5.4, 3.0], p1=[5.4, 0.0])
REACHABLE["joints"][2].update(start=[5.4, 2.5, 1.2], end=[5.4, 0.5, 1.2])
REACHABLE["areas"][0].update(origin=[0.0, 3.0, 0.1], height=1.9)


def _store(path):
    return DataManager(MemoryStore(), SqliteStore(str(path)), persistent_collections=["features", PROGRESS])


def _spray_tree(store, locem, tree_id="SPRAY_AREA", clock=None):
    """``tree_id`` (SPRAY_AREA of wall_1_area_1, or RECOVER) on ``store`` against ``locem``; ``clock``: the
    context's clock (default the real one)."""
    hdh = DataHandler(store)
    hdh.ingest_scan(REACHABLE)
    timing = {"clock": clock} if clock is not None else {}
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=OperatorDesk(**timing), data_handler=hdh, **timing)
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    bb.update({"param_area": "wall_1_area_1", "param_robot": "robot"})
    lib = TreeLibrary()
    lib.load_directory(TREES)
    return lib.build(tree_id, ctx, bb), ctx


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


# ----------------------------------------------------------------------------- unreachable sections: manual work --
UNREACHABLE = ("pose [0.5000, -1.2000, 2.6000, 0.0000, 3.1416, 0.0000] is not reachable by the arm: getInverseKinematics "
               "found no solution")


def _tick_refusing(tree, locem, refusals):
    """Tick; the n-th SPRAY_AREA (1-based) is answered ``refusals[n]``."""
    refusals = dict(refusals)
    for _ in range(400):
        n = sum(c.startswith("SPRAY_AREA ") for c in locem.sent)
        if n + 1 in refusals:
            locem.fail_next["SPRAY_AREA"] = refusals.pop(n + 1)
        st = tree.tick()
        if st != R:
            return st
    raise AssertionError("tree still running")


def test_a_section_the_arm_cannot_reach_is_left_for_manual_work_and_the_area_goes_on(tmp_path):
    # the 4.8 m area in 8 sections of 0.6 m; sections 3 and 8 are out of reach (LOCEM's IK refusal)
    store = _store(tmp_path / "hdict.sqlite")
    locem = LocemDouble()
    tree, ctx = _spray_tree(store, locem)
    assert _tick_refusing(tree, locem, {n: LocemReply(False, "INVALID_ARGUMENT", UNREACHABLE) for n in (3, 8)}) == S, ctx.failures
    assert len(_sprays(locem)) == 8                       # every section tried once, none twice
    detail = tree.blackboard.get("task_detail")
    ext = params().raw["spray"]["edge_run_in"]
    assert detail == ("sprayed; manual work on wall_1_area_1: section 3 (along 1.2..1.8 m, height 0.1..2 m), "
                      "section 8 (along 4.2..4.8 m, height 0.1..2 m)"), detail
    assert ext > 0                                       # the last section reaches beyond the area: clipped to it
    assert parse_manual_work(detail) == [
        {"area": "wall_1_area_1", "section": 3, "along": [1.2, 1.8], "height": [0.1, 2.0]},
        {"area": "wall_1_area_1", "section": 8, "along": [4.2, 4.8], "height": [0.1, 2.0]}]
    assert store.value(PROGRESS, "spray/wall_1_area_1") is None      # the area is done: record dropped
    assert parse_manual_work("sprayed") == [] and parse_manual_work("") == []


def test_other_refusals_still_fail_the_task_with_the_commands_reason(tmp_path):
    for reply in (LocemReply(False, "HARDWARE_ERROR", "arm protective stop (safety mode 3): not reachable?"),
                  LocemReply(False, "INVALID_ARGUMENT", "tool spray_gun is not mounted (mounted: sander)")):
        store = _store(tmp_path / ("hdict_%s.sqlite" % reply.code))
        locem = LocemDouble()
        tree, ctx = _spray_tree(store, locem)
        assert _tick_refusing(tree, locem, {2: reply}) == F
        assert len(_sprays(locem)) == 2
        node, reason = ctx.last_failure()
        assert node == "locem_command" and reply.message in reason and reply.code in reason
        assert store.value(PROGRESS, "spray/wall_1_area_1") == {"done": [0]}


def test_a_retried_area_does_not_try_its_manual_section_again(tmp_path):
    store = _store(tmp_path / "hdict.sqlite")
    first = LocemDouble()
    tree, _ = _spray_tree(store, first)
    # section 2 out of reach, then the compressor link drops on section 4: the task fails
    assert _tick_refusing(tree, first, {2: LocemReply(False, "INVALID_ARGUMENT", UNREACHABLE),
                                        4: LocemReply(False, "HARDWARE_ERROR", "compressor: link down")}) == F
    record = store.value(PROGRESS, "spray/wall_1_area_1")
    assert record["done"] == [0, 1, 2] and [m["index"] for m in record["manual"]] == [1]
    second = LocemDouble()
    tree, ctx = _spray_tree(store, second)
    assert _tick_refusing(tree, second, {}) == S, ctx.failures
    assert len(_sprays(second)) == 5                     # sections 4..8; the manual one is not tried again
    assert [m["section"] for m in parse_manual_work(tree.blackboard.get("task_detail"))] == [2]


# ------------------------------------------------------------------------- a section cut while it runs: resume --
def _skip(command):
    return float([w for w in command.split() if w.startswith("skip=")][0].split("=", 1)[1])


def test_a_cut_section_goes_on_after_the_raster_length_its_feedback_reported_and_the_record_goes_when_done(tmp_path):
    # the 4th section's SPRAY_AREA is cut (LOCEM went away) after its feedback reported 2.345 m of its raster
    store = _store(tmp_path / "hdict.sqlite")
    first = LocemDouble()
    first.feedback["SPRAY_AREA"] = "raster 2.345 of 6.480 m"
    tree, _ = _spray_tree(store, first)
    assert _tick(tree, first, fail_at=4) == F
    assert [_skip(c) for c in _sprays(first)] == [0.0] * 4
    # sections 0-2 finished (their partial records dropped), section 3 cut at 2.345 m
    assert store.value(PROGRESS, "spray/wall_1_area_1") == {"done": [0, 1, 2], "partial": {"3": 2.345}}
    store.close()
    # HICEM restarts on the same HDICT file; the task is run again: section 3 goes on at 2.345 m, the rest from 0
    store = _store(tmp_path / "hdict.sqlite")
    again = LocemDouble()
    tree, _ = _spray_tree(store, again)
    assert _tick(tree, again) == S
    sprays = _sprays(again)
    assert len(sprays) == 5 and [_skip(c) for c in sprays] == [2.345, 0.0, 0.0, 0.0, 0.0]
    assert sprays[0].replace("skip=2.345", "skip=0") == _sprays(first)[3]            # the same section
    assert store.get(PROGRESS, "spray/wall_1_area_1") is None
    store.close()


def test_progress_is_recorded_as_the_feedback_arrives_only_forward_and_dropped_with_the_section(tmp_path):
    store = DataManager()
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T"><Sequence>'
                    '<RecordSectionProgress area_id="a" work="spray" index="2" feedback="{fb}">'
                    '<SendLocemCommand command="SPRAY_AREA 0 0 0 1 0 0 1 1 0 -1 0" timeout="100" feedback="{fb}"/>'
                    '</RecordSectionProgress>'
                    '<RecordSectionDone area_id="a" work="spray" index="2"/>'
                    '</Sequence></BehaviorTree></root>')
    locem = LocemDouble(durations={"SPRAY_AREA": 60.0})
    ctx = NodeContext(locem=locem, store=store)
    tree = lib.build("T", ctx, Blackboard())
    assert tree.tick() == R
    assert store.get(PROGRESS, "spray/a") is None                  # no feedback yet: nothing recorded
    for text, recorded in (("raster 0.500 of 6.000 m", 0.5), ("waypoint 3 of 24", 0.5),
                           ("raster 1.250 of 6.000 m", 1.25), ("raster 1.000 of 6.000 m", 1.25)):
        locem.feedback["SPRAY_AREA"] = text
        assert tree.tick() == R
        assert store.value(PROGRESS, "spray/a") == {"done": [], "partial": {"2": recorded}}, text
    locem.handles[-1].t_done = 0.0                                 # the command ends: OK
    assert tree.tick() == S
    assert store.value(PROGRESS, "spray/a") == {"done": [2]}       # the section's partial record is gone


def _section_command(store):
    """Section 2 of area 'a' running one SPRAY_AREA inside RecordSectionProgress: (tree, the LOCEM double)."""
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">'
                    '<RecordSectionProgress area_id="a" work="spray" index="2">'
                    '<SendLocemCommand command="SPRAY_AREA 0 0 0 1 0 0 1 1 0 -1 0" timeout="100" feedback="{feedback}" '
                    'code="{code}" message="{message}"/>'
                    '</RecordSectionProgress></BehaviorTree></root>')
    locem = LocemDouble(durations={"SPRAY_AREA": 60.0})
    return lib.build("T", NodeContext(locem=locem, store=store), Blackboard()), locem


def _cut(feedback_texts, reply):
    """A section's command reports ``feedback_texts`` (one per tick) and then ends with ``reply``; the recorded
    progress of section 2."""
    store = DataManager()
    tree, locem = _section_command(store)
    for text in feedback_texts:
        locem.feedback["SPRAY_AREA"] = text
        assert tree.tick() == R
    locem.handles[-1]._reply, locem.handles[-1].t_done = reply, 0.0
    assert tree.tick() == F
    return store.value(PROGRESS, "spray/a")["partial"]["2"]


def test_a_section_cut_by_locem_going_away_is_recorded_where_the_spray_went_on_to_before_the_watchdog():
    texts = ["raster 0.000 of 6.000 m (0.120 m if LOCEM stops now)", "raster 0.050 of 6.000 m (0.260 m if LOCEM "
             "stops now)"]
    lost = LocemReply(False, "ABORTED", "LOCEM action server /locem/command_action went away while running "
                      "'SPRAY_AREA ...'; not sent again (LOCEM commands are not idempotent)")
    # LOCEM died: the valve stayed open until the compressor's watchdog closed it, the arm went on meanwhile
    assert _cut(texts, lost) == 0.26
    # any other end (LOCEM closed the valve itself, the arm stopped): the point measured
    assert _cut(texts, LocemReply(False, "HARDWARE_ERROR", "compressor: link down")) == 0.05
    assert _cut(texts, LocemReply(False, "ABORTED", "cancelled")) == 0.05


def test_section_resume_gives_the_recorded_point_less_the_back_off():
    store = DataManager()
    store.put(PROGRESS, "spray/a", {"done": [0], "partial": {"1": 2.5}}, source="test")
    tree, bb = _leaf_tree('<Sequence><SectionResume area_id="a" work="spray" index="1" skip="{s1}"/>'
                          '<SectionResume area_id="a" work="spray" index="1" back_off="0.1" skip="{s2}"/>'
                          '<SectionResume area_id="a" work="spray" index="2" back_off="0.1" skip="{s3}"/>'
                          '<SectionResume area_id="a" work="sand" index="1" skip="{s4}"/></Sequence>', store)
    assert tree.tick() == S
    assert (bb.get("s1"), bb.get("s2"), bb.get("s3"), bb.get("s4")) == (2.5, 2.4, 0.0, 0.0)
    tree, _ = _leaf_tree('<SectionResume area_id="a" work="spray" index="1" back_off="-0.1" skip="{s}"/>', store)
    assert tree.tick() == F
    assert "back_off must be >= 0 m, got -0.1" in tree.ctx.last_failure()[1]


def test_the_controllers_timed_handle_passes_the_feedback_on():
    # the executive wraps every LOCEM handle to time it; the progress feedback must reach the trees through it
    from locem_bridge.hicem.controller import _TimedHandle
    locem = LocemDouble(durations={"SPRAY_AREA": 60.0})
    locem.feedback["SPRAY_AREA"] = "raster 0.500 of 6.000 m"
    assert _TimedHandle(locem.send("SPRAY_AREA 0 0 0 1 0 0 1 1 0 -1 0"), lambda: None).feedback() == \
        "raster 0.500 of 6.000 m"


# ------------------------------------------------------------------------------------ a power loss mid-section --
def _spray_args(command):
    """origin, u, width, height, normal and the keyword values of a SPRAY_AREA command text."""
    words = command.split()
    nums = [float(w) for w in words[1:12]]
    kw = {k: float(v) for k, v in (w.split("=", 1) for w in words[12:])}
    return nums[0:3], nums[3:6], nums[6], nums[7], nums[8:11], kw


def _tcp_at(command, raster_m):
    """The TCP point ``raster_m`` m into the first (forward) lane of a SPRAY_AREA command's raster."""
    origin, u, _w, _h, normal, kw = _spray_args(command)
    along = raster_m - kw["run_in"]
    return [origin[k] + u[k] * along + normal[k] * kw["standoff"] for k in range(3)]


def _recover(store, locem):
    """RECOVER on ``store`` against ``locem``, ticked on a simulated clock."""
    clock = [1000.0]
    tree, _ = _spray_tree(store, locem, "RECOVER", clock=lambda: clock[0])
    for _ in range(2000):
        st = tree.tick()
        if st != R:
            return st
        clock[0] += 0.05
    raise AssertionError("RECOVER still running")


def _cut_by_power_loss(tmp_path, feedback):
    """The first section's SPRAY_AREA runs with ``feedback`` when every process stops at once (no end seen: the
    tree is dropped, the HDICT closed); returns the command sent."""
    store = _store(tmp_path / "hdict.sqlite")
    first = LocemDouble(durations={"SPRAY_AREA": 60.0})
    first.feedback["SPRAY_AREA"] = feedback
    tree, _ = _spray_tree(store, first)
    for _ in range(50):
        assert tree.tick() == R
    assert len(_sprays(first)) == 1
    store.close()
    return _sprays(first)[0]


def test_a_section_cut_by_a_power_loss_goes_on_where_the_tool_stood_not_where_the_last_feedback_was_recorded(
        tmp_path):
    # the last feedback that reached the store said 0.175 m sprayed (0.6 m should LOCEM stop now); the arm went on
    # to 0.355 m before the power went, and stands there when everything comes back
    command = _cut_by_power_loss(tmp_path, "raster 0.175 of 6.480 m (0.600 m if LOCEM stops now)")
    store = _store(tmp_path / "hdict.sqlite")
    assert store.value(PROGRESS, "spray/wall_1_area_1") == {"done": [], "partial": {"0": 0.175}, "bound": {"0": 0.6}}
    locem = LocemDouble()
    locem.tool_point = _tcp_at(command, 0.355)
    # RECOVER reads where the tool stands before it moves the arm, and notes it for the cut section
    assert _recover(store, locem) == S
    assert locem.sent[-2:] == ["GET_TOOL_POINT", "WALL_READY"]
    record = store.value(PROGRESS, "spray/wall_1_area_1")
    assert record["tool_at"] == {"0": pytest.approx(locem.tool_point, abs=1e-4)}
    # a second RECOVER (the arm now at wall_ready) keeps the note of the cut and reads nothing
    elsewhere = LocemDouble()
    assert _recover(store, elsewhere) == S
    assert "GET_TOOL_POINT" not in elsewhere.sent
    assert store.value(PROGRESS, "spray/wall_1_area_1")["tool_at"] == record["tool_at"]
    # the retried task: the section goes on at 0.355 m, where the spray stopped
    again = LocemDouble()
    tree, _ = _spray_tree(store, again)
    assert _tick(tree, again) == S
    sprays = _sprays(again)
    assert _skip(sprays[0]) == pytest.approx(0.355, abs=1e-3)
    assert sprays[0].split(" skip=")[0] == command.split(" skip=")[0]            # the same section
    assert store.get(PROGRESS, "spray/wall_1_area_1") is None
    store.close()


@pytest.mark.parametrize("raster_m, off, expected", [
    (0.5, 0.0, 0.5),         # within them: there
    (0.9, 0.0, 0.6),         # beyond the bound the last feedback allowed (the arm went on with the valve closed)
    (0.1, 0.0, 0.175),       # behind the recorded point: never goes back before what was recorded
    (0.355, 0.25, 0.175),    # not on the raster (25 cm off the spray plane): the recorded point
])
def test_a_noted_tool_point_is_used_only_on_the_raster_and_between_the_recorded_point_and_the_bound(
        tmp_path, raster_m, off, expected):
    command = _cut_by_power_loss(tmp_path, "raster 0.175 of 6.480 m (0.600 m if LOCEM stops now)")
    store = _store(tmp_path / "hdict.sqlite")
    locem = LocemDouble()
    _o, _u, _w, _h, normal, _kw = _spray_args(command)
    locem.tool_point = [c + n * off for c, n in zip(_tcp_at(command, raster_m), normal)]
    assert _recover(store, locem) == S
    again = LocemDouble()
    tree, _ = _spray_tree(store, again)
    assert _tick(tree, again) == S
    assert _skip(_sprays(again)[0]) == pytest.approx(expected, abs=1e-3)
    store.close()


def test_a_command_that_ended_with_a_reply_keeps_its_recorded_point_and_recover_notes_nothing(tmp_path):
    # the compressor link dropped: LOCEM answered, its last feedback is where the spray got; the arm stopped
    # after the valve had closed, so its point would leave a strip unsprayed
    store = _store(tmp_path / "hdict.sqlite")
    first = LocemDouble(durations={"SPRAY_AREA": 60.0})
    first.feedback["SPRAY_AREA"] = "raster 0.175 of 6.480 m (0.600 m if LOCEM stops now)"
    tree, _ = _spray_tree(store, first)
    for _ in range(20):
        assert tree.tick() == R
    first.handles[-1]._reply = LocemReply(False, "HARDWARE_ERROR", "compressor: link down")
    first.handles[-1].t_done = 0.0
    assert tree.tick() == F
    assert store.value(PROGRESS, "spray/wall_1_area_1") == {"done": [], "partial": {"0": 0.175}}   # no bound
    locem = LocemDouble()
    locem.tool_point = _tcp_at(_sprays(first)[0], 0.355)
    assert _recover(store, locem) == S
    assert "GET_TOOL_POINT" not in locem.sent and "tool_at" not in store.value(PROGRESS, "spray/wall_1_area_1")
    again = LocemDouble()
    tree, _ = _spray_tree(store, again)
    assert _tick(tree, again) == S
    assert _skip(_sprays(again)[0]) == pytest.approx(0.175)
    store.close()


def test_note_tool_at_cut_refuses_a_point_that_is_not_get_tool_points_result():
    store = DataManager()
    store.put(PROGRESS, "spray/a", {"done": [], "partial": {"1": 0.2}, "bound": {"1": 0.5}}, source="test")
    tree, bb = _leaf_tree('<NoteToolAtCut point="{p}"/>', store)
    bb.set("p", {"pose": [1, 2, 3]})
    assert tree.tick() == F
    assert "point must be GET_TOOL_POINT's result {point: [x, y, z], ...}" in tree.ctx.last_failure()[1]
    assert "tool_at" not in store.value(PROGRESS, "spray/a")


def test_a_command_halted_while_it_ran_leaves_no_bound_open_and_no_tool_no_note(tmp_path):
    # a halt (a health fault, a cancel) is an end HICEM saw: LOCEM closes the valve, the recorded point stands
    store = DataManager()
    tree, locem = _section_command(store)
    locem.feedback["SPRAY_AREA"] = "raster 0.300 of 6.000 m (0.700 m if LOCEM stops now)"
    assert tree.tick() == R
    assert store.value(PROGRESS, "spray/a") == {"done": [], "partial": {"2": 0.3}, "bound": {"2": 0.7}}
    tree.halt()
    assert store.value(PROGRESS, "spray/a") == {"done": [], "partial": {"2": 0.3}}
    # with a bound open and no tool on the arm (GET_TOOL_POINT's tool ''), nothing is noted
    store.put(PROGRESS, "spray/a", {"done": [], "partial": {"2": 0.3}, "bound": {"2": 0.7}}, source="test")
    tree, bb = _leaf_tree('<NoteToolAtCut point="{p}" noted="{n}"/>', store)
    bb.set("p", {"point": [1.0, 2.0, 0.5], "axis": [0, 1, 0], "tool": ""})
    assert tree.tick() == S and bb.get("n") == 0 and "tool_at" not in store.value(PROGRESS, "spray/a")
