"""Typed ports of behavior-tree nodes, in the BehaviorTree.CPP (format 4) sense.

A node declares its ports as :class:`PortSpec` objects (name, direction, :class:`PortType`, default, unit,
description). In the XML a port value is either a *literal* (converted once, at load time, by the declared
type; a conversion failure is a load-time error) or a *blackboard pointer* ``{key}`` (resolved on every read;
a string found on the blackboard is converted by the declared type, any other value must already have it).

Keys may carry dots (``{cfg.taping.speed}``); a leading ``@`` (``{@cfg.x}``) addresses the root blackboard
of the tree, as in BT.CPP 4.
"""
import json
import math
import re
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple, Union

from .errors import NodeDeclarationError, PortError

INPUT = "input"
OUTPUT = "output"
INOUT = "inout"
_DIRECTIONS = (INPUT, OUTPUT, INOUT)

_KEY_RE = re.compile(r"^\{(@?[A-Za-z_][A-Za-z0-9_.]*)\}$")
TEMPLATE_FIELD = re.compile(r"\{(@?[A-Za-z_][A-Za-z0-9_.]*)\}")


def template_keys(text: str) -> List[str]:
    """Blackboard keys a template text refers to (``GOTO {pose}`` → ``['pose']``)."""
    return TEMPLATE_FIELD.findall(text)


def blackboard_key(text: str) -> Optional[str]:
    """Return the key if ``text`` is exactly a blackboard pointer ``{key}``, else None."""
    m = _KEY_RE.match(text.strip())
    return m.group(1) if m else None


class PortType:
    """A value type a port can carry.

    ``name`` is the Python-side name, ``xml_type`` the name written into the Groot2 catalogue (BT.CPP spelling
    where one exists). ``parse`` turns XML/blackboard text into a value; ``check`` validates a non-string value
    found on the blackboard. Both raise ValueError with a message naming the allowed form.
    """

    def __init__(self, name: str, xml_type: str, parse: Callable[[str], Any],
                 check: Callable[[Any], Any], allowed: str) -> None:
        self.name = name
        self.xml_type = xml_type
        self._parse = parse
        self._check = check
        self.allowed = allowed

    def parse(self, text: str) -> Any:
        try:
            return self._parse(text)
        except (ValueError, TypeError) as exc:
            raise ValueError("'%s' is not a valid %s (%s)%s" % (
                text, self.name, self.allowed, (": %s" % exc) if str(exc) else ""))

    def coerce(self, value: Any) -> Any:
        """Convert a blackboard value: strings are parsed, other values checked."""
        if isinstance(value, str) and self.name not in ("str", "any"):
            return self.parse(value)
        try:
            return self._check(value)
        except (ValueError, TypeError):
            raise ValueError("%r (a %s) is not a valid %s (%s)" % (value, type(value).__name__, self.name,
                                                                     self.allowed))

    def __repr__(self) -> str:
        return "PortType(%s)" % self.name


def _finite(x: float) -> float:
    if not math.isfinite(x):
        raise ValueError("NaN and Inf are not allowed")
    return x


def _parse_float(text: str) -> float:
    return _finite(float(text.strip()))


def _check_float(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise TypeError()
    return _finite(float(v))


def _parse_int(text: str) -> int:
    return int(text.strip(), 10)


def _check_int(v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise TypeError()
    return v


def _parse_bool(text: str) -> bool:
    t = text.strip().lower()
    if t in ("true", "1"):
        return True
    if t in ("false", "0"):
        return False
    raise ValueError("")


def _check_bool(v: Any) -> bool:
    if not isinstance(v, bool):
        raise TypeError()
    return v


def _split(text: str) -> List[str]:
    t = text.strip()
    if t.startswith("["):
        return [str(x) for x in json.loads(t)]
    if not t:
        return []
    return [p.strip() for p in t.split(";")]


def _parse_float_list(text: str) -> List[float]:
    t = text.strip()
    if t.startswith("["):
        return _check_float_list(json.loads(t))
    return [_parse_float(p) for p in _split(t)]


def _check_float_list(v: Any) -> List[float]:
    if not isinstance(v, (list, tuple)):
        raise TypeError()
    return [_check_float(x) for x in v]


def _check_str_list(v: Any) -> List[str]:
    if not isinstance(v, (list, tuple)) or not all(isinstance(x, str) for x in v):
        raise TypeError()
    return list(v)


def _parse_json(text: str) -> Any:
    return json.loads(text)


def _check_json(v: Any) -> Any:
    json.dumps(v, allow_nan=False)
    return v


def _check_str(v: Any) -> str:
    if isinstance(v, (dict, list, tuple)):
        raise TypeError()
    return v if isinstance(v, str) else str(v)


STRING = PortType("str", "std::string", lambda t: t, _check_str, "any text")
FLOAT = PortType("float", "double", _parse_float, _check_float, "a finite number")
INT = PortType("int", "int", _parse_int, _check_int, "a whole number")
BOOL = PortType("bool", "bool", _parse_bool, _check_bool, "true or false")
FLOAT_LIST = PortType("float_list", "std::vector<double>", _parse_float_list, _check_float_list,
                      "numbers separated by ';' or a JSON list")
STRING_LIST = PortType("str_list", "std::vector<std::string>", _split, _check_str_list,
                       "texts separated by ';' or a JSON list")
JSON = PortType("json", "json", _parse_json, _check_json, "a JSON value")
ANY = PortType("any", "BT::Any", lambda t: t, lambda v: v, "any value")

PORT_TYPES = {t.name: t for t in (STRING, FLOAT, INT, BOOL, FLOAT_LIST, STRING_LIST, JSON, ANY)}


class PortSpec:
    """Declaration of one port: name, direction, type, default (XML text or None = required), unit, doc.

    ``choices`` optionally restricts a string port to a closed set (checked at load time for literals).
    """

    def __init__(self, name: str, direction: str, ptype: PortType, default: Optional[str] = None,
                 unit: str = "", description: str = "", choices: Optional[Sequence[str]] = None) -> None:
        if direction not in _DIRECTIONS:
            raise NodeDeclarationError("port %s: direction %r not in %s" % (name, direction, _DIRECTIONS))
        if not re.match(r"^[A-Za-z][A-Za-z0-9_]*$", name):
            raise NodeDeclarationError("port name %r: must match [A-Za-z][A-Za-z0-9_]*" % name)
        self.name = name
        self.direction = direction
        self.type = ptype
        self.default = default
        self.unit = unit
        self.description = description
        self.choices = tuple(choices) if choices else None
        if default is not None and blackboard_key(default) is None and direction != OUTPUT:
            self.convert_literal(default)  # a bad default is a declaration error: fail at import

    @property
    def required(self) -> bool:
        return self.default is None and self.direction != OUTPUT

    def convert_literal(self, text: str) -> Any:
        value = self.type.parse(text)
        self._check_choice(value)
        return value

    def _check_choice(self, value: Any) -> None:
        if self.choices is not None and value not in self.choices:
            raise ValueError("'%s' is not allowed; allowed: %s" % (value, ", ".join(self.choices)))

    def coerce(self, value: Any) -> Any:
        v = self.type.coerce(value)
        self._check_choice(v)
        return v


def input_port(name: str, ptype: PortType, default: Optional[str] = None, unit: str = "",
               description: str = "", choices: Optional[Sequence[str]] = None) -> PortSpec:
    return PortSpec(name, INPUT, ptype, default, unit, description, choices)


def output_port(name: str, ptype: PortType, default: Optional[str] = None, unit: str = "",
                description: str = "") -> PortSpec:
    return PortSpec(name, OUTPUT, ptype, default, unit, description)


def inout_port(name: str, ptype: PortType, default: Optional[str] = None, unit: str = "",
               description: str = "") -> PortSpec:
    return PortSpec(name, INOUT, ptype, default, unit, description)


class Literal:
    """A port bound to a constant (already converted)."""
    __slots__ = ("value", "text")

    def __init__(self, value: Any, text: str) -> None:
        self.value = value
        self.text = text


class Ref:
    """A port bound to a blackboard key."""
    __slots__ = ("key",)

    def __init__(self, key: str) -> None:
        self.key = key


Binding = Union[Literal, Ref]


class PortBinding:
    """The ports of one node instance bound to values and to the node's blackboard scope.

    ``get(name)`` returns the converted input value (raises :class:`PortError` if a pointed-to key is unset or
    has the wrong type); ``set(name, value)`` writes an output port to the blackboard (type-checked).
    """

    def __init__(self, node_name: str, specs: Dict[str, PortSpec], bindings: Dict[str, Binding],
                 blackboard: Any) -> None:
        self.node_name = node_name
        self.specs = specs
        self.bindings = bindings
        self.blackboard = blackboard

    def has(self, name: str) -> bool:
        return name in self.bindings

    def key(self, name: str) -> Optional[str]:
        b = self.bindings.get(name)
        return b.key if isinstance(b, Ref) else None

    def get(self, name: str) -> Any:
        b = self.bindings.get(name)
        if b is None:
            if name not in self.specs:
                raise PortError("%s: no port named '%s'" % (self.node_name, name))
            return None  # optional port without default
        if isinstance(b, Literal):
            return b.value
        spec = self.specs[name]
        try:
            raw = self.blackboard.get(b.key)
        except KeyError:
            raise PortError("%s: port '%s' points to blackboard key '%s', which is not set" % (
                self.node_name, name, b.key))
        try:
            return spec.coerce(raw)
        except ValueError as exc:
            raise PortError("%s: port '%s' (key '%s'): %s" % (self.node_name, name, b.key, exc))

    def set(self, name: str, value: Any) -> None:
        b = self.bindings.get(name)
        spec = self.specs.get(name)
        if spec is None:
            raise PortError("%s: no port named '%s'" % (self.node_name, name))
        if b is None:
            return  # output not connected: BT.CPP drops it as well
        if not isinstance(b, Ref):
            raise PortError("%s: output port '%s' is bound to a literal, not a {key}" % (self.node_name, name))
        try:
            v = spec.type.coerce(value) if spec.type.name not in ("str", "any") else value
        except ValueError as exc:
            raise PortError("%s: output port '%s': %s" % (self.node_name, name, exc))
        self.blackboard.set(b.key, v)

    def describe(self) -> List[Tuple[str, str]]:
        out = []
        for n, b in self.bindings.items():
            out.append((n, ("{%s}" % b.key) if isinstance(b, Ref) else b.text))
        return out
