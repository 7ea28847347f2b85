"""The node library against the data store, the HEM, the operator desk and the LOCEM test double."""
import logging
import math

import pytest
from py_trees.common import Status

from hicem_doubles import SITE, LocemDouble
from locem_bridge.hicem.blackboard import Blackboard
from locem_bridge.hicem.datahandler import DataHandler
from locem_bridge.hicem.datastore import DataManager
from locem_bridge.hicem.errors import TreeLoadError
from locem_bridge.hicem.health import HealthMonitor, ModuleSpec
from locem_bridge.hicem.interfaces import LocemReply
from locem_bridge.hicem.node_base import NodeContext
from locem_bridge.hicem.nodes.generic import format_number, render
from locem_bridge.hicem.nodes.plasterboard import GetAreaRaster
from locem_bridge.hicem.operator import OperatorDesk
from locem_bridge.hicem.xml_loader import TreeLibrary

S, F, R = Status.SUCCESS, Status.FAILURE, Status.RUNNING


class Rig:
    def __init__(self, body, cfg=None, clock=None, durations=None):
        self.now = [0.0]
        self.clock = clock or (lambda: self.now[0])
        self.locem = LocemDouble(durations=durations)
        self.store = DataManager()
        self.health = HealthMonitor([ModuleSpec("locem", crucial=True)], clock=self.clock)
        self.operator = OperatorDesk()
        self.hdh = DataHandler(self.store, None, self.health)
        self.hdh.ingest_scan(SITE)
        lib = TreeLibrary()
        lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T">%s</BehaviorTree></root>' % body)
        self.ctx = NodeContext(locem=self.locem, store=self.store, health=self.health, operator=self.operator,
                               data_handler=self.hdh, clock=self.clock)
        bb = Blackboard()
        bb.update({"cfg.locem.command_timeout_s": 10.0, "robot.tools": ["taping_tool", "spray_gun"],
                   "robot.work.taping.base_standoff": 0.8, "cfg.taping.lateral_offset": 0.1,
                   "cfg.taping.yaw_offset": 0.0, "cfg.taping.surface_offset": 0.01,
                   "cfg.taping.plumb_tolerance": 0.02})
        bb.update(cfg or {})
        self.tree = lib.build("T", self.ctx, bb)
        self.bb = bb

    def reason(self):
        return self.ctx.last_failure()[1]


def test_send_locem_command_fills_template_and_returns_result():
    rig = Rig('<SendLocemCommand command="GOTO {pose} " result="{r}" code="{c}"/>', cfg={"pose": [1.2, -0.5, math.pi / 2]})
    assert rig.tree.tick() == S
    assert rig.locem.sent == ["GOTO 1.2 -0.5 1.570796 "]
    assert rig.bb.get("c") == "OK" and rig.bb.get("r") == {}


def test_send_locem_command_runs_until_reply_and_cancels_on_halt():
    rig = Rig('<SendLocemCommand command="HOME"/>', durations={"HOME": 5.0})
    assert rig.tree.tick() == R
    assert rig.tree.tick() == R
    h = rig.locem.handles[0]
    rig.tree.halt()
    assert h.cancelled and rig.locem.sent[-1] == "CANCEL HOME"
    assert rig.ctx.outstanding() == []


@pytest.mark.parametrize("reply,expect", [
    (LocemReply(False, "HARDWARE_ERROR", "compressor link down"), "LOCEM HARDWARE_ERROR for 'SCAN': compressor link down"),
    (LocemReply(False, "EXPLODED", "?"), "unexpected code 'EXPLODED'"),
    (LocemReply(True, "BUSY", ""), "inconsistent"),
])
def test_send_locem_command_fails_on_error_and_unexpected_codes(reply, expect):
    rig = Rig('<SendLocemCommand command="SCAN"/>')
    rig.locem.fail_next["SCAN"] = reply
    assert rig.tree.tick() == F
    assert expect in rig.reason()


def test_send_locem_command_refused_command_and_timeout():
    rig = Rig('<SendLocemCommand command="FLY 1"/>')
    assert rig.tree.tick() == F and "INVALID_COMMAND" in rig.reason()
    rig = Rig('<SendLocemCommand command="HOME" timeout="2"/>', durations={"HOME": 60.0})
    assert rig.tree.tick() == R
    rig.now[0] = 2.5
    assert rig.tree.tick() == F
    assert "no reply to 'HOME' within 2.000 s" in rig.reason() and rig.locem.handles[0].cancelled


def test_template_refuses_values_that_would_inject_arguments():
    rig = Rig('<SendLocemCommand command="MOUNT_TOOL {tool}"/>', cfg={"tool": "spray_gun STOP"})
    assert rig.tree.tick() == F
    assert "whitespace" in rig.reason() and rig.locem.sent == []
    rig = Rig('<SendLocemCommand command="GOTO {missing}"/>')
    assert rig.tree.tick() == F and "'missing' is not set" in rig.reason()


def test_render_numbers_and_fields():
    bb = Blackboard()
    bb.update({"s": {"origin": [0.0, -0.0, 1e-7], "w": 4.8}, "n": 3, "flag": True})
    assert render("X {s.origin} {s.w} {n} {flag}", bb) == "X 0 0 0 4.8 3 true"
    assert format_number(1.23456789) == "1.234568"


def test_check_health_guards_running_command():
    rig = Rig('<ReactiveSequence><CheckHealth/><SendLocemCommand command="HOME"/></ReactiveSequence>',
              durations={"HOME": 60.0})
    assert rig.tree.tick() == R
    rig.health.report("locem", "ERROR", "RTDE link lost")
    assert rig.tree.tick() == F
    assert rig.locem.handles[0].cancelled
    assert "RTDE link lost" in rig.reason()


def test_wait_for_operator_prompt_answer_and_withdraw():
    rig = Rig('<WaitForOperator kind="validate_line" text="Is {line} ok?" choices="valid;invalid" answer="{a}"/>',
              cfg={"line": "wall 1 joint 2"})
    assert rig.tree.tick() == R
    (p,) = rig.operator.open_prompts()
    assert p.text == "Is wall 1 joint 2 ok?" and p.choices == ("valid", "invalid")
    rig.operator.reply(p.id, "invalid")
    assert rig.tree.tick() == S and rig.bb.get("a") == "invalid"
    rig2 = Rig('<WaitForOperator kind="k" text="t" choices="done"/>')
    assert rig2.tree.tick() == R
    rig2.tree.halt()
    assert rig2.operator.open_prompts() == []


def test_wait_for_operator_timeout():
    rig = Rig('<WaitForOperator kind="k" text="t" choices="done" timeout="30"/>')
    assert rig.tree.tick() == R
    rig.now[0] = 31.0
    assert rig.tree.tick() == F and "did not answer within 30.0 s" in rig.reason()
    assert rig.operator.open_prompts() == []


def test_data_store_read_write_and_missing():
    rig = Rig('<Sequence><WriteDataStore collection="robot" key="tool" value="{t}"/>'
              '<ReadDataStore collection="features" key="wall_1_joint_1" field="start" value="{s}"/>'
              '<ReadDataStore collection="robot" key="tool" value="{back}"/></Sequence>', cfg={"t": "sander"})
    assert rig.tree.tick() == S
    assert rig.bb.get("s") == [1.2, 3.0, 0.0] and rig.bb.get("back") == "sander"
    rig = Rig('<ReadDataStore collection="robot" key="nothing" value="{x}"/>')
    assert rig.tree.tick() == F and "no entry robot/nothing" in rig.reason()


def test_tag_id_name_to_object_id_maps_iris_and_checks_kind():
    rig = Rig('<TagIdNameToObjectId symbol="{p}" kind="joint" object_id="{o}"/>',
              cfg={"p": "http://example.org/world#wall_1_joint_2"})
    assert rig.tree.tick() == S and rig.bb.get("o") == "wall_1_joint_2"
    rig = Rig('<TagIdNameToObjectId symbol="wall_1_area_1" kind="joint" object_id="{o}"/>')
    assert rig.tree.tick() == F and "no stored joint with id 'wall_1_area_1'" in rig.reason()
    rig = Rig('<TagIdNameToObjectId symbol="drill" kind="tool" object_id="{o}"/>')
    assert rig.tree.tick() == F and "unknown tool 'drill'" in rig.reason()


def test_get_taping_position_vertical_and_horizontal():
    rig = Rig('<GetTapingPosition line_id="wall_1_joint_1" approach_pose="{p}"/>')
    assert rig.tree.tick() == S
    x, y, th = rig.bb.get("p")
    # wall_1 runs +x at y=3 with normal -y: base 0.8 m in front, shifted 0.1 m along +x, facing +y
    assert (x, y) == pytest.approx((1.3, 2.2)) and th == pytest.approx(math.pi / 2)
    rig = Rig('<GetTapingPosition line_id="wall_2_joint_1" approach_pose="{p}" lateral_offset="0"/>')
    assert rig.tree.tick() == S
    x, y, th = rig.bb.get("p")
    # horizontal joint on wall_2 (x=4.8, normal -x): middle at y=1.5, base at x=4.0 facing +x
    assert (x, y, th) == pytest.approx((4.0, 1.5, 0.0))


def test_get_tape_path_offsets_along_normal():
    rig = Rig('<GetTapePath line_id="wall_1_joint_1" path_start="{s}" path_end="{e}" normal="{n}" length="{l}"/>')
    assert rig.tree.tick() == S
    assert rig.bb.get("s") == pytest.approx([1.2, 2.99, 0.0])
    assert rig.bb.get("e") == pytest.approx([1.2, 2.99, 2.5])
    assert rig.bb.get("n") == pytest.approx([0, -1, 0]) and rig.bb.get("l") == pytest.approx(2.5)


def _scanned(joint_id, start, end):
    """SITE as a scan that measured ``joint_id`` with the given ends."""
    import copy
    site = copy.deepcopy(SITE)
    j = next(j for j in site["joints"] if j["id"] == joint_id)
    j["start"], j["end"] = list(start), list(end)
    site["stamp"] = 2.0
    return site


def test_tape_path_straightens_a_nearly_plumb_joint_through_the_mean_of_its_ends():
    # the scanner put the foot of wall_1_joint_1 13 mm and the top 1 mm to the right of x = 1.2: the path is
    # plumb at their mean (7 mm), not a line leaning out of a 15 mm band at the foot
    body = ('<Sequence><GetTapePath line_id="wall_1_joint_1" path_start="{s}" path_end="{e}" normal="{n}" '
            'length="{l}"/><GetTapingPosition line_id="wall_1_joint_1" approach_pose="{p}" '
            'lateral_offset="0"/></Sequence>')
    rig = Rig(body)
    rig.hdh.ingest_scan(_scanned("wall_1_joint_1", [1.213, 3.0, 0.0], [1.201, 3.0, 2.5]))
    assert rig.tree.tick() == S
    assert rig.bb.get("s") == pytest.approx([1.207, 2.99, 0.0])
    assert rig.bb.get("e") == pytest.approx([1.207, 2.99, 2.5])
    assert rig.bb.get("p")[:2] == pytest.approx([1.207, 2.2])
    # tilted beyond the tolerance (0.1 rad): a real slanted joint, taped as measured
    rig = Rig(body)
    rig.hdh.ingest_scan(_scanned("wall_1_joint_1", [1.2, 3.0, 0.0], [1.45, 3.0, 2.5]))
    assert rig.tree.tick() == S
    assert rig.bb.get("s") == pytest.approx([1.2, 2.99, 0.0]) and rig.bb.get("e") == pytest.approx([1.45, 2.99, 2.5])
    # max_tilt 0: every line as measured
    rig = Rig(body, cfg={"cfg.taping.plumb_tolerance": 0.0})
    rig.hdh.ingest_scan(_scanned("wall_1_joint_1", [1.213, 3.0, 0.0], [1.201, 3.0, 2.5]))
    assert rig.tree.tick() == S
    assert rig.bb.get("s")[0] == pytest.approx(1.213) and rig.bb.get("e")[0] == pytest.approx(1.201)


def test_tape_path_levels_a_nearly_level_joint_and_refuses_a_negative_tolerance():
    rig = Rig('<GetTapePath line_id="wall_2_joint_1" path_start="{s}" path_end="{e}" normal="{n}" length="{l}"/>')
    rig.hdh.ingest_scan(_scanned("wall_2_joint_1", [4.8, 2.5, 1.21], [4.8, 0.5, 1.196]))
    assert rig.tree.tick() == S
    assert rig.bb.get("s")[2] == pytest.approx(1.203) and rig.bb.get("e")[2] == pytest.approx(1.203)
    bad = Rig('<GetTapePath line_id="wall_2_joint_1" max_tilt="-0.1" path_start="{s}" path_end="{e}" '
              'normal="{n}" length="{l}"/>')
    assert bad.tree.tick() == F and "max_tilt must be >= 0 rad, got -0.1" in bad.reason()


def test_get_area_raster_sections_cover_the_area():
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="1.5" base_standoff="0.9" yaw_offset="0" '
              'sections="{s}" count="{c}"/>')
    assert rig.tree.tick() == S
    secs = rig.bb.get("s")
    assert rig.bb.get("c") == 4 and len(secs) == 4
    assert sum(s["width"] for s in secs) == pytest.approx(4.8)
    assert [s["origin"][0] for s in secs] == pytest.approx([0.0, 1.2, 2.4, 3.6])
    assert secs[0]["approach"] == pytest.approx([0.6, 2.1, math.pi / 2])


def test_get_area_raster_cuts_narrower_sections_where_the_bases_end_and_leaves_the_rest_manual():
    # wall_1 (4.8 m, area 0..4.8 x 0..2.5): the tool reaches 0.3..3.3 m along it, free bases only 0.6..2.9 m,
    # 0.3 m to either side: up to 3.2 m every point is reachable from some base, but the last of five 0.6 m
    # sections (2.7..3.3) has no base for both its ends; of 5..8 sections, 8 (0.375 m) leave the least unreached
    plan = {"wall": "wall_1", "work": "spray", "tool": [[0.3, 3.3]], "base": [[0.6, 2.9]], "t": [0.0, 2.5],
            "reach": 0.3, "why": []}
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="0.9" yaw_offset="0" '
              'min_manual="0.03" plan="{p}" sections="{s}" count="{c}" manual="{m}"/>', cfg={"p": plan})
    assert rig.tree.tick() == S
    secs, manual = rig.bb.get("s"), rig.bb.get("m")
    assert secs and all(s["width"] <= 0.6 + 1e-9 for s in secs)
    for sec in secs:               # every section sent has a free base that reaches both its ends
        a0, a1 = sec["origin"][0], sec["origin"][0] + sec["width"]
        base = sec["approach"][0]
        assert 0.6 - 1e-6 <= base <= 2.9 + 1e-6 and a1 - 0.3 - 1e-6 <= base <= a0 + 0.3 + 1e-6
    assert len(secs) == 7 and sum(s["width"] for s in secs) == pytest.approx(3.0 - 0.375)
    beyond = sorted(m["along"] for m in manual if m["along"][0] > 1.0)
    assert beyond == [pytest.approx([2.925, 3.3], abs=1e-6), pytest.approx([3.3, 4.8], abs=1e-6)]
    assert any("no free base pose" in m["reason"] for m in manual)


def test_get_area_raster_runs_the_lanes_on_into_a_part_left_manual_where_a_free_base_reaches_that_too():
    """Beside a column left manual (no free base pose reaches all of it) the worked section's lanes run on by
    edge_extension, as at an open edge (else the fan's soft edge leaves its last centimetres thin: generated bay 41
    sprayed 0.975 of its reachable part, 0.992 with it) -- only as far as a free base reaches."""
    plan = {"wall": "wall_1", "work": "spray", "tool": [[0.3, 3.3]], "base": [[0.6, 2.9]], "t": [0.0, 2.5],
            "reach": 0.3, "why": []}

    def worked(ext):
        rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="0.9" yaw_offset="0" '
                  'min_manual="0.03" edge_extension="%s" plan="{p}" sections="{s}" count="{c}" manual="{m}"/>'
                  % ext, cfg={"p": plan})
        assert rig.tree.tick() == S
        last = max(rig.bb.get("s"), key=lambda sec: sec["origin"][0])
        a0, a1, base = last["origin"][0], last["origin"][0] + last["width"], last["approach"][0]
        # from a free base that reaches both its ends, the run-on included
        assert 0.6 - 1e-6 <= base <= 2.9 + 1e-6 and a1 - 0.3 - 1e-6 <= base <= a0 + 0.3 + 1e-6, last
        manual = sorted(m["along"] for m in rig.bb.get("m") if m["along"][0] > 1.0)
        return a1, manual
    end, manual = worked(0.07)
    assert end == pytest.approx(2.925 + 0.07)
    assert manual[0] == pytest.approx([2.925, 3.3], abs=1e-6)       # the manual part's extent is unchanged
    end, _manual = worked(0.3)                                      # no free base reaches 0.3 m on
    assert end == pytest.approx(2.925)


def test_node_needing_a_missing_handle_fails_clearly():
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T"><CheckHealth/></BehaviorTree></root>')
    t = lib.build("T", NodeContext())
    assert t.tick() == F
    assert "needs the 'health' handle" in t.ctx.last_failure()[1]


def test_select_entry_with_fallback_and_unknown_key():
    body = '<SelectEntry table="{@cfg.site.locations}" key="{param_location}" fallback_key="home" value="{v}"/>'
    locs = {"cfg.site.locations": {"home": [1.0, 2.0, 0.0], "dock": [0.0, 0.0, 3.1]}}
    rig = Rig(body, cfg=locs)
    assert rig.tree.tick() == S and rig.bb.get("v") == [1.0, 2.0, 0.0]
    rig = Rig(body, cfg=dict(locs, param_location="dock"))
    assert rig.tree.tick() == S and rig.bb.get("v") == [0.0, 0.0, 3.1]
    rig = Rig(body, cfg=dict(locs, param_location="garage"))
    assert rig.tree.tick() == F and "no entry 'garage'; the table has: dock, home" in rig.reason()


# --------------------------------------------------------------------------------------------------- Log --
LOG_BODY = ('<Log message="tape {line} from {pose} ({note}), speed {@cfg.taping.speed} m/s, first section at '
            '{sec.origin}" level="%s"/>')
LOG_CFG = {"line": "wall_1_joint_1", "pose": [1.2, -0.5, math.pi / 2], "note": "second pass, by request",
           "cfg.taping.speed": 0.15, "sec": {"origin": [0.0, 3.0, 1e-9]}}
LOG_TEXT = ("tape wall_1_joint_1 from 1.2 -0.5 1.570796 (second pass, by request), speed 0.15 m/s, first "
            "section at 0 3 0")


def _records(caplog, logger="locem_bridge.hicem"):
    return [(r.levelname, r.getMessage()) for r in caplog.records if r.name == logger]


@pytest.mark.parametrize("level", ["debug", "info", "warning", "error"])
def test_log_writes_its_message_with_blackboard_values_at_its_level_and_succeeds(caplog, level):
    caplog.set_level("DEBUG", logger="locem_bridge.hicem")
    rig = Rig(LOG_BODY % level, cfg=LOG_CFG)
    assert rig.tree.tick() == S
    # numbers in plain decimal, lists space-separated, a field of an entry, and texts with spaces kept whole
    assert _records(caplog) == [(level.upper(), LOG_TEXT)]
    # a log line commands nothing, asks nothing and records no failure
    assert rig.locem.sent == [] and rig.operator.open_prompts() == [] and rig.ctx.failures == []


def test_log_level_defaults_to_info_and_goes_to_the_injected_logger(caplog):
    caplog.set_level("DEBUG")
    lib = TreeLibrary()
    lib.load_string('<root BTCPP_format="4"><BehaviorTree ID="T"><Log message="done with {line}"/></BehaviorTree>'
                    '</root>')
    bb = Blackboard()
    bb.set("line", "wall_2_joint_1")
    t = lib.build("T", NodeContext(log=logging.getLogger("test.hicem.operator_log")), bb)
    assert t.tick() == S
    assert _records(caplog, "test.hicem.operator_log") == [("INFO", "done with wall_2_joint_1")]
    assert _records(caplog) == []  # nothing on the default HICEM logger


def test_log_with_an_unset_key_fails_naming_it_and_writes_nothing(caplog):
    caplog.set_level("DEBUG", logger="locem_bridge.hicem")
    rig = Rig('<Log message="tape {line} now" level="warning"/>')
    assert rig.tree.tick() == F
    assert rig.reason() == "blackboard key 'line' is not set (or has no such field)"
    assert [m for lvl, m in _records(caplog) if "tape" in m] == []


def test_log_level_outside_its_choices_is_a_load_error():
    with pytest.raises(TreeLoadError) as ei:
        TreeLibrary().load_string('<root BTCPP_format="4"><BehaviorTree ID="T">\n<Log message="x" level="loud"/>'
                                  '</BehaviorTree></root>', "log.xml")
    e = ei.value
    assert (e.file, e.line) == ("log.xml", 2) and "port 'level'" in str(e)
    assert "debug, info, warning, error" in str(e)


def test_get_area_raster_leaves_a_door_out_and_runs_the_lanes_on_past_its_frame():
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="1.3" yaw_offset="0" '
              'edge_extension="0.05" band_gap="0.15" sections="{s}" count="{c}"/>')
    scan = {"walls": [dict(SITE["walls"][0], openings=[{"id": "door_1", "kind": "door", "s": [1.5, 2.4],
                                                       "t": [0.0, 2.05], "frame": 0.05}])],
            "areas": [{"id": "wall_1_area_1", "wall": "wall_1", "origin": [0.0, 3.0, 0.1], "u": [1.0, 0.0, 0.0],
                       "width": 4.8, "height": 2.3, "holes": [{"s": [1.45, 2.45], "t": [0.0, 2.0]}]}]}
    rig.hdh.ingest_scan(scan)
    assert rig.tree.tick() == S
    secs = rig.bb.get("s")
    assert rig.bb.get("c") == len(secs) and [s["index"] for s in secs] == list(range(len(secs)))
    door = (1.45, 2.45)          # along the wall (area origin at s 0), frame included, up to 2.1 m above the floor
    for s in secs:
        a, b = s["origin"][0], s["origin"][0] + s["width"]
        z0, z1 = s["origin"][2], s["origin"][2] + s["height"]
        overlap = min(b, door[1]) - max(a, door[0])
        if z0 < 2.1 - 1e-9 and overlap > 0:
            # only a section that ends at the frame runs on into it, by the edge extension
            assert overlap == pytest.approx(0.05), s
        # the approach faces the section's own middle, not the area's
        assert s["approach"][0] == pytest.approx(a + s["width"] / 2.0, abs=0.06)
    lintel = [s for s in secs if s["origin"][0] >= 1.45 - 1e-9 and s["origin"][0] + s["width"] <= 2.45 + 1e-9]
    assert lintel and all(s["origin"][2] == pytest.approx(2.1) for s in lintel)
    assert sum(s["width"] for s in lintel) == pytest.approx(1.0)     # shared sides: no run-on past them


def test_get_area_raster_keeps_a_pad_its_radius_off_a_frame_and_runs_the_columns_up_beside_a_low_door():
    body = ('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="1.0" yaw_offset="0" '
            'band_gap="0.18" hole_margin="%s" sections="{s}" count="{c}"/>')
    scan = {"walls": [dict(SITE["walls"][0], openings=[{"id": "door_1", "kind": "door", "s": [1.5, 2.4],
                                                       "t": [0.0, 1.8], "frame": 0.05}])],
            "areas": [{"id": "wall_1_area_1", "wall": "wall_1", "origin": [0.0, 3.0, 0.1], "u": [1.0, 0.0, 0.0],
                       "width": 4.8, "height": 1.9, "holes": [{"s": [1.45, 2.45], "t": [0.0, 1.75]}]}]}
    for margin in (0.0, 0.1125):
        rig = Rig(body % margin)
        rig.hdh.ingest_scan(scan)
        assert rig.tree.tick() == S
        secs = rig.bb.get("s")
        beside = [s for s in secs if s["origin"][2] == pytest.approx(0.1)]
        left = max(s["origin"][0] + s["width"] for s in beside if s["origin"][0] < 1.45)
        right = min(s["origin"][0] for s in beside if s["origin"][0] > 1.45)
        # a margin reaches GetAreaRaster.FRAME_REACH (2 mm) over the frame's outer line: the wall up to it is sanded
        margin = max(0.0, margin - GetAreaRaster.FRAME_REACH) if margin > 0 else 0.0
        assert left == pytest.approx(1.45 - margin) and right == pytest.approx(2.45 + margin)
        # the 0.15 m above the door's frame is no taller than a lane gap: the columns beside it run up to the top
        assert all(s["origin"][2] + s["height"] == pytest.approx(2.0) for s in beside)
        lintel = [s for s in secs if s["origin"][2] > 0.1 + 1e-9]
        assert lintel and all(s["origin"][2] == pytest.approx(1.85 + margin) for s in lintel)


def test_get_area_raster_edge_passes_follow_the_sections_beside_a_frame_up_its_sides():
    body = ('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="1.0" yaw_offset="0" '
            'band_gap="0.18" hole_margin="0.1125" edge_passes="%s" sections="{s}" count="{c}"/>')
    scan = {"walls": [dict(SITE["walls"][0], openings=[{"id": "door_1", "kind": "door", "s": [1.5, 2.4],
                                                       "t": [0.0, 1.8], "frame": 0.05}])],
            "areas": [{"id": "wall_1_area_1", "wall": "wall_1", "origin": [0.0, 3.0, 0.1], "u": [1.0, 0.0, 0.0],
                       "width": 4.8, "height": 1.9, "holes": [{"s": [1.45, 2.45], "t": [0.0, 1.75]}]}]}
    rig = Rig(body % "false")
    rig.hdh.ingest_scan(scan)
    assert rig.tree.tick() == S
    plain = rig.bb.get("s")
    assert {s["lanes"] for s in plain} == {"horizontal"}
    rig = Rig(body % "true")
    rig.hdh.ingest_scan(scan)
    assert rig.tree.tick() == S
    secs = rig.bb.get("s")
    assert rig.bb.get("c") == len(secs) == len(plain) + 2 and [s["index"] for s in secs] == list(range(len(secs)))
    passes = [(i, s) for i, s in enumerate(secs) if s["lanes"] == "vertical"]
    margin = 0.1125 - GetAreaRaster.FRAME_REACH
    assert [s["origin"][0] for _, s in passes] == pytest.approx([1.45 - margin, 2.45 + margin])
    for i, s in passes:
        # width 0 (one lane), from the column's bottom up to the frame's top plus the margin, the same base pose
        # as the section it follows, which ends (left) or starts (right) at that side
        assert s["width"] == 0.0 and s["origin"][2] == pytest.approx(0.1)
        assert s["origin"][2] + s["height"] == pytest.approx(0.1 + 1.75 + margin)
        before = secs[i - 1]
        assert before["lanes"] == "horizontal" and s["approach"] == before["approach"]
        assert s["origin"][0] == pytest.approx(before["origin"][0] + before["width"]) or \
            s["origin"][0] == pytest.approx(before["origin"][0])
    # the sections themselves are the same as without the passes
    assert [dict(s, index=0) for s in secs if s["lanes"] == "horizontal"] == [dict(s, index=0) for s in plain]


def test_get_area_raster_gives_every_section_the_same_coat_per_m2_whatever_its_height():
    """A window cuts the area into pieces 0.7, 0.55, 0.5 and 0.35 m tall. At the nominal 0.15 m spacing LOCEM
    would lay their lanes ceil(h / 0.15) intervals apart: 0.14, 0.1375, 0.125, 0.1167 m (+7 %, +9 %, +20 %,
    +29 % of coat). Each
    section gets the whole number of intervals nearest 0.15 m, rounded up to what the command carries, and a
    speed scaled by the ratio (at most max_speed): spacing x speed, the coat's inverse, is the same everywhere."""
    from locem_bridge.common.raster_progress import lane_heights
    scan = {"walls": [dict(SITE["walls"][0], openings=[{"id": "w", "kind": "window", "s": [1.5, 2.4],
                                                       "t": [0.85, 1.45], "frame": 0.05}])],
            "areas": [{"id": "wall_1_area_1", "wall": "wall_1", "origin": [0.0, 3.0, 0.1], "u": [1.0, 0.0, 0.0],
                       "width": 4.8, "height": 1.9, "holes": [{"s": [1.45, 2.45], "t": [0.7, 1.4]}]}]}
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="1.3" yaw_offset="0" '
              'band_gap="0.15" lane_spacing="0.15" speed="0.5" max_speed="0.6" sections="{s}" count="{c}"/>')
    rig.hdh.ingest_scan(scan)
    assert rig.tree.tick() == S
    secs = rig.bb.get("s")
    heights = sorted({round(s["height"], 4) for s in secs})
    # the sill row, beside the window, above it (from its top at 1.4 m), above the columns (one gap higher)
    assert heights == [0.35, 0.5, 0.55, 0.7]
    for s in secs:
        n = round(s["height"] / 0.15) or 1
        lanes = lane_heights(s["height"], s["spacing"])
        assert len(lanes) == n + 1 and s["spacing"] == pytest.approx(s["height"] / n, abs=1e-5), s
        assert s["speed"] * s["spacing"] == pytest.approx(0.5 * 0.15, rel=1e-3), s
    # without lane_spacing: the spacing given (band_gap) and the speed port as they are
    rig = Rig('<GetAreaRaster area_id="wall_1_area_1" section_width="0.6" base_standoff="1.3" yaw_offset="0" '
              'band_gap="0.15" speed="0.5" sections="{s}" count="{c}"/>')
    rig.hdh.ingest_scan(scan)
    assert rig.tree.tick() == S
    assert {(s["spacing"], s["speed"]) for s in rig.bb.get("s")} == {(0.15, 0.5)}
