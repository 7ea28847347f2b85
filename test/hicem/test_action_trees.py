"""Each shipped action tree, run against the LOCEM test double with the shipped parameters and a scanned site:
the LOCEM commands it sends, with the numbers computed from the scan and the parameters."""
import copy
import math
import threading
import time

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, Heartbeats, LocemDouble, PemkreDouble
from hicem_rig import TREES, params
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager
from locem_bridge.hicem.errors import OperatorError
from locem_bridge.hicem.executive import create_executive
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

LIB = TreeLibrary()
LIB.load_directory(TREES)


def build(action_type, desk=None, **param_values):
    """The shipped tree for ``action_type`` with the shipped parameters, a scanned site and PEMKRE parameters."""
    locem = LocemDouble()
    store = DataManager()
    hdh = DataHandler(store)
    hdh.ingest_scan(SITE)
    desk = desk or OperatorDesk()
    ctx = NodeContext(locem=locem, store=store, health=HealthMonitor([ModuleSpec("locem", crucial=True)]),
                      operator=desk, data_handler=hdh)
    bb = Blackboard()
    bb.update(params().blackboard_entries())
    bb.update({"param_%s" % k: v for k, v in param_values.items()})
    return LIB.build(action_type, ctx, bb), locem, bb, ctx, hdh


def run(action_type, answers=None, **param_values):
    desk = OperatorDesk()
    desk.add_listener(lambda ev, p: ev == "opened" and desk.reply(p.id, (answers or {})[p.kind]))
    tree, locem, bb, ctx, hdh = build(action_type, desk, **param_values)
    for _ in range(100):
        st = tree.tick()
        if st != Status.RUNNING:
            break
    return st, locem, bb, ctx, hdh


def test_spray_area_sections_and_command_arguments():
    st, locem, bb, ctx, hdh = run("SPRAY_AREA", area="wall_1_area_1")
    assert st == Status.SUCCESS, ctx.failures
    # 4.8 m wide, 2.5 m high area running into wall_2: planned first (GetWallReach), the spray gun's wrist keeps
    # 0.21 m from wall_2 and its lanes run on 0.1 m past a section, the arm reaches z 0.1..2.0 m: so 0..4.48 x
    # 0.1..2.0 m is sprayed in sections of
    # at most 0.6 m (8 base poses, each reached with the arm in wall_ready) and the rest is manual work
    gotos = [c for c in locem.sent if c.startswith("GOTO")]
    sprays = [c for c in locem.sent if c.startswith("SPRAY_AREA")]
    # from the start pose (facing the room's corner) the base turns towards wall_1 at the transit point first
    assert len(sprays) == 8 and locem.sent[:3] == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854"]
    assert gotos[1:3] == ["GOTO 1.4 1.4 1.570796",
                          "GOTO 0.28 1.7 1.570796"]  # 1.3 m in front of the first section's middle, facing it
    assert len(gotos) == 3 + 7                     # the other sections: along the wall, no turn, no transit
    # the outer sections reach edge_run_in (0.07 m) beyond the worked part; every section's lanes run
    # section_run_in (0 m) beyond its own ends; a section not begun before is sprayed from its start (skip=0)
    # the 1.9 m in 13 whole lane spacings of 0.14616 m (not 0.15), the lanes sped up in proportion (0.5 x 0.15 /
    # 0.14616 m/s): the same coat per m2 as at the nominal spacing
    assert sprays[0] == ("SPRAY_AREA -0.07 3 0.1 1 0 0 0.63 1.9 0 -1 0 spacing=0.14616 standoff=0.3 speed=0.5131 "
                         "pressure=3.5 run_in=0 skip=0")
    assert sprays[1].startswith("SPRAY_AREA 0.56 3 0.1 1 0 0 0.56 1.9 ")
    assert sprays[7].startswith("SPRAY_AREA 3.92 3 0.1 1 0 0 0.63 1.9 ")
    assert hdh.feature("wall_1_area_1")["status"] == "sprayed"
    assert bb.get("task_detail") == ("sprayed; manual work on wall_1_area_1: section 9 (along 4.48..4.8 m, height "
                                     "0..2.5 m), section 10 (along 0..4.48 m, height 0..0.1 m), section 11 (along "
                                     "0..4.48 m, height 2..2.5 m)")


def test_sand_area_uses_the_sanding_parameters():
    st, locem, *_ = run("SAND_AREA", area="wall_1_area_1")
    assert st == Status.SUCCESS
    sands = [c for c in locem.sent if c.startswith("SAND_AREA")]
    assert len(sands) == 8 and sands[0].endswith("spacing=0.18 speed=0.35 force=20 contact=force lanes=horizontal")


def test_tape_line_on_a_horizontal_joint():
    st, locem, bb, *_ = run("TAPE_LINE", line="wall_2_joint_1")
    assert st == Status.SUCCESS
    # planned before the base moves: the 2 m joint is longer than the 1.2 m the arm tapes from one pose
    # (robot.work.taping.segment_length), so it is taped in two 1 m pieces, each from in front of its middle
    assert locem.sent == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854", "GOTO 1.4 1.4 0", "GOTO 3.75 2 0",
                          "APPLY_TAPE 4.8 2.5 1.2 4.8 1.5 1.2 -1 0 0 speed=0.15", "WALL_READY", "GET_POSE",
                          "GOTO 3.75 1 0", "APPLY_TAPE 4.8 1.5 1.2 4.8 0.5 1.2 -1 0 0 speed=0.15"]
    assert bb.get("task_detail") == "taped"


def _with_joint(monkeypatch, joint):
    site = copy.deepcopy(SITE)
    site["joints"].append(dict({"width": 0.05}, **joint))
    monkeypatch.setitem(globals(), "SITE", site)


def test_tape_line_leaves_a_joint_in_the_corner_to_the_hand_without_moving(monkeypatch):
    # 5 cm from the inside corner with wall_2: neither the tool nor a base pose fits there
    _with_joint(monkeypatch, {"id": "wall_1_joint_9", "wall": "wall_1", "kind": "vertical", "start": [4.75, 3.0, 0.0],
                              "end": [4.75, 3.0, 2.5]})
    st, locem, bb, ctx, hdh = run("TAPE_LINE", line="wall_1_joint_9")
    assert st == Status.SUCCESS, ctx.failures
    assert not any(c.startswith(("GOTO", "APPLY_TAPE", "WALL_READY")) for c in locem.sent), locem.sent
    assert hdh.feature("wall_1_joint_9")["status"] == "manual"
    assert bb.get("task_detail").startswith("manual work on wall_1_joint_9: part 1 (along 0..2.5 m; ")


def test_tape_line_tapes_a_horizontal_joint_up_to_where_the_corner_allows(monkeypatch):
    # runs from the inside corner with wall_1 (y 3.0) along wall_2
    _with_joint(monkeypatch, {"id": "wall_2_joint_9", "wall": "wall_2", "kind": "horizontal", "start": [4.8, 3.0, 1.0],
                              "end": [4.8, 0.5, 1.0]})
    st, locem, bb, ctx, hdh = run("TAPE_LINE", line="wall_2_joint_9")
    assert st == Status.SUCCESS, ctx.failures
    tapes = [[float(x) for x in c.split()[1:7]] for c in locem.sent if c.startswith("APPLY_TAPE ")]
    ys = sorted(y for t in tapes for y in (t[1], t[4]))
    corner_gap = 3.0 - ys[-1]
    assert len(tapes) == math.ceil((2.5 - corner_gap) / 1.2)   # the rest, in pieces of <= 1.2 m
    assert 0.1 < corner_gap < 0.6 and ys[0] == pytest.approx(0.5)
    assert all(abs(t[1] - t[4]) <= 1.2 + 1e-6 for t in tapes)
    detail = bb.get("task_detail")
    assert detail.startswith("taped; manual work on wall_2_joint_9: part 1 (along 0..%s m; " % (
        ("%.2f" % corner_gap).rstrip("0").rstrip(".")))
    assert hdh.feature("wall_2_joint_9")["status"] == "taped"


def test_validate_tape_line_of_a_joint_out_of_reach_is_invalid_without_moving(monkeypatch):
    _with_joint(monkeypatch, {"id": "wall_1_joint_9", "wall": "wall_1", "kind": "vertical", "start": [4.75, 3.0, 0.0],
                              "end": [4.75, 3.0, 2.5]})
    st, locem, bb, *_ = run("VALIDATE_TAPE_LINE", line="wall_1_joint_9")
    assert st == Status.SUCCESS and bb.get("task_detail") == "invalid"
    assert not any(c.startswith(("GOTO", "APPLY_TAPE")) for c in locem.sent)


def test_validate_tape_line_answer_becomes_the_detail():
    st, locem, bb, *_ = run("VALIDATE_TAPE_LINE", answers={"validate_line": "invalid"}, line="wall_1_joint_1")
    assert st == Status.SUCCESS and bb.get("task_detail") == "invalid"
    assert locem.sent == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854", "GOTO 1.4 1.4 1.570796",
                          "GOTO 1.2 1.95 1.570796", "APPLY_TAPE_START 1.2 3 0.1 1.2 3 2 0 -1 0"]


def test_go_home_to_a_named_location_and_unknown_location():
    st, locem, *_ = run("GO_HOME", location="home")
    # arm in wall_ready while the base drives, home only at the location
    assert st == Status.SUCCESS and locem.sent == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854", "HOME"]
    st, locem, bb, ctx, _ = run("GO_HOME", location="garage")
    assert st == Status.FAILURE and locem.sent == []
    assert "no entry 'garage'; the table has: home" in ctx.last_failure()[1]


def test_scan_ingests_features_and_get_tool_asks_the_operator():
    st, locem, bb, ctx, hdh = run("SCAN")
    assert st == Status.SUCCESS and locem.sent == ["SCAN"] and bb.get("new_features") == 0  # already known
    st, locem, bb, ctx, hdh = run("GET_TOOL", answers={"mount_tool": "done"}, tool="spray_gun")
    # the tool is changed at the tool-change location (home), arm home for the operator
    assert st == Status.SUCCESS and locem.sent == ["WALL_READY", "GET_POSE", "GOTO 1.4 1.4 0.7854", "HOME",
                                                   "MOUNT_TOOL spray_gun"]
    assert bb.get("task_detail") == "spray_gun"


@pytest.mark.parametrize("action_type,params,reason", [
    ("TAPE_LINE", {"line": "wall_9_joint_1"}, "no stored joint with id 'wall_9_joint_1'"),
    ("TAPE_LINE", {}, "'param_line', which is not set"),
    ("SPRAY_AREA", {"area": "wall_1_joint_1"}, "no stored area with id 'wall_1_joint_1'"),
    ("GET_TOOL", {"tool": "hammer"}, "unknown tool 'hammer'"),
])
def test_bad_parameters_fail_before_any_command(action_type, params, reason):
    st, locem, bb, ctx, _ = run(action_type, **params)
    assert st == Status.FAILURE and locem.sent == []
    assert reason in ctx.last_failure()[1]


MANUAL_TEXT = "Please tape joint wall_1_joint_2 by hand, then answer done."


def _manual_taping_waiting_for_the_operator():
    """MANUAL_TAPING for wall_1_joint_2 (given as PEMKRE's IRI) ticked until it waits on its prompt."""
    desk = OperatorDesk()
    tree, locem, bb, ctx, hdh = build("MANUAL_TAPING", desk, line="http://example.org/world#wall_1_joint_2")
    for _ in range(20):
        assert tree.tick() == Status.RUNNING, ctx.failures
        if desk.open_prompts():
            break
    (prompt,) = desk.open_prompts()
    return tree, locem, bb, ctx, hdh, desk, prompt


def test_manual_taping_asks_the_operator_and_succeeds_on_done():
    tree, locem, bb, ctx, hdh, desk, prompt = _manual_taping_waiting_for_the_operator()
    # the arm is retracted out of the operator's way first, then the operator is asked to tape the line by hand
    assert locem.sent == ["WALL_READY"] and locem.running() == []
    assert (prompt.kind, prompt.text, prompt.choices) == ("manual_taping", MANUAL_TEXT, ("done",))
    # it waits for the answer: more ticks send nothing and record nothing
    for _ in range(5):
        assert tree.tick() == Status.RUNNING
    assert locem.sent == ["WALL_READY"] and hdh.feature("wall_1_joint_2")["status"] != "manual"
    assert not bb.has("task_detail")
    desk.reply(prompt.id, "done")
    assert tree.tick() == Status.SUCCESS, ctx.failures
    assert bb.get("task_detail") == "manual" and hdh.feature("wall_1_joint_2")["status"] == "manual"
    assert prompt.state == "answered" and desk.open_prompts() == [] and locem.sent == ["WALL_READY"]


def test_manual_taping_refuses_an_answer_it_did_not_offer():
    tree, locem, bb, ctx, hdh, desk, prompt = _manual_taping_waiting_for_the_operator()
    with pytest.raises(OperatorError) as ei:
        desk.reply(prompt.id, "skip")
    assert "answer 'skip' is not allowed" in str(ei.value) and "allowed: done" in str(ei.value)
    assert tree.tick() == Status.RUNNING and prompt.state == "open"


def test_manual_taping_halted_while_waiting_withdraws_the_prompt_and_records_nothing():
    tree, locem, bb, ctx, hdh, desk, prompt = _manual_taping_waiting_for_the_operator()
    tree.halt()  # what the controller does on /hicem/stop or a health fault
    assert prompt.state == "cancelled" and desk.open_prompts() == []
    assert tree.root.status == Status.INVALID
    assert hdh.feature("wall_1_joint_2")["status"] != "manual" and not bb.has("task_detail")
    assert locem.running() == [] and ctx.outstanding() == []
    with pytest.raises(OperatorError) as ei:  # a late answer from the HMI is refused, not applied
        desk.reply(prompt.id, "done")
    assert "is already cancelled" in str(ei.value)


def test_manual_taping_stopped_by_the_operator_is_reported_failed(tmp_path):
    """Through the controller (PEMKRE double: 'invalid' sends the joint to MANUAL_TAPING): /hicem/stop while the
    manual-taping prompt is open fails the task with the stop reason, withdraws the prompt, makes the devices
    safe and records no manual taping."""
    pemkre = PemkreDouble()
    ex = create_executive(pemkre, LocemDouble(), str(tmp_path / "hdict.sqlite"), params=params(), library=LIB)
    prompts = []

    def operator(event, p):
        if event != "opened":
            return
        prompts.append(p)
        if p.kind == "mount_tool":
            threading.Thread(target=ex.controller.operator_reply, args=(p.id, "done")).start()
        elif p.kind == "validate_line":
            threading.Thread(target=ex.controller.operator_reply, args=(p.id, "invalid")).start()
        # manual_taping: left open, the operator presses stop instead
    ex.operator.add_listener(operator)
    ex.health.heartbeat("locem")
    beats = Heartbeats(ex.health)
    try:
        ex.controller.start_process(PemkreDouble.PROCESS)
        deadline = time.monotonic() + 10
        while not any(p.kind == "manual_taping" for p in prompts) and time.monotonic() < deadline:
            time.sleep(0.005)
        (manual,) = [p for p in prompts if p.kind == "manual_taping"]
        assert manual.text == "Please tape joint wall_1_joint_1 by hand, then answer done."
        assert ex.controller.state()["tree"] == "MANUAL_TAPING"
        ex.controller.stop("operator pressed stop")
        assert ex.controller.join(5)
        assert ex.controller.state()["phase"] == "stopped"
        (task,) = pemkre.executed("MANUAL_TAPING")
        assert task[2:4] == ["failed", "stopped: operator pressed stop"]
        assert manual.state == "cancelled" and ex.operator.open_prompts() == []
        assert ex.data_handler.feature("wall_1_joint_1")["status"] != "manual"
        assert ex.controller.locem.sent[-1] == "STOP" and ex.controller.locem.running() == []
    finally:
        beats.stop()
        ex.close()
