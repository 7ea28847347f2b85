"""The command-string grammar: what is a command at all, and how tokens are split."""
import pytest

from locem_bridge.locem.errors import InvalidArgument, InvalidCommand
from locem_bridge.locem.grammar import MAX_COMMAND_LENGTH, parse


def test_name_is_case_insensitive_and_tokens_split_on_whitespace():
    parsed = parse("goto  1.2\t0.8   1.5708 tol=0.02")
    assert parsed.name == "GOTO"
    assert parsed.positional == ("1.2", "0.8", "1.5708")
    assert parsed.keyword_dict == {"tol": "0.02"}


def test_quoted_tokens_keep_spaces_and_escapes():
    parsed = parse('SAY "hello world" "a \\"b\\" c" msg="x y"')
    assert parsed.positional == ("hello world", 'a "b" c')
    assert parsed.keyword_dict == {"msg": "x y"}


def test_quoted_key_value_is_positional():
    assert parse('SAY "a=b"').positional == ("a=b",)


def test_keyword_keys_are_lower_case():
    assert parse("WAIT 1 HOLD=arm").keyword_dict == {"hold": "arm"}


@pytest.mark.parametrize("text", ["", "   ", "\t \t"])
def test_empty_and_whitespace_only_are_refused(text):
    with pytest.raises(InvalidCommand, match="empty command"):
        parse(text)


@pytest.mark.parametrize("char", ["\x00", "\n", "\r", "\x1b", "\x7f", "\u2028"])
def test_control_characters_are_refused_with_their_position(char):
    with pytest.raises(InvalidCommand, match=r"U\+%04X at position 4" % ord(char)):
        parse("WAIT" + char + "1")


def test_too_long_is_refused_naming_the_limit():
    with pytest.raises(InvalidCommand, match="at most %d" % MAX_COMMAND_LENGTH):
        parse("WAIT " + "1" * MAX_COMMAND_LENGTH)
    parse("WAIT " + "1" * (MAX_COMMAND_LENGTH - 5))  # exactly at the limit is fine


@pytest.mark.parametrize("text", ["1GOTO", "GO-TO 1", '"HELP"', "é"])
def test_bad_names_are_refused(text):
    with pytest.raises(InvalidCommand, match="not a command name"):
        parse(text)


def test_not_a_string_is_refused():
    with pytest.raises(InvalidCommand, match="must be a string"):
        parse(b"HELP")


@pytest.mark.parametrize("text,message", [
    ("WAIT hold=arm 1", "follows keyword"),
    ("WAIT 1 hold=arm hold=base", "given twice"),
    ("WAIT 1 hold=", "has no value"),
    ('SAY "open', "unterminated quote"),
    ('SAY "a"b', "closing quote"),
    ('SAY a"b', "unexpected quote"),
])
def test_malformed_argument_lists_name_the_problem(text, message):
    with pytest.raises(InvalidArgument, match=message):
        parse(text)
