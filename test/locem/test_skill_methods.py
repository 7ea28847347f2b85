"""LOCEM's commands are skill instances: SUSPEND / RESUME / HALT / RESET take the state machine's transitions,
publish each with its cause, refuse what the state does not allow (and change nothing), and a suspension does not
count against the command's deadline."""
import time

from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.registry import Interface


def _transitions(events, exec_id):
    return [(e.transition.name, e.transition.method, e.transition.cause) for e in events
            if e.id == exec_id and e.transition is not None]


def test_suspend_resume_of_a_wait_publishes_every_transition_and_pause_time_does_not_count(core):
    events = []
    core.dispatcher.add_listener(events.append)
    t0 = time.monotonic()
    wait = core.dispatcher.submit("WAIT 0.4", Interface.PROCEDURE)
    time.sleep(0.1)
    r = core.dispatcher.execute("SUSPEND id=%d cause=operator" % wait.id)
    assert r.success and r.result["states"] == {str(wait.id): "Suspended"}, r
    time.sleep(0.5)
    assert wait.wait(0.0) is None
    assert core.dispatcher.execute("RESUME").result["ids"] == [wait.id]      # no id: every suspended command
    done = wait.wait(3.0)
    assert done is not None and done.success and time.monotonic() - t0 >= 0.9
    assert _transitions(events, wait.id) == [
        ("ReadyToRunning", "Start", "procedure interface"), ("RunningToSuspended", "Suspend", "operator"),
        ("SuspendedToRunning", "Resume", "RESUME command"), ("RunningToReady", "", "completed")]
    # the skill methods themselves are no skill instances: they publish no transition
    assert all(e.transition is None for e in events if e.name in ("SUSPEND", "RESUME"))


def test_refused_methods_name_the_state_and_change_nothing(core, device):
    wait = core.dispatcher.submit("WAIT 5", Interface.ACTION)
    r = core.dispatcher.execute("RESUME id=%d" % wait.id)
    assert r.code is Code.INVALID_ARGUMENT and "Running" in r.message and "Suspend, Halt" in r.message, r
    assert core.dispatcher.execute("RESET id=%d" % wait.id).code is Code.INVALID_ARGUMENT
    assert wait.program.value == "Running" and not wait.done
    arm = core.dispatcher.submit("ARM_MOVE 1", Interface.ACTION)                 # not pausable
    r = core.dispatcher.execute("SUSPEND id=%d" % arm.id)
    assert r.code is Code.INVALID_ARGUMENT and "cannot be suspended" in r.message and "halt" in r.message, r
    assert arm.program.value == "Running"
    r = core.dispatcher.execute("SUSPEND id=99999")
    assert r.code is Code.INVALID_ARGUMENT and "no command with id 99999" in r.message, r
    r = core.dispatcher.execute("SUSPEND id=-1")
    assert r.code is Code.INVALID_ARGUMENT and "id" in r.message, r
    assert core.dispatcher.execute("STOP").success


def test_halt_while_suspended_ends_it_halted_and_reset_makes_it_ready(core):
    events = []
    core.dispatcher.add_listener(events.append)
    wait = core.dispatcher.submit("WAIT 5", Interface.ACTION)
    assert core.dispatcher.execute("SUSPEND id=%d" % wait.id).success
    r = core.dispatcher.execute("HALT id=%d cause=hose_kinked" % wait.id)
    assert r.success and r.result["states"] == {str(wait.id): "Halted"}, r
    done = wait.wait(1.0)
    assert done.code is Code.ABORTED and "halted: hose_kinked" in done.message, done
    assert core.dispatcher.execute("RESUME id=%d" % wait.id).code is Code.INVALID_ARGUMENT
    assert core.dispatcher.execute("RESET id=%d" % wait.id).success
    names = [t[0] for t in _transitions(events, wait.id)]
    assert names == ["ReadyToRunning", "RunningToSuspended", "SuspendedToHalted", "HaltedToReady"]
    r = core.dispatcher.execute("SUSPEND")
    assert r.code is Code.INVALID_ARGUMENT and "no running command" in r.message, r


def test_a_failure_takes_running_to_halted_without_a_method(core):
    events = []
    core.dispatcher.add_listener(events.append)
    wait = core.dispatcher.submit("WAIT 5", Interface.ACTION)
    wait._expire()                     # its deadline: the command fails TIMEOUT
    assert wait.wait(2.0).code is Code.TIMEOUT
    assert _transitions(events, wait.id)[-1][:2] == ("RunningToHalted", "")
    assert core.dispatcher.execute("RESET id=%d" % wait.id).success
