"""One error type for bad configuration files, printed as one line an integrator can act on.

Every loader of a file a person edits (robot YAML, site YAML, HICEM parameters, Turtle ontologies, behavior-tree
XML) raises a subclass of :class:`ConfigError`; it carries the file, the key path (or line / element), the
problem and, where there is a closed set, the allowed values, and prints as::

    FILE: KEY: PROBLEM (allowed: ...)

Each layer keeps its own error family (``SimConfigError`` is a ``SimError``, ``BridgeConfigError`` a
``BridgeError``, ...) and also derives from :class:`ConfigError`, so a node catches every configuration problem in
one ``except ConfigError`` at start-up and prints :meth:`ConfigError.one_line` instead of a traceback.
"""
from typing import Any, Callable, Sequence, Union

import yaml

Allowed = Union[None, str, int, float, Sequence[Any]]


def allowed_text(allowed: Allowed) -> str:
    """``allowed`` as text: a string as it is, a sequence joined with commas."""
    if allowed is None:
        return ""
    if isinstance(allowed, str):
        return allowed
    if isinstance(allowed, (list, tuple, set, frozenset)):
        return ", ".join(str(a) for a in allowed)
    return str(allowed)


class ConfigError(Exception):
    """A configuration file is missing, unreadable, malformed or holds a value that is not allowed.

    ``file`` is the file's path ("" while a loader validates a parsed document; :meth:`in_file` fills it in),
    ``key`` the dotted key path (``robot.arm.controller.rtde_port``), a line (``line 12``) or an element,
    ``problem`` what is wrong with the value found, ``allowed`` what would be accepted.
    """

    def __init__(self, problem: str, file: str = "", key: str = "", allowed: Allowed = None) -> None:
        self.problem = problem
        self.file = file
        self.key = key
        self.allowed = allowed_text(allowed)
        super().__init__(problem)

    def in_file(self, path: str) -> "ConfigError":
        """This error with ``file`` set to ``path`` unless it already names one (returns ``self``)."""
        if not self.file:
            self.file = path
        return self

    def recast(self, error: Callable[..., "ConfigError"]) -> "ConfigError":
        """This error as ``error`` (a layer's own :class:`ConfigError` type: ``SimConfigError``,
        ``BridgeConfigError``, ...) with the same file, key, problem and allowed values; itself if it is one."""
        if isinstance(error, type) and isinstance(self, error):
            return self
        return error(self.problem, file=self.file, key=self.key, allowed=self.allowed or None)

    def one_line(self) -> str:
        """``FILE: KEY: PROBLEM (allowed: ...)``, leaving out the parts that are empty; always one line."""
        parts = [p for p in (self.file, self.key, self.problem) if p]
        text = ": ".join(parts)
        if self.allowed:
            text += " (allowed: %s)" % self.allowed
        return " ".join(text.split())

    def __str__(self) -> str:
        return self.one_line()


def read_yaml(path: str, error: Callable[..., ConfigError] = ConfigError) -> Any:
    """The parsed YAML document of ``path``; an unreadable file, one that is not UTF-8 or not valid YAML raises
    ``error`` (a :class:`ConfigError` type) naming the file and, for a syntax error, the line."""
    try:
        with open(path, "r", encoding="utf-8") as handle:
            return yaml.safe_load(handle)
    except OSError as exc:
        raise error("cannot be read: %s" % exc.strerror, file=path)
    except UnicodeDecodeError as exc:
        raise error("is not UTF-8 text: %s" % exc.reason, file=path)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        raise error("not valid YAML: %s" % (getattr(exc, "problem", None) or exc), file=path,
                    key="line %d" % (mark.line + 1) if mark is not None else "")
