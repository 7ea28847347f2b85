"""The command registry: every LOCEM command is declared exactly once, here-shaped.

A :class:`CommandSpec` says everything a caller, the dispatcher and the documentation need: typed arguments
with SI units and ranges, which interfaces may carry the command, which resources it occupies while it runs,
its deadline, and what its result holds. A handler (a callable ``handler(ctx, **values) -> dict``) is bound
separately, so the API documentation can be generated from declarations alone and a LOCEM without, say, an
arm answers arm commands with ``NOT_READY`` instead of not knowing them.

Adding a device command is a declaration plus a handler::

    SPEC = CommandSpec("SET_PRESSURE", "Set the compressor pressure set-point.",
                       args=(Arg.number("pressure", "bar", 0.0, 6.0, "set-point"),),
                       resources=frozenset({"compressor"}), timeout=10.0)
    registry.declare(SPEC)
    registry.bind("SET_PRESSURE", backend.set_pressure_handler)
"""

import difflib
import math
import re
from dataclasses import dataclass, field
from enum import Enum
from typing import Any, Callable, Dict, FrozenSet, Iterable, List, Mapping, Optional, Tuple

from .errors import InvalidArgument, InvalidCommand, NotReady
from .grammar import ParsedCommand


class Interface(str, Enum):
    """The LOCEM interfaces that carry commands in (the publisher only carries results out)."""

    SERVICE = "service"
    ACTION = "action"
    PROCEDURE = "procedure"
    SUBSCRIBER = "subscriber"

    def __str__(self) -> str:
        return self.value


ALL_INTERFACES: FrozenSet[Interface] = frozenset(Interface)

_REQUIRED = object()
# ASCII digits only: Python's \\d, float() and int() also take other scripts' digits ('\u0661' is 1)
_NUMBER = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?\Z")
_INTEGER = re.compile(r"[+-]?[0-9]+\Z")
_TRUE = {"true", "1", "on", "yes"}
_FALSE = {"false", "0", "off", "no"}
_STRING = re.compile(r"[A-Za-z0-9_.:/#\-]+\Z")
_CAPABILITY = re.compile(r"([A-Za-z][A-Za-z0-9_-]*:)?[A-Za-z_][A-Za-z0-9_]*\Z")
_COMMAND_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}\Z")


class ArgType(str, Enum):
    FLOAT = "float"
    INT = "int"
    BOOL = "bool"
    ENUM = "enum"
    NAME = "name"
    """An identifier-like string: letters, digits and ``_ . : / # -`` (tags, tool names, IRIs)."""
    COMMAND = "command"
    """The name of a command declared in the registry (checked when the command is bound, on every interface)."""


@dataclass(frozen=True)
class Arg:
    """One declared argument. Positional unless ``keyword_only``; optional when it has a default."""

    name: str
    type: ArgType
    doc: str
    unit: str = ""
    minimum: Optional[float] = None
    maximum: Optional[float] = None
    default: Any = _REQUIRED
    choices: Tuple[str, ...] = ()
    keyword_only: bool = False
    max_length: int = 256          # characters, name arguments (the whole command is capped by the grammar)

    # -- constructors that read like the documentation ---------------------------------------------------
    @classmethod
    def number(cls, name: str, unit: str, minimum: float, maximum: float, doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.FLOAT, doc, unit=unit, minimum=minimum, maximum=maximum, **kw)

    @classmethod
    def integer(cls, name: str, minimum: int, maximum: int, doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.INT, doc, minimum=minimum, maximum=maximum, **kw)

    @classmethod
    def flag(cls, name: str, doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.BOOL, doc, **kw)

    @classmethod
    def choice(cls, name: str, choices: Iterable[str], doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.ENUM, doc, choices=tuple(choices), **kw)

    @classmethod
    def word(cls, name: str, doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.NAME, doc, **kw)

    @classmethod
    def command(cls, name: str, doc: str, **kw: Any) -> "Arg":
        return cls(name, ArgType.COMMAND, doc, **kw)

    # -- description ----------------------------------------------------------------------------------------
    @property
    def required(self) -> bool:
        return self.default is _REQUIRED

    def allowed(self) -> str:
        """Human description of the allowed values, e.g. ``a number in s from 0 to 3600``."""
        unit = " %s" % self.unit if self.unit else ""
        if self.type in (ArgType.FLOAT, ArgType.INT):
            kind = "a number" if self.type is ArgType.FLOAT else "an integer"
            if self.minimum is not None and self.maximum is not None:
                return "%s from %s to %s%s" % (kind, _fmt(self.minimum), _fmt(self.maximum), unit)
            if self.minimum is not None:
                return "%s of at least %s%s" % (kind, _fmt(self.minimum), unit)
            if self.maximum is not None:
                return "%s of at most %s%s" % (kind, _fmt(self.maximum), unit)
            return kind + (" in%s" % unit if unit else "")
        if self.type is ArgType.BOOL:
            return "true or false"
        if self.type is ArgType.ENUM:
            return "one of " + ", ".join(self.choices)
        if self.type is ArgType.COMMAND:
            return "the name of a command of this LOCEM (HELP lists them)"
        return "a name (letters, digits and _ . : / # -)"

    def describe(self) -> Dict[str, Any]:
        out: Dict[str, Any] = {"name": self.name, "type": self.type.value, "doc": self.doc, "unit": self.unit,
                               "required": self.required, "keyword_only": self.keyword_only,
                               "allowed": self.allowed()}
        if self.minimum is not None:
            out["minimum"] = self.minimum
        if self.maximum is not None:
            out["maximum"] = self.maximum
        if self.choices:
            out["choices"] = list(self.choices)
        if not self.required:
            out["default"] = self.default
        return out

    # -- conversion -----------------------------------------------------------------------------------------
    def convert(self, command: str, token: str) -> Any:
        """Turn one token into a typed value or raise :class:`InvalidArgument` naming this argument.

        Every check is ASCII-only: digits of other scripts, look-alike letters that lower-case to ASCII (the
        Kelvin sign) and the like are refused, never converted.
        """
        if not token.isascii():
            raise self._error(command, "expects %s in ASCII characters, got '%s' (non-ASCII character U+%04X)"
                              % (self.allowed(), _clip(token), ord(next(c for c in token if ord(c) > 0x7F))))
        if self.type in (ArgType.FLOAT, ArgType.INT):
            pattern = _NUMBER if self.type is ArgType.FLOAT else _INTEGER
            if not pattern.match(token):
                raise self._error(command, "expects %s, got '%s'" % (self.allowed(), _clip(token)))
            value: Any = float(token) if self.type is ArgType.FLOAT else int(token)
            if self.type is ArgType.FLOAT and not math.isfinite(value):
                raise self._error(command, "must be finite, got '%s'; allowed: %s" % (_clip(token), self.allowed()))
            if (self.minimum is not None and value < self.minimum) or (
                self.maximum is not None and value > self.maximum
            ):
                raise self._error(
                    command, "= %s%s is out of range; allowed: %s"
                    % (_clip(token), " " + self.unit if self.unit else "", self.allowed())
                )
            return value
        if self.type is ArgType.BOOL:
            lowered = token.lower()
            if lowered in _TRUE:
                return True
            if lowered in _FALSE:
                return False
            raise self._error(command, "expects true or false, got '%s'" % _clip(token))
        if self.type is ArgType.ENUM:
            for choice in self.choices:
                if token.lower() == choice.lower():
                    return choice
            hint = difflib.get_close_matches(token.lower(), [c.lower() for c in self.choices], n=1)
            extra = " (did you mean '%s'?)" % hint[0] if hint else ""
            raise self._error(command, "expects %s, got '%s'%s" % (self.allowed(), _clip(token), extra))
        if self.type is ArgType.COMMAND:
            if not _COMMAND_NAME.match(token):
                raise self._error(command, "expects %s, got '%s'" % (self.allowed(), _clip(token)))
            return token.upper()  # whether it is declared is checked by the registry, which knows the names
        if not _STRING.match(token) or len(token) > self.max_length:
            raise self._error(command, "expects %s of at most %d characters, got '%s'"
                              % (self.allowed(), self.max_length, _clip(token)))
        return token

    def _error(self, command: str, text: str) -> InvalidArgument:
        return InvalidArgument("%s: argument '%s' %s" % (command, self.name, text), argument=self.name)


@dataclass(frozen=True)
class CommandSpec:
    """The one declaration of a command.

    ``resources`` are occupied while the command runs (``base``, ``arm``, ``compressor``, ``tool``, ...): a
    second command needing one of them is answered ``BUSY``. ``claims`` may compute them from the argument
    values instead. ``timeout`` (s) is the deadline from start to result; ``deadline`` may compute it from
    the values (e.g. from path length and speed). ``preemptive`` commands (``STOP``) are never ``BUSY``.
    ``inline`` commands are quick queries answered in the caller's thread. ``query`` commands only read state:
    they change nothing, so their (successful) runs are not published as state changes. ``pausable`` commands
    honour pause/resume through their context. ``capability`` names the capability the command realizes as a basic
    skill (an ``sk:Capability`` of ``ontologies/``, as a prefixed name: ``sk:cap_DriveBase``, ``plb:cap_SprayRaster``;
    a bare local name is looked up in ``sk:`` then ``plb:``); empty when it realizes none (queries, stops). The
    resource model (:mod:`locem_bridge.skills`) reads it.
    """

    name: str
    summary: str
    args: Tuple[Arg, ...] = ()
    resources: FrozenSet[str] = frozenset()
    interfaces: FrozenSet[Interface] = ALL_INTERFACES
    timeout: float = 5.0
    result: Tuple[Tuple[str, str], ...] = ()
    category: str = "system"
    pausable: bool = False
    preemptive: bool = False
    inline: bool = False
    query: bool = False
    claims: Optional[Callable[[Mapping[str, Any]], FrozenSet[str]]] = field(default=None, compare=False)
    deadline: Optional[Callable[[Mapping[str, Any]], float]] = field(default=None, compare=False)
    capability: str = ""

    def __post_init__(self) -> None:
        if not re.match(r"[A-Z][A-Z0-9_]*\Z", self.name):
            raise ValueError("command names are upper-case identifiers: %r" % self.name)
        if self.capability and not _CAPABILITY.match(self.capability):
            raise ValueError("%s: capability must be a prefixed name like sk:cap_DriveBase, got %r"
                             % (self.name, self.capability))
        names = [a.name for a in self.args]
        if len(set(names)) != len(names):
            raise ValueError("%s declares an argument twice" % self.name)
        seen_optional = False
        for arg in self.positional_args:
            if not arg.required:
                seen_optional = True
            elif seen_optional:
                raise ValueError("%s: required positional '%s' follows an optional one" % (self.name, arg.name))

    @property
    def positional_args(self) -> Tuple[Arg, ...]:
        return tuple(a for a in self.args if not a.keyword_only)

    @property
    def usage(self) -> str:
        parts = [self.name]
        for arg in self.args:
            if arg.keyword_only:
                parts.append("[%s=%s]" % (arg.name, _fmt(arg.default) if not arg.required else "VALUE"))
            elif arg.required:
                parts.append(arg.name)
            else:
                parts.append("[%s]" % arg.name)
        return " ".join(parts)

    def describe(self) -> Dict[str, Any]:
        return {
            "name": self.name,
            "usage": self.usage,
            "summary": self.summary,
            "category": self.category,
            "args": [a.describe() for a in self.args],
            "resources": sorted(self.resources),
            "interfaces": sorted(i.value for i in self.interfaces),
            "timeout_s": self.timeout,
            "result": [{"key": k, "doc": d} for k, d in self.result],
            "pausable": self.pausable,
            "preemptive": self.preemptive,
            "query": self.query,
            **({"capability": self.capability} if self.capability else {}),
        }


@dataclass(frozen=True)
class BoundCommand:
    """A command whose arguments are typed and checked: safe to hand to a handler."""

    spec: CommandSpec
    values: Mapping[str, Any]
    text: str

    @property
    def name(self) -> str:
        return self.spec.name

    @property
    def claims(self) -> FrozenSet[str]:
        return self.spec.claims(self.values) if self.spec.claims else self.spec.resources

    @property
    def timeout(self) -> float:
        return float(self.spec.deadline(self.values)) if self.spec.deadline else self.spec.timeout


Handler = Callable[..., Optional[Dict[str, Any]]]


class CommandRegistry:
    """Declarations (name → :class:`CommandSpec`) and the handlers bound to them."""

    def __init__(self, specs: Iterable[CommandSpec] = ()) -> None:
        self._specs: Dict[str, CommandSpec] = {}
        self._handlers: Dict[str, Handler] = {}
        self.version = 0
        """Changes with every declaration, so whoever remembers bindings knows when to forget them."""
        for spec in specs:
            self.declare(spec)

    def declare(self, spec: CommandSpec) -> None:
        if spec.name in self._specs and self._specs[spec.name] != spec:
            raise ValueError("command %s is declared twice with different specs" % spec.name)
        self._specs[spec.name] = spec
        self.version += 1

    def bind(self, name: str, handler: Handler) -> None:
        if name not in self._specs:
            raise KeyError("cannot bind a handler to undeclared command %s" % name)
        self._handlers[name] = handler

    def specs(self) -> List[CommandSpec]:
        return sorted(self._specs.values(), key=lambda s: (s.category != "system", s.category, s.name))

    def names(self) -> List[str]:
        return sorted(self._specs)

    def handler(self, name: str) -> Optional[Handler]:
        return self._handlers.get(name)

    def lookup(self, name: str) -> CommandSpec:
        """The spec for ``name`` (case-insensitive) or :class:`InvalidCommand` with a did-you-mean."""
        spec = self._specs.get(name.upper())
        if spec is None:
            raise InvalidCommand("unknown command '%s'%s; send HELP to list all commands"
                                 % (_clip(name), self.suggest(name)))
        return spec

    def suggest(self, name: str) -> str:
        close = difflib.get_close_matches(name.upper(), list(self._specs), n=3, cutoff=0.6)
        return " (did you mean %s?)" % " or ".join(close) if close else ""

    def bind_arguments(self, parsed: ParsedCommand, interface: Optional[Interface] = None) -> BoundCommand:
        """Check ``parsed`` against its declaration; raise the typed error naming the culprit."""
        spec = self.lookup(parsed.name)
        if interface is not None and interface not in spec.interfaces:
            raise InvalidCommand("%s is not available over the %s interface; allowed: %s"
                                 % (spec.name, interface.value, ", ".join(sorted(i.value for i in spec.interfaces))))
        positional = spec.positional_args
        if len(parsed.positional) > len(positional):
            extra = " ".join("'%s'" % _clip(t) for t in parsed.positional[len(positional):])
            raise InvalidArgument("%s takes at most %d positional argument%s, got %d (extra: %s); usage: %s"
                                  % (spec.name, len(positional), "" if len(positional) == 1 else "s",
                                     len(parsed.positional), extra, spec.usage))
        values: Dict[str, Any] = {}
        for arg, token in zip(positional, parsed.positional):
            values[arg.name] = arg.convert(spec.name, token)
        by_name = {a.name: a for a in spec.args}
        for key, token in parsed.keywords:
            arg = by_name.get(key)
            if arg is None:
                allowed = ", ".join(a.name for a in spec.args) or "none"
                raise InvalidArgument("%s: unknown keyword '%s'; allowed keywords: %s" % (spec.name, key, allowed),
                                      argument=key)
            if key in values:
                raise InvalidArgument("%s: argument '%s' is given both by position and as a keyword"
                                      % (spec.name, key), argument=key)
            values[key] = arg.convert(spec.name, token)
        for arg in spec.args:
            if arg.name in values:
                if arg.type is ArgType.COMMAND and values[arg.name] and values[arg.name] not in self._specs:
                    raise InvalidArgument(
                        "%s: argument '%s': no command named '%s'%s; the commands are those declared in this "
                        "LOCEM's command registry (system commands and the configured robot's bridges): send HELP "
                        "to list them" % (spec.name, arg.name, _clip(values[arg.name]),
                                          self.suggest(values[arg.name])), argument=arg.name)
                continue
            if arg.required:
                raise InvalidArgument("%s: missing argument '%s' (%s: %s); usage: %s"
                                      % (spec.name, arg.name, arg.doc, arg.allowed(), spec.usage), argument=arg.name)
            values[arg.name] = arg.default
        return BoundCommand(spec, values, parsed.text)

    def require_handler(self, bound: BoundCommand) -> Handler:
        handler = self._handlers.get(bound.name)
        if handler is None:
            raise NotReady("%s is declared but no backend serves it on this robot (category %s); "
                           "check the robot configuration" % (bound.name, bound.spec.category))
        return handler


def _fmt(value: Any) -> str:
    if isinstance(value, float):
        return ("%.6g" % value)
    return str(value)


def _clip(token: str, limit: int = 40) -> str:
    return token if len(token) <= limit else token[: limit - 3] + "..."
