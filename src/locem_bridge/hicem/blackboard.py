"""Scoped blackboards with BehaviorTree.CPP 4 semantics.

Each tree and each SubTree instance owns a :class:`Blackboard`. A SubTree's blackboard is isolated from its
parent except for (a) keys remapped explicitly (``<SubTree ID="X" line="{param_line}"/>`` links subtree key
``line`` to parent key ``param_line``; a literal ``speed="0.5"`` sets the subtree's own entry), (b) every
other key when ``_autoremap="true"`` (keys starting with ``_`` stay private), and (c) ``@key``, which always
addresses the root blackboard.

py_trees' own blackboard is process-global; HICEM runs several trees in one process (and tests run many), so
the executive keeps its scopes here and hands them to nodes through their port bindings.
Not thread-safe: only the thread that ticks the tree touches it (plus the controller between ticks).
"""
from typing import Any, Dict, Iterator, Optional, Tuple


class Blackboard:
    """One scope: local entries, a link to the parent scope, explicit remaps and the autoremap flag."""

    def __init__(self, parent: Optional["Blackboard"] = None, remap: Optional[Dict[str, str]] = None,
                 autoremap: bool = False) -> None:
        self.parent = parent
        self.remap = dict(remap or {})
        self.autoremap = autoremap
        self._data: Dict[str, Any] = {}

    @property
    def root(self) -> "Blackboard":
        bb = self
        while bb.parent is not None:
            bb = bb.parent
        return bb

    def _resolve(self, key: str) -> Tuple["Blackboard", str]:
        bb, k = self, key
        for _ in range(64):  # bounded: scopes are at most as deep as the subtree nesting
            if k.startswith("@"):
                return bb.root, k[1:]
            if bb.parent is not None:
                if k in bb.remap:
                    bb, k = bb.parent, bb.remap[k]
                    continue
                if bb.autoremap and not k.startswith("_") and k not in bb._data:
                    bb = bb.parent
                    continue
            return bb, k
        raise RuntimeError("blackboard remap chain too deep for key %r" % key)

    def get(self, key: str) -> Any:
        """Value of ``key``; KeyError if it is not set in the scope it resolves to.

        A dotted key that is not an entry itself is read as entry + fields: ``section.approach`` is field
        ``approach`` of entry ``section`` (list elements by index: ``pose.0``).
        """
        bb, k = self._resolve(key)
        if k in bb._data:
            return bb._data[k]
        if "." in k:  # the key as resolved (a remapped port may point to "section.approach" in the parent)
            parts = k.split(".")
            for cut in range(len(parts) - 1, 0, -1):
                bb2, k2 = bb._resolve(".".join(parts[:cut]))
                if k2 in bb2._data:
                    v = bb2._data[k2]
                    for f in parts[cut:]:
                        if isinstance(v, dict) and f in v:
                            v = v[f]
                        elif isinstance(v, (list, tuple)) and f.isdigit() and int(f) < len(v):
                            v = v[int(f)]
                        else:
                            raise KeyError(key)
                    return v
        raise KeyError(key)

    def get_default(self, key: str, default: Any = None) -> Any:
        try:
            return self.get(key)
        except KeyError:
            return default

    def has(self, key: str) -> bool:
        try:
            self.get(key)
            return True
        except KeyError:
            return False

    def set(self, key: str, value: Any) -> None:
        bb, k = self._resolve(key)
        bb._data[k] = value

    def set_local(self, key: str, value: Any) -> None:
        """Write into this scope regardless of remapping (used for SubTree literal ports)."""
        self._data[key] = value

    def unset(self, key: str) -> None:
        bb, k = self._resolve(key)
        bb._data.pop(k, None)

    def items(self) -> Iterator[Tuple[str, Any]]:
        return iter(list(self._data.items()))

    def update(self, values: Dict[str, Any]) -> None:
        for k, v in values.items():
            self.set(k, v)
