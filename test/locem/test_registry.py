"""Declarations and argument binding: every rejection names the argument and what is allowed."""
import pytest

from locem_bridge.locem.errors import InvalidArgument, InvalidCommand, NotReady
from locem_bridge.locem.grammar import parse
from locem_bridge.locem.registry import Arg, CommandRegistry, CommandSpec, Interface

GOTO = CommandSpec(
    "GOTO", "Drive the base to a pose.",
    args=(Arg.number("x", "m", -50, 50, "x in map"), Arg.number("y", "m", -50, 50, "y in map"),
          Arg.number("theta", "rad", -3.1416, 3.1416, "heading"),
          Arg.number("tol", "m", 0.001, 0.5, "position tolerance", default=0.02, keyword_only=True),
          Arg.flag("precise", "final approach slowly", default=False, keyword_only=True)),
    resources=frozenset({"base"}), interfaces=frozenset({Interface.ACTION, Interface.SERVICE}), category="base",
)
TOOL = CommandSpec("MOUNT_TOOL", "Activate a tool.", args=(
    Arg.choice("name", ("taping_tool", "spray_gun", "sander"), "tool"),
    Arg.integer("slot", 0, 3, "slot", default=0)), category="tool")


@pytest.fixture
def registry():
    return CommandRegistry([GOTO, TOOL])


def bind(registry, text, interface=None):
    return registry.bind_arguments(parse(text), interface)


def test_binding_converts_types_and_fills_defaults(registry):
    bound = bind(registry, "goto 1.5 -2 0.5 precise=on")
    assert dict(bound.values) == {"x": 1.5, "y": -2.0, "theta": 0.5, "tol": 0.02, "precise": True}
    assert bound.claims == frozenset({"base"})


def test_enum_is_case_insensitive_and_optional_positional_defaults(registry):
    bound = bind(registry, "MOUNT_TOOL SPRAY_GUN")
    assert dict(bound.values) == {"name": "spray_gun", "slot": 0}


def test_unknown_command_suggests_a_close_name(registry):
    with pytest.raises(InvalidCommand, match=r"unknown command 'GOTOO' \(did you mean GOTO\?\)"):
        bind(registry, "GOTOO 1 2 3")


@pytest.mark.parametrize("text,fragment", [
    ("GOTO 1 2", "missing argument 'theta'"),
    ("GOTO 1 2 3 4", "at most 3 positional arguments, got 4"),
    ("GOTO one 2 0", "argument 'x' expects a number from -50 to 50 m, got 'one'"),
    ("GOTO nan 2 0", "argument 'x' expects a number"),
    ("GOTO 1e400 2 0", "argument 'x' must be finite"),
    ("GOTO 1 2 0 tol=-1", "argument 'tol' = -1 m is out of range; allowed: a number from 0.001 to 0.5 m"),
    ("GOTO 1 2 0 speed=1", "unknown keyword 'speed'; allowed keywords: x, y, theta, tol, precise"),
    ("GOTO 1 2 0 x=1", "given both by position and as a keyword"),
    ("GOTO 1 2 0 precise=maybe", "argument 'precise' expects true or false"),
    ("GOTO 0x10 2 0", "argument 'x' expects a number"),
    ("GOTO 1_0 2 0", "argument 'x' expects a number"),
    ("MOUNT_TOOL sprey_gun", "did you mean 'spray_gun'"),
    ("MOUNT_TOOL sander 1.5", "argument 'slot' expects an integer from 0 to 3"),
    ("MOUNT_TOOL sander 9", "argument 'slot' = 9 is out of range"),
])
def test_bad_arguments_are_named_with_the_allowed_values(registry, text, fragment):
    with pytest.raises(InvalidArgument) as info:
        bind(registry, text)
    assert fragment in str(info.value)


def test_interface_restrictions_are_enforced(registry):
    with pytest.raises(InvalidCommand, match="GOTO is not available over the subscriber interface; "
                                             "allowed: action, service"):
        bind(registry, "GOTO 1 2 0", Interface.SUBSCRIBER)


def test_declared_but_unserved_command_is_not_ready(registry):
    with pytest.raises(NotReady, match="no backend serves it"):
        registry.require_handler(bind(registry, "GOTO 1 2 0"))


def test_declarations_are_checked():
    with pytest.raises(ValueError, match="upper-case"):
        CommandSpec("goto", "x")
    with pytest.raises(ValueError, match="declares an argument twice"):
        CommandSpec("A", "x", args=(Arg.flag("f", "f"), Arg.flag("f", "f")))
    with pytest.raises(ValueError, match="follows an optional one"):
        CommandSpec("A", "x", args=(Arg.flag("f", "f", default=True), Arg.flag("g", "g")))
    registry = CommandRegistry([GOTO])
    with pytest.raises(ValueError, match="declared twice"):
        registry.declare(CommandSpec("GOTO", "another"))
    with pytest.raises(KeyError):
        registry.bind("NOPE", lambda ctx: None)


def test_usage_and_description_carry_units_and_ranges():
    assert GOTO.usage == "GOTO x y theta [tol=0.02] [precise=False]"
    described = GOTO.describe()
    assert described["args"][0] == {"name": "x", "type": "float", "doc": "x in map", "unit": "m", "required": True,
                                    "keyword_only": False, "allowed": "a number from -50 to 50 m",
                                    "minimum": -50, "maximum": 50}
    assert described["resources"] == ["base"]
