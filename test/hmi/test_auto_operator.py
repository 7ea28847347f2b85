"""The automatic operator: configuration checking, the pure policy, and whole runs against the HICEM test double
(prompts managed by HICEM's real OperatorDesk)."""
import threading
import time

import pytest
import yaml

from hicem_double import TAPING, ScriptedHicemDouble
from locem_bridge.hmi import (AutoOperator, AutoOperatorConfig, AutoOperatorConfigError, AutoOperatorPolicy,
                              BackendUnavailable)

CONFIG_YAML = """
poll_period_s: 0.02
kinds:
  mount_tool:    {answer: done, delay_s: 2.0}
  validate_line: {answer: valid, delay_s: 0.5, per_feature: {invalid: [wall_1_joint_2]}}
  manual_taping: {answer: done, delay_s: 1.0}
"""


def config():
    return AutoOperatorConfig.from_dict(yaml.safe_load(CONFIG_YAML))


def prompt(kind, text, choices, **context):
    return {"id": "p", "kind": kind, "text": text, "choices": list(choices), "context": context}


# the text the real VALIDATE_TAPE_LINE tree renders (trees/VALIDATE_TAPE_LINE.xml); context is only the node name
def line_prompt(joint):
    return prompt("validate_line", "Is joint %s well placed for taping from here? Answer valid or invalid." % joint,
                  ("valid", "invalid"), node="ask_valid")


class ManualClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_policy_answers_by_kind_after_the_delay():
    pol = AutoOperatorPolicy(config())
    mount = prompt("mount_tool", "Mount the taping_tool on the arm, then answer done.", ("done",))
    assert pol.decide(mount, 1.99).answer is None and not pol.decide(mount, 1.99).final
    d = pol.decide(mount, 2.0)
    assert d.answer == "done" and d.final
    assert pol.decide(line_prompt("wall_1_joint_1"), 0.5).answer == "valid"
    assert pol.decide(line_prompt("wall_1_joint_1"), 0.4).answer is None


def test_listed_lines_are_rejected_by_whole_word_only():
    pol = AutoOperatorPolicy(config())
    d = pol.decide(line_prompt("wall_1_joint_2"), 1.0)
    assert d.answer == "invalid" and d.features == ("wall_1_joint_2",) and "wall_1_joint_2" in d.reason
    assert pol.decide(line_prompt("wall_1_joint_20"), 1.0).answer == "valid"
    assert pol.decide(line_prompt("wall_11_joint_2"), 1.0).answer == "valid"
    by_context = prompt("validate_line", "Is this line valid?", ("valid", "invalid"), line="wall_1_joint_2")
    assert pol.decide(by_context, 1.0).answer == "invalid"


def test_answers_outside_the_choices_are_never_sent():
    pol = AutoOperatorPolicy(AutoOperatorConfig.from_dict({"kinds": {"mount_tool": {"answer": "yes"}}}))
    d = pol.decide(prompt("mount_tool", "Mount the sander", ("done",)), 10.0)
    assert d.answer is None and d.final and "'yes'" in d.reason and "done" in d.reason
    # unknown kind, default rule: only a single-choice prompt is answered
    assert pol.decide(prompt("confirm", "Ready?", ("ok",)), 0.0).answer == "ok"
    d = pol.decide(prompt("choose", "Which?", ("a", "b")), 0.0)
    assert d.answer is None and "left for a human" in d.reason


@pytest.mark.parametrize("raw, words", [
    ({"kinds": {"mount_tool": {"anwser": "done"}}}, ["kinds.mount_tool", "anwser", "answer, delay_s, per_feature"]),
    ({"kinds": {"mount_tool": {"delay_s": -1}}}, ["kinds.mount_tool.delay_s", "-1", "[0, 86400]"]),
    ({"kinds": {"mount_tool": {"delay_s": "2"}}}, ["delay_s", "'2'"]),
    ({"kinds": {"validate_line": {"per_feature": {"invalid": "wall_1_joint_2"}}}}, ["per_feature.invalid", "list"]),
    ({"kinds": {"validate_line": {"per_feature": {"invalid": ["joint 2"]}}}}, ["'joint 2'", "feature id"]),
    ({"kinds": {"validate_line": {"per_feature": {"invalid": ["j1"], "valid": ["j1"]}}}}, ["j1", "both"]),
    ({"kinds": {"mount_tool": "done"}}, ["kinds.mount_tool", "mapping"]),
    ({"poll_period_s": 0}, ["poll_period_s", "[0.01, 10]"]),
    ({"answers": {}}, ["unknown key", "answers", "poll_period_s, default, kinds"]),
    ({"kinds": {"mount_tool": {"answer": ""}}}, ["answer", "non-empty"]),
])
def test_bad_configuration_is_named(raw, words):
    with pytest.raises(AutoOperatorConfigError) as info:
        AutoOperatorConfig.from_dict(raw)
    for w in words:
        assert w in str(info.value), (w, str(info.value))


def test_a_whole_run_stepped_with_a_manual_clock():
    double = ScriptedHicemDouble()
    clock = ManualClock()
    auto = AutoOperator(double, config(), clock=clock)
    double.start_process(TAPING)
    assert auto.step() == []                          # mount_tool seen at t=100, due at 102
    clock.t = 101.9
    assert auto.step() == []
    clock.t = 102.0
    (given,) = auto.step()
    assert (given["kind"], given["answer"]) == ("mount_tool", "done")
    for expect_joint, expect in (("wall_1_joint_1", "valid"), ("wall_1_joint_2", "invalid"),
                                 ("wall_2_joint_1", "valid")):
        assert auto.step() == []                      # new prompt first seen now
        clock.t += 0.5
        (given,) = auto.step()
        assert given["answer"] == expect and expect_joint in given["text"]
    assert double.snapshot()["phase"] == "ended"
    assert double.joint_state == {"wall_1_joint_1": "taped", "wall_1_joint_2": "manual", "wall_2_joint_1": "taped"}
    replies = [c for c in double.calls if c[0] == "reply"]
    assert [c[2] for c in replies] == ["done", "valid", "invalid", "valid"]
    assert [a["answer"] for a in auto.answers] == ["done", "valid", "invalid", "valid"]
    assert auto.answers[2]["features"] == ["wall_1_joint_2"] and double.desk.interventions == 4


def test_the_thread_runs_a_run_to_the_end_and_stops():
    double = ScriptedHicemDouble()
    cfg = AutoOperatorConfig.from_dict({"poll_period_s": 0.01, "kinds": {
        "mount_tool": {"answer": "done", "delay_s": 0.05},
        "validate_line": {"answer": "valid", "per_feature": {"invalid": ["wall_2_joint_1"]}}}})
    auto = AutoOperator(double, cfg)
    auto.start()
    try:
        double.start_process(TAPING)
        end = time.monotonic() + 5.0
        while double.snapshot()["phase"] != "ended" and time.monotonic() < end:
            time.sleep(0.01)
        assert double.snapshot()["phase"] == "ended"
    finally:
        auto.stop()
    assert auto._thread is None
    assert double.joint_state == {"wall_1_joint_1": "taped", "wall_1_joint_2": "taped", "wall_2_joint_1": "manual"}
    assert not any(t.name == "auto-operator" for t in threading.enumerate())


def test_a_prompt_answered_by_a_human_first_is_left_alone():
    double = ScriptedHicemDouble()
    clock = ManualClock()
    auto = AutoOperator(double, config(), clock=clock)
    double.start_process(TAPING)
    auto.step()
    pid = double.prompts()[0]["id"]

    class Racing:
        """Lists the prompt as still open although a human has just answered it."""
        def prompts(self):
            return [dict(p, state="open") for p in [double.desk.get(pid).as_dict()]]

        def reply(self, prompt_id, answer):
            return double.reply(prompt_id, answer)

    double.reply(pid, "done")                         # the human was faster
    auto.backend = Racing()
    clock.t += 5
    assert auto.step() == []                          # tried once, refused by the desk -> logged, no crash
    assert auto.step() == []                          # and not retried
    assert [c for c in double.calls if c[0] == "reply"] == [("reply", pid, "done")] * 2
    assert auto.answers == [] and double.desk.interventions == 1


def test_an_unreachable_backend_is_retried_not_fatal():
    calls = []

    class Down:
        def __init__(self):
            self.up = False

        def prompts(self):
            if not self.up:
                raise BackendUnavailable("/hicem/prompts not published yet")
            return [{"id": "a", "kind": "mount_tool", "text": "Mount the sander", "choices": ["done"]}]

        def reply(self, pid, answer):
            calls.append((pid, answer))

    down = Down()
    auto = AutoOperator(down, AutoOperatorConfig.from_dict({"kinds": {"mount_tool": {"answer": "done"}}}))
    assert auto.step() == [] and "not published yet" in auto.errors[-1]
    down.up = True
    assert [a["answer"] for a in auto.step()] == ["done"] and calls == [("a", "done")]
    assert auto.step() == [] and calls == [("a", "done")]          # answered once only
