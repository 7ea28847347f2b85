"""The folders a run reads Turtle and trees from: the package's own folder plus an integrator's folders.

An integrator keeps their use case in folders of their own (Turtle for PEMKRE, tree XML for HICEM and the
resource model) and names them beside the shipped ones: ``tools/main.sh --ontologies DIR --trees DIR`` and the
launch arguments ``extra_ontology_dirs`` / ``extra_trees_dirs`` (one text, folders separated by ``:`` or ``,``).
Every layer that reads those folders lists them here, the same way:

- :func:`split_folders`: ``"a:b"``, ``"a, b"`` or ``["a", "b"]`` -> ``["a", "b"]`` (empty entries dropped).
- :func:`folder_files`: the files of each folder ending in a suffix, each folder sorted, folders in the order
  given (a folder named twice is read once); a folder that does not exist (or is not a folder) raises
  :class:`ConfigError` naming it.
"""
import os
import re
from typing import Any, List, Sequence

from .config_errors import ConfigError


def split_folders(value: Any) -> List[str]:
    """The folders of a ``:``- or ``,``-separated text or a list (``[]`` for None or an empty text)."""
    if value is None:
        return []
    items = re.split(r"[:,]", value) if isinstance(value, str) else [str(v) for v in value]
    return [os.path.expanduser(v.strip()) for v in items if v and v.strip()]


def folder_files(folders: Sequence[str], suffix: str, what: str, exclude: Sequence[str] = ()) -> List[str]:
    """Absolute paths of the files ending in ``suffix`` in each of ``folders`` (``exclude``: base names left
    out); ``what`` names the folder kind in the error (``ontology folder``, ``trees folder``)."""
    files: List[str] = []
    for folder in folders:
        path = os.path.abspath(folder)
        if not os.path.isdir(path):
            raise ConfigError("%s does not exist" % what if not os.path.exists(path) else
                              "%s is not a folder" % what, file=path)
        found = sorted(os.path.join(path, f) for f in os.listdir(path) if f.endswith(suffix) and f not in exclude)
        files += [f for f in found if os.path.isfile(f) and f not in files]      # a folder named twice: read once
    return files
