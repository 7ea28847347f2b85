"""The move path that ur_rtde injects into its control script, read from the uploaded script text.

How ur_rtde (1.5 / 1.6) sends a path: ``RTDEControlInterface.moveL(path)``, ``moveJ(path)`` and ``movePath(Path)``
stop the running control script (command 255), upload the control script again with the path written into the
body of ``def exec_move_path():`` below the line ``# inject move path``, one block per waypoint::

        signal_async_progress(0)
        movel(p[-0.691398,-0.12415,0.67685,-2.22144,-2.22144,1.63164e-11],a=1.2,v=0.25,r=0.02)
        signal_async_progress(1)
        movej([0.1,-1.5,1.5,-1.6,-1.57,0],a=1.4,v=1.05,r=0)

and then send command 45 (``MOVE_PATH``, input recipe 15: ``input_int_register_0`` = 45, ``_1`` = async flag).
Numbers are printed with C++ stream defaults (6 significant digits). ``movel`` / ``movep`` targets are poses
``p[...]``, ``movej`` targets joint positions ``[...]`` (either may be given the other kind, as in URScript).

:func:`parse_move_path` turns that text into :class:`PathEntry` items; lifecycle: parsed once per uploaded
program, executed (planned and checked) when command 45 arrives.
"""
import math
import re
from collections import namedtuple
from typing import List, Optional, Tuple

PathEntry = namedtuple("PathEntry", "kind target is_pose a v r progress line")
PathEntry.__doc__ = ("One waypoint of an injected path: kind 'movel' | 'movej' | 'movep', target (6 floats), "
                     "is_pose (p[...] target), a, v, r (blend radius, m), progress (the signal_async_progress "
                     "value before it, or -1) and the script line (for error messages).")

_DEF = re.compile(r"^\s*def\s+exec_move_path\s*\(\s*\)\s*:\s*$")
_PROGRESS = re.compile(r"^\s*signal_async_progress\(\s*(-?\d+)\s*\)\s*$")
_MOVE = re.compile(r"^\s*(movel|movej|movep)\(\s*(p?)\[([^\]]*)\]\s*((?:,\s*[a-z]+\s*=\s*[^,()]+)*)\)\s*$")
_IGNORED = re.compile(r"^\s*(#.*|textmsg\(.*\)|sync\(\)|)\s*$")


def parse_move_path(text: str) -> Tuple[List[PathEntry], Optional[str]]:
    """Read the body of ``exec_move_path`` from a control script: ``(entries, error)``.

    ``error`` is None when every statement was understood; otherwise it names the first statement the stand-in
    cannot execute (the program still runs: command 45 then halts it with that error). No ``exec_move_path``
    function gives ``([], None)``.
    """
    lines = text.split("\n")
    start = None
    for i, line in enumerate(lines):
        if _DEF.match(line):
            start = i + 1
            break
    if start is None:
        return [], None
    entries: List[PathEntry] = []
    progress = -1
    for line in lines[start:]:
        stripped = line.strip()
        if stripped == "end":
            break
        m = _PROGRESS.match(line)
        if m:
            progress = int(m.group(1))
            continue
        m = _MOVE.match(line)
        if m:
            entry, error = _move(m, progress, stripped)
            if error:
                return entries, error
            entries.append(entry)
            continue
        if _IGNORED.match(line):
            continue
        return entries, "exec_move_path: statement not emulated by the UR stand-in: %r" % stripped[:80]
    return entries, None


def _move(m, progress: int, line: str):
    kind, is_pose, raw, kwargs = m.group(1), m.group(2) == "p", m.group(3), m.group(4)
    try:
        target = [float(x) for x in raw.split(",")]
    except ValueError:
        return None, "exec_move_path: target of %r is not 6 numbers" % line[:80]
    if len(target) != 6 or not all(math.isfinite(x) for x in target):
        return None, "exec_move_path: target of %r is not 6 finite numbers" % line[:80]
    params = {"a": None, "v": None, "r": 0.0}
    for part in kwargs.split(","):
        if not part.strip():
            continue
        key, _, value = part.partition("=")
        key = key.strip()
        if key not in params:
            return None, "exec_move_path: %s argument %r is not emulated (a, v, r)" % (kind, key)
        try:
            params[key] = float(value)
        except ValueError:
            return None, "exec_move_path: %s=%r in %r is not a number" % (key, value.strip(), line[:80])
    if params["a"] is None or params["v"] is None:
        # URScript defaults: movel a=1.2 m/s^2 v=0.25 m/s, movej a=1.4 rad/s^2 v=1.05 rad/s
        defaults = (1.4, 1.05) if kind == "movej" else (1.2, 0.25)
        params["a"] = defaults[0] if params["a"] is None else params["a"]
        params["v"] = defaults[1] if params["v"] is None else params["v"]
    return PathEntry(kind, target, is_pose, params["a"], params["v"], params["r"], progress, line), None
