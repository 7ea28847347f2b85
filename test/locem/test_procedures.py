"""The procedure queue: order, states published on change only, pause/resume/cancel, STOP."""
import time

import pytest

from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.errors import InvalidArgument, InvalidCommand
from locem_bridge.locem.procedures import ProcedureState
from locem_bridge.locem.registry import Interface


Q, R, P, F = ProcedureState.QUEUED, ProcedureState.RUNNING, ProcedureState.PAUSED, ProcedureState.FINISHED


@pytest.fixture
def published(core):
    log = []
    core.procedures.add_listener(log.append)
    return log


def history(published, pid):
    return [s.state for s in published if s.id == pid]


def test_procedures_run_one_at_a_time_in_order(core, published, wait_until):
    ids = [core.procedures.add("WAIT %s" % t).id for t in (0.2, 0.05, 0.05)]
    assert wait_until(lambda: all(core.procedures.query_state(i).state is F for i in ids))
    finished = [s.id for s in published if s.state is F]
    assert finished == ids
    for pid in ids:
        assert history(published, pid) == [Q, R, F]  # each change once, nothing else
        assert core.procedures.query_state(pid).code == "OK"


def test_pause_resume_and_cancel(core, published, wait_until):
    first = core.procedures.add("WAIT 0.3").id
    second = core.procedures.add("WAIT 0.05").id
    third = core.procedures.add("WAIT 0.05").id
    assert wait_until(lambda: core.procedures.query_state(first).state is R)
    with pytest.raises(InvalidArgument, match="only the running procedure can be paused"):
        core.procedures.pause(second)
    assert core.procedures.pause(first).state is P
    assert core.procedures.cancel(third).state is F
    assert not wait_until(lambda: core.procedures.query_state(second).state is not Q, timeout=0.5)
    assert core.procedures.resume(first).state is R
    with pytest.raises(InvalidArgument, match="not paused"):
        core.procedures.resume(first)
    assert wait_until(lambda: core.procedures.query_state(second).state is F)
    assert history(published, first) == [Q, R, P, R, F]
    assert history(published, third) == [Q, F]
    assert core.procedures.query_state(third).code == "ABORTED"
    assert core.procedures.query_state(first).result == {"waited_s": 0.3}


def test_cancel_running_procedure(core, wait_until):
    pid = core.procedures.add("WAIT 10").id
    assert wait_until(lambda: core.procedures.query_state(pid).state is R)
    snapshot = core.procedures.cancel(pid)
    assert snapshot.state is F and snapshot.code == "ABORTED"
    with pytest.raises(InvalidArgument, match="already finished"):
        core.procedures.cancel(pid)


def test_invalid_commands_are_never_queued(core, published):
    with pytest.raises(InvalidCommand):
        core.procedures.add("FLY 1")
    assert core.procedures.list() == [] and published == []


def test_unknown_id_is_named(core):
    with pytest.raises(InvalidArgument, match="no procedure with id 42"):
        core.procedures.query_state(42)


def test_stop_clears_the_queue(core, published, wait_until):
    ids = [core.procedures.add("WAIT 5").id for _ in range(3)]
    assert wait_until(lambda: core.procedures.query_state(ids[0]).state is R)
    assert core.dispatcher.execute("STOP").success
    assert wait_until(lambda: all(core.procedures.query_state(i).state is F for i in ids))
    assert {core.procedures.query_state(i).code for i in ids} == {"ABORTED"}
    assert history(published, ids[2]) == [Q, F]  # never started


def test_procedure_waits_for_a_resource_held_by_another_interface(core, wait_until):
    service_cmd = core.dispatcher.submit("WAIT 0.3 hold=arm", Interface.SERVICE)
    pid = core.procedures.add("ARM_MOVE 0.05").id
    assert not wait_until(lambda: core.procedures.query_state(pid).state is not Q, timeout=0.15)
    assert service_cmd.wait(2.0).code is Code.OK
    assert wait_until(lambda: core.procedures.query_state(pid).state is F)
    assert core.procedures.query_state(pid).code == "OK"


def transitions_of(core):
    seen = []
    core.dispatcher.add_listener(lambda e: seen.append((e.id, e.transition)) if e.transition else None)
    return seen


def test_suspend_resume_halt_reset_drive_the_procedures_skill(core, published, wait_until):
    seen = transitions_of(core)
    pid = core.procedures.add("WAIT 5").id
    queued = core.procedures.add("WAIT 0.05").id
    assert wait_until(lambda: core.procedures.query_state(pid).state is R)
    with pytest.raises(InvalidArgument, match=r"procedure %d is queued.*Suspend is not allowed.*cancel" % queued):
        core.procedures.suspend(queued)
    snapshot = core.procedures.suspend(pid, "operator")
    assert (snapshot.state, snapshot.skill_state.value) == (P, "Suspended")
    with pytest.raises(InvalidArgument, match=r"is Suspended \(allowed in Suspended: Resume, Halt\)"):
        core.procedures.suspend(pid)
    assert core.procedures.resume(pid, "go on").state is R
    with pytest.raises(InvalidArgument, match=r"not paused.*Resume is not allowed.*Running \(allowed in Running: "
                                              r"Suspend, Halt\)"):
        core.procedures.resume(pid)
    with pytest.raises(InvalidArgument, match=r"Reset is not allowed.*Running"):
        core.procedures.reset(pid)
    started = time.monotonic()
    halted = core.procedures.halt(pid, "operator")  # answered once the command has ended
    assert time.monotonic() - started < 1.0
    assert (halted.state, halted.code, halted.skill_state.value) == (F, "ABORTED", "Halted")
    assert "halted: operator" in halted.message
    with pytest.raises(InvalidArgument, match="Halt is not allowed.*Halted"):
        core.procedures.halt(pid)
    reset = core.procedures.reset(pid, "operator")
    assert (reset.state, reset.code, reset.skill_state.value) == (F, "ABORTED", "Ready")  # still finished
    assert history(published, pid) == [Q, R, P, R, F]
    command_id = reset.command_id
    names = [(t.name, t.method, t.cause) for i, t in seen if i == command_id]
    assert names == [("ReadyToRunning", "Start", "procedure interface"),
                     ("RunningToSuspended", "Suspend", "operator"), ("SuspendedToRunning", "Resume", "go on"),
                     ("RunningToHalted", "Halt", names[3][2]), ("HaltedToReady", "Reset", "operator")]
    assert "halted: operator" in names[3][2]
    assert wait_until(lambda: core.procedures.query_state(queued).state is F)  # the queue went on


def test_halt_of_a_paused_procedure_and_reset_of_a_successful_one(core, wait_until):
    pid = core.procedures.add("WAIT 5").id
    assert wait_until(lambda: core.procedures.query_state(pid).state is R)
    assert core.procedures.pause(pid).state is P
    assert core.procedures.halt(pid).state is F
    quick = core.procedures.add("WAIT 0.01").id
    assert wait_until(lambda: core.procedures.query_state(quick).state is F)
    assert core.procedures.query_state(quick).skill_state.value == "Ready"
    with pytest.raises(InvalidArgument, match=r"procedure %d is finished: Reset is not allowed.*has ended.*skill state "
                                              r"Ready.*send it again" % quick):
        core.procedures.reset(quick)
