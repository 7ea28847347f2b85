"""Property-based: 10,000 generated strings through parser, binder and dispatcher.

Nothing but the typed LOCEM errors may escape, every answer carries a known code, and a device handler only
ever sees arguments that satisfy its declaration (finite, in range, right type).
"""
import math
import time
import threading

from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from locem_bridge.common.locem_codes import Code
from locem_bridge.locem.core import LocemCore
from locem_bridge.locem.errors import LocemError
from locem_bridge.locem.registry import Arg, ArgType, CommandSpec, Interface

PROBE = CommandSpec("PROBE", "Accepts every argument type.", args=(
    Arg.number("x", "m", -2.5, 2.5, "a length"),
    Arg.integer("n", 0, 10, "a count"),
    Arg.flag("on", "a switch", default=False),
    Arg.choice("tool", ("taping_tool", "spray_gun"), "a tool", default="spray_gun", keyword_only=True),
    Arg.word("tag", "a name", default="home", keyword_only=True)), category="probe", resources=frozenset({"arm"}))
CALLS = []
EXAMPLES = []
LOCK = threading.Lock()


def probe(ctx, **values):
    with LOCK:
        CALLS.append(values)
    return {}


NAMES = ["PROBE", "probe", "HELP", "STATUS", "WAIT", "STOP", "GOTO", "P", ""]
NUMBERS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10 ** 30, 10 ** 30).map(str),
    st.sampled_from(["nan", "inf", "-inf", "1e999", "0x10", "1_0", ".5", "5.", "+1", "--1", "1e", "", "true"]),
)
TOKENS = st.one_of(NUMBERS, st.text(max_size=12), st.sampled_from(["tool=spray_gun", "tag=x", "tool=", "=",
                                                                   '"a b"', '"', "on=1", "x=1", "hold=arm"]))
STRUCTURED = st.builds(lambda name, toks: " ".join([name] + toks), st.sampled_from(NAMES),
                       st.lists(TOKENS, max_size=7))
NEAR_VALID = st.builds(
    lambda x, n, rest: "PROBE %r %d %s" % (x, n, " ".join(rest)),
    st.floats(-3.0, 3.0), st.integers(-1, 11),
    st.lists(st.sampled_from(["on", "off", "1", "maybe", "tool=spray_gun", "tool=taping_tool", "tool=sander",
                              "tag=wall_1", "tag=a b", "tag=", "x=0"]), max_size=3))
ANY_TEXT = st.one_of(STRUCTURED, NEAR_VALID, st.text(max_size=80), st.text(alphabet=st.characters(max_codepoint=0x7f),
                                                                   max_size=40),
                     st.binary(max_size=20).map(lambda b: b.decode("latin-1")), st.just("X" * 2000))

CORE = LocemCore(grace=0.1, stop_timeout=0.5)
CORE.registry.declare(PROBE)
CORE.registry.bind("PROBE", probe)


def valid_for_probe(values):
    by_name = {a.name: a for a in PROBE.args}
    for key, value in values.items():
        arg = by_name[key]
        if arg.type is ArgType.FLOAT:
            assert isinstance(value, float) and math.isfinite(value) and arg.minimum <= value <= arg.maximum
        elif arg.type is ArgType.INT:
            assert isinstance(value, int) and arg.minimum <= value <= arg.maximum
        elif arg.type is ArgType.BOOL:
            assert isinstance(value, bool)
        elif arg.type is ArgType.ENUM:
            assert value in arg.choices
    return True


@settings(max_examples=10000, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(ANY_TEXT, st.sampled_from(list(Interface)))
def generated_strings_never_escape_and_never_reach_a_device_invalid(text, interface):
    EXAMPLES.append(text)
    if text.strip().upper().startswith("WAIT"):
        # validate only: running a valid WAIT would sleep
        try:
            CORE.dispatcher.bind(text, interface)
        except LocemError as error:
            assert error.code in set(Code) and error.message
        return
    if text.strip().upper().startswith("STOP"):
        text = "STATUS"
    before = len(CALLS)
    response = CORE.dispatcher.execute(text, interface)
    assert response.code in set(Code)
    assert isinstance(response.message, str) and response.message
    if len(CALLS) > before:
        assert response.success or response.code is Code.BUSY
        assert valid_for_probe(CALLS[-1])
    if response.success:
        assert response.result_json.startswith("{")


def test_10000_generated_strings_never_escape_and_never_reach_a_device_invalid():
    del EXAMPLES[:], CALLS[:]
    generated_strings_never_escape_and_never_reach_a_device_invalid()
    # the property ran on (at least) 10,000 strings, many of them distinct ...
    assert len(EXAMPLES) >= 10000, len(EXAMPLES)
    assert len(set(EXAMPLES)) > 5000, len(set(EXAMPLES))
    # ... and a strategy that never produced a valid PROBE would make it pass vacuously: some reached the device
    assert len(CALLS) > 20, len(CALLS)


ADDED = []


@settings(max_examples=2000, deadline=None, derandomize=True, database=None,
          suppress_health_check=list(HealthCheck))
@given(ANY_TEXT)
def generated_strings_through_the_procedure_interface(text):
    if text.strip().upper().startswith(("WAIT", "STOP")):
        text = "STATUS"  # a valid WAIT would hold the queue, STOP would cancel it
    before = len(CORE.procedures.list())
    try:
        snapshot = CORE.procedures.add(text)
    except LocemError as error:  # refused: a known code, a message, and nothing queued
        assert error.code in set(Code) and error.message
        assert len(CORE.procedures.list()) == before
        return
    ADDED.append(snapshot.id)


def test_2000_generated_strings_through_the_procedure_interface_are_refused_or_run_valid():
    del ADDED[:], CALLS[:]
    generated_strings_through_the_procedure_interface()
    end = time.monotonic() + 30
    while time.monotonic() < end and any(CORE.procedures.query_state(i).state.value != "finished" for i in ADDED
                                         if i in {s.id for s in CORE.procedures.list()}):
        time.sleep(0.05)
    kept = {s.id: s for s in CORE.procedures.list()}
    assert all(kept[i].state.value == "finished" and kept[i].code in {c.value for c in Code} for i in ADDED if i in kept)
    assert len(ADDED) > 20 and CALLS, "no generated string was a valid command"
    assert all(valid_for_probe(values) for values in CALLS)  # the device saw only valid arguments
