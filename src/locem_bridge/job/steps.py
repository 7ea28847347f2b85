"""The job file: the processes a job runs in order (``config/jobs/plasterboard.yaml``, or an integrator's own).

``steps: [{name, process, options}]``: ``process`` an abstract process IRI of the loaded Turtle, ``options`` its
process options. :func:`load_steps` reads it for the job node and for ``tools/main.sh``'s pre-flight alike.
"""
from typing import Any, List

from ..common.config_errors import ConfigError, read_yaml
from .tracker import JobStep


def load_steps(path: str, validate_lines: Any = "") -> List[JobStep]:
    """The job file's steps; a bad file raises :class:`ConfigError` (one line: file, key, problem).
    ``validate_lines`` (not empty) overrides a step's ``validateLines`` option."""
    doc = read_yaml(path, ConfigError) or {}
    if not isinstance(doc, dict) or not isinstance(doc.get("steps", []), list):
        raise ConfigError("must hold a mapping with a list 'steps'", file=path, key="steps")
    steps = []
    for i, entry in enumerate(doc.get("steps", [])):
        key = "steps[%d]" % i
        if not isinstance(entry, dict) or not isinstance(entry.get("name"), str) or \
                not isinstance(entry.get("process"), str):
            raise ConfigError("needs a name and a process (IRI), found %r" % (entry,), file=path, key=key)
        options = entry.get("options") or {}
        if not isinstance(options, dict):
            raise ConfigError("must be a mapping, found %r" % (options,), file=path, key=key + ".options")
        options = dict(options)
        if validate_lines not in ("", None) and "validateLines" in options:
            options["validateLines"] = str(validate_lines).lower() in ("true", "1", "yes")
        steps.append(JobStep(entry["name"], entry["process"], options))
    if not steps:
        raise ConfigError("lists no steps", file=path, key="steps")
    return steps
