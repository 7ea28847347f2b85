"""Progress along a raster, as LOCEM's area commands report it and HICEM keeps it.

A raster (``SPRAY_AREA``) is measured by its worked length: the lanes' stretches where the tool is on (each lane
with its run-in at both ends), laid end to end in the order they are worked; turns and run-ups do not count.
While it works, the command reports in its action feedback ``progress`` = done / total and the text
:func:`progress_text` (``"raster 2.350 of 11.520 m"``: metres of that length done so far, counted from the
raster's start, a skipped part included). HICEM reads the metres back with :func:`parse_progress_text` and, when
the command is cut (LOCEM killed, a link lost), passes them as ``skip=`` to the retried command, which then goes
on from that point instead of working the raster again from its start.
"""
import re
from typing import Optional, Tuple

_TEXT = re.compile(r"^raster (\d+(?:\.\d+)?) of (\d+(?:\.\d+)?) m$")


def progress_text(done_m: float, total_m: float) -> str:
    """The feedback text of ``done_m`` metres of a raster of ``total_m`` metres (mm resolution)."""
    return "raster %.3f of %.3f m" % (max(0.0, done_m), max(0.0, total_m))


def parse_progress_text(text: str) -> Optional[Tuple[float, float]]:
    """``(done_m, total_m)`` of a :func:`progress_text`; None for any other text (other feedback)."""
    m = _TEXT.match((text or "").strip())
    if not m:
        return None
    return float(m.group(1)), float(m.group(2))
