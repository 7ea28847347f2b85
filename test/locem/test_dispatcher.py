"""The dispatcher's policy: validation first, one command per resource, STOP pre-empts, deadlines hold."""
import time

import pytest

from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.execution import ExecState
from locem_bridge.locem.registry import Interface



def test_help_lists_every_command_and_marks_unserved_ones(core):
    response = core.dispatcher.execute("HELP")
    assert response.success
    names = [c["name"] for c in response.result["commands"]]
    assert sorted(names[:8]) == ["HALT", "HELP", "RESET", "RESUME", "STATUS", "STOP", "SUSPEND", "WAIT"] and "ARM_MOVE" in names
    assert "UNSERVED" in response.message and "[not served here]" in response.message
    detail = core.dispatcher.execute("help arm_move")
    assert detail.success and "a number from 0 to 60 s" in detail.message
    assert detail.result["command"]["resources"] == ["arm"]


def test_help_for_an_unknown_name_suggests(core):
    response = core.dispatcher.execute("HELP ARM_MOOVE")
    assert response.code is Code.INVALID_ARGUMENT and "did you mean ARM_MOVE" in response.message


def test_second_command_on_a_busy_resource_is_refused_other_resources_run(core, device):
    first = core.dispatcher.submit("ARM_MOVE 2", Interface.ACTION)
    busy = core.dispatcher.execute("ARM_MOVE 0.1")
    assert busy.code is Code.BUSY
    assert "needs the arm, which is running 'ARM_MOVE 2' (id %d)" % first.id in busy.message
    assert core.dispatcher.execute("BASE_MOVE 0.05").success  # the base is free
    assert device.calls.count(("move", 0.1)) == 0  # the refused command never reached the device
    first.cancel()
    assert first.wait(1.0).code is Code.ABORTED


def test_a_command_sent_as_soon_as_the_previous_one_answered_is_not_busy(core, wait_until):
    # a client that sends the next arm command the moment the previous one's answer arrives (the reply of a
    # service call, the final /locem/status event) must find the arm free: the resource is released before the
    # answer is visible, not after
    replies = []

    def on_event(event):
        if event.name == "ARM_MOVE" and event.state.terminal and event.command == "ARM_MOVE 0":
            replies.append(core.dispatcher.execute("ARM_MOVE 0.01"))

    core.dispatcher.add_listener(on_event)
    assert core.dispatcher.execute("ARM_MOVE 0").success
    assert wait_until(lambda: replies, timeout=2.0), "the final event of ARM_MOVE 0 never came"
    assert replies[0].success, replies[0].message


def test_stop_preempts_everything_and_runs_device_stops(core, device):
    arm = core.dispatcher.submit("ARM_MOVE 30", Interface.ACTION)
    base = core.dispatcher.submit("BASE_MOVE 0.4", Interface.SUBSCRIBER)
    start = time.monotonic()
    stop = core.dispatcher.execute("STOP")
    elapsed = time.monotonic() - start
    assert stop.success and sorted(stop.result["stopped"]) == sorted([arm.id, base.id])
    assert stop.result["still_running"] == []
    assert elapsed < 0.5
    assert arm.wait(0.1).code is Code.ABORTED and "stopped by STOP" in arm.response.message
    assert base.wait(0.1).code is Code.ABORTED
    assert device.stops >= 3  # each command's on_cancel stop plus the set's stop hook
    assert core.dispatcher.execute("ARM_MOVE 0").success  # accepted again afterwards


def test_deadline_turns_into_timeout_and_frees_the_resource(core):
    start = time.monotonic()
    response = core.dispatcher.execute("BASE_MOVE 5")  # declared timeout 0.5 s
    assert response.code is Code.TIMEOUT
    assert "did not finish within 0.5 s" in response.message
    assert 0.45 < time.monotonic() - start < 1.0
    assert core.dispatcher.owner_of("base") is None


def test_handler_ignoring_the_deadline_still_answers_and_keeps_the_resource(core, device, wait_until):
    start = time.monotonic()
    response = core.dispatcher.execute("ARM_HANG")  # timeout 0.2 s + grace 0.3 s
    assert response.code is Code.TIMEOUT
    assert time.monotonic() - start < 1.0
    status = core.dispatcher.execute("STATUS").result
    assert [r["stuck"] for r in status["running"]] == [True]
    assert "stuck after a timeout" in core.dispatcher.execute("ARM_MOVE 0").message
    device.release.set()
    assert wait_until(lambda: core.dispatcher.owner_of("arm") is None)
    assert core.dispatcher.execute("ARM_MOVE 0").success


def test_device_errors_and_handler_bugs_become_codes_and_serving_continues(core):
    hw = core.dispatcher.execute("ARM_MOVE 1 fail=true")
    assert hw.code is Code.HARDWARE_ERROR and "overcurrent" in hw.message
    bug = core.dispatcher.execute("BUGGY")
    assert bug.code is Code.HARDWARE_ERROR and "ZeroDivisionError" in bug.message
    assert core.dispatcher.execute("STATUS").success


def test_declared_command_without_backend_is_not_ready(core):
    response = core.dispatcher.execute("UNSERVED")
    assert response.code is Code.NOT_READY


def test_pause_does_not_count_against_wait_or_deadline(core):
    start = time.monotonic()
    execution = core.dispatcher.submit("WAIT 0.3", Interface.ACTION)
    time.sleep(0.1)
    execution.pause()
    assert execution.state is ExecState.PAUSED
    time.sleep(0.4)
    assert not execution.done
    execution.resume()
    response = execution.wait(2.0)
    assert response.success and response.result["waited_s"] == 0.3
    assert time.monotonic() - start >= 0.7


def test_non_pausable_command_refuses_pause(core):
    execution = core.dispatcher.submit("ARM_MOVE 1", Interface.ACTION)
    try:
        execution.pause()
        raise AssertionError("pause accepted")
    except Exception as error:
        assert "cannot be suspended" in str(error)
    execution.cancel()


def test_every_interface_publishes_state_changes_and_rejections(core):
    events = []
    core.dispatcher.add_listener(events.append)
    core.dispatcher.execute("WAIT 0.1")
    core.dispatcher.execute("WAIT -1")
    states = [(e.name, e.state, e.code) for e in events]
    assert states == [("WAIT", ExecState.RUNNING, ""), ("WAIT", ExecState.SUCCEEDED, "OK"),
                      ("WAIT", ExecState.REJECTED, "INVALID_ARGUMENT")]


def test_progress_feedback_reaches_the_command_listener_only(core):
    seen, published = [], []
    core.dispatcher.add_listener(published.append)
    core.dispatcher.submit("WAIT 0.2", Interface.ACTION, listener=seen.append).wait(2.0)
    progress = [e.progress for e in seen if e.state is ExecState.RUNNING]
    assert len(progress) >= 3 and progress == sorted(progress) and progress[-1] == 1.0
    assert [e.state for e in published] == [ExecState.RUNNING, ExecState.SUCCEEDED]


def test_status_reports_health_of_installed_backends(core):
    status = core.dispatcher.execute("STATUS")
    assert status.result["health"] == {"fake": {"link": "up", "device": "ok", "last_error": ""}}


def test_read_only_queries_are_not_published_as_state_changes(core):
    events = []
    core.dispatcher.add_listener(events.append)
    assert core.dispatcher.execute("STATUS").success and core.dispatcher.execute("HELP").success
    assert events == []
    core.dispatcher.execute("STATUS now")  # a rejected query is still published
    assert [(e.name, e.state.value) for e in events] == [("STATUS", "rejected")]


def test_status_names_what_runs_and_what_it_holds_then_idle_again(core, wait_until):
    idle = core.dispatcher.execute("STATUS")
    assert idle.message == "0 running; all resources idle"
    assert (idle.result["running"], idle.result["resources"]) == ([], {})
    assert isinstance(idle.result["uptime_s"], float) and idle.result["uptime_s"] >= 0.0
    wait = core.dispatcher.submit("WAIT 5 hold=arm", Interface.SERVICE)
    busy = core.dispatcher.execute("STATUS")
    assert busy.message == "1 running; arm: %d" % wait.id
    assert busy.result["resources"] == {"arm": wait.id}
    assert [(r["id"], r["command"], r["resources"]) for r in busy.result["running"]] == [
        (wait.id, "WAIT 5 hold=arm", ["arm"])]
    wait.cancel()
    assert wait_until(lambda: core.dispatcher.execute("STATUS").message == "0 running; all resources idle")


def test_results_are_compact_json_with_sorted_keys_whatever_the_handler_returns():
    import json

    import numpy as np
    from locem_bridge.locem.response import Response

    result = {"b": (1, 2), "a": {3, 1}, "n": np.float64(0.25), "v": np.arange(3), "nan": float("nan"),
              "text": "Wand \u00e4 \"1\"", "nested": {"z": None, "y": [True, 1.5]}}
    text = Response(Code.OK, "done", result).result_json
    assert text == ('{"a":[1,3],"b":[1,2],"n":0.25,"nan":NaN,"nested":{"y":[true,1.5],"z":null},'
                    '"text":"Wand \\u00e4 \\"1\\"","v":[0,1,2]}')
    assert json.loads(text)["text"] == result["text"]
    cyclic = {"a": []}
    cyclic["a"].append(cyclic)
    with pytest.raises(ValueError, match="Circular reference"):
        Response(Code.OK, "done", cyclic).result_json
