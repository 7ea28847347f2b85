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
"""
import re
from typing import Optional, Tuple

_NUM = r"(\d+(?:\.\d+)?)"
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
