"""How HICEM's state reads on the operator's screen, the picture folder scan, the default answers."""
from locem_bridge.hmi import DEFAULT_CONFIG, AutoOperatorConfig, snapshot_from_hicem, wall_pictures_in
from locem_bridge.hmi.auto_operator import AutoOperatorPolicy


def test_snapshot_from_a_controller_state():
    state = {"process": "https://x.org/ont/plasterboard#TapingProcess", "specific_process": "urn:run:1",
             "action_type": "VALIDATE_TAPE_LINE", "task": "http://example.org/run#task_7", "tree": "VALIDATE_TAPE_LINE",
             "node": "ask_valid", "path": "validate_tape_line/ask_valid", "phase": "running", "detail": ""}
    snap = snapshot_from_hicem(state, None, {"done": 1, "total": 3, "text": "joint 2 of 3"})
    assert snap["action"] == "VALIDATE_TAPE_LINE (task_7)" and snap["node"] == "ask_valid" and snap["skill"] == ""
    basic = snapshot_from_hicem(dict(state, action_type="CHANGE_TOOL", skill="CHANGE_TOOL", tree="BASIC_SKILL"))
    assert (basic["skill"], basic["tree"]) == ("CHANGE_TOOL", "BASIC_SKILL")
    assert snap["phase"] == "running" and snap["health"]["status"] == "unknown" and snap["progress"]["total"] == 3
    idle = snapshot_from_hicem({}, None)
    assert idle["phase"] == "idle" and idle["action"] == "" and idle["progress"] is None


def test_wall_pictures_in_a_folder(tmp_path):
    assert wall_pictures_in(str(tmp_path / "not_yet")) == {} and wall_pictures_in(None) == {}
    for name in ("wall_1.png", "wall_2.PNG", "report.json", "1st wall.png", "notes.txt"):
        (tmp_path / name).write_bytes(b"x")
    assert wall_pictures_in(str(tmp_path)) == {"wall_1": str(tmp_path / "wall_1.png"),
                                               "wall_2": str(tmp_path / "wall_2.PNG")}


def test_default_answers_and_overrides():
    pol = AutoOperatorPolicy(AutoOperatorConfig.defaults())
    resume = {"kind": "finish_interrupted", "text": "Finish joint wall_1_joint_1 by hand?",
              "choices": ["done", "abandon"]}
    assert pol.decide(resume, 0.0).answer == "done"
    cfg = AutoOperatorConfig.from_dict({"kinds": {"validate_line": {"answer": "valid",
                                                                    "per_feature": {"invalid": ["wall_2_joint_1"]}}}},
                                       base=DEFAULT_CONFIG)
    assert cfg.kinds["mount_tool"].answer == "done" and cfg.kinds["validate_line"].delay_s == 0.0
    line = {"kind": "validate_line", "text": "Is joint wall_2_joint_1 well placed?", "choices": ["valid", "invalid"]}
    assert AutoOperatorPolicy(cfg).decide(line, 0.0).answer == "invalid"
    assert AutoOperatorConfig.from_dict(None, base=DEFAULT_CONFIG).poll_period_s == DEFAULT_CONFIG["poll_period_s"]


def test_the_backends_satisfy_the_protocol():
    import os
    import sys
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    from hicem_double import ScriptedHicemDouble
    from locem_bridge.hmi import ExecutiveBackend, HmiBackend

    assert isinstance(ScriptedHicemDouble(), HmiBackend)
    assert isinstance(ExecutiveBackend(controller=None, operator=None), HmiBackend)
    assert not isinstance(object(), HmiBackend)
