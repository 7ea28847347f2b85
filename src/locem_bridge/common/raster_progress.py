"""Progress along a raster, as LOCEM's area commands report it and HICEM keeps it.

A raster (``SPRAY_AREA``) is measured by its worked length: the lanes' stretches where the tool is on (each lane
with its run-in at both ends), laid end to end in the order they are worked; turns and run-ups do not count.
While it works, the command reports in its action feedback ``progress`` = done / total and the text
:func:`progress_text`: ``"raster 2.350 of 11.520 m"`` (metres of that length done so far, counted from the raster's
start, a skipped part included), while the spray valve is open followed by ``" (2.900 m if LOCEM stops now)"``:
how far the spray gets for sure when LOCEM dies at that moment -- the compressor's communication watchdog keeps
the valve open for a while (its timeout less one poll) and the arm's controller goes on along the path, within
the current lane. HICEM reads both back with :func:`parse_progress_text` and passes the point reached as ``skip=``
to the retried command (the second number when the command was cut by LOCEM going away, else the first), which
then goes on from there instead of working the raster again from its start.

The raster's lanes (:func:`lane_heights`: horizontal lanes from the area's bottom to its top, lane k worked
forward along ``u`` when k is even, backward when odd, each over ``-run_in .. width + run_in``) are defined here
once: LOCEM works them, and :func:`raster_point` finds where on them a tool point stands -- after a power loss the
arm stands where the spray stopped, which HICEM reads back before anything moves the arm (a recorded feedback
lags the spray by its transport).
"""
import math
import re
from typing import Optional, Sequence, Tuple

_NUM = r"(\d+(?:\.\d+)?)"
#: m, the farthest a raster's run-up or turn reaches past a lane's worked stretch (LOCEM's run-up at lane speed is
#: a few centimetres plus its blend): a tool point farther along the wall is on no lane of that raster
RUN_UP_M = 0.5
_TEXT = re.compile(r"^raster %s of %s m(?: \(%s m if LOCEM stops now\))?$" % (_NUM, _NUM, _NUM))


def progress_text(done_m: float, total_m: float, if_stopped_m: Optional[float] = None) -> str:
    """The feedback text of ``done_m`` metres of a raster of ``total_m`` metres (mm resolution); with
    ``if_stopped_m`` (valve open) the point the spray reaches for sure should LOCEM die now."""
    text = "raster %.3f of %.3f m" % (max(0.0, done_m), max(0.0, total_m))
    if if_stopped_m is not None:
        text += " (%.3f m if LOCEM stops now)" % max(0.0, if_stopped_m)
    return text


def parse_progress_text(text: str) -> Optional[Tuple[float, float, float]]:
    """``(done_m, total_m, if_stopped_m)`` of a :func:`progress_text` (``if_stopped_m`` = ``done_m`` when the text
    has none: the valve was closed); None for any other text (other feedback)."""
    m = _TEXT.match((text or "").strip())
    if not m:
        return None
    done = float(m.group(1))
    return done, float(m.group(2)), (float(m.group(3)) if m.group(3) is not None else done)


def lane_heights(height: float, spacing: float) -> Tuple[float, ...]:
    """Heights of a raster's lanes above the area's origin: bottom to top, ``spacing`` at most apart, the first at
    the bottom and the last at the top (one lane at 0 for an area of no height: a pass of width 0)."""
    if height <= 1e-9:
        return (0.0,)
    lanes = max(1, int(math.ceil(height / spacing - 1e-9))) + 1
    return tuple(height * k / (lanes - 1) for k in range(lanes)) if lanes > 1 else (height / 2.0,)


def raster_point(point: Sequence[float], origin: Sequence[float], u: Sequence[float], width: float,
                 height: float, normal: Sequence[float], spacing: float, run_in: float, standoff: float,
                 reach: Optional[float] = None, depth: float = 0.05) -> Optional[float]:
    """Where the tool point ``point`` (map frame, the TCP: ``standoff`` in front of the wall) stands on the
    raster of ``SPRAY_AREA origin u width height normal spacing= standoff= run_in=``, in metres of its worked
    length (counted from the raster's start as its feedback and ``skip=`` are): on lane k at ``along`` m from
    the area's origin it is ``k (width + 2 run_in)`` plus the length of the lane's worked stretch behind it (a
    point before the stretch counts as its start, one past it as its end: the tool is off in the run-ups).
    None when the point is on no lane: farther than ``reach`` (default a quarter of the lane spacing) from every
    lane's height, in a turn between two lanes, more than ``depth`` off the standoff plane, or farther along the
    wall than a run-up past the area's ends (``RUN_UP_M``)."""
    o = [float(v) for v in origin]
    uu = _unit(u)
    n = _unit(normal)
    if uu is None or n is None:
        return None
    d = [float(point[k]) - o[k] for k in range(3)]
    along = sum(d[k] * uu[k] for k in range(3))
    up = d[2]
    off = sum(d[k] * n[k] for k in range(3))
    if abs(off - standoff) > depth or along < -run_in - RUN_UP_M or along > width + run_in + RUN_UP_M:
        return None
    reach = 0.25 * spacing if reach is None else reach
    heights = lane_heights(height, spacing)
    k = min(range(len(heights)), key=lambda i: abs(heights[i] - up))
    if abs(heights[k] - up) > reach:
        return None
    lane_len = width + 2.0 * run_in
    worked = along + run_in if k % 2 == 0 else width + run_in - along
    return k * lane_len + min(max(worked, 0.0), lane_len)


def _unit(v: Sequence[float]) -> Optional[Tuple[float, float, float]]:
    x, y, z = (float(c) for c in v)
    length = math.sqrt(x * x + y * y + z * z)
    return (x / length, y / length, z / length) if length > 1e-9 else None
