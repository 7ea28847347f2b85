"""The command-string grammar: ``NAME arg1 arg2 ... key=value ...``.

Rules (the generated API documentation repeats them):

* at most :data:`MAX_COMMAND_LENGTH` characters of printable text; tabs count as spaces, every other
  control character is refused;
* tokens are separated by white space; a token in double quotes may contain spaces, ``\\"`` and ``\\\\``;
* the first token is the command name, ``[A-Za-z][A-Za-z0-9_]*``, case-insensitive (stored upper-case);
* an unquoted token ``key=value`` with ``key`` an identifier is a keyword argument (key case-insensitive,
  stored lower-case); keywords follow all positional arguments and appear at most once.

The grammar knows nothing about particular commands; :mod:`.registry` gives the tokens their types.
"""

import re
from dataclasses import dataclass
from typing import Dict, List, Tuple

from .errors import InvalidArgument, InvalidCommand

MAX_COMMAND_LENGTH = 1024
"""Longest accepted command string, in characters."""

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*\Z")
_KEYWORD = re.compile(r"([A-Za-z][A-Za-z0-9_]*)=(.*)\Z", re.DOTALL)


@dataclass(frozen=True)
class ParsedCommand:
    """A syntactically valid command string, not yet checked against any declaration."""

    name: str
    positional: Tuple[str, ...]
    keywords: Tuple[Tuple[str, str], ...]
    text: str

    @property
    def keyword_dict(self) -> Dict[str, str]:
        return dict(self.keywords)


def parse(text: object) -> ParsedCommand:
    """Split ``text`` into name, positional and keyword tokens.

    Raises :class:`InvalidCommand` for strings that are not commands at all and :class:`InvalidArgument`
    for a malformed argument list. Never raises anything else.
    """
    if not isinstance(text, str):
        raise InvalidCommand("a command must be a string, got %s" % type(text).__name__)
    if len(text) > MAX_COMMAND_LENGTH:
        raise InvalidCommand(
            "command is %d characters long; at most %d are allowed" % (len(text), MAX_COMMAND_LENGTH)
        )
    if not text.isprintable():  # the common case skips the per-character loop
        for position, char in enumerate(text):
            if char != "\t" and not char.isprintable():
                raise InvalidCommand(
                    "character U+%04X at position %d is not allowed; commands are printable text "
                    "(spaces and tabs separate tokens)" % (ord(char), position)
                )
    tokens = _tokenize(text)
    if not tokens:
        raise InvalidCommand("empty command; send a command name, e.g. HELP to list all commands")
    name, quoted = tokens[0]
    if quoted or not _NAME.match(name):
        raise InvalidCommand(
            "'%s' is not a command name; names are letters, digits and '_', starting with a letter "
            "(send HELP to list all commands)" % _clip(name)
        )
    positional: List[str] = []
    keywords: List[Tuple[str, str]] = []
    seen = set()
    for token, quoted in tokens[1:]:
        match = None if quoted else _KEYWORD.match(token)
        if match is None:
            if keywords:
                raise InvalidArgument(
                    "positional argument '%s' follows keyword argument '%s'; keywords go last"
                    % (_clip(token), keywords[-1][0])
                )
            positional.append(token)
            continue
        key, value = match.group(1).lower(), match.group(2)
        if key in seen:
            raise InvalidArgument("keyword '%s' is given twice" % key, argument=key)
        if value == "":
            raise InvalidArgument("keyword '%s' has no value; write %s=VALUE" % (key, key), argument=key)
        seen.add(key)
        keywords.append((key, _unquote(value)))
    return ParsedCommand(name.upper(), tuple(positional), tuple(keywords), text)


def _tokenize(text: str) -> List[Tuple[str, bool]]:
    """Return (token, was_quoted) pairs. A quoted token keeps its inner spaces."""
    tokens: List[Tuple[str, bool]] = []
    i, n = 0, len(text)
    while i < n:
        char = text[i]
        if char in " \t":
            i += 1
            continue
        start = i
        if char == '"':
            i += 1
            chars: List[str] = []
            while True:
                if i >= n:
                    raise InvalidArgument("unterminated quote starting at position %d" % start)
                char = text[i]
                if char == "\\" and i + 1 < n and text[i + 1] in '"\\':
                    chars.append(text[i + 1])
                    i += 2
                    continue
                if char == '"':
                    i += 1
                    break
                chars.append(char)
                i += 1
            if i < n and text[i] not in " \t":
                raise InvalidArgument("a closing quote must be followed by a space (position %d)" % i)
            tokens.append(("".join(chars), True))
            continue
        # An unquoted token runs to the next white space; a quote may open a keyword value (key="a b").
        while i < n and text[i] not in " \t":
            if text[i] == '"':
                if i > start and text[i - 1] == "=":
                    end = _closing_quote(text, i)
                    i = end + 1
                    if i < n and text[i] not in " \t":
                        raise InvalidArgument("a closing quote must be followed by a space (position %d)" % i)
                    break
                raise InvalidArgument("unexpected quote at position %d inside a token" % i)
            i += 1
        tokens.append((text[start:i], False))
    return tokens


def _closing_quote(text: str, opening: int) -> int:
    i = opening + 1
    while i < len(text):
        if text[i] == "\\" and i + 1 < len(text) and text[i + 1] in '"\\':
            i += 2
            continue
        if text[i] == '"':
            return i
        i += 1
    raise InvalidArgument("unterminated quote starting at position %d" % opening)


def _unquote(value: str) -> str:
    if len(value) >= 2 and value[0] == '"' and value[-1] == '"':
        return re.sub(r'\\(["\\])', r"\1", value[1:-1])
    return value


def _clip(token: str, limit: int = 40) -> str:
    return token if len(token) <= limit else token[: limit - 3] + "..."
