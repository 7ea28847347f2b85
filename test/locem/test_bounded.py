"""Bounded LOCEM: a limit on running commands, waits that sleep, ASCII-only numbers, HELP names checked at admission."""
import threading
import time

import pytest

from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.dispatcher import DEFAULT_MAX_RUNNING
from locem_bridge.locem.errors import InvalidArgument
from locem_bridge.locem.execution import ExecState
from locem_bridge.locem.procedures import ProcedureState
from locem_bridge.locem.registry import Arg, CommandRegistry, CommandSpec, Interface
from locem_bridge.locem.grammar import parse

LIMIT = 8


@pytest.fixture
def small():
    core = LocemCore(grace=0.3, stop_timeout=1.0, max_running=LIMIT)
    yield core
    core.close()


def fill(core, count, seconds=30):
    return [core.dispatcher.submit("WAIT %d.%03d" % (seconds, i), Interface.SUBSCRIBER) for i in range(count)]


# -- the limit ------------------------------------------------------------------------------------------------
def test_past_the_limit_a_command_is_busy_naming_the_limit_and_stop_help_status_still_run(small):
    events = []
    small.dispatcher.add_listener(events.append)
    running = fill(small, LIMIT)
    refused = small.dispatcher.execute("WAIT 0.1")
    assert refused.code is Code.BUSY
    assert "already running %d commands, its limit (max_running = %d" % (LIMIT, LIMIT) in refused.message
    assert "~max_running" in refused.message
    rejected = [e for e in events if e.state is ExecState.REJECTED]
    assert [(e.command, e.code) for e in rejected] == [("WAIT 0.1", "BUSY")]  # the refusal is published too
    assert small.dispatcher.execute("HELP WAIT").success and small.dispatcher.execute("STATUS").success
    stop = small.dispatcher.execute("STOP")
    assert stop.success and sorted(stop.result["stopped"]) == sorted(e.id for e in running)
    assert all(e.wait(1.0).code is Code.ABORTED for e in running)
    assert small.dispatcher.execute("WAIT 0").success  # room again


def test_the_limit_frees_as_commands_end(small, wait_until):
    running = fill(small, LIMIT - 1) + [small.dispatcher.submit("WAIT 0.2", Interface.SERVICE)]
    assert small.dispatcher.execute("WAIT 0").code is Code.BUSY
    assert running[-1].wait(2.0).success
    assert small.dispatcher.execute("WAIT 0").success
    small.dispatcher.execute("STOP")


def test_a_queued_procedure_waits_for_room_instead_of_failing(small, wait_until):
    running = fill(small, LIMIT)
    pid = small.procedures.add("WAIT 0").id
    time.sleep(0.3)
    assert small.procedures.query_state(pid).state is ProcedureState.QUEUED
    running[0].cancel()
    assert wait_until(lambda: small.procedures.query_state(pid).state is ProcedureState.FINISHED, 2.0)
    assert small.procedures.query_state(pid).code == "OK"
    small.dispatcher.execute("STOP")


def test_limit_must_be_positive_and_defaults_to_the_documented_value():
    with pytest.raises(ValueError, match="max_running must be at least 1"):
        LocemCore(max_running=0)
    core = LocemCore()
    try:
        assert core.dispatcher.max_running == DEFAULT_MAX_RUNNING
    finally:
        core.close()


# -- waits sleep ----------------------------------------------------------------------------------------------
def test_the_limits_worth_of_waits_costs_no_cpu_and_stop_ends_them_at_once():
    core = LocemCore(grace=0.3, stop_timeout=1.0)
    try:
        threads_before = threading.active_count()
        running = fill(core, DEFAULT_MAX_RUNNING)
        assert threading.active_count() <= threads_before + DEFAULT_MAX_RUNNING
        time.sleep(0.2)
        cpu = time.process_time()
        time.sleep(1.0)
        idle_cpu = time.process_time() - cpu
        # 64 waits polling every 50 ms cost tens of ms of CPU per second here; sleeping ones cost nothing
        assert idle_cpu < 0.02, "%.3f s CPU in 1 s of %d idle WAITs" % (idle_cpu, len(running))
        start = time.monotonic()
        stop = core.dispatcher.execute("STOP")
        elapsed = time.monotonic() - start
        assert stop.success and stop.result["still_running"] == [] and len(stop.result["stopped"]) == len(running)
        assert elapsed < 0.5, elapsed
        assert all(e.wait(0.1).code is Code.ABORTED for e in running)
    finally:
        core.close()


def test_a_paused_wait_wakes_at_once_on_resume_and_on_cancel(small):
    execution = small.dispatcher.submit("WAIT 10", Interface.ACTION)
    execution.pause()
    time.sleep(0.2)
    start = time.monotonic()
    execution.cancel("test")
    assert execution.wait(0.5) is not None and execution.response.code is Code.ABORTED
    assert time.monotonic() - start < 0.1
    short = small.dispatcher.submit("WAIT 0.2", Interface.SUBSCRIBER)
    short.pause()
    time.sleep(0.3)
    assert not short.done
    start = time.monotonic()
    short.resume()
    assert short.wait(1.0).success
    assert 0.15 < time.monotonic() - start < 0.5


# -- ASCII-only numbers -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("token", ["\u0661", "\uff11", "1\u0660", "\u09e8.5", "\U0001d7cf", "1e\u0661"])
def test_digits_of_other_scripts_are_refused_naming_the_argument(small, token):
    for interface in Interface:
        response = small.dispatcher.execute("WAIT %s" % token, interface)
        assert response.code is Code.INVALID_ARGUMENT, (token, response)
        assert "argument 'seconds'" in response.message and "ASCII" in response.message
    with pytest.raises(InvalidArgument, match="argument 'seconds'"):
        small.procedures.add("WAIT %s" % token)
    assert small.procedures.list() == []


def test_integers_choices_and_flags_are_ascii_only_too():
    registry = CommandRegistry([CommandSpec("PAINT", "t", args=(
        Arg.integer("coats", 0, 9, "coats"), Arg.choice("colour", ("black", "white"), "colour"),
        Arg.flag("dry", "dry", default=False)))])
    assert registry.bind_arguments(parse("PAINT 2 BLACK yes")).values == {"coats": 2, "colour": "black", "dry": True}
    for text, argument in (("PAINT \u0662 black", "coats"), ("PAINT 2 blac\u212a", "colour"),  # Kelvin sign
                           ("PAINT 2 black \uff59es", "dry")):
        with pytest.raises(InvalidArgument) as caught:
            registry.bind_arguments(parse(text))
        assert caught.value.argument == argument and "non-ASCII character" in caught.value.message


def test_unicode_white_space_does_not_separate_tokens(small):
    for text in ("WAIT\u00a01", "WAIT 1\u2003", "WAIT\u30001"):
        assert small.dispatcher.execute(text).code is Code.INVALID_COMMAND


# -- HELP names checked at admission ------------------------------------------------------------------------
def test_help_of_an_unknown_command_is_refused_at_admission_on_every_interface(small):
    events = []
    small.dispatcher.add_listener(events.append)
    for interface in Interface:
        with pytest.raises(InvalidArgument) as caught:
            small.dispatcher.submit("HELP NO_SUCH", interface)
        assert caught.value.argument == "name"
        assert "no command named 'NO_SUCH'" in caught.value.message
        assert "command registry" in caught.value.message and "send HELP to list them" in caught.value.message
    assert [(e.interface, e.state, e.code) for e in events] == [
        (i.value, ExecState.REJECTED, "INVALID_ARGUMENT") for i in Interface]
    assert small.dispatcher.running() == []
    assert "did you mean WAIT" in small.dispatcher.execute("HELP WAITT").message


def test_a_procedure_add_of_help_unknown_is_refused_and_never_queued(small, wait_until):
    published = []
    small.procedures.add_listener(published.append)
    with pytest.raises(InvalidArgument, match="no command named 'FLY'"):
        small.procedures.add("HELP fly")
    assert small.procedures.list() == [] and published == []
    pid = small.procedures.add("help wait").id  # a known name still runs
    assert wait_until(lambda: small.procedures.query_state(pid).state is ProcedureState.FINISHED)
    assert small.procedures.query_state(pid).code == "OK"
    assert "WAIT seconds" in small.procedures.query_state(pid).message
