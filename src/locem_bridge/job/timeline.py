"""Where the time of a job went: intervals per layer, merged, and one wall-clock window split between layers.

ROS-free. The job benchmark (``bench/bench_job.py``) records time-stamped events from the running stack
(HICEM state changes, LOCEM command events, operator prompts, device motion samples, PEMKRE call records) and
turns them into intervals with the helpers here:

- :func:`merge`, :func:`clip`, :func:`total`, :func:`subtract`, :func:`intersect`: plain interval arithmetic on
  lists of ``(start, end)`` pairs (seconds, any common clock);
- :func:`spans_from_events`: pairs "started"/"ended" events by key (e.g. LOCEM command id, prompt id);
- :func:`activity_intervals`: turns periodic "moving or not" samples into intervals of motion;
- :func:`phase_spans`: turns a sequence of state snapshots (HICEM ``phase``, ``process``, ``action_type``) into
  spans, each lasting until the next snapshot;
- :func:`split_window`: assigns every instant of a window to the first layer (in priority order) that covers it,
  the rest to a remainder layer, so the parts add up to the window exactly.

Every function is pure: nothing is stored between calls. Bad input (an interval ending before it starts, a
window of negative length, an unknown event kind) raises :class:`TimelineError` naming what was wrong.
"""

from typing import Any, Dict, Hashable, Iterable, List, Mapping, Optional, Sequence, Tuple

Interval = Tuple[float, float]


class TimelineError(ValueError):
    """Input the interval helpers cannot use (an interval ending before it starts, an unknown event kind...)."""


def _checked(intervals: Iterable[Interval]) -> List[Interval]:
    out = []
    for item in intervals:
        try:
            start, end = float(item[0]), float(item[1])
        except (TypeError, ValueError, IndexError):
            raise TimelineError("an interval must be a (start, end) pair of numbers, got %r" % (item,)) from None
        if end < start:
            raise TimelineError("interval (%r, %r) ends before it starts" % (start, end))
        out.append((start, end))
    return out


def merge(intervals: Iterable[Interval], gap: float = 0.0) -> List[Interval]:
    """Union of ``intervals`` as sorted, disjoint intervals; pieces closer than ``gap`` seconds are joined."""
    if gap < 0:
        raise TimelineError("gap must be >= 0, got %r" % gap)
    items = sorted(_checked(intervals))
    out: List[Interval] = []
    for start, end in items:
        if out and start <= out[-1][1] + gap:
            if end > out[-1][1]:
                out[-1] = (out[-1][0], end)
        else:
            out.append((start, end))
    return out


def total(intervals: Iterable[Interval]) -> float:
    """Seconds covered by ``intervals`` (overlaps counted once)."""
    return sum(end - start for start, end in merge(intervals))


def clip(intervals: Iterable[Interval], start: float, end: float) -> List[Interval]:
    """The parts of ``intervals`` inside ``[start, end]`` (merged)."""
    if end < start:
        raise TimelineError("window (%r, %r) ends before it starts" % (start, end))
    out = []
    for a, b in merge(intervals):
        a, b = max(a, start), min(b, end)
        if b > a:
            out.append((a, b))
    return out


def intersect(a: Iterable[Interval], b: Iterable[Interval]) -> List[Interval]:
    """Instants covered by both ``a`` and ``b``."""
    left, right = merge(a), merge(b)
    out: List[Interval] = []
    i = j = 0
    while i < len(left) and j < len(right):
        lo, hi = max(left[i][0], right[j][0]), min(left[i][1], right[j][1])
        if hi > lo:
            out.append((lo, hi))
        if left[i][1] < right[j][1]:
            i += 1
        else:
            j += 1
    return out


def subtract(a: Iterable[Interval], b: Iterable[Interval]) -> List[Interval]:
    """Instants covered by ``a`` and not by ``b``."""
    out: List[Interval] = []
    cut = merge(b)
    for start, end in merge(a):
        cursor = start
        for c0, c1 in cut:
            if c1 <= cursor or c0 >= end:
                continue
            if c0 > cursor:
                out.append((cursor, c0))
            cursor = max(cursor, c1)
            if cursor >= end:
                break
        if cursor < end:
            out.append((cursor, end))
    return out


def split_window(window: Interval, layers: Sequence[Tuple[str, Iterable[Interval]]],
                 rest: str = "rest") -> Dict[str, float]:
    """Seconds of ``window`` per layer: an instant belongs to the first layer in ``layers`` covering it.

    ``layers`` is an ordered list of ``(name, intervals)``; the instants no layer covers go to ``rest``. The
    values add up to the window's length. A name used twice, or ``rest`` used as a layer name, is an error.
    """
    start, end = _checked([window])[0]
    names = [name for name, _ in layers]
    if len(set(names)) != len(names) or rest in names:
        raise TimelineError("layer names must be unique and differ from %r, got %s" % (rest, names))
    taken: List[Interval] = []
    out: Dict[str, float] = {}
    for name, intervals in layers:
        mine = subtract(clip(intervals, start, end), taken)
        out[name] = sum(b - a for a, b in mine)
        taken = merge(taken + mine)
    out[rest] = (end - start) - sum(out.values())
    if out[rest] < 0:  # rounding only
        out[rest] = 0.0
    return out


def spans_from_events(events: Iterable[Tuple[float, Hashable, str]], end: Optional[float] = None
                      ) -> Dict[Hashable, Interval]:
    """Pair ``(stamp, key, kind)`` events into one span per key; ``kind`` is ``"start"``, ``"event"`` or ``"end"``.

    A key's span runs from its first event to its ``"end"`` event (the first one; later events are ignored).
    A key that never ended runs until ``end`` (the end of the observation), or until its last event when
    ``end`` is None. Events may arrive out of order: they are sorted by stamp first.
    """
    first: Dict[Hashable, float] = {}
    last: Dict[Hashable, float] = {}
    closed: Dict[Hashable, float] = {}
    for stamp, key, kind in sorted(events, key=lambda e: float(e[0])):
        if kind not in ("start", "event", "end"):
            raise TimelineError("event kind must be start, event or end, got %r" % (kind,))
        if key in closed:
            continue
        stamp = float(stamp)
        first.setdefault(key, stamp)
        last[key] = stamp
        if kind == "end":
            closed[key] = stamp
    spans = {}
    for key, t0 in first.items():
        t1 = closed.get(key, last[key] if end is None else max(end, last[key]))
        spans[key] = (t0, t1)
    return spans


def activity_intervals(samples: Iterable[Tuple[float, bool]], max_period: float) -> List[Interval]:
    """Intervals of activity from periodic samples ``(stamp, active)``.

    An active sample covers the time back to the previous sample, but at most ``max_period`` seconds (a gap in
    the samples is not counted as activity). Consecutive active samples join into one interval.
    """
    if max_period <= 0:
        raise TimelineError("max_period must be > 0, got %r" % max_period)
    out: List[Interval] = []
    previous: Optional[float] = None
    for stamp, active in sorted(samples, key=lambda s: float(s[0])):
        stamp = float(stamp)
        if active:
            start = stamp - max_period if previous is None else max(previous, stamp - max_period)
            out.append((start, stamp))
        previous = stamp
    return merge(out)


def phase_spans(snapshots: Iterable[Tuple[float, Mapping[str, Any]]], end: float,
                keys: Sequence[str] = ("process", "phase", "action_type")) -> List[Dict[str, Any]]:
    """Spans of constant ``keys`` from state snapshots ``(stamp, state)``; the last one lasts until ``end``.

    Each span is ``{"start", "end", <key>: value...}``. Snapshots that change none of ``keys`` extend the current
    span. Snapshots are sorted by stamp first.
    """
    out: List[Dict[str, Any]] = []
    for stamp, state in sorted(snapshots, key=lambda s: float(s[0])):
        values = {k: state.get(k, "") for k in keys}
        if out and all(out[-1][k] == v for k, v in values.items()):
            continue
        if out:
            out[-1]["end"] = float(stamp)
        span: Dict[str, Any] = {"start": float(stamp), "end": float(stamp)}
        span.update(values)
        out.append(span)
    if out:
        out[-1]["end"] = max(float(end), out[-1]["start"])
    return out
