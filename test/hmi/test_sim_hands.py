"""The simulated operator's hands: which simulator operations an answer implies, for the prompt texts the
shipped trees render (trees/GET_TOOL.xml, MANUAL_TAPING.xml, RESUME_TAPE_LINE.xml)."""
import pytest

from locem_bridge.hmi.sim_hands import HandsError, hand_actions

JOINTS = ["wall_1_joint_1", "wall_1_joint_2", "wall_1_joint_20"]


def prompt(kind, text, **context):
    return {"id": "p1", "kind": kind, "text": text, "choices": ["done"], "context": context}


@pytest.mark.parametrize("tool", ["taping_tool", "spray_gun", "sander"])
def test_mounting_a_tool(tool):
    p = prompt("mount_tool", "Mount the %s on the arm, then answer done." % tool, node="ask_mount")
    assert hand_actions(p, "done") == [("remove_tool", {}), ("mount_tool", {"name": tool})]


def test_taping_by_hand_names_the_exact_joint():
    p = prompt("manual_taping", "Please tape joint wall_1_joint_2 by hand, then answer done.")
    assert hand_actions(p, "done", JOINTS) == [("manual_taping", {"joint": "wall_1_joint_2"})]
    resume = prompt("finish_interrupted", "Taping of joint wall_1_joint_20 was interrupted by a HICEM restart. "
                    "Finish it by hand and answer done, or answer abandon.")
    assert hand_actions(resume, "done", JOINTS) == [("manual_taping", {"joint": "wall_1_joint_20"})]
    assert hand_actions(resume, "abandon", JOINTS) == []
    assert hand_actions(prompt("manual_taping", "Tape it by hand.", line="wall_1_joint_1"), "done", JOINTS) == [
        ("manual_taping", {"joint": "wall_1_joint_1"})]


def test_answers_that_need_no_hands():
    line = {"id": "p2", "kind": "validate_line", "text": "Is joint wall_1_joint_1 well placed?",
            "choices": ["valid", "invalid"]}
    assert hand_actions(line, "invalid", JOINTS) == [] and hand_actions(line, "valid", JOINTS) == []


@pytest.mark.parametrize("p, words", [
    (prompt("mount_tool", "Mount the trowel on the arm."), ["p1", "taping_tool, spray_gun, sander", "trowel"]),
    (prompt("manual_taping", "Please tape joint wall_9_joint_9 by hand."), ["no known joint", "wall_9_joint_9"]),
])
def test_prompts_that_name_nothing_known(p, words):
    with pytest.raises(HandsError) as info:
        hand_actions(p, "done", JOINTS)
    for w in words:
        assert w in str(info.value)
