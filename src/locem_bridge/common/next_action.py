"""The PEMKRE -> HICEM next-action answer: the one record and its one N-Triples parameter codec.

docs/contracts.md, "PEMKRE next action": ``status`` is ``action``, ``ended`` or ``failed``; with ``action`` the
answer names the ``action_type``, the matched ``skill`` and its ``skill_kind`` (``composite``: HICEM runs that
tree; ``basic``: one LOCEM command; both empty: the tree is the action type), the ``task`` (the task instance IRI)
and its ``parameters``, an N-Triples document whose triples have the task as subject. A predicate's local name
(after the last ``#`` or ``/``) is the parameter name, the object an IRI (its local name is the value: a feature
id, a tool name) or a literal (its Python value). PEMKRE's engine writes the answer (:func:`encode_parameters`),
the ROS adapters carry its fields, HICEM checks it (:meth:`NextAction.from_answer`) and puts the parameters on
its blackboard as ``param_<name>``.

Standard library only: HICEM reads the parameters without an RDF library. PEMKRE turns its RDF terms into the
N-Triples text :func:`iri_term` / :func:`literal_term` write (canonical N-Triples, as pyoxigraph writes it).
"""
import re
from dataclasses import dataclass, field
from typing import Any, Dict, Iterable, Mapping, Optional, Tuple

ACTION = "action"
"""The answer names a task to run."""
ENDED = "ended"
"""The process reached an end node (``message``: its outcome)."""
FAILED = "failed"
"""The process failed (``message``: why)."""
ANSWER_STATUSES: Tuple[str, ...] = (ACTION, ENDED, FAILED)

COMPOSITE = "composite"
"""``skill_kind``: the skill is an action tree (``skill`` = its tree ID)."""
BASIC = "basic"
"""``skill_kind``: the skill is one LOCEM command (``skill`` = the command name)."""
SKILL_KINDS: Tuple[str, ...] = (COMPOSITE, BASIC)
"""The kinds a matched skill may have; ``""`` (no skill named) = the tree is the action type."""

XSD = "http://www.w3.org/2001/XMLSchema#"


class NextActionError(ValueError):
    """A next-action answer or its parameter document does not follow docs/contracts.md (the message says where)."""


def local_name(iri: str) -> str:
    """The part after the last ``#`` or ``/`` (docs/contracts.md: the parameter name, the feature id)."""
    return re.split(r"[#/]", str(iri))[-1]


# ------------------------------------------------------------------------------------------------ encoding --
_ESCAPE_OUT = {"\b": "\\b", "\t": "\\t", "\n": "\\n", "\f": "\\f", "\r": "\\r", '"': '\\"', "\\": "\\\\"}


def _quote(text: str) -> str:
    out = []
    for c in text:
        esc = _ESCAPE_OUT.get(c)
        if esc is None and (c < " " or c == "\x7f"):
            esc = "\\u%04X" % ord(c)
        out.append(esc if esc is not None else c)
    return '"%s"' % "".join(out)


def iri_term(iri: str) -> str:
    """``<iri>``: an IRI as an N-Triples term (the caller has checked it is an absolute IRI)."""
    return "<%s>" % iri


def literal_term(lexical: str, datatype: Optional[str] = None, language: Optional[str] = None) -> str:
    """A literal as an N-Triples term: ``"text"``, ``"text"@lang`` or ``"1.5"^^<datatype>`` (xsd:string is
    written plain, the language tag in lower case, control characters escaped)."""
    if language:
        return "%s@%s" % (_quote(lexical), language.lower())
    if datatype and datatype != XSD + "string":
        return "%s^^<%s>" % (_quote(lexical), datatype)
    return _quote(lexical)


def encode_parameters(task: str, parameters: Iterable[Tuple[str, str]]) -> str:
    """The parameter document of ``task``: one triple a line for each ``(predicate IRI, N-Triples term)``."""
    subject = iri_term(task)
    return "".join("%s %s %s .\n" % (subject, iri_term(p), term) for p, term in parameters)


# ------------------------------------------------------------------------------------------------ decoding --
_IRI = r"<([^<>\"{}|^`\\\s]*)>"
_LIT = r"\"((?:[^\"\\]|\\.)*)\"(?:\^\^<([^<>\s]*)>|@([A-Za-z]+(?:-[A-Za-z0-9]+)*))?"
_TRIPLE = re.compile(r"^\s*" + _IRI + r"\s+" + _IRI + r"\s+(?:" + _IRI + "|" + _LIT + r")\s*\.\s*$")
_ESCAPE_IN = {"t": "\t", "b": "\b", "n": "\n", "r": "\r", "f": "\f", '"': '"', "'": "'", "\\": "\\"}


def _unescape(s: str) -> str:
    out, i = [], 0
    while i < len(s):
        c = s[i]
        if c == "\\" and i + 1 < len(s):
            n = s[i + 1]
            if n in _ESCAPE_IN:
                out.append(_ESCAPE_IN[n])
                i += 2
                continue
            if n in "uU":
                width = 4 if n == "u" else 8
                out.append(chr(int(s[i + 2:i + 2 + width], 16)))
                i += 2 + width
                continue
        out.append(c)
        i += 1
    return "".join(out)


def _literal_value(text: str, dtype: Optional[str]) -> Any:
    if dtype in (XSD + "integer", XSD + "int", XSD + "long", XSD + "nonNegativeInteger"):
        return int(text)
    if dtype in (XSD + "decimal", XSD + "double", XSD + "float"):
        return float(text)
    if dtype == XSD + "boolean":
        if text not in ("true", "false", "1", "0"):
            raise ValueError("bad xsd:boolean %r" % text)
        return text in ("true", "1")
    return text


def decode_parameters(task: str, ntriples: str) -> Dict[str, Any]:
    """The parameter document as ``{name: value}``: predicate local name -> object local name (IRIs) or Python
    value (literals). Raises :class:`NextActionError` naming the line for anything else."""
    params: Dict[str, Any] = {}
    for n, line in enumerate(ntriples.split("\n"), 1):   # N-Triples ends lines at LF (CR LF) only, never at U+2028
        line = line[:-1] if line.endswith("\r") else line
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        m = _TRIPLE.match(line)
        if not m:
            raise NextActionError("parameters line %d is not an N-Triples triple: %r" % (n, line[:120]))
        subj, pred, obj_iri, lit, dtype, _lang = m.groups()
        if subj != task:
            raise NextActionError("parameters line %d: subject <%s> is not the task <%s>" % (n, subj, task))
        name = local_name(pred)
        if obj_iri is not None:
            value: Any = local_name(obj_iri)
        else:
            try:
                value = _literal_value(_unescape(lit), dtype)
            except ValueError as exc:
                raise NextActionError("parameters line %d: literal %r: %s" % (n, lit, exc))
        params[name] = value
    return params


# -------------------------------------------------------------------------------------------------- record --
@dataclass
class NextAction:
    """One next-action answer (the engine's return value, the ROS response's fields, what HICEM runs)."""

    status: str                      # action | ended | failed
    process: str = ""                # the specific process IRI
    task: str = ""                   # the task instance IRI (action)
    action_type: str = ""            # e.g. TAPE_LINE (action)
    parameters: str = ""             # N-Triples, subject = task (action)
    task_status: str = ""            # issued | in_progress (a repeated answer)
    message: str = ""                # the outcome (ended) or the reason (failed)
    skill: str = ""                  # the matched skill: a tree ID (composite) or LOCEM command name (basic)
    skill_kind: str = ""             # composite | basic | "" (no skill named: the tree is the action type)
    #: the decoded parameters, when the holder has them already (checked answers, HICEM's stored action)
    values: Optional[Dict[str, Any]] = field(default=None, repr=False, compare=False)

    def params(self) -> Dict[str, Any]:
        """``{name: local name or Python value}`` (docs/contracts.md)."""
        if self.values is None:
            self.values = decode_parameters(self.task, self.parameters) if self.parameters else {}
        return dict(self.values)

    def blackboard_entries(self) -> Dict[str, Any]:
        """The parameters as HICEM's trees see them: ``param_<name>``."""
        return {"param_%s" % k: v for k, v in self.params().items()}

    def as_answer(self) -> Dict[str, Any]:
        """The answer as a plain object (the shape :meth:`from_answer` reads)."""
        return {"status": self.status, "process": self.process, "task": self.task, "action_type": self.action_type,
                "parameters": self.parameters, "task_status": self.task_status, "message": self.message,
                "skill": self.skill, "skill_kind": self.skill_kind}

    @classmethod
    def from_answer(cls, answer: Any) -> "NextAction":
        """Check an answer (a :class:`NextAction` or its plain-object form; ``detail`` is accepted for
        ``message``) and decode its parameters; :class:`NextActionError` names the first problem.

        An action type (or skill) nobody runs is not rejected here: HICEM reports it to PEMKRE as a failure.
        ``skill`` and ``skill_kind`` are optional (absent or ``""``: the tree is the action type); a kind must be
        one of :data:`SKILL_KINDS` and name a skill, a skill must have a kind.
        """
        if isinstance(answer, NextAction):
            answer = answer.as_answer()
        if not isinstance(answer, Mapping):
            raise NextActionError("next_action answer must be an object, got %s" % type(answer).__name__)
        status = answer.get("status")
        message = str(answer.get("detail", answer.get("message", "")))
        process = str(answer.get("process") or "")
        if status in (ENDED, FAILED):
            return cls(status, process, message=message)
        if status != ACTION:
            raise NextActionError("next_action status %r is not one of: action, ended, failed" % (status,))
        at = answer.get("action_type")
        task = answer.get("task")
        if not isinstance(at, str) or not at:
            raise NextActionError("next_action: 'action_type' missing or not a string")
        if not isinstance(task, str) or not task:
            raise NextActionError("next_action: 'task' (the task instance IRI) missing or not a string")
        nt = answer.get("parameters", "")
        if not isinstance(nt, str):
            raise NextActionError("next_action: 'parameters' must be an N-Triples string")
        skill, kind = answer.get("skill") or "", answer.get("skill_kind") or ""
        if not isinstance(skill, str) or not isinstance(kind, str):
            raise NextActionError("next_action: 'skill' and 'skill_kind' must be strings")
        if kind and kind not in SKILL_KINDS:
            raise NextActionError("next_action: skill_kind %r is not one of: %s (or empty: the tree is the action "
                                  "type)" % (kind, ", ".join(SKILL_KINDS)))
        if bool(skill) != bool(kind):
            raise NextActionError("next_action: 'skill' and 'skill_kind' go together (got skill %r, skill_kind %r)"
                                  % (skill, kind))
        if skill and (skill != skill.strip() or any(c.isspace() for c in skill)):
            raise NextActionError("next_action: skill %r must be a tree ID or command name without whitespace"
                                  % skill)
        return cls(ACTION, process, task, at, nt, str(answer.get("task_status") or ""), message, skill, kind,
                   values=decode_parameters(task, nt))
